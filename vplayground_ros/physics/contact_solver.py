"""Contact solver: the collision pass and the contact pass of Guendelman, Bridson & Fedkiw (2003)
as the 2008 thesis adapted them, solved as sequential impulses.

- Collision pass (`resolve_iterations` sweeps, order alternating): contacts that the step's
  motion would close (predicted separation < 0) faster than RESTITUTION_THRESHOLD are resolved
  with the pre-step velocities and the pair's elasticity, aiming at -e times the approach speed
  they had before the pass. Slower ones would not bounce: they are resting contacts, the contact
  pass's.
- Contact pass (twice as many sweeps) after gravity: zero elasticity, the normal velocity may only
  close the remaining gap (speculative contacts), warm-started from last step's impulses.
- Shock propagation (the contact pass's last pass, Guendelman et al. 2003): bottom up, each body
  against its supports as if they had infinite mass, on top of the contact pass's impulses; a
  body's one-sided impulses are taken back when they would give it kinetic energy.
- Position pass (after the contact pass): penetration beyond LINEAR_SLOP is removed through
  pseudo velocities that move the bodies this step and are then forgotten (split impulse), so
  correcting an overlap never adds kinetic energy to a resting pile.
- Sweep order: bottom to top along gravity, then top to bottom. Bridson et al. solve the
  deepest contacts first and the 2008 program chose a random order; ordering by height is what
  lets brick walls converge in the 2008 iteration counts; towers also need shock propagation.
  (Shock propagation on the normal rows alone, one manifold at a time, made walls creep
  sideways: it must take friction and all of a body's supports together.)

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
from numba import njit, prange

from .atomics import atomic_add, atomic_load, atomic_store, spin_pause, yield_thread
from .constants import (LINEAR_SLOP, MAX_CORRECTION_SPEED, POSITION_CORRECTION,
                        RESTITUTION_THRESHOLD, SHOCK_SWEEPS, SHOCK_TOLERANCE,
                        STICKING_SPEED)
from .contact import ARM_A, ARM_B, DIRECTION, TURN_A, TURN_B
from .joints import (COLLISION_IMPULSE, COLLISION_TARGET, CONTACT_TARGET, IMPULSE, islands_touched,
                     settle_island_impulses, solve_islands_alone, solve_joint_sweep)
from .math3d import cross
from .solve_schedule import shock_levels, split_chains, support_groups
from .sorting import stable_argsort

# Products may fuse with the sum they feed into one multiply-add (one rounding instead of two):
# the sweeps' dot products and impulse updates are mostly that, and fused the velocity sweeps
# took 10-18 % less time (the loose pile's landing, 3,400-4,000 points, hot). Nothing is
# reordered ("contract" only, not "fast"): every caller of the inlined point solve compiles the
# same fused arithmetic, so one and two threads stay bit-identical (test_parallel_solve).
SOLVER_MATH = {"contract"}

# A row whose target is this low is not solved in that pass.
INACTIVE = -1.0e30

# Passes with fewer points than this are solved by one thread: sharing a pass costs the split
# (about 12 ns a point) and a parallel region, whose second thread wakes some tens of us late;
# on a free core 10 sweeps over 4,000 points took 1.26-1.36 -> 0.85-1.10 ms, while the loose
# pile's median step (about 400 points) got slower with a threshold of 256.
PARALLEL_MIN_POINTS = 1000

# A pass in which more than 1/MAX_WAITING_SHARE of the points may wait for the other thread is
# solved by one thread after all: each wait hands a cache line across and stalls a thread, and
# the 20-row pyramid (a fifth of its points waiting) stepped 2.04-2.14 -> 2.22-2.40 ms with two
# threads on a free core. Piles have a few per cent.
MAX_WAITING_SHARE = 16

# The threads' shared counters stand this many int64 apart, a cache line each, so one thread's
# writes do not evict the line the other is spinning on.
SYNC_STRIDE = 8

# A waiting thread spins this many pauses (tens of microseconds) before giving up its core once:
# by then the thread it waits for has lost its own core to another process.
SPINS_BEFORE_YIELD = 2000

# A thread blocked on a chain that no thread has taken takes it after this many pauses: Numba's
# second thread, asleep between regions, usually starts within 5-20 us; one that comes later
# finds nothing left to take (the results are the same whoever runs what).
SPINS_BEFORE_TAKING = 1000

# Shared shock propagation: groups a thread claims at once (a landing box's group, 4 points and
# 10 sweeps, takes about a microsecond; a claim is an atomic add on a line both threads write),
# and the groups a level must have on average (a tower has one a level: the threads would wait
# for each other at every box).
SHOCK_CLAIM = 4
MIN_GROUPS_PER_LEVEL = 16

# Shock propagation's per-row view of a support point (the last axis of its scratch array):
# with the upper body's velocity u = (linear, angular), the row's relative velocity is
# BIAS + LINEAR . u_linear + ANGULAR . u_angular, and an impulse j along it adds
# j * PUSH_LINEAR and j * PUSH_ANGULAR to u.
BIAS, LINEAR, ANGULAR, PUSH_LINEAR, PUSH_ANGULAR, MASS, INV_MASS = 0, 1, 4, 7, 10, 13, 14
SHOCK_ROW_SIZE = 15


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def tangent_basis(n):
    """Two unit tangents completing n to a right-handed basis."""
    if abs(n[0]) > 0.57735:
        inv = 1.0 / np.sqrt(n[0] * n[0] + n[1] * n[1])
        t1 = (n[1] * inv, -n[0] * inv, 0.0)
    else:
        inv = 1.0 / np.sqrt(n[1] * n[1] + n[2] * n[2])
        t1 = (0.0, n[2] * inv, -n[1] * inv)
    return t1, cross(n, t1)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
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
        # Collision pass: contacts this step's motion would close (Guendelman: detect at the
        # predicted positions, resolve with the pre-step velocities), fast enough to bounce.
        # Slower ones are resting contacts, held by the contact pass's warm-started impulses:
        # this pass's impulses on them were cold-started, lopsided after a few sweeps, and
        # never taken back (the contact pass only adds), and they kept tall stacks rocking.
        if vn < -RESTITUTION_THRESHOLD and -depth + dt * vn < 0.0:
            contacts.collision_target[c] = -restitution * vn
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
        # Last step's friction impulses (warm_start_from) on this step's tangents: the contact
        # pass's, and shock propagation's (order_supports keeps those only on support points).
        fw, sw = contacts.friction_world[c], contacts.support_friction_world[c]
        contacts.friction[c, 0] = fw[0] * t1[0] + fw[1] * t1[1] + fw[2] * t1[2]
        contacts.friction[c, 1] = fw[0] * t2[0] + fw[1] * t2[1] + fw[2] * t2[2]
        contacts.support_friction[c, 0] = sw[0] * t1[0] + sw[1] * t1[1] + sw[2] * t1[2]
        contacts.support_friction[c, 1] = sw[0] * t2[0] + sw[1] * t2[1] + sw[2] * t2[2]
    # A manifold that this step's motion closes bounces at each of its points approaching fast
    # enough, not only at those whose own gap closes: two symmetric points of one flat contact
    # (equal depth, exactly v dt) were split by rounding, one bounced, and the body spun away.
    for m in range(contacts.manifold_count[0]):
        start, end = contacts.manifold_start[m], contacts.manifold_start[m] + contacts.manifold_size[m]
        closing = False
        for c in range(start, end):
            closing = closing or contacts.collision_target[c] > INACTIVE
        if not closing:
            continue
        for c in range(start, end):
            vn = contacts.approach_speed[c]
            if contacts.collision_target[c] == INACTIVE and vn < -RESTITUTION_THRESHOLD:
                contacts.collision_target[c] = -contacts.restitution[c] * vn
    # Sweep order of the points: bottom to top along gravity, ties in detection order.
    count = contacts.count[0]
    heights = np.empty(count)
    for c in range(count):
        p = contacts.point[c]
        heights[c] = -(p[0] * gravity[0] + p[1] * gravity[1] + p[2] * gravity[2])
    # Copied point by point, as build_ray_grid copies its rows: an array assigned to a slice or a
    # row compiles Numba's shape-mismatch message (number formatting, 2-3.5 s of a cold compile).
    by_height = stable_argsort(heights)
    for k in range(count):
        contacts.solve_order[k] = by_height[k]
    order_supports(contacts, bodies, gravity)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def order_supports(contacts, bodies, gravity):
    """Finds each point's upper body (the one the other holds up against gravity; none for side
    contacts, or when the upper one does not move) and groups the support points per upper
    body, bodies bottom to top by the height of their centre, ties by slot (a row of bricks
    stands at exactly one height), each body's points in detection order; the other points
    follow, in detection order.

    The bodies are sorted, not the points: a pile's landing has ~4 support points per body, and
    two stable sorts of every point (by body, then by height) were most of this function."""
    count = contacts.count[0]
    g = np.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])
    # Each upper body's rank among the uppers, uppers[rank] its slot and points[rank] how many
    # support points it has. rank is not initialised: rank[u] counts only while uppers[rank[u]]
    # points back at u (so a step costs its points, not the World's capacity).
    rank = np.empty(len(bodies.active), np.int64)
    uppers = np.empty(count, np.int64)
    points = np.empty(count, np.int64)
    n_uppers = 0
    supports = 0
    for c in range(count):
        contacts.support_body[c] = -1
        a, b = contacts.body_a[c], contacts.body_b[c]
        upper = -1  # no gravity: nothing holds anything up
        if g != 0.0:
            n = contacts.normal[c]
            # n points from A to B: pointing down, B holds A up.
            up = -(n[0] * gravity[0] + n[1] * gravity[1] + n[2] * gravity[2]) / g
            upper = a if up < -0.5 else (b if up > 0.5 else -1)
        # A jointed body is no upper: shock propagation moves the upper body alone, which
        # would pull it off its joints (it still holds up what rests on it).
        if upper < 0 or not bodies.awake[upper] or bodies.jointed[upper]:
            # Last step's one-sided impulses (warm_start_from, prepare_contacts) stay on a point
            # that is a support again; any other has none.
            contacts.support_impulse[c] = contacts.support_friction[c, 0] = contacts.support_friction[c, 1] = 0.0
            continue
        contacts.support_body[c] = upper
        m = contacts.row_inv_mass[c, 0] if upper == a else contacts.row_inv_mass[c, 1]
        arm, turn = (ARM_A, TURN_A) if upper == a else (ARM_B, TURN_B)
        for row in range(3):
            k = m
            for e in range(3):
                k += contacts.rows[c, row, arm + e] * contacts.rows[c, row, turn + e]
            contacts.support_mass[c, row] = 1.0 / k if k > 0.0 else 0.0
        r = rank[upper]
        if not (0 <= r < n_uppers and uppers[r] == upper):
            r = n_uppers
            rank[upper], uppers[r], points[r] = r, upper, 0
            n_uppers += 1
        points[r] += 1
        supports += 1
    # Uppers by slot, then (stably) by height.
    heights = np.empty(n_uppers)
    for r in range(n_uppers):
        p = bodies.position[uppers[r]]
        heights[r] = -(p[0] * gravity[0] + p[1] * gravity[1] + p[2] * gravity[2])
    slots = np.empty(n_uppers)
    for r in range(n_uppers):
        slots[r] = uppers[r]  # (exact as floats)
    by_slot = stable_argsort(slots)
    ranked = by_slot[stable_argsort(heights[by_slot])]
    # Each upper's first place in the order (reusing `points` as the running place).
    place = 0
    for k in range(n_uppers):
        r = ranked[k]
        place, points[r] = place + points[r], place
    for c in range(count):
        u = contacts.support_body[c]
        if u < 0:
            contacts.support_order[place] = c
            place += 1
        else:
            r = rank[u]
            contacts.support_order[points[r]] = c
            points[r] += 1
    contacts.support_count[0] = supports


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def select_points(contacts, target):
    """Puts the points a pass solves (target set) in contacts.sweep_points, in the sweep order;
    returns how many. Once a pass: the collision pass takes only fast closing contacts and the
    position pass only penetrating ones, and re-skipping the rest in every sweep cost more than
    solving them."""
    order, points = contacts.solve_order, contacts.sweep_points
    # A typed zero: a literal 0 made Numba compile solve_rows_shared (and split_chains) once
    # more for count == 0 while it typed this loop.
    count = np.int64(0)
    for k in range(contacts.count[0]):
        if target[order[k]] > INACTIVE:
            points[count] = order[k]
            count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def solve_rows(velocity, contacts, sweeps, target, normal_impulse, friction, with_friction, position,
               gravity, threads):
    """Sequential impulses over every point, `sweeps` times. Points are visited bottom to top
    along gravity, then top to bottom, alternating as the 2008 program alternated its order (no
    contact is always solved last, and so always wins): upward sweeps hand a stack's support up,
    downward ones its weight down, which converges tall stacks and walls in the 2008 iteration
    counts. Within a manifold that also puts the lowest (most loaded) corner first. With
    `threads` > 1 and enough points, two threads share the sweeps, with the same result
    (solve_schedule)."""
    count = select_points(contacts, target)
    solve_selected(velocity, contacts, sweeps, target, normal_impulse, friction, with_friction,
                   position, gravity, count, threads)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def solve_selected(velocity, contacts, sweeps, target, normal_impulse, friction, with_friction,
                   position, gravity, count, threads):
    """solve_rows' sweeps over the `count` points select_points chose."""
    points = contacts.sweep_points
    if threads > 1 and count >= PARALLEL_MIN_POINTS and solve_rows_shared(
            velocity, contacts, sweeps, target, normal_impulse, friction, with_friction, position,
            gravity, points, count, threads):
        return
    rows, row_mass, row_inv_mass = contacts.rows, contacts.row_mass, contacts.row_inv_mass
    rows_a, rows_b, mu = contacts.velocity_a, contacts.velocity_b, contacts.friction_coefficient
    for sweep in range(sweeps):
        solve_span(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, points, 0, count,
                   sweep % 2 == 1, target, normal_impulse, friction, with_friction)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def row_speed(rows, c, r, dv0, dv1, dv2, wa0, wa1, wa2, wb0, wb1, wb2):
    """Relative velocity along row r of point c: d . (v_B - v_A) - arm_A . w_A + arm_B . w_B."""
    speed = 0.0
    speed += rows[c, r, DIRECTION] * dv0 - rows[c, r, ARM_A] * wa0 + rows[c, r, ARM_B] * wb0
    speed += rows[c, r, DIRECTION + 1] * dv1 - rows[c, r, ARM_A + 1] * wa1 + rows[c, r, ARM_B + 1] * wb1
    speed += rows[c, r, DIRECTION + 2] * dv2 - rows[c, r, ARM_A + 2] * wa2 + rows[c, r, ARM_B + 2] * wb2
    return speed


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def solve_span(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, points, start, end,
               backwards, target, normal_impulse, friction, with_friction):
    """One sweep of sequential impulses over points[start:end] (backwards: from the end). Per
    point: the friction circle (when asked), then the normal row driven to at least its target
    with a non-negative accumulated impulse. A row's relative velocity is d . (v_B - v_A) +
    arm_B . w_B - arm_A . w_A; an impulse j along it changes v by -/+ inv_mass j d and w by -/+
    j turn. Static sides (no inverse mass, so no turn either) are not written: their change is
    zero, and two threads may share one (the ground). The two bodies' velocities are read into
    locals once a point and written back once (they are two rows: the broad phase pairs no body
    with itself, and only the ground is the static row): stored into `velocity` between the rows, they
    made the compiler read the rows again after every store (it cannot tell that the arrays do
    not overlap). (Inlined into its callers, and the per-point work inlined here: Numba would
    pay reference counting for each array passed to a call, and the two-thread solve calls this
    for every stretch of points between waits.)"""
    for k in range(start, end):
        c = points[end - 1 - (k - start)] if backwards else points[k]
        goal = target[c]
        a, b = rows_a[c], rows_b[c]
        m_a, m_b = row_inv_mass[c, 0], row_inv_mass[c, 1]
        va0, va1, va2, wa0, wa1, wa2 = (velocity[a, 0], velocity[a, 1], velocity[a, 2],
                                        velocity[a, 3], velocity[a, 4], velocity[a, 5])
        vb0, vb1, vb2, wb0, wb1, wb2 = (velocity[b, 0], velocity[b, 1], velocity[b, 2],
                                        velocity[b, 3], velocity[b, 4], velocity[b, 5])
        if with_friction:
            v1 = row_speed(rows, c, 1, vb0 - va0, vb1 - va1, vb2 - va2, wa0, wa1, wa2, wb0, wb1, wb2)
            v2 = row_speed(rows, c, 2, vb0 - va0, vb1 - va1, vb2 - va2, wa0, wa1, wa2, wb0, wb1, wb2)
            old1, old2 = friction[c, 0], friction[c, 1]
            new1, new2 = old1 - row_mass[c, 1] * v1, old2 - row_mass[c, 2] * v2
            magnitude = np.sqrt(new1 * new1 + new2 * new2)
            limit = mu[c] * normal_impulse[c]
            if magnitude > limit:
                new1 *= limit / magnitude
                new2 *= limit / magnitude
            friction[c, 0], friction[c, 1] = new1, new2
            d1, d2 = new1 - old1, new2 - old2
            linear0 = rows[c, 1, DIRECTION] * d1 + rows[c, 2, DIRECTION] * d2
            linear1 = rows[c, 1, DIRECTION + 1] * d1 + rows[c, 2, DIRECTION + 1] * d2
            linear2 = rows[c, 1, DIRECTION + 2] * d1 + rows[c, 2, DIRECTION + 2] * d2
            if m_a != 0.0:
                va0, va1, va2 = va0 - m_a * linear0, va1 - m_a * linear1, va2 - m_a * linear2
                wa0 -= rows[c, 1, TURN_A] * d1 + rows[c, 2, TURN_A] * d2
                wa1 -= rows[c, 1, TURN_A + 1] * d1 + rows[c, 2, TURN_A + 1] * d2
                wa2 -= rows[c, 1, TURN_A + 2] * d1 + rows[c, 2, TURN_A + 2] * d2
            if m_b != 0.0:
                vb0, vb1, vb2 = vb0 + m_b * linear0, vb1 + m_b * linear1, vb2 + m_b * linear2
                wb0 += rows[c, 1, TURN_B] * d1 + rows[c, 2, TURN_B] * d2
                wb1 += rows[c, 1, TURN_B + 1] * d1 + rows[c, 2, TURN_B + 1] * d2
                wb2 += rows[c, 1, TURN_B + 2] * d1 + rows[c, 2, TURN_B + 2] * d2
        vn = row_speed(rows, c, 0, vb0 - va0, vb1 - va1, vb2 - va2, wa0, wa1, wa2, wb0, wb1, wb2)
        old = normal_impulse[c]
        new = max(old + row_mass[c, 0] * (goal - vn), 0.0)
        normal_impulse[c] = new
        d = new - old
        if m_a != 0.0:
            velocity[a, 0] = va0 - m_a * d * rows[c, 0, DIRECTION]
            velocity[a, 1] = va1 - m_a * d * rows[c, 0, DIRECTION + 1]
            velocity[a, 2] = va2 - m_a * d * rows[c, 0, DIRECTION + 2]
            velocity[a, 3] = wa0 - d * rows[c, 0, TURN_A]
            velocity[a, 4] = wa1 - d * rows[c, 0, TURN_A + 1]
            velocity[a, 5] = wa2 - d * rows[c, 0, TURN_A + 2]
        if m_b != 0.0:
            velocity[b, 0] = vb0 + m_b * d * rows[c, 0, DIRECTION]
            velocity[b, 1] = vb1 + m_b * d * rows[c, 0, DIRECTION + 1]
            velocity[b, 2] = vb2 + m_b * d * rows[c, 0, DIRECTION + 2]
            velocity[b, 3] = wb0 + d * rows[c, 0, TURN_B]
            velocity[b, 4] = wb1 + d * rows[c, 0, TURN_B + 1]
            velocity[b, 5] = wb2 + d * rows[c, 0, TURN_B + 2]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def solve_rows_shared(velocity, contacts, sweeps, target, normal_impulse, friction, with_friction,
                      position, gravity, points, count, threads):
    """solve_rows' sweeps over points[:count] on up to two threads, bit for bit the serial
    result: the points go into two chains that wait for each other only where they share a body
    (solve_schedule), in one parallel region. False, having solved nothing, when too many
    points would wait: solve_rows then solves them on its own thread."""
    items = np.empty(count, np.int64)
    chain_start = np.empty(3, np.int64)
    need_up = np.empty(count, np.int64)
    need_down = np.empty(count, np.int64)
    publish_up = np.empty(count, np.bool_)
    publish_down = np.empty(count, np.bool_)
    waiting = split_chains(points, count, contacts, position, gravity, items, chain_start,
                           need_up, need_down, publish_up, publish_down)
    if waiting * MAX_WAITING_SHARE > count:
        return False
    # Which chains are taken, and each chain's progress, each on its own cache line.
    sync = np.zeros(3 * SYNC_STRIDE, np.int64)
    run_workers(min(threads, 2), velocity, contacts.rows, contacts.row_mass, contacts.row_inv_mass,
                contacts.velocity_a, contacts.velocity_b, contacts.friction_coefficient, target,
                normal_impulse, friction, with_friction, items, chain_start, need_up, need_down,
                publish_up, publish_down, sweeps, sync)
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH, parallel=True)
def run_workers(workers, velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, target,
                normal_impulse, friction, with_friction, items, chain_start, need_up, need_down,
                publish_up, publish_down, sweeps, sync):
    """One parallel region for a whole pass: Numba starts one in 5-20 us."""
    for _ in prange(workers):
        work_chains(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, target,
                    normal_impulse, friction, with_friction, items, chain_start, need_up,
                    need_down, publish_up, publish_down, sweeps, sync)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def work_chains(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, target,
                normal_impulse, friction, with_friction, items, chain_start, need_up, need_down,
                publish_up, publish_down, sweeps, sync):
    """One worker: takes a chain and runs its sweeps, each stretch of points that need not wait
    in one go, publishing its progress where the other chain may wait for it. A worker that has
    waited long for a chain nobody took, or has finished its own, takes that one too and runs
    both, interleaved: so one thread alone (the other late, or never started: Numba with one
    thread runs the region's iterations one after the other) does everything itself."""
    taken, progress = 0, SYNC_STRIDE  # sync[taken]: chains taken; sync[progress + c * SYNC_STRIDE]
    own = np.zeros(2, np.bool_)
    sweep = np.zeros(2, np.int64)
    done = np.zeros(2, np.int64)  # points done this sweep, per chain
    seen = np.zeros(2, np.int64)  # the other chain's progress, as last read
    length = np.empty(2, np.int64)
    for c in range(2):
        length[c] = chain_start[c + 1] - chain_start[c]
    c = atomic_add(sync, taken, 1)
    if c >= 2:
        return
    own[c] = True
    spins = 0
    while True:
        moved = False
        busy = False
        for c in range(2):
            if not own[c]:
                continue
            other = 1 - c
            while sweep[c] < sweeps:
                busy = True
                if done[c] == length[c]:
                    sweep[c] += 1
                    done[c] = 0
                    atomic_store(sync, progress + c * SYNC_STRIDE, sweep[c] * length[c])
                    continue
                upward = sweep[c] % 2 == 0
                base = sweep[c] * length[other]
                # The stretch of points that may run now, up to one the other chain may wait for.
                first = done[c]
                last = first
                while last < length[c]:
                    slot = chain_start[c] + (last if upward else length[c] - 1 - last)
                    need = base + (need_up[slot] if upward else need_down[slot])
                    if need > seen[other]:
                        if own[other]:
                            seen[other] = sweep[other] * length[other] + done[other]
                        else:
                            seen[other] = atomic_load(sync, progress + other * SYNC_STRIDE)
                        if need > seen[other]:
                            break
                    last += 1
                    if publish_up[slot] if upward else publish_down[slot]:
                        break
                if last == first:
                    break  # waits for the other chain
                if upward:
                    start, end = chain_start[c] + first, chain_start[c] + last
                else:
                    start, end = chain_start[c + 1] - last, chain_start[c + 1] - first
                solve_span(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu, items,
                           start, end, not upward, target, normal_impulse, friction, with_friction)
                done[c] = last
                atomic_store(sync, progress + c * SYNC_STRIDE, sweep[c] * length[c] + last)
                moved = True
        if not busy:
            # Own chains finished: take the other if nobody has (it cannot wait for ours).
            if own[0] and own[1] or atomic_load(sync, taken) >= 2:
                return
            c = atomic_add(sync, taken, 1)
            if c >= 2:
                return
            own[c] = True
            continue
        if moved:
            spins = 0
            continue
        spins += 1
        spin_pause()
        if spins % SPINS_BEFORE_YIELD == 0:
            yield_thread()
        if spins >= SPINS_BEFORE_TAKING and atomic_load(sync, taken) < 2:
            c = atomic_add(sync, taken, 1)
            if c < 2:
                own[c] = True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def collision_pass(contacts, bodies, iterations, gravity, threads):
    before, bouncing = velocities_before(contacts, bodies.velocity)
    solve_rows(bodies.velocity, contacts, iterations, contacts.collision_target,
               contacts.collision_impulse, contacts.collision_friction, True, bodies.position,
               gravity, threads)
    if bouncing:
        take_back_gains(contacts, bodies, before)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def velocities_before(contacts, velocity):
    """(K, 2, 6): the velocities of both sides of each point the collision pass solves, before
    it (only those points' rows are set: a large world pays for its collisions alone), and
    whether there is any such point."""
    before = np.empty((contacts.count[0], 2, 6))
    bouncing = False
    for c in range(contacts.count[0]):
        if contacts.collision_target[c] > INACTIVE:
            bouncing = True
            for e in range(6):
                before[c, 0, e] = velocity[contacts.velocity_a[c], e]
                before[c, 1, e] = velocity[contacts.velocity_b[c], e]
    return before, bouncing


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def take_back_gains(contacts, bodies, before):
    """A bounce off what does not move (the ground, the playground, frozen and immovable bodies)
    gives a body no energy; where the collision pass's sweeps, short of converged over many
    points, gave it some, its change is scaled back to the energy it had (`before`:
    velocities_before). A 20 cm box of elasticity 1 dropped onto a crease of the half-pipe (24
    points) had left with 1.11 times its energy; 20 sweeps instead of 5 gave 0.976. With the
    pass's impulses L on rows J, the change scaled by s changes the energy by s a + s^2 b / 2,
    a = L . J v_before, b = L . J (v_after - v_before); s = -2 a / b keeps it. Bodies that
    bounced off moving ones (energy passes between them) and jointed ones are left as the
    sweeps left them."""
    velocity, rows, count = bodies.velocity, contacts.rows, contacts.count[0]
    # Per body of the pass, by its rank among them (rank as in order_supports: not initialised,
    # valid while members[rank[body]] points back, so a step pays for its points, not the
    # World's capacity): a and b, a point of it, and whether it met a moving side.
    rank = np.empty(len(bodies.active) + 1, np.int64)
    members = np.empty(2 * count, np.int64)
    work = np.zeros((2 * count, 2))
    point = np.empty(2 * count, np.int64)
    mixed = np.zeros(2 * count, np.bool_)
    n = 0
    for c in range(count):
        if contacts.collision_target[c] <= INACTIVE:
            continue
        ra, rb = contacts.velocity_a[c], contacts.velocity_b[c]
        moving = (contacts.row_inv_mass[c, 0] != 0.0, contacts.row_inv_mass[c, 1] != 0.0)
        for side in range(2):
            if not moving[side]:
                continue
            body = ra if side == 0 else rb
            k = rank[body]
            if not (0 <= k < n and members[k] == body):
                k = n
                rank[body], members[k], point[k] = k, body, 2 * c + side
                n += 1
            if moving[1 - side]:
                mixed[k] = True
                continue
            for r in range(3):
                impulse = contacts.collision_impulse[c] if r == 0 else contacts.collision_friction[c, r - 1]
                if impulse == 0.0:
                    continue
                speed_before = row_speed(rows, c, r, before[c, 1, 0] - before[c, 0, 0],
                                         before[c, 1, 1] - before[c, 0, 1], before[c, 1, 2] - before[c, 0, 2],
                                         before[c, 0, 3], before[c, 0, 4], before[c, 0, 5],
                                         before[c, 1, 3], before[c, 1, 4], before[c, 1, 5])
                speed_after = row_speed(rows, c, r, velocity[rb, 0] - velocity[ra, 0],
                                        velocity[rb, 1] - velocity[ra, 1], velocity[rb, 2] - velocity[ra, 2],
                                        velocity[ra, 3], velocity[ra, 4], velocity[ra, 5],
                                        velocity[rb, 3], velocity[rb, 4], velocity[rb, 5])
                work[k, 0] += impulse * speed_before
                work[k, 1] += impulse * (speed_after - speed_before)
    for k in range(n):
        body = members[k]
        if mixed[k] or bodies.jointed[body]:
            continue
        a, b = work[k, 0], work[k, 1]
        if a + 0.5 * b <= 0.0 or b <= 0.0:
            continue  # no energy gained
        scale = -2.0 * a / b
        c, side = point[k] // 2, point[k] % 2
        for e in range(6):
            velocity[body, e] = before[c, side, e] + scale * (velocity[body, e] - before[c, side, e])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def collision_pass_with_joints(contacts, joints, bodies, iterations, gravity, threads):
    """collision_pass in a world with joints (worlds without do not hand the joints over:
    each array handed to a call costs it)."""
    # Typed flags: with a literal False here and True in the contact pass, Numba compiled
    # solve_with_joints twice (~11 s of the engine's cold compile).
    before, bouncing = velocities_before(contacts, bodies.velocity)
    solve_with_joints(bodies.velocity, contacts, joints, iterations, contacts.collision_target,
                      contacts.collision_impulse, contacts.collision_friction,
                      joints.row_values[:, :, COLLISION_TARGET],
                      joints.row_values[:, :, COLLISION_IMPULSE], np.bool_(False), bodies.position,
                      gravity, threads)
    if bouncing:
        take_back_gains(contacts, bodies, before)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def solve_with_joints(velocity, contacts, joints, sweeps, target, normal_impulse, friction,
                      joint_target, joint_impulse, with_motors, position, gravity, threads):
    """solve_rows' sweeps (with friction) with a sweep over the joint rows of the islands the
    pass's contact points touch after each, in alternating order too: one pass over both kinds
    of row, so a robot's wheels press on the ground through its axles. The islands no point
    touches are solved after (with the pile's contacts in between, their rows fell out of the
    cache every sweep: a KUKA arm beside a 200-box pile cost 4 times what it costs alone): at
    once where solved whole (solve_island_alone), else their sweeps in a row; the collision
    pass leaves them out (nothing hits them). Sweeps with joint rows run on the stepping thread
    alone (the two-thread schedule knows contacts only); when no point touches an island, the
    points are solve_rows' alone (and threads share them as in a world without joints)."""
    count = select_points(contacts, target)
    rows, row_mass, row_inv_mass = contacts.rows, contacts.row_mass, contacts.row_inv_mass
    rows_a, rows_b, mu = contacts.velocity_a, contacts.velocity_b, contacts.friction_coefficient
    touched = islands_touched(joints, rows_a, rows_b, contacts.sweep_points, count, len(velocity))
    if touched.any():
        for sweep in range(sweeps):
            backwards = sweep % 2 == 1
            solve_span(velocity, rows, row_mass, row_inv_mass, rows_a, rows_b, mu,
                       contacts.sweep_points, 0, count, backwards, target, normal_impulse, friction,
                       True)
            solve_joint_sweep(velocity, joints, joint_target, joint_impulse, backwards, with_motors,
                              touched)
    else:
        solve_selected(velocity, contacts, sweeps, target, normal_impulse, friction, True, position,
                       gravity, count, threads)
    if with_motors:
        by_joint = solve_islands_alone(velocity, joints, joint_target, joint_impulse, touched, sweeps)
        if by_joint.any():
            for sweep in range(sweeps):
                solve_joint_sweep(velocity, joints, joint_target, joint_impulse, sweep % 2 == 1,
                                  with_motors, by_joint)
    settle_island_impulses(joints, joint_impulse)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
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


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH)
def shock_propagation(contacts, bodies, threads):
    """Guendelman, Bridson & Fedkiw (2003) section 7: one last pass of the contact pass, from the
    bottom up, in which each body meets its supports as if they had infinite mass. Body by body,
    sweeps over its support points (up to SHOCK_SWEEPS, fewer once converged) drive the normal
    and friction rows on the totals (contact-pass impulse plus this pass's) to the contact
    pass's targets, changing only the upper body's velocity: what the supports below do is
    final by then, so a stack leaves the step as rigid as its lowest contact, however tall. Plain sweeps hand the load of a tall
    stack down and its overturning moment through every joint only a little per sweep; the part
    left over lets each joint tilt a little each step, gravity on the leaning stack turns that
    tilt into more, and a 20-box tower rocks while a 30-box one falls. The one-sided impulses
    are warm-started like the contact pass's: a resting stack leaves each step's contact pass
    with much the same residue, so the sweeps start near their answer (with up to 16 sweeps,
    resting stacks and a jostling pile took 8-10 a body instead of 12-15), and 10 warm sweeps
    hold stacks better than 16 cold ones did (SHOCK_SWEEPS: over 20 s the 55-brick wall drifted
    0.36 mm instead of 1.3, the 20-row pyramid 1.6 instead of 5.8).
    The impulses are one-sided: nothing pushes back on the supports. So they may take energy out
    of a body, never put it in (finish_group), or a support's leftover motion drives the stack
    above it.
    A body's sweeps are one chain of dependent arithmetic, so two groups that do not read each
    other's upper body run interleaved (shock_pair), which at the loose pile's landing takes
    about a fifth off the pass. With `threads` > 1 and enough support points, two threads share
    the groups level by level (solve_schedule.shock_levels). Either way the result is that of
    one group after the other."""
    order, supports, support_body = contacts.support_order, contacts.support_count[0], contacts.support_body
    group_start = np.empty(supports + 1, np.int64)
    groups = support_groups(order, supports, support_body, group_start)
    view = np.empty((supports, 3, SHOCK_ROW_SIZE))
    if threads > 1 and supports >= PARALLEL_MIN_POINTS and shock_propagation_shared(
            contacts, bodies, threads, group_start, groups, view):
        return
    # Groups in order, two at a time where the second does not read the first's upper body
    # (the first may read the second's: its velocity stays put until both are done): the
    # shared path's worker alone, all groups claimed at once, a pair being two places with
    # the same `need` (one kernel holds the inlined sweeps for both paths: a shorter compile).
    velocity_a, velocity_b = contacts.velocity_a, contacts.velocity_b
    by_level = np.arange(groups)
    need = np.empty(groups, np.int64)
    g = 0
    while g < groups:
        need[g] = g
        if g + 1 < groups and not reads_body(order, velocity_a, velocity_b, group_start[g + 1],
                                             group_start[g + 2], support_body[order[group_start[g]]]):
            need[g + 1] = g
            g += 2
        else:
            g += 1
    sync = np.zeros(2 * SYNC_STRIDE, np.int64)
    shock_worker(bodies.velocity, contacts.rows, contacts.row_inv_mass, contacts.contact_target,
                 contacts.friction_coefficient, contacts.impulse, contacts.friction,
                 contacts.support_impulse, contacts.support_friction, contacts.support_mass, order,
                 velocity_a, velocity_b, support_body, group_start, by_level, need, groups, sync,
                 view, np.int64(max(groups, 1)))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def shock_start(velocity, rows, row_inv_mass, shock, shock_friction, support_mass, order,
                velocity_a, velocity_b, group_start, group_end, upper, view):
    """Fills one group's view (what the supports below do is final, so their part of each
    row's relative velocity is taken once, BIAS) and returns its upper body's velocity with
    last step's one-sided impulses applied again (a resting stack's sweeps start near their
    answer)."""
    for k in range(group_start, group_end):
        c = order[k]
        if upper == velocity_a[c]:
            sign, m, arm, turn, below, below_arm = -1.0, row_inv_mass[c, 0], ARM_A, TURN_A, velocity_b[c], ARM_B
        else:
            sign, m, arm, turn, below, below_arm = 1.0, row_inv_mass[c, 1], ARM_B, TURN_B, velocity_a[c], ARM_A
        for r in range(3):
            bias = 0.0
            for e in range(3):
                bias -= sign * (rows[c, r, DIRECTION + e] * velocity[below, e]
                                + rows[c, r, below_arm + e] * velocity[below, 3 + e])
                view[k, r, LINEAR + e] = sign * rows[c, r, DIRECTION + e]
                view[k, r, ANGULAR + e] = sign * rows[c, r, arm + e]
                view[k, r, PUSH_LINEAR + e] = sign * m * rows[c, r, DIRECTION + e]
                view[k, r, PUSH_ANGULAR + e] = sign * rows[c, r, turn + e]
            view[k, r, BIAS] = bias
            mass = support_mass[c, r]
            view[k, r, MASS] = mass
            view[k, r, INV_MASS] = 1.0 / mass if mass > 0.0 else 0.0
    u0, u1, u2, u3, u4, u5 = (velocity[upper, 0], velocity[upper, 1], velocity[upper, 2],
                              velocity[upper, 3], velocity[upper, 4], velocity[upper, 5])
    for k in range(group_start, group_end):
        c = order[k]
        j0, j1, j2 = shock[c], shock_friction[c, 0], shock_friction[c, 1]
        u0 += view[k, 0, PUSH_LINEAR + 0] * j0 + view[k, 1, PUSH_LINEAR + 0] * j1 + view[k, 2, PUSH_LINEAR + 0] * j2
        u1 += view[k, 0, PUSH_LINEAR + 1] * j0 + view[k, 1, PUSH_LINEAR + 1] * j1 + view[k, 2, PUSH_LINEAR + 1] * j2
        u2 += view[k, 0, PUSH_LINEAR + 2] * j0 + view[k, 1, PUSH_LINEAR + 2] * j1 + view[k, 2, PUSH_LINEAR + 2] * j2
        u3 += view[k, 0, PUSH_ANGULAR + 0] * j0 + view[k, 1, PUSH_ANGULAR + 0] * j1 + view[k, 2, PUSH_ANGULAR + 0] * j2
        u4 += view[k, 0, PUSH_ANGULAR + 1] * j0 + view[k, 1, PUSH_ANGULAR + 1] * j1 + view[k, 2, PUSH_ANGULAR + 1] * j2
        u5 += view[k, 0, PUSH_ANGULAR + 2] * j0 + view[k, 1, PUSH_ANGULAR + 2] * j1 + view[k, 2, PUSH_ANGULAR + 2] * j2
    return u0, u1, u2, u3, u4, u5


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def view_speed(view, k, r, start, u):
    """start + row r of support point k's view (LINEAR, ANGULAR) . u, u = (linear, angular):
    with start = the row's BIAS, the row's relative velocity."""
    return (start + view[k, r, LINEAR] * u[0] + view[k, r, LINEAR + 1] * u[1] + view[k, r, LINEAR + 2] * u[2]
            + view[k, r, ANGULAR] * u[3] + view[k, r, ANGULAR + 1] * u[4] + view[k, r, ANGULAR + 2] * u[5])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def shock_point(u, k, c, view, target, mu, impulse, friction, shock, shock_friction):
    """One support point of a sweep: the friction circle on the total friction, then the
    normal row on the total. Returns the upper body's new velocity and the largest velocity
    change a row made. (The point's one-sided impulses are stored last, after every read:
    a store between them made the compiler read again what it had read before.)"""
    shock0, shock1, shock2 = shock[c], shock_friction[c, 0], shock_friction[c, 1]
    contact_impulse = impulse[c]
    v1 = view_speed(view, k, 1, view[k, 1, BIAS], u)
    v2 = view_speed(view, k, 2, view[k, 2, BIAS], u)
    old1 = friction[c, 0] + shock1
    old2 = friction[c, 1] + shock2
    new1 = old1 - view[k, 1, MASS] * v1
    new2 = old2 - view[k, 2, MASS] * v2
    magnitude = np.sqrt(new1 * new1 + new2 * new2)
    # Until this sweep's normal row has run, the total is negative where last step's one-sided
    # impulse (the warm start) outweighs this step's contact pass: no friction then (a negative
    # limit turned the friction round and kept its size).
    total = contact_impulse + shock0
    limit = mu[c] * max(total, 0.0)
    if magnitude > limit:
        new1 *= limit / magnitude
        new2 *= limit / magnitude
    d1, d2 = new1 - old1, new2 - old2
    largest = max(abs(d1) * view[k, 1, INV_MASS], abs(d2) * view[k, 2, INV_MASS])
    u0, u1, u2, u3, u4, u5 = u
    u0 += view[k, 1, PUSH_LINEAR + 0] * d1 + view[k, 2, PUSH_LINEAR + 0] * d2
    u1 += view[k, 1, PUSH_LINEAR + 1] * d1 + view[k, 2, PUSH_LINEAR + 1] * d2
    u2 += view[k, 1, PUSH_LINEAR + 2] * d1 + view[k, 2, PUSH_LINEAR + 2] * d2
    u3 += view[k, 1, PUSH_ANGULAR + 0] * d1 + view[k, 2, PUSH_ANGULAR + 0] * d2
    u4 += view[k, 1, PUSH_ANGULAR + 1] * d1 + view[k, 2, PUSH_ANGULAR + 1] * d2
    u5 += view[k, 1, PUSH_ANGULAR + 2] * d1 + view[k, 2, PUSH_ANGULAR + 2] * d2
    vn = view_speed(view, k, 0, view[k, 0, BIAS], (u0, u1, u2, u3, u4, u5))
    d = max(total + view[k, 0, MASS] * (target[c] - vn), 0.0) - total
    largest = max(largest, abs(d) * view[k, 0, INV_MASS])
    shock_friction[c, 0], shock_friction[c, 1] = shock1 + d1, shock2 + d2
    shock[c] = shock0 + d
    return ((u0 + view[k, 0, PUSH_LINEAR + 0] * d, u1 + view[k, 0, PUSH_LINEAR + 1] * d,
             u2 + view[k, 0, PUSH_LINEAR + 2] * d, u3 + view[k, 0, PUSH_ANGULAR + 0] * d,
             u4 + view[k, 0, PUSH_ANGULAR + 1] * d, u5 + view[k, 0, PUSH_ANGULAR + 2] * d), largest)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def finish_group(velocity, body, u, order, group_start, group_end, view, shock, shock_friction):
    """Stores the upper body's new velocity u, unless the group's one-sided impulses gave it
    kinetic energy: then they are taken back (the body keeps its velocity from before the
    group, and the impulses are zeroed: none applied, none carried to the next step). They
    hand a support's motion up without pushing back on it, so a support's spurious motion (what
    the sweeps left unconverged) made the whole stack above it move, from nothing. A column of
    six boxes balanced on an edge between two neighbours was pumped so for ever in a settled
    10,000-box pile (~35 J in 5 s), never froze, and kept its neighbours awake. Energy gained:
    1/2 J . (u_before + u_after), J the group's impulses (its rows' LINEAR, ANGULAR times each
    row's total): exact, since u_after - u_before is the inverse mass times J."""
    both = (velocity[body, 0] + u[0], velocity[body, 1] + u[1], velocity[body, 2] + u[2],
            velocity[body, 3] + u[3], velocity[body, 4] + u[4], velocity[body, 5] + u[5])
    work = 0.0
    for k in range(group_start, group_end):
        c = order[k]
        for r in range(3):
            j = shock[c] if r == 0 else shock_friction[c, r - 1]
            work += j * view_speed(view, k, r, 0.0, both)
    if work > 0.0:
        for k in range(group_start, group_end):
            c = order[k]
            shock[c] = shock_friction[c, 0] = shock_friction[c, 1] = 0.0
        return
    velocity[body, 0], velocity[body, 1], velocity[body, 2] = u[0], u[1], u[2]
    velocity[body, 3], velocity[body, 4], velocity[body, 5] = u[3], u[4], u[5]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def shock_group(velocity, rows, row_inv_mass, target, mu, impulse, friction, shock, shock_friction,
                support_mass, order, velocity_a, velocity_b, group_start, group_end, upper, view):
    """Shock propagation's sweeps over one upper body's support points, order[group_start:
    group_end]: they change its velocity (and their one-sided impulses) only. `view` is scratch
    (support points, 3, SHOCK_ROW_SIZE), indexed by place in `order`."""
    u = shock_start(velocity, rows, row_inv_mass, shock, shock_friction, support_mass, order,
                    velocity_a, velocity_b, group_start, group_end, upper, view)
    size = group_end - group_start
    for sweep in range(SHOCK_SWEEPS):
        largest = 0.0  # the largest velocity change of this sweep
        for i in range(size):
            k = group_start + (i if sweep % 2 == 0 else size - 1 - i)
            u, change = shock_point(u, k, order[k], view, target, mu, impulse, friction, shock,
                                    shock_friction)
            largest = max(largest, change)
        if largest < SHOCK_TOLERANCE:
            break
    finish_group(velocity, upper, u, order, group_start, group_end, view, shock, shock_friction)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def shock_pair(velocity, rows, row_inv_mass, target, mu, impulse, friction, shock, shock_friction,
               support_mass, order, velocity_a, velocity_b, start_a, end_a, upper_a, start_b,
               end_b, upper_b, view):
    """shock_group of group A then group B, at once: each group's sweeps are one chain of
    dependent arithmetic (every point waits for the velocity the one before it left), so
    interleaving two chains lets the core work on one while the other waits. B must not read
    A's upper body; A may read B's, since a group reads the bodies below it only in shock_start,
    before either stores. Each group's arithmetic and sweep count are its own: the same result
    as one group after the other."""
    u_a = shock_start(velocity, rows, row_inv_mass, shock, shock_friction, support_mass, order,
                      velocity_a, velocity_b, start_a, end_a, upper_a, view)
    u_b = shock_start(velocity, rows, row_inv_mass, shock, shock_friction, support_mass, order,
                      velocity_a, velocity_b, start_b, end_b, upper_b, view)
    size_a, size_b = end_a - start_a, end_b - start_b
    running_a = running_b = True
    for sweep in range(SHOCK_SWEEPS):
        largest_a = largest_b = 0.0
        for i in range(max(size_a if running_a else 0, size_b if running_b else 0)):
            if running_a and i < size_a:
                k = start_a + (i if sweep % 2 == 0 else size_a - 1 - i)
                u_a, change = shock_point(u_a, k, order[k], view, target, mu, impulse, friction,
                                          shock, shock_friction)
                largest_a = max(largest_a, change)
            if running_b and i < size_b:
                k = start_b + (i if sweep % 2 == 0 else size_b - 1 - i)
                u_b, change = shock_point(u_b, k, order[k], view, target, mu, impulse, friction,
                                          shock, shock_friction)
                largest_b = max(largest_b, change)
        running_a = running_a and not largest_a < SHOCK_TOLERANCE
        running_b = running_b and not largest_b < SHOCK_TOLERANCE
        if not (running_a or running_b):
            break
    finish_group(velocity, upper_a, u_a, order, start_a, end_a, view, shock, shock_friction)
    if end_b > start_b:  # B empty: A alone, as shock_group (B's body is not written)
        finish_group(velocity, upper_b, u_b, order, start_b, end_b, view, shock, shock_friction)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH)
