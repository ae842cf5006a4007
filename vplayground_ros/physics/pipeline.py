"""The step pipeline: one compiled call runs many whole steps. Read `step_world` top to bottom to
read the physics; each stage lives in the module named after it."""
import time
import warnings

import numpy as np

from numba import njit, objmode
from numba.core.errors import NumbaWarning

from .broad_phase import build_index, find_body_pairs
from .constants import STATIC_REINDEX_MIN_PENDING, STATIC_REINDEX_PENDING_FRACTION
from .contact import index_manifolds, warm_start_from
from .contact_solver import (collision_pass, collision_pass_with_joints, contact_pass,
                             contact_pass_with_joints, prepare_contacts, warm_start)
from .freezing import freeze_joint_groups, update_freezing, wake_joint_groups, wake_touched
from .integrate import integrate_positions, integrate_velocities, update_bodies
from .joints import drop_jointed_pairs, prepare_joints, record_effort, warm_start_joints
from .narrow_phase import collide
from .playground import find_playground_pairs
from .step_context import swap_contacts
from .vehicle import drive_vehicles

# step_world's status: why it returned before doing every step.
DONE, GROW_PAIRS, GROW_CONTACTS, GROW_INDEX = 0, 1, 2, 3

# The stages of a step, in order; step_world times each (nanoseconds of the stepping thread's CPU
# time summed over its steps, so other processes on a shared machine do not inflate them) when
# asked to profile. STAGES names them for reports; the constants index stage_ns.
STAGES = ("derived state", "detection", "wake", "collision pass", "forces and wheels",
          "contact pass", "positions", "freezing")
(STAGE_DERIVED, STAGE_DETECTION, STAGE_WAKE, STAGE_COLLISION, STAGE_FORCES, STAGE_CONTACT,
 STAGE_POSITIONS, STAGE_FREEZING) = range(len(STAGES))


# clock_ns reads the clock in object mode, which Numba warns holds the GIL: only when profiling.
warnings.filterwarnings("ignore", message="Code running in object mode won't allow parallel",
                        category=NumbaWarning)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def clock_ns(profile):
    """This thread's CPU nanoseconds when profiling (briefly takes the GIL to read the clock),
    else 0."""
    if not profile:
        return 0
    with objmode(now="int64"):
        now = time.thread_time_ns()
    return now


