"""Contact solver: the collision pass and the contact pass of Guendelman, Bridson & Fedkiw (2003)
as the 2008 thesis adapted them, solved as sequential impulses.

- Collision pass (`resolve_iterations` sweeps, order alternating): contacts that the step's
  motion would close (predicted separation < 0) are resolved with the pre-step velocities and the
  pair's elasticity, aiming at -e times the approach speed they had before the pass.
- Contact pass (twice as many sweeps) after gravity: zero elasticity, the normal velocity may only
  close the remaining gap (speculative contacts), warm-started from last step's impulses.
- Position pass (after the contact pass): penetration beyond LINEAR_SLOP is removed through
  pseudo velocities that move the bodies this step and are then forgotten (split impulse), so
  correcting an overlap never adds kinetic energy to a resting pile.
- Sweep order: bottom to top along gravity, then top to bottom. Bridson et al. solve the
  deepest contacts first and the 2008 program chose a random order; ordering by height is what
  lets 20-box towers and brick walls converge in the 2008 iteration counts. (Guendelman's shock
  propagation was tried here too: its one-sided impulses made brick walls creep sideways.)

Impulses are accumulated per point and clamped (normal >= 0, friction inside its cone), which
converges where the 2008 per-iteration impulses could only approximate. Friction is Coulomb with
a friction circle: a point that was not slipping when the step began (slip speed below
STICKING_SPEED) may hold up to static_friction x normal impulse; a slipping one gets
dynamic_friction x normal impulse. Deciding per step, not per iteration, matters: early in a
sweep the normal impulse is still small, and a per-iteration rule would let a box that should
stick start sliding, and never stop. Pair rule: friction coefficients combine as the
geometric mean (SPEC 4), elasticity as the larger of the two (a bouncy body bounces on anything).
"""
import numpy as np
from numba import njit

from .constants import (LINEAR_SLOP, MAX_CORRECTION_SPEED, POSITION_CORRECTION,
                        RESTITUTION_THRESHOLD, STICKING_SPEED)
from .contact import ARM_A, ARM_B, DIRECTION, TURN_A, TURN_B
from .math3d import cross

# A row whose target is this low is not solved in that pass.
INACTIVE = -1.0e30


@njit(cache=True, nogil=True)
def tangent_basis(n):
    """Two unit tangents completing n to a right-handed basis."""
    if abs(n[0]) > 0.57735:
        inv = 1.0 / np.sqrt(n[0] * n[0] + n[1] * n[1])
        t1 = (n[1] * inv, -n[0] * inv, 0.0)
    else:
        inv = 1.0 / np.sqrt(n[1] * n[1] + n[2] * n[2])
        t1 = (0.0, n[2] * inv, -n[1] * inv)
    return t1, cross(n, t1)