def reads_body(order, velocity_a, velocity_b, start, end, body):
    """Whether any point of order[start:end] has `body` on one of its sides."""
    for k in range(start, end):
        c = order[k]
        if velocity_a[c] == body or velocity_b[c] == body:
            return True
    return False


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def shock_propagation_shared(contacts, bodies, threads, group_start, groups, view):
    """shock_propagation on up to two threads, bit for bit the serial result: the groups
    (support_groups) level by level (solve_schedule.shock_levels), claimed a few at a time by
    whichever thread is free, each run once every group of the levels below it is done. False,
    having solved nothing, when the levels are too thin to share."""
    order = contacts.support_order
    by_level = np.empty(groups, np.int64)
    level_start = np.empty(groups + 1, np.int64)
    levels = shock_levels(order, contacts.support_body, contacts.velocity_a, contacts.velocity_b,
                          len(bodies.active) + 1, group_start, groups, by_level, level_start)
    if groups < MIN_GROUPS_PER_LEVEL * levels:
        return False
    # How many groups must be done before the one in each place may run: its level's start.
    need = np.empty(groups, np.int64)
    for level in range(levels):
        need[level_start[level]:level_start[level + 1]] = level_start[level]
    sync = np.zeros(2 * SYNC_STRIDE, np.int64)  # groups claimed; groups done (a line each)
    run_shock_workers(min(threads, 2), bodies.velocity, contacts.rows, contacts.row_inv_mass,
                      contacts.contact_target, contacts.friction_coefficient, contacts.impulse,
                      contacts.friction, contacts.support_impulse, contacts.support_friction,
                      contacts.support_mass, order, contacts.velocity_a, contacts.velocity_b,
                      contacts.support_body, group_start, by_level, need, groups, sync, view)
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH, parallel=True)
def run_shock_workers(workers, velocity, rows, row_inv_mass, target, mu, impulse, friction, shock,
                      shock_friction, support_mass, order, velocity_a, velocity_b, support_body,
                      group_start, by_level, need, groups, sync, view):
    for _ in prange(workers):
        shock_worker(velocity, rows, row_inv_mass, target, mu, impulse, friction, shock,
                     shock_friction, support_mass, order, velocity_a, velocity_b, support_body,
                     group_start, by_level, need, groups, sync, view, np.int64(SHOCK_CLAIM))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def shock_worker(velocity, rows, row_inv_mass, target, mu, impulse, friction, shock,
                 shock_friction, support_mass, order, velocity_a, velocity_b, support_body,
                 group_start, by_level, need, groups, sync, view, claim):
    """One thread of the shared shock propagation: claims `claim` groups at a time, in
    level order, until none are left. A thread alone (the other late, or Numba running the
    region's iterations one after the other) claims and runs them all: every group it waits
    for was claimed before its own, by itself (done) or by a thread that is running."""
    claimed, done = 0, SYNC_STRIDE
    while True:
        first = atomic_add(sync, claimed, claim)
        if first >= groups:
            return
        last = min(first + claim, groups)
        place = first
        while place < last:
            spins = 0
            while atomic_load(sync, done) < need[place]:
                spins += 1
                spin_pause()
                if spins % SPINS_BEFORE_YIELD == 0:
                    yield_thread()
            g = by_level[place]
            start, end = group_start[g], group_start[g + 1]
            upper = support_body[order[start]]
            if place + 1 < last and need[place + 1] == need[place]:  # one level: independent
                h = by_level[place + 1]
                start_b, end_b = group_start[h], group_start[h + 1]
                upper_b = support_body[order[start_b]]
                count = 2
            else:  # one group: a pair with an empty second (one call site: the sweeps inlined once)
                start_b = end_b = end
                upper_b = upper
                count = 1
            shock_pair(velocity, rows, row_inv_mass, target, mu, impulse, friction, shock,
                       shock_friction, support_mass, order, velocity_a, velocity_b, start, end,
                       upper, start_b, end_b, upper_b, view)
            atomic_add(sync, done, count)
            place += count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def contact_pass(contacts, bodies, iterations, gravity, threads):
    """Velocities (zero elasticity, friction), shock propagation, then the split-impulse
    position pass on the pseudo velocities; keeps the friction as a world vector for the next
    step's warm start."""
    solve_rows(bodies.velocity, contacts, iterations, contacts.contact_target, contacts.impulse,
               contacts.friction, True, bodies.position, gravity, threads)
    finish_contact_pass(contacts, bodies, iterations, gravity, threads)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, fastmath=SOLVER_MATH)