# step_world's counters, summed over its steps (the caller zeroes them).
STAT_WOKEN, STAT_FROZEN, STAT_PAIRS, STAT_POINTS, STAT_TRIANGLES = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def lap(profile, stage_ns, stage, since):
    """Adds the time since `since` to stage_ns[stage] when profiling; returns now. (Not handed
    the StepContext: each stage constant is a specialisation of its own, and each took 4.5 s to
    compile for the wrapper unboxing the context's ~170 arrays. The callers hand the stage as
    np.int64: a bare constant is a literal type, and compiled lap once per stage.)"""
    now = clock_ns(profile)
    if profile:
        stage_ns[stage] += now - since
    return now


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def rebuild_static_index(bodies, broad, settings):
    """Indexes every resting (frozen or immovable) body (those that collide with nothing are
    counted in but not filed: nothing finds them). False when the index is too small."""
    ids = np.nonzero(bodies.active & ~bodies.awake)[0]
    if not build_index(broad.static, ids[bodies.collides[ids]], bodies.aabb_min, bodies.aabb_max,
                       bodies.octree_level, settings.root_min, settings.root_size):
        return False
    bodies.static_indexed[:] = False
    bodies.static_indexed[ids] = True
    broad.indexed[0] = len(ids)
    broad.stale[0] = 0
    broad.force_rebuild[0] = False
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def list_live_bodies(bodies, broad, everyone):
    """The step's live bodies in slot order, in broad.moving_ids: the active ones outside the
    static index (every active one when `everyone`). Every awake body is among them, so the
    per-body stages visit these alone and a world at rest costs one pass over two flags."""
    n = 0
    active, indexed = bodies.active, bodies.static_indexed
    for i in range(len(active)):
        if active[i] and (everyone or not indexed[i]):
            broad.moving_ids[n] = i
            n += 1
    return broad.moving_ids[:n]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def list_colliding(bodies, broad, live):
    """The live bodies that collide (bodies.collides), in broad.colliding_ids: what the broad and
    narrow phases see."""
    n = 0
    for k in range(len(live)):
        if bodies.collides[live[k]]:
            broad.colliding_ids[n] = live[k]
            n += 1
    return broad.colliding_ids[:n]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def static_index_outdated(bodies, broad, live):
    """Enough bodies wait for the static index (resting but outside it), or enough of its
    entries are stale. Every un-indexing counts one stale entry, so the index holds
    `indexed - stale` bodies."""
    pending = 0
    for k in range(len(live)):
        if not bodies.awake[live[k]]:
            pending += 1
    limit = reindex_limit(broad.indexed[0], broad.stale[0])
    return broad.force_rebuild[0] or pending >= limit or broad.stale[0] >= limit


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def reindex_limit(indexed, stale):
    """How many waiting or stale entries make the static index outdated: a share of the bodies
    it holds (`indexed - stale`), at least STATIC_REINDEX_MIN_PENDING. (Scalars: resting_steps
    calls it from Python, where handing over the broad phase's arrays would cost more.)"""
    return max(STATIC_REINDEX_MIN_PENDING, int(STATIC_REINDEX_PENDING_FRACTION * (indexed - stale)))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def detect(bodies, hulls, parts, broad, playground, contacts, settings, moving_ids, excluded_pairs):
    """Broad phase then narrow phase for the current positions of the live bodies `moving_ids`
    (list_live_bodies) that collide; `hulls` and `parts` are the World's hull table (of convex
    bodies and parts) and parts table (of compound bodies); pairs whose key is in
    `excluded_pairs` (jointed, sorted) are not collided. Returns a status."""
    s = settings
    moving_ids = list_colliding(bodies, broad, moving_ids)
    if not build_index(broad.moving, moving_ids, bodies.aabb_min, bodies.aabb_max,
                       bodies.octree_level, s.root_min, s.root_size):
        return GROW_INDEX
    pairs = find_body_pairs(broad.moving, broad.static, bodies.aabb_min, bodies.aabb_max,
                            bodies.awake, bodies.static_indexed, s.root_min, s.root_size,
                            broad.pair_a, broad.pair_b)
    if pairs < 0:
        return GROW_PAIRS
    if len(excluded_pairs) > 0:
        pairs = drop_jointed_pairs(broad.pair_a, broad.pair_b, pairs, excluded_pairs)
    broad.pair_count[0] = pairs
    pairs = find_playground_pairs(playground, moving_ids, bodies, s.root_min, s.root_size,
                                  broad.playground_body, broad.playground_triangle)
    if pairs < 0:
        return GROW_PAIRS
    broad.playground_count[0] = pairs
    if not collide(contacts, bodies, hulls, parts, broad, playground, s.ground_enabled, s.ground_height,
                   moving_ids, s.solver_threads):
        return GROW_CONTACTS
    return DONE


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def at_rest(bodies, live, vehicles):
    """No live body is awake (those outside the static index are frozen ones waiting for it)
    and no car drives: nothing can move or touch a moving body this step."""
    if np.any(vehicles.active):
        return False
    for k in range(len(live)):
        if bodies.awake[live[k]]:
            return False
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def rest_step(bodies, broad, contacts, settings, live):
    """What the stages leave behind in a step `at_rest`: the moving index (of the frozen bodies
    not yet in the static one, which ray casts query), no pairs, no contacts (indexed, for the
    next step's warm start). Stage by stage that cost several times the step's own work: Numba
    counts references to every array of the tuples handed to each call. False when the moving
    index is too small."""
    if not build_index(broad.moving, live, bodies.aabb_min, bodies.aabb_max, bodies.octree_level,
                       settings.root_min, settings.root_size):
        return False
    broad.pair_count[0] = 0
    broad.playground_count[0] = 0
    contacts.count[0] = 0
    contacts.manifold_count[0] = 0
    contacts.support_count[0] = 0
    index_manifolds(contacts)
    return True


