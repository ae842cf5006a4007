"""Contact solver: the collision pass and the contact pass of Guendelman, Bridson & Fedkiw (2003)
as the 2008 thesis adapted them, solved as sequential impulses.

- Collision pass (`resolve_iterations` sweeps, order alternating): contacts that the step's
  motion would close (predicted separation < 0) are resolved with the pre-step velocities and the
  pair's elasticity, aiming at -e times the approach speed they had before the pass.
- Contact pass (twice as many sweeps) after gravity: zero elasticity, the normal velocity may only
  close the remaining gap (speculative contacts), warm-started from last step's impulses.
- Position pass (interleaved with the contact pass): penetration beyond LINEAR_SLOP is removed
  through pseudo velocities that move the bodies this step and are then forgotten (split
  impulse), so correcting an overlap never adds kinetic energy to a resting pile.

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


@njit(cache=True, nogil=True, inline="always")
def tangent_basis(n):
    """Two unit tangents completing n to a right-handed basis."""
    if abs(n[0]) > 0.57735:
        inv = 1.0 / np.sqrt(n[0] * n[0] + n[1] * n[1])
        t1 = (n[1] * inv, -n[0] * inv, 0.0)
    else:
        inv = 1.0 / np.sqrt(n[1] * n[1] + n[2] * n[2])
        t1 = (0.0, n[2] * inv, -n[1] * inv)
    t2 = (n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0])
    return t1, t2


@njit(cache=True, nogil=True, inline="always")
def angular_term(inv_inertia, r, d):
    """(r x d) . I^-1 (r x d): what a unit impulse along d at r costs in rotation."""
    cx, cy, cz = r[1] * d[2] - r[2] * d[1], r[2] * d[0] - r[0] * d[2], r[0] * d[1] - r[1] * d[0]
    ix = inv_inertia[0, 0] * cx + inv_inertia[0, 1] * cy + inv_inertia[0, 2] * cz
    iy = inv_inertia[1, 0] * cx + inv_inertia[1, 1] * cy + inv_inertia[1, 2] * cz
    iz = inv_inertia[2, 0] * cx + inv_inertia[2, 1] * cy + inv_inertia[2, 2] * cz
    return cx * ix + cy * iy + cz * iz


@njit(cache=True, nogil=True, inline="always")
def effective_mass(bodies, a, b, r_a, r_b, d):
    k = bodies.solver_inv_mass[a] + angular_term(bodies.inv_inertia_world[a], r_a, d)
    if b >= 0:
        k += bodies.solver_inv_mass[b] + angular_term(bodies.inv_inertia_world[b], r_b, d)
    return 1.0 / k if k > 0.0 else 0.0


@njit(cache=True, nogil=True, inline="always")
def relative_velocity(linear, angular, a, b, r_a, r_b):
    """Velocity of B's surface point minus A's, for the given velocity arrays."""
    va, wa = linear[a], angular[a]
    vx = -(va[0] + wa[1] * r_a[2] - wa[2] * r_a[1])
    vy = -(va[1] + wa[2] * r_a[0] - wa[0] * r_a[2])
    vz = -(va[2] + wa[0] * r_a[1] - wa[1] * r_a[0])
    if b >= 0:
        vb, wb = linear[b], angular[b]
        vx += vb[0] + wb[1] * r_b[2] - wb[2] * r_b[1]
        vy += vb[1] + wb[2] * r_b[0] - wb[0] * r_b[2]
        vz += vb[2] + wb[0] * r_b[1] - wb[1] * r_b[0]
    return vx, vy, vz


@njit(cache=True, nogil=True, inline="always")
def apply_body_impulse(bodies, linear, angular, body, r, px, py, pz):
    """Impulse p at lever arm r on one body; bodies that do not move ignore it."""
    if body < 0 or not bodies.awake[body]:
        return
    m = bodies.solver_inv_mass[body]
    linear[body, 0] += px * m
    linear[body, 1] += py * m
    linear[body, 2] += pz * m
    cx, cy, cz = r[1] * pz - r[2] * py, r[2] * px - r[0] * pz, r[0] * py - r[1] * px
    inv_i = bodies.inv_inertia_world[body]
    angular[body, 0] += inv_i[0, 0] * cx + inv_i[0, 1] * cy + inv_i[0, 2] * cz
    angular[body, 1] += inv_i[1, 0] * cx + inv_i[1, 1] * cy + inv_i[1, 2] * cz
    angular[body, 2] += inv_i[2, 0] * cx + inv_i[2, 1] * cy + inv_i[2, 2] * cz


@njit(cache=True, nogil=True, inline="always")
def apply_impulse(bodies, linear, angular, a, b, r_a, r_b, px, py, pz):
    """Impulse p on B at r_b and -p on A at r_a."""
    apply_body_impulse(bodies, linear, angular, a, r_a, -px, -py, -pz)
    apply_body_impulse(bodies, linear, angular, b, r_b, px, py, pz)


@njit(cache=True, nogil=True)
def prepare_contacts(contacts, bodies, ground_material):
    """Lever arms, tangents, effective masses, pair materials and approach speeds of every point,
    and the warm-start impulses applied to the velocities."""
    ground_elasticity, ground_static, ground_dynamic = ground_material
    for c in range(contacts.count[0]):
        a, b = contacts.body_a[c], contacts.body_b[c]
        n = contacts.normal[c]
        for e in range(3):
            contacts.r_a[c, e] = contacts.point[c, e] - bodies.position[a, e]
            contacts.r_b[c, e] = contacts.point[c, e] - bodies.position[b, e] if b >= 0 else 0.0
        r_a, r_b = contacts.r_a[c], contacts.r_b[c]
        t1, t2 = tangent_basis(n)
        for e in range(3):
            contacts.tangent1[c, e] = t1[e]
            contacts.tangent2[c, e] = t2[e]
        contacts.mass_normal[c] = effective_mass(bodies, a, b, r_a, r_b, n)
        contacts.mass_tangent1[c] = effective_mass(bodies, a, b, r_a, r_b, t1)
        contacts.mass_tangent2[c] = effective_mass(bodies, a, b, r_a, r_b, t2)
        if b >= 0:
            elasticity, mu_s, mu_d = (bodies.elasticity[b], bodies.static_friction[b],
                                      bodies.dynamic_friction[b])
        else:  # the ground, and the playground mesh, which is made of the same material
            elasticity, mu_s, mu_d = ground_elasticity, ground_static, ground_dynamic
        contacts.restitution[c] = max(bodies.elasticity[a], elasticity)
        v = relative_velocity(bodies.linear_velocity, bodies.angular_velocity, a, b, r_a, r_b)
        vn = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
        contacts.approach_speed[c] = vn
        slip_sq = v[0] ** 2 + v[1] ** 2 + v[2] ** 2 - vn * vn
        if slip_sq < STICKING_SPEED * STICKING_SPEED:
            contacts.friction_coefficient[c] = np.sqrt(bodies.static_friction[a] * mu_s)
        else:
            contacts.friction_coefficient[c] = np.sqrt(bodies.dynamic_friction[a] * mu_d)
        contacts.collision_impulse[c] = 0.0
        contacts.collision_friction[c, 0] = 0.0
        contacts.collision_friction[c, 1] = 0.0
        contacts.position_impulse[c] = 0.0
        fw = contacts.friction_world[c]
        contacts.friction[c, 0] = fw[0] * t1[0] + fw[1] * t1[1] + fw[2] * t1[2]
        contacts.friction[c, 1] = fw[0] * t2[0] + fw[1] * t2[1] + fw[2] * t2[2]


@njit(cache=True, nogil=True)
def warm_start(contacts, bodies):
    lin, ang = bodies.linear_velocity, bodies.angular_velocity
    for c in range(contacts.count[0]):
        n, t1, t2 = contacts.normal[c], contacts.tangent1[c], contacts.tangent2[c]
        pn, f1, f2 = contacts.impulse[c], contacts.friction[c, 0], contacts.friction[c, 1]
        apply_impulse(bodies, lin, ang, contacts.body_a[c], contacts.body_b[c], contacts.r_a[c],
                      contacts.r_b[c], pn * n[0] + f1 * t1[0] + f2 * t2[0],
                      pn * n[1] + f1 * t1[1] + f2 * t2[1], pn * n[2] + f1 * t1[2] + f2 * t2[2])


@njit(cache=True, nogil=True, inline="always")
def solve_friction(contacts, bodies, c, normal_impulse, friction):
    """Coulomb friction of point c given its accumulated normal impulse; `friction` is the (K, 2)
    accumulator of the pass."""
    a, b = contacts.body_a[c], contacts.body_b[c]
    r_a, r_b = contacts.r_a[c], contacts.r_b[c]
    t1, t2 = contacts.tangent1[c], contacts.tangent2[c]
    lin, ang = bodies.linear_velocity, bodies.angular_velocity
    v = relative_velocity(lin, ang, a, b, r_a, r_b)
    old1, old2 = friction[c, 0], friction[c, 1]
    new1 = old1 - contacts.mass_tangent1[c] * (v[0] * t1[0] + v[1] * t1[1] + v[2] * t1[2])
    new2 = old2 - contacts.mass_tangent2[c] * (v[0] * t2[0] + v[1] * t2[1] + v[2] * t2[2])
    magnitude = np.sqrt(new1 * new1 + new2 * new2)
    limit = contacts.friction_coefficient[c] * normal_impulse
    if magnitude > limit:
        new1 *= limit / magnitude
        new2 *= limit / magnitude
    friction[c, 0], friction[c, 1] = new1, new2
    d1, d2 = new1 - old1, new2 - old2
    apply_impulse(bodies, lin, ang, a, b, r_a, r_b, d1 * t1[0] + d2 * t2[0],
                  d1 * t1[1] + d2 * t2[1], d1 * t1[2] + d2 * t2[2])


@njit(cache=True, nogil=True, inline="always")
def solve_normal(contacts, bodies, linear, angular, c, target, accumulated):
    """Drives the normal velocity of point c (in the given velocity arrays) towards at least
    `target`, keeping the accumulated impulse non-negative. Returns the new accumulated impulse."""
    a, b = contacts.body_a[c], contacts.body_b[c]
    r_a, r_b, n = contacts.r_a[c], contacts.r_b[c], contacts.normal[c]
    v = relative_velocity(linear, angular, a, b, r_a, r_b)
    vn = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
    new = max(accumulated + contacts.mass_normal[c] * (target - vn), 0.0)
    delta = new - accumulated
    apply_impulse(bodies, linear, angular, a, b, r_a, r_b, delta * n[0], delta * n[1], delta * n[2])
    return new


@njit(cache=True, nogil=True, inline="always")
def sweep_order(count, sweep, k):
    """Alternates the order of the contact list between sweeps, as the 2008 program did, so no
    contact is always solved last (and so always wins)."""
    return k if sweep % 2 == 0 else count - 1 - k


@njit(cache=True, nogil=True)
def collision_pass(contacts, bodies, iterations, dt):
    count = contacts.count[0]
    for sweep in range(iterations):
        for k in range(count):
            c = sweep_order(count, sweep, k)
            approach = contacts.approach_speed[c]
            # Only contacts that this step's motion would close collide (Guendelman: detect at
            # the predicted positions, resolve with the pre-step velocities).
            if approach >= 0.0 or -contacts.depth[c] + dt * approach >= 0.0:
                continue
            target = -contacts.restitution[c] * approach if approach < -RESTITUTION_THRESHOLD else 0.0
            contacts.collision_impulse[c] = solve_normal(
                contacts, bodies, bodies.linear_velocity, bodies.angular_velocity, c, target,
                contacts.collision_impulse[c])
            solve_friction(contacts, bodies, c, contacts.collision_impulse[c],
                           contacts.collision_friction)


@njit(cache=True, nogil=True)
def contact_pass(contacts, bodies, iterations, dt):
    count = contacts.count[0]
    inv_dt = 1.0 / dt
    for sweep in range(iterations):
        for k in range(count):
            c = sweep_order(count, sweep, k)
            depth = contacts.depth[c]
            solve_friction(contacts, bodies, c, contacts.impulse[c], contacts.friction)
            # A speculative contact may close its gap this step, but no more.
            target = depth * inv_dt if depth < 0.0 else 0.0
            contacts.impulse[c] = solve_normal(contacts, bodies, bodies.linear_velocity,
                                               bodies.angular_velocity, c, target,
                                               contacts.impulse[c])
            if depth > LINEAR_SLOP:
                push = min(POSITION_CORRECTION * (depth - LINEAR_SLOP) * inv_dt, MAX_CORRECTION_SPEED)
                contacts.position_impulse[c] = solve_normal(
                    contacts, bodies, bodies.pseudo_velocity, bodies.pseudo_angular_velocity, c,
                    push, contacts.position_impulse[c])
    for c in range(count):
        t1, t2 = contacts.tangent1[c], contacts.tangent2[c]
        f1, f2 = contacts.friction[c, 0], contacts.friction[c, 1]
        for e in range(3):
            contacts.friction_world[c, e] = f1 * t1[e] + f2 * t2[e]


SHOCK_SWEEPS_PER_MANIFOLD = 4  # a manifold's points against a fixed support converge in a few


@njit(cache=True, nogil=True)
def shock_propagation(contacts, bodies, gravity, dt):
    """One more pass, manifold by manifold from the bottom up, in which the lower body of each
    load-bearing manifold has infinite mass (Guendelman et al. 2003, section 7): the support a
    stack's bottom box gets is handed up the stack within the step, where a fixed number of plain
    sweeps leaves tall stacks sinking and rocking. Each manifold is swept a few times in
    alternating order so its points share the load evenly (no spin from solving corners one at a
    time). Impulses of this pass are one-sided by design and not kept for warm starting."""
    count = contacts.manifold_count[0]
    g_norm = np.sqrt(gravity[0] ** 2 + gravity[1] ** 2 + gravity[2] ** 2)
    if count == 0 or g_norm == 0.0:
        return
    up = (-gravity[0] / g_norm, -gravity[1] / g_norm, -gravity[2] / g_norm)
    heights = np.empty(count)
    for m in range(count):
        p = contacts.point[contacts.manifold_start[m]]
        heights[m] = p[0] * up[0] + p[1] * up[1] + p[2] * up[2]
    lin, ang = bodies.linear_velocity, bodies.angular_velocity
    inv_dt = 1.0 / dt
    accumulated = np.zeros(4)
    for m in np.argsort(heights):
        start, size = contacts.manifold_start[m], contacts.manifold_size[m]
        a, b = contacts.body_a[start], contacts.body_b[start]
        n = contacts.normal[start]
        vertical = n[0] * up[0] + n[1] * up[1] + n[2] * up[2]
        if abs(vertical) < 0.5:
            continue  # side contacts carry no load of the stack
        # n points from A to B: with n pointing down, A is the upper body.
        upper, sign = (a, -1.0) if vertical < 0.0 else (b, 1.0)
        if upper < 0 or not bodies.awake[upper]:
            continue
        accumulated[:] = 0.0
        for sweep in range(SHOCK_SWEEPS_PER_MANIFOLD):
            for k in range(size):
                c = start + sweep_order(size, sweep, k)
                r = contacts.r_a[c] if upper == a else contacts.r_b[c]
                mass = 1.0 / (bodies.solver_inv_mass[upper]
                              + angular_term(bodies.inv_inertia_world[upper], r, n))
                depth = contacts.depth[c]
                target = depth * inv_dt if depth < 0.0 else 0.0
                v = relative_velocity(lin, ang, a, b, contacts.r_a[c], contacts.r_b[c])
                vn = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
                old = accumulated[k]
                accumulated[k] = max(old + mass * (target - vn), 0.0)
                p = (accumulated[k] - old) * sign
                apply_body_impulse(bodies, lin, ang, upper, r, p * n[0], p * n[1], p * n[2])