@njit(cache=True, nogil=True)
def prepare_contacts(contacts, bodies, ground_material, gravity, dt):
    """Rows (directions, lever arms, angular responses, effective masses), pair materials, the
    targets of the three passes, and the warm-start friction projected onto this step's
    tangents."""
    ground_elasticity, ground_static, ground_dynamic = ground_material
    position, velocity = bodies.position, bodies.velocity
    inv_mass, inv_inertia = bodies.solver_inv_mass, bodies.inv_inertia_world
    static_row = len(bodies.active)
    rows, row_mass, row_inv_mass = contacts.rows, contacts.row_mass, contacts.row_inv_mass
    inv_dt = 1.0 / dt
    for c in range(contacts.count[0]):
        a, b = contacts.body_a[c], contacts.body_b[c]
        n = (contacts.normal[c, 0], contacts.normal[c, 1], contacts.normal[c, 2])
        p = contacts.point[c]
        r_a = (p[0] - position[a, 0], p[1] - position[a, 1], p[2] - position[a, 2])
        row_b = b if b >= 0 else static_row
        r_b = (p[0] - position[b, 0], p[1] - position[b, 1], p[2] - position[b, 2]) if b >= 0 else (0.0, 0.0, 0.0)
        contacts.velocity_a[c], contacts.velocity_b[c] = a, row_b
        m_a = inv_mass[a]
        m_b = inv_mass[b] if b >= 0 else 0.0
        row_inv_mass[c, 0], row_inv_mass[c, 1] = m_a, m_b
        t1, t2 = tangent_basis(n)
        for row, d in enumerate((n, t1, t2)):
            arm_a, arm_b = cross(r_a, d), cross(r_b, d)
            k = (m_a + m_b) * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            for e in range(3):
                turn_a = (inv_inertia[a, e, 0] * arm_a[0] + inv_inertia[a, e, 1] * arm_a[1]
                          + inv_inertia[a, e, 2] * arm_a[2])
                turn_b = (inv_inertia[b, e, 0] * arm_b[0] + inv_inertia[b, e, 1] * arm_b[1]
                          + inv_inertia[b, e, 2] * arm_b[2]) if b >= 0 else 0.0
                rows[c, row, DIRECTION + e] = d[e]
                rows[c, row, ARM_A + e], rows[c, row, ARM_B + e] = arm_a[e], arm_b[e]
                rows[c, row, TURN_A + e], rows[c, row, TURN_B + e] = turn_a, turn_b
                k += arm_a[e] * turn_a + arm_b[e] * turn_b
            row_mass[c, row] = 1.0 / k if k > 0.0 else 0.0
        if b >= 0:
            elasticity, mu_s, mu_d = (bodies.elasticity[b], bodies.static_friction[b],
                                      bodies.dynamic_friction[b])
        else:  # the ground, and the playground mesh, which is made of the same material
            elasticity, mu_s, mu_d = ground_elasticity, ground_static, ground_dynamic
        restitution = max(bodies.elasticity[a], elasticity)
        contacts.restitution[c] = restitution
        vn = v1 = v2 = 0.0
        for e in range(3):
            dv, wa, wb = velocity[row_b, e] - velocity[a, e], velocity[a, 3 + e], velocity[row_b, 3 + e]
            vn += n[e] * dv - rows[c, 0, ARM_A + e] * wa + rows[c, 0, ARM_B + e] * wb
            v1 += t1[e] * dv - rows[c, 1, ARM_A + e] * wa + rows[c, 1, ARM_B + e] * wb
            v2 += t2[e] * dv - rows[c, 2, ARM_A + e] * wa + rows[c, 2, ARM_B + e] * wb
        contacts.approach_speed[c] = vn
        if v1 * v1 + v2 * v2 < STICKING_SPEED * STICKING_SPEED:
            contacts.friction_coefficient[c] = np.sqrt(bodies.static_friction[a] * mu_s)
        else:
            contacts.friction_coefficient[c] = np.sqrt(bodies.dynamic_friction[a] * mu_d)
        depth = contacts.depth[c]
        # Collision pass: only contacts this step's motion would close (Guendelman: detect at
        # the predicted positions, resolve with the pre-step velocities).
        if vn < 0.0 and -depth + dt * vn < 0.0:
            contacts.collision_target[c] = -restitution * vn if vn < -RESTITUTION_THRESHOLD else 0.0
        else:
            contacts.collision_target[c] = INACTIVE
        # Contact pass: a speculative contact may close its gap this step, but no more.
        contacts.contact_target[c] = depth * inv_dt if depth < 0.0 else 0.0
        if depth > LINEAR_SLOP:
            contacts.position_target[c] = min(POSITION_CORRECTION * (depth - LINEAR_SLOP) * inv_dt,
                                              MAX_CORRECTION_SPEED)
        else:
            contacts.position_target[c] = INACTIVE
        contacts.collision_impulse[c] = 0.0
        contacts.collision_friction[c, 0] = contacts.collision_friction[c, 1] = 0.0
        contacts.position_impulse[c] = 0.0
        fw = contacts.friction_world[c]
        contacts.friction[c, 0] = fw[0] * t1[0] + fw[1] * t1[1] + fw[2] * t1[2]
        contacts.friction[c, 1] = fw[0] * t2[0] + fw[1] * t2[1] + fw[2] * t2[2]
    # Sweep order of the points: bottom to top along gravity, ties in detection order.
    count = contacts.count[0]
    heights = np.empty(count)
    for c in range(count):
        p = contacts.point[c]
        heights[c] = -(p[0] * gravity[0] + p[1] * gravity[1] + p[2] * gravity[2])
    contacts.solve_order[:count] = np.argsort(heights, kind="mergesort")