def resting_steps(bodies, broad, vehicles, contacts, steps):
    """Runs `steps` steps of a world in which every body sits in the static index (frozen or
    immovable) and no car drives, in Python, and returns True; or returns False, having done
    nothing, when the world is not in that state (or its static index is due for a rebuild).
    Each such step of step_world is `rest_step` with no live body; this is the same, without
    the call: handing the StepContext's ~170 arrays to the compiled code costs ~30 us per call
    (typing and unboxing them), several times the step of a world at rest."""
    # count_nonzero: any() takes twice as long on a bool array (and np.any's wrapper alone took a
    # third of a resting World.step(1)).
    if (broad.force_rebuild[0] or np.count_nonzero(vehicles.active)
            or np.count_nonzero(bodies.active > bodies.static_indexed)):
        return False
    if broad.stale[0] >= reindex_limit(broad.indexed[0], broad.stale[0]):
        return False  # static_index_outdated: step_world rebuilds the index first
    broad.moving.count[0] = broad.moving.level_mask[0] = 0
    broad.pair_count[0] = broad.playground_count[0] = 0
    # Each step empties the buffer it fills and makes it the newest: after two, both are empty.
    for _ in range(min(steps, 2)):
        current = contacts.pair[1 - contacts.newest[0]]
        current.count[0] = current.manifold_count[0] = current.support_count[0] = 0
        if current.table_count[0]:  # (a buffer emptied by an earlier resting step has none)
            current.table_key[current.table_slot[:current.table_count[0]]] = -1  # index_manifolds
            current.table_count[0] = 0
        contacts.newest[0] = 1 - contacts.newest[0]
    if steps > 2:
        contacts.newest[0] ^= (steps - 2) % 2
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def step_world(steps, ctx):
    """Runs up to `steps` steps of the StepContext `ctx`. Returns (steps done, status). A status
    other than DONE means a buffer was too small; that step has not been applied and the caller
    grows the buffer and goes on."""
    bodies, broad, playground, s, joints = ctx.bodies, ctx.broad, ctx.playground, ctx.settings, ctx.joints
    profile, stage_ns = ctx.profile, ctx.stage_ns
    jointed = joints.count[0] > 0
    for done in range(steps):
        previous = ctx.contacts.pair[ctx.contacts.newest[0]]
        current = ctx.contacts.pair[1 - ctx.contacts.newest[0]]
        t = clock_ns(profile)
        if jointed:  # a body the World woke between steps wakes its group
            broad.stale[0] += wake_joint_groups(bodies, joints)
        # 1. Derived state: rotations, solver masses, broad-phase bounds (of every body when the
        #    octree changed under the static index).
        live = list_live_bodies(bodies, broad, broad.force_rebuild[0])
        update_bodies(bodies, live, s.dt, s.root_size, s.octree_depth)
        if static_index_outdated(bodies, broad, live):
            if not rebuild_static_index(bodies, broad, s):
                return done, GROW_INDEX
            live = list_live_bodies(bodies, broad, np.bool_(False))
        if at_rest(bodies, live, ctx.vehicles):
            # Every body asleep or immovable: the step is its empty result (no counters). Sleepers
            # still waiting for the static index join it now, once: nothing else will freeze
            # while the world rests, and with none live the World's next calls step in Python
            # (resting_steps) instead of re-indexing them here every step.
            if len(live) > 0:
                if not rebuild_static_index(bodies, broad, s):
                    return done, GROW_INDEX
                live = list_live_bodies(bodies, broad, np.bool_(False))
            if not rest_step(bodies, broad, current, s, live):
                return done, GROW_INDEX
            lap(profile, stage_ns, np.int64(STAGE_DERIVED), t)
            swap_contacts(ctx.contacts)
            continue
        t = lap(profile, stage_ns, np.int64(STAGE_DERIVED), t)
        # 2. Collision detection (octree broad phase, narrow phase per shape pair) at the current
        #    positions, with speculative margins covering this step's motion.
        status = detect(bodies, ctx.hulls, ctx.parts, broad, playground, current, s, live, joints.excluded_pairs)
        if status != DONE:
            return done, status
        t = lap(profile, stage_ns, np.int64(STAGE_DETECTION), t)
        # 3. Freezing: sleepers touched by moving bodies wake, and are detected again with their
        #    own contacts so they do not sink for a step, and so do their jointed groups.
        woken, stale = wake_touched(current, bodies, s.freezing_linear_speed)
        if woken > 0 and jointed:
            stale += wake_joint_groups(bodies, joints)
        if woken > 0:
            live = list_live_bodies(bodies, broad, np.bool_(False))
            update_bodies(bodies, live, s.dt, s.root_size, s.octree_depth)
            broad.stale[0] += stale
            status = detect(bodies, ctx.hulls, ctx.parts, broad, playground, current, s, live, joints.excluded_pairs)
            if status != DONE:
                return done, status
        t = lap(profile, stage_ns, np.int64(STAGE_WAKE), t)
        # 4. Collision pass with the pre-step velocities and the bodies' elasticity; the joints
        #    hold (their rows without position correction or motors' drive).
        warm_start_from(previous, current)
        prepare_contacts(current, bodies, s.ground_material, s.gravity, s.dt)
        if jointed:
            prepare_joints(joints, bodies, s.dt)
            collision_pass_with_joints(current, joints, bodies, s.resolve_iterations, s.gravity,
                                       s.solver_threads)
        else:
            collision_pass(current, bodies, s.resolve_iterations, s.gravity, s.solver_threads)
        t = lap(profile, stage_ns, np.int64(STAGE_COLLISION), t)
        # 5. Velocity update with external forces: the cars' wheels (springs and dampers see the
        #    velocities before gravity adds its share, or dampers would hold up the cars), then
        #    gravity and pushes.
        drive_vehicles(ctx.vehicles, bodies, ctx.hulls, ctx.parts, broad, playground, s)
        integrate_velocities(bodies, live, s.gravity, s.dt)
        t = lap(profile, stage_ns, np.int64(STAGE_FORCES), t)
        # 6. Contact pass: zero elasticity, twice the iterations, split-impulse penetration fix;
        #    the joints' rows with the contacts', correcting their drift and driving motors.
        warm_start(current, bodies)
        if jointed:
            warm_start_joints(joints, bodies.velocity)
            contact_pass_with_joints(current, joints, bodies, 2 * s.resolve_iterations, s.gravity,
                                     s.solver_threads)
            record_effort(joints, s.dt)
        else:
            contact_pass(current, bodies, 2 * s.resolve_iterations, s.gravity, s.solver_threads)
        t = lap(profile, stage_ns, np.int64(STAGE_CONTACT), t)
        # 7. Positions from velocities.
        integrate_positions(bodies, live, s.dt)
        t = lap(profile, stage_ns, np.int64(STAGE_POSITIONS), t)
        # 8. Freezing of bodies that have been at rest long enough.
        frozen_now = update_freezing(bodies, live, s.freezing_enabled, s.freezing_time,
                                     s.freezing_linear_speed, s.freezing_angular_speed, s.dt)
        if jointed and s.freezing_enabled:
            frozen_now += freeze_joint_groups(bodies, joints, s.freezing_time)
        index_manifolds(current)
        lap(profile, stage_ns, np.int64(STAGE_FREEZING), t)
        stats = ctx.stats
        stats[STAT_WOKEN] += woken
        stats[STAT_FROZEN] += frozen_now
        stats[STAT_PAIRS] += broad.pair_count[0]
        stats[STAT_POINTS] += current.count[0]
        stats[STAT_TRIANGLES] += broad.playground_count[0]
        swap_contacts(ctx.contacts)
    return steps, DONE
