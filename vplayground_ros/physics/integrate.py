"""Per-body stages of the step: derived quantities, velocity update, position update.

Explicit (symplectic) Euler as in the 2008 program: velocities first, positions from the new
velocities; exact for constant gravity in velocity, first order in position.
"""
import numpy as np
from numba import njit

from .broad_phase import object_level
from .constants import CONTACT_MARGIN
from .math3d import integrate_orientation, quat_to_matrix
from .shapes import world_extent


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def update_bodies(bodies, live, dt, root_size, depth):
    """Rotations, solver masses, speculative reach and the broad-phase bounds (grown by this
    step's motion) of the bodies `live` (slots). The step passes the bodies outside the static
    index: those in it have not moved since they were indexed (the World un-indexes a body it
    edits), so their derived state still holds, and a settled pile costs next to nothing."""
    velocity, position = bodies.velocity, bodies.position
    for k in range(len(live)):
        i = live[k]
        if not finite_state(bodies, i):
            quarantine(bodies, i)
            continue
        awake = not bodies.frozen[i] and not bodies.immovable[i]
        bodies.awake[i] = awake
        r = bodies.rotation[i]
        o = bodies.orientation  # (its row as a tuple: a row handed over costs a view a body)
        quat_to_matrix((o[i, 0], o[i, 1], o[i, 2], o[i, 3]), r)
        inv_i = bodies.inv_inertia_world[i]
        if awake:
            bodies.solver_inv_mass[i] = bodies.inv_mass[i]
            d = bodies.inv_inertia[i]
            # R D R^T as (R D) R^T: for a diagonal D (every shape but a convex one) each product
            # and sum is the one of the principal-axes formula, so a box's result is bitwise
            # what it was before the tensor became 3x3 (a 210-box pyramid's drift over 20 s,
            # chaotic, went from 6 to 14 mm with the other rounding).
            for row in range(3):
                a0 = r[row, 0] * d[0, 0] + r[row, 1] * d[1, 0] + r[row, 2] * d[2, 0]
                a1 = r[row, 0] * d[0, 1] + r[row, 1] * d[1, 1] + r[row, 2] * d[2, 1]
                a2 = r[row, 0] * d[0, 2] + r[row, 1] * d[1, 2] + r[row, 2] * d[2, 2]
                for col in range(3):
                    inv_i[row, col] = a0 * r[col, 0] + a1 * r[col, 1] + a2 * r[col, 2]
        else:
            bodies.solver_inv_mass[i] = 0.0
            for row in range(3):
                for col in range(3):
                    inv_i[row, col] = 0.0
        h = bodies.half_extents[i]
        speed = np.sqrt(velocity[i, 0] ** 2 + velocity[i, 1] ** 2 + velocity[i, 2] ** 2)
        # Surface points sweep at most |w| |h| dt by rotation (h: the bounding box's half extents).
        spin = (np.sqrt(velocity[i, 3] ** 2 + velocity[i, 4] ** 2 + velocity[i, 5] ** 2)
                * np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2))
        bodies.speculative_reach[i] = (speed + spin) * dt if awake else 0.0
        # Half the margin on each side: two bounds meet once the boxes are CONTACT_MARGIN apart.
        grow = spin * dt + 0.5 * CONTACT_MARGIN
        dims = (bodies.dimensions[i, 0], bodies.dimensions[i, 1], bodies.dimensions[i, 2])
        for e in range(3):
            extent = world_extent(bodies.shape[i], dims, r, e) + grow
            step = velocity[i, e] * dt
            bodies.aabb_min[i, e] = position[i, e] - extent + min(step, 0.0)
            bodies.aabb_max[i, e] = position[i, e] + extent + max(step, 0.0)
        lo, hi = bodies.aabb_min, bodies.aabb_max
        bodies.octree_level[i] = object_level((lo[i, 0], lo[i, 1], lo[i, 2]), (hi[i, 0], hi[i, 1], hi[i, 2]),
                                              root_size, depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def finite_state(bodies, i):
    total = 0.0
    for e in range(3):
        total += bodies.position[i, e]
    for e in range(4):
        total += bodies.orientation[i, e]
    for e in range(6):
        total += bodies.velocity[i, e]
    return np.isfinite(total)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def quarantine(bodies, i):
    """A body whose state went non-finite takes no part in the step (empty bounds, no mass), so
    it cannot spread NaN to others before the World removes it (World.remove_escaped)."""
    bodies.awake[i] = False
    bodies.solver_inv_mass[i] = 0.0
    bodies.inv_inertia_world[i, :, :] = 0.0
    bodies.speculative_reach[i] = 0.0
    bodies.aabb_min[i, :] = np.inf
    bodies.aabb_max[i, :] = -np.inf
    bodies.octree_level[i] = 0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def integrate_velocities(bodies, live, gravity, dt):
    """The gyroscopic term, gravity and the queued external impulses (cleared once applied), for
    the awake bodies among `live` (every awake body is: see pipeline.list_live_bodies)."""
    # Element by element: a body's rows taken as arrays and cleared as slices made this 52 us at
    # 1,000 bodies instead of 46 (the rest is the gyroscopic step, see isotropic).
    velocity, inv_i = bodies.velocity, bodies.inv_inertia_world
    j, l = bodies.external_impulse, bodies.external_angular_impulse
    for k in range(len(live)):
        i = live[k]
        if not bodies.awake[i]:
            continue
        m = bodies.inv_mass[i]
        if not isotropic(bodies.inv_inertia, i):  # (else w x I w = 0: the step keeps w)
            velocity[i, 3], velocity[i, 4], velocity[i, 5] = gyroscopic_step(
                inv_i[i], (velocity[i, 3], velocity[i, 4], velocity[i, 5]), dt)
        for e in range(3):
            velocity[i, e] += gravity[e] * dt + j[i, e] * m
            velocity[i, 3 + e] += inv_i[i, e, 0] * l[i, 0] + inv_i[i, e, 1] * l[i, 1] + inv_i[i, e, 2] * l[i, 2]
        for e in range(3):
            j[i, e] = l[i, e] = 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def isotropic(inv_inertia, i):
    """Body i's inertia is a multiple of the identity (a sphere's, a cube's): it turns about any
    axis alike, so no gyroscopic torque turns its angular velocity. The Newton iterations were
    most of a pile of cubes' velocity update (46 -> 9 us at 1,000) and moved w by rounding alone
    (1e-17 of itself, in 15 of 1,000 landing cubes: the world-frame tensor's rounding)."""
    return (inv_inertia[i, 0, 1] == 0.0 and inv_inertia[i, 0, 2] == 0.0 and inv_inertia[i, 1, 0] == 0.0
            and inv_inertia[i, 1, 2] == 0.0 and inv_inertia[i, 2, 0] == 0.0 and inv_inertia[i, 2, 1] == 0.0
            and inv_inertia[i, 0, 0] == inv_inertia[i, 1, 1] and inv_inertia[i, 1, 1] == inv_inertia[i, 2, 2])


# Newton iterations of the gyroscopic step: from w the first is Catto's; the second makes the
# midpoint rule's energy exact to rounding (one left 5e-6 of a tumbling box's in 20 s).
GYROSCOPIC_NEWTON_STEPS = 2
# The most a body turns (|w| dt, rad) in one solve of the gyroscopic step: a faster body's step
# is solved in as many equal pieces as that takes. Two Newton iterations from w converge while
# it turns less than about a radian; beyond, they did not, and an asymmetric body tumbling at
# 150 rad/s (2 rad a step at 128 Hz) gained 10^9 times its kinetic energy in 10 s.
GYROSCOPIC_MAX_TURN = 0.5
GYROSCOPIC_MAX_PIECES = 4096  # (1.7e4 rad/s, the speed limit, at 10 steps a second: 3,400)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def gyroscopic_step(inv_i, omega, dt):
    """The angular velocity after a step of torque-free rotation, I dw/dt = -w x I w (I the
    world inertia, inv_i its inverse): without it w stays fixed while the body turns, so an
    asymmetric body's angular momentum drifted by half in a few seconds of flight and nothing
    tumbled. The implicit midpoint rule, I (w' - w) + dt m x I m = 0 with m = (w + w') / 2,
    solved by Newton from w: it keeps the kinetic energy and |I w| exactly (a quadratic
    invariant), and the orientation's step turns the body about w', which leaves both as they
    are. Backward Euler (Catto, GDC 2015), used before, lost energy as (w dt)^2: a capsule
    tumbling at 2 rev/s lost a third of it a second."""
    inertia = inverse3(((inv_i[0, 0], inv_i[0, 1], inv_i[0, 2]), (inv_i[1, 0], inv_i[1, 1], inv_i[1, 2]),
                        (inv_i[2, 0], inv_i[2, 1], inv_i[2, 2])))
    turn = np.sqrt(omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]) * dt
    if not turn > GYROSCOPIC_MAX_TURN:  # (one piece: the arithmetic as it always was)
        return midpoint_rotation(inertia, omega, dt)
    pieces = min(int(np.ceil(turn / GYROSCOPIC_MAX_TURN)), GYROSCOPIC_MAX_PIECES)
    for _ in range(pieces):
        omega = midpoint_rotation(inertia, omega, dt / pieces)
    return omega


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def midpoint_rotation(inertia, omega, dt):
    """gyroscopic_step's implicit midpoint rule over `dt` with the world inertia `inertia` (rows
    as tuples), by GYROSCOPIC_NEWTON_STEPS Newton iterations from w."""
    (i00, i01, i02), (i10, i11, i12), (i20, i21, i22) = inertia
    w0, w1, w2 = omega
    x0, x1, x2 = w0, w1, w2  # w', the unknown
    h = 0.5 * dt
    for _ in range(GYROSCOPIC_NEWTON_STEPS):
        m0, m1, m2 = 0.5 * (w0 + x0), 0.5 * (w1 + x1), 0.5 * (w2 + x2)
        l0, l1, l2 = i00 * m0 + i01 * m1 + i02 * m2, i10 * m0 + i11 * m1 + i12 * m2, i20 * m0 + i21 * m1 + i22 * m2
        d0, d1, d2 = x0 - w0, x1 - w1, x2 - w2
        # Residual g = I (w' - w) + dt m x L; Jacobian dg/dw' = I + dt/2 (skew(m) I - skew(L)).
        g = (i00 * d0 + i01 * d1 + i02 * d2 + dt * (m1 * l2 - m2 * l1),
             i10 * d0 + i11 * d1 + i12 * d2 + dt * (m2 * l0 - m0 * l2),
             i20 * d0 + i21 * d1 + i22 * d2 + dt * (m0 * l1 - m1 * l0))
        jacobian = ((i00 + h * (m1 * i20 - m2 * i10), i01 + h * (m1 * i21 - m2 * i11 + l2),
                     i02 + h * (m1 * i22 - m2 * i12 - l1)),
                    (i10 + h * (m2 * i00 - m0 * i20 - l2), i11 + h * (m2 * i01 - m0 * i21),
                     i12 + h * (m2 * i02 - m0 * i22 + l0)),
                    (i20 + h * (m0 * i10 - m1 * i00 + l1), i21 + h * (m0 * i11 - m1 * i01 - l0),
                     i22 + h * (m0 * i12 - m1 * i02)))
        step = inverse3(jacobian)
        x0 -= step[0][0] * g[0] + step[0][1] * g[1] + step[0][2] * g[2]
        x1 -= step[1][0] * g[0] + step[1][1] * g[1] + step[1][2] * g[2]
        x2 -= step[2][0] * g[0] + step[2][1] * g[1] + step[2][2] * g[2]
    return x0, x1, x2


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def inverse3(m):
    """Inverse of a 3x3 matrix given and returned as a tuple of rows; zero if it is singular."""
    c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1]
    c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2]
    c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0]
    det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02
    if det == 0.0:
        return ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    inv = 1.0 / det
    return ((c00 * inv, (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv, (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv),
            (c01 * inv, (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv, (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv),
            (c02 * inv, (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv, (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def integrate_positions(bodies, live, dt):
    """Positions of the awake bodies among `live` from the solved velocities plus this step's
    position correction, which is then dropped so it never becomes momentum."""
    velocity, pseudo = bodies.velocity, bodies.pseudo_velocity
    for k in range(len(live)):
        i = live[k]
        if not bodies.awake[i]:
            continue
        for e in range(3):
            bodies.position[i, e] += (velocity[i, e] + pseudo[i, e]) * dt
        omega = (velocity[i, 3] + pseudo[i, 3], velocity[i, 4] + pseudo[i, 4],
                 velocity[i, 5] + pseudo[i, 5])
        q = bodies.orientation  # (rows as tuples and element writes: no view a body)
        q[i, 0], q[i, 1], q[i, 2], q[i, 3] = integrate_orientation((q[i, 0], q[i, 1], q[i, 2], q[i, 3]), omega, dt)
        for e in range(6):
            pseudo[i, e] = 0.0