@njit(cache=True, nogil=True)
def solve_rows(velocity, contacts, sweeps, target, normal_impulse, friction, with_friction):
    """Sequential impulses over every point, `sweeps` times. Points are visited bottom to top
    along gravity, then top to bottom, alternating as the 2008 program alternated its order (no
    contact is always solved last, and so always wins): upward sweeps hand a stack's support up,
    downward ones its weight down, which converges tall stacks and walls in the 2008 iteration
    counts. Within a manifold that also puts the lowest (most loaded) corner first. Per point: the
    friction circle (when asked), then the normal row driven to at least its target with a
    non-negative accumulated impulse. A row's relative velocity is d . (v_B - v_A) + arm_B . w_B
    - arm_A . w_A; an impulse j along it changes v by -/+ inv_mass j d and w by -/+ j turn.
    (Per-point work is inlined: Numba would pay reference counting for each array passed to a
    helper.)"""
    rows, row_mass, row_inv_mass = contacts.rows, contacts.row_mass, contacts.row_inv_mass
    rows_a, rows_b, mu = contacts.velocity_a, contacts.velocity_b, contacts.friction_coefficient
    order, count = contacts.solve_order, contacts.count[0]
    for sweep in range(sweeps):
        for k in range(count):
            c = order[k] if sweep % 2 == 0 else order[count - 1 - k]
            goal = target[c]
            if goal <= INACTIVE:
                continue
            a, b = rows_a[c], rows_b[c]
            m_a, m_b = row_inv_mass[c, 0], row_inv_mass[c, 1]
            if with_friction:
                v1 = v2 = 0.0
                for e in range(3):
                    dv, wa, wb = velocity[b, e] - velocity[a, e], velocity[a, 3 + e], velocity[b, 3 + e]
                    v1 += rows[c, 1, DIRECTION + e] * dv - rows[c, 1, ARM_A + e] * wa + rows[c, 1, ARM_B + e] * wb
                    v2 += rows[c, 2, DIRECTION + e] * dv - rows[c, 2, ARM_A + e] * wa + rows[c, 2, ARM_B + e] * wb
                old1, old2 = friction[c, 0], friction[c, 1]
                new1, new2 = old1 - row_mass[c, 1] * v1, old2 - row_mass[c, 2] * v2
                magnitude = np.sqrt(new1 * new1 + new2 * new2)
                limit = mu[c] * normal_impulse[c]
                if magnitude > limit:
                    new1 *= limit / magnitude
                    new2 *= limit / magnitude
                friction[c, 0], friction[c, 1] = new1, new2
                d1, d2 = new1 - old1, new2 - old2
                for e in range(3):
                    linear = rows[c, 1, DIRECTION + e] * d1 + rows[c, 2, DIRECTION + e] * d2
                    velocity[a, e] -= m_a * linear
                    velocity[b, e] += m_b * linear
                    velocity[a, 3 + e] -= rows[c, 1, TURN_A + e] * d1 + rows[c, 2, TURN_A + e] * d2
                    velocity[b, 3 + e] += rows[c, 1, TURN_B + e] * d1 + rows[c, 2, TURN_B + e] * d2
            vn = 0.0
            for e in range(3):
                vn += (rows[c, 0, DIRECTION + e] * (velocity[b, e] - velocity[a, e])
                       - rows[c, 0, ARM_A + e] * velocity[a, 3 + e] + rows[c, 0, ARM_B + e] * velocity[b, 3 + e])
            old = normal_impulse[c]
            new = max(old + row_mass[c, 0] * (goal - vn), 0.0)
            normal_impulse[c] = new
            d = new - old
            for e in range(3):
                velocity[a, e] -= m_a * d * rows[c, 0, DIRECTION + e]
                velocity[b, e] += m_b * d * rows[c, 0, DIRECTION + e]
                velocity[a, 3 + e] -= d * rows[c, 0, TURN_A + e]
                velocity[b, 3 + e] += d * rows[c, 0, TURN_B + e]


@njit(cache=True, nogil=True)
def collision_pass(contacts, bodies, iterations):
    solve_rows(bodies.velocity, contacts, iterations, contacts.collision_target,
               contacts.collision_impulse, contacts.collision_friction, True)


@njit(cache=True, nogil=True)
def warm_start(contacts, bodies):
    """Applies last step's contact-pass impulses: stacks start each solve near the answer."""
    velocity, rows, row_inv_mass = bodies.velocity, contacts.rows, contacts.row_inv_mass
    for c in range(contacts.count[0]):
        a, b = contacts.velocity_a[c], contacts.velocity_b[c]
        pn, f1, f2 = contacts.impulse[c], contacts.friction[c, 0], contacts.friction[c, 1]
        for e in range(3):
            linear = rows[c, 0, DIRECTION + e] * pn + rows[c, 1, DIRECTION + e] * f1 + rows[c, 2, DIRECTION + e] * f2
            velocity[a, e] -= row_inv_mass[c, 0] * linear
            velocity[b, e] += row_inv_mass[c, 1] * linear
            velocity[a, 3 + e] -= rows[c, 0, TURN_A + e] * pn + rows[c, 1, TURN_A + e] * f1 + rows[c, 2, TURN_A + e] * f2
            velocity[b, 3 + e] += rows[c, 0, TURN_B + e] * pn + rows[c, 1, TURN_B + e] * f1 + rows[c, 2, TURN_B + e] * f2


@njit(cache=True, nogil=True)
def contact_pass(contacts, bodies, iterations):
    """Velocities (zero elasticity, friction), then the split-impulse position pass on the
    pseudo velocities; keeps the friction as a world vector for the next step's warm start."""
    solve_rows(bodies.velocity, contacts, iterations, contacts.contact_target, contacts.impulse,
               contacts.friction, True)
    solve_rows(bodies.pseudo_velocity, contacts, iterations, contacts.position_target,
               contacts.position_impulse, contacts.friction, False)
    rows = contacts.rows
    for c in range(contacts.count[0]):
        f1, f2 = contacts.friction[c, 0], contacts.friction[c, 1]
        for e in range(3):
            contacts.friction_world[c, e] = f1 * rows[c, 1, DIRECTION + e] + f2 * rows[c, 2, DIRECTION + e]