def contact_pass_with_joints(contacts, joints, bodies, iterations, gravity, threads):
    """contact_pass in a world with joints: their rows in each velocity sweep."""
    solve_with_joints(bodies.velocity, contacts, joints, iterations, contacts.contact_target,
                      contacts.impulse, contacts.friction, joints.row_values[:, :, CONTACT_TARGET],
                      joints.row_values[:, :, IMPULSE], np.bool_(True), bodies.position,
                      gravity, threads)
    finish_contact_pass(contacts, bodies, iterations, gravity, threads)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, fastmath=SOLVER_MATH, inline="always")
def finish_contact_pass(contacts, bodies, iterations, gravity, threads):
    """The contact pass after its velocity sweeps: shock propagation, the position pass, and
    the friction kept as world vectors."""
    shock_propagation(contacts, bodies, threads)
    solve_rows(bodies.pseudo_velocity, contacts, iterations, contacts.position_target,
               contacts.position_impulse, contacts.friction, False, bodies.position, gravity, threads)
    rows = contacts.rows
    for c in range(contacts.count[0]):
        f1, f2 = contacts.friction[c, 0], contacts.friction[c, 1]
        s1, s2 = contacts.support_friction[c, 0], contacts.support_friction[c, 1]
        for e in range(3):
            contacts.friction_world[c, e] = f1 * rows[c, 1, DIRECTION + e] + f2 * rows[c, 2, DIRECTION + e]
            contacts.support_friction_world[c, e] = s1 * rows[c, 1, DIRECTION + e] + s2 * rows[c, 2, DIRECTION + e]
