"""Per-body stages of the step: derived quantities, velocity update, position update.

Explicit (symplectic) Euler as in the 2008 program: velocities first, positions from the new
velocities; exact for constant gravity in velocity, first order in position.
"""
import numpy as np
from numba import njit

from .broad_phase import object_level
from .constants import CONTACT_MARGIN
from .math3d import integrate_orientation, quat_to_matrix


@njit(cache=True, nogil=True)
def update_body(bodies, i, dt, root_size, depth):
    """Rotation, solver masses and the broad-phase bounds (grown by this step's motion) of i."""
    awake = bodies.active[i] and not bodies.frozen[i] and not bodies.immovable[i]
    bodies.awake[i] = awake
    r = bodies.rotation[i]
    quat_to_matrix(bodies.orientation[i], r)
    inv_i = bodies.inv_inertia_world[i]
    if awake:
        bodies.solver_inv_mass[i] = bodies.inv_mass[i]
        d = bodies.inv_inertia[i]
        for row in range(3):
            for col in range(3):
                inv_i[row, col] = (r[row, 0] * d[0] * r[col, 0] + r[row, 1] * d[1] * r[col, 1]
                                   + r[row, 2] * d[2] * r[col, 2])
    else:
        bodies.solver_inv_mass[i] = 0.0
        inv_i[:, :] = 0.0
    h = bodies.half_extents[i]
    v, w = bodies.linear_velocity[i], bodies.angular_velocity[i]
    # Corners sweep at most |w| |h| dt by rotation; half the margin on each side so two bounds
    # meet once the boxes are within CONTACT_MARGIN.
    spin = np.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2) * np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
    grow = spin * dt + 0.5 * CONTACT_MARGIN
    for e in range(3):
        extent = abs(r[e, 0]) * h[0] + abs(r[e, 1]) * h[1] + abs(r[e, 2]) * h[2] + grow
        step = v[e] * dt
        bodies.aabb_min[i, e] = bodies.position[i, e] - extent + min(step, 0.0)
        bodies.aabb_max[i, e] = bodies.position[i, e] + extent + max(step, 0.0)
    bodies.octree_level[i] = object_level(bodies.aabb_min[i], bodies.aabb_max[i], root_size, depth)


@njit(cache=True, nogil=True)
def speculative_reach(bodies, i, dt):
    """How far body i's surface can move towards anything in one step."""
    if not bodies.awake[i]:
        return 0.0
    h, v, w = bodies.half_extents[i], bodies.linear_velocity[i], bodies.angular_velocity[i]
    speed = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    spin = np.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2) * np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
    return (speed + spin) * dt


@njit(cache=True, nogil=True)
def integrate_velocities(bodies, gravity, dt):
    """Gravity and the queued external impulses (cleared once applied)."""
    for i in range(len(bodies.active)):
        if not bodies.awake[i]:
            continue
        m = bodies.inv_mass[i]
        inv_i = bodies.inv_inertia_world[i]
        j, l = bodies.external_impulse[i], bodies.external_angular_impulse[i]
        for e in range(3):
            bodies.linear_velocity[i, e] += gravity[e] * dt + j[e] * m
            bodies.angular_velocity[i, e] += inv_i[e, 0] * l[0] + inv_i[e, 1] * l[1] + inv_i[e, 2] * l[2]
        j[:] = 0.0
        l[:] = 0.0


@njit(cache=True, nogil=True)
def integrate_positions(bodies, dt):
    """Positions from the solved velocities plus this step's position correction, which is then
    dropped so it never becomes momentum."""
    for i in range(len(bodies.active)):
        if not bodies.awake[i]:
            continue
        v, pv = bodies.linear_velocity[i], bodies.pseudo_velocity[i]
        w, pw = bodies.angular_velocity[i], bodies.pseudo_angular_velocity[i]
        for e in range(3):
            bodies.position[i, e] += (v[e] + pv[e]) * dt
        integrate_orientation(bodies.orientation[i], (w[0] + pw[0], w[1] + pw[1], w[2] + pw[2]), dt)
        pv[:] = 0.0
        pw[:] = 0.0
