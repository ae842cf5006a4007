"""Freezing (the 2008 feature): bodies at rest stop being simulated and act as static.

A body slower than both thresholds for `freezing.time` seconds freezes. A frozen body wakes when
an awake body touches it moving faster than WAKE_SPEED_FACTOR x the linear threshold at the
contact (it was hit, or what it rests on moves), when a body it touches is removed or edited, and
when it is edited itself (those two are the World's job, between steps).

Bodies a joint holds together freeze and wake as one (a robot standing still sleeps whole; a
link knocked wakes its robot): a jointed body freezes only with every moving body of its group,
and a group does not freeze while one of its motors drives it (however slowly: a hinge turned at
0.03 rad/s, below the thresholds, froze after 0.5 s and stopped).
"""
from numba import njit

from .constants import WAKE_DEPTH, WAKE_SPEED_FACTOR
from .joints import (BODY_A, BODY_B, CONTACT_TARGET, ISLAND_BODIES, ISLAND_BODY_START, ISLAND_JOINTS,
                     ISLAND_START, MOTOR_ROW, ROW_MASS, SPEED)

# A motor whose goal and joint are both faster than this (rad/s, m/s) drives its group: it does
# not freeze. (A position motor holding its target has a goal of rounding's size; one stalled
# against a limit or an obstacle has a goal but no motion, and its group may sleep.)
DRIVING_SPEED = 1.0e-4


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def wake_body(bodies, i):
    """Wakes body i (in a step, or between steps by the World). Returns True when it leaves a
    stale entry in the static index (skipped by queries, counted towards the next rebuild); an
    immovable body never moves, so it stays indexed."""
    bodies.frozen[i] = False
    bodies.freeze_timer[i] = 0.0
    bodies.awake[i] = not bodies.immovable[i]
    if not bodies.static_indexed[i] or bodies.immovable[i]:
        return False
    bodies.static_indexed[i] = False
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def wake_touched(contacts, bodies, linear_threshold):
    """Wakes frozen bodies that an awake body touches fast enough, or overlaps deeper than
    WAKE_DEPTH. Returns how many woke and how many of them left stale static-index entries."""
    limit_sq = (WAKE_SPEED_FACTOR * linear_threshold) ** 2
    velocity, position, awake = bodies.velocity, bodies.position, bodies.awake
    woken = stale = 0
    for c in range(contacts.count[0]):
        a, b = contacts.body_a[c], contacts.body_b[c]
        if b < 0 or awake[a] == awake[b]:
            continue
        mover, sleeper = (a, b) if awake[a] else (b, a)
        if not bodies.frozen[sleeper]:
            continue  # immovable, never woken
        # The mover's surface velocity at the contact (the sleeper is at rest).
        r = contacts.point[c] - position[mover]
        v, w = velocity[mover, :3], velocity[mover, 3:]
        vx = v[0] + w[1] * r[2] - w[2] * r[1]
        vy = v[1] + w[2] * r[0] - w[0] * r[2]
        vz = v[2] + w[0] * r[1] - w[1] * r[0]
        if vx * vx + vy * vy + vz * vz > limit_sq or contacts.depth[c] > WAKE_DEPTH:
            stale += wake_body(bodies, sleeper)
            woken += 1
    return woken, stale


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def update_freezing(bodies, live, enabled, time_to_freeze, linear_threshold, angular_threshold, dt):
    """Advances the freeze timers of the awake bodies among `live` and freezes those that stayed
    slow long enough. Returns how many froze."""
    frozen = 0
    lin_sq, ang_sq = linear_threshold * linear_threshold, angular_threshold * angular_threshold
    velocity = bodies.velocity
    for k in range(len(live)):
        i = live[k]
        if not bodies.awake[i]:
            continue
        v = velocity[i]
        slow = (v[0] ** 2 + v[1] ** 2 + v[2] ** 2 < lin_sq and v[3] ** 2 + v[4] ** 2 + v[5] ** 2 < ang_sq)
        if not (enabled and bodies.allow_freezing[i] and slow):
            bodies.freeze_timer[i] = 0.0
            continue
        bodies.freeze_timer[i] += dt
        if bodies.freeze_timer[i] >= time_to_freeze and not bodies.jointed[i]:
            bodies.frozen[i] = True
            bodies.awake[i] = False
            v[:] = 0.0
            frozen += 1
    return frozen


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def wake_joint_groups(bodies, joints):
    """Wakes the frozen bodies jointed to a moving one, group-wide. Returns how many left stale
    static-index entries."""
    stale = 0
    changed = True
    while changed:  # one pass per link of the longest chain woken from one end
        changed = False
        for j in range(joints.count[0]):
            a, b = joints.links[j, BODY_A], joints.links[j, BODY_B]
            if a < 0 or b < 0 or bodies.frozen[a] == bodies.frozen[b]:
                continue
            sleeper, other = (a, b) if bodies.frozen[a] else (b, a)
            if not bodies.immovable[other]:
                stale += wake_body(bodies, sleeper)
                changed = True
    return stale


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def freeze_joint_groups(bodies, joints, time_to_freeze):
    """Freezes the islands of jointed moving bodies (grouped by this step's prepare_joints:
    immovable ones and the world hold, not join) whose every body has been slow for
    time_to_freeze (update_freezing keeps their timers) and none of whose motors drives it.
    Returns how many bodies froze."""
    start, members = joints.islands[ISLAND_BODY_START], joints.islands[ISLAND_BODIES]
    frozen = 0
    for island in range(joints.count[1]):
        ready = True
        for place in range(start[island], start[island + 1]):
            body = members[place]
            ready = ready and bodies.awake[body] and bodies.freeze_timer[body] >= time_to_freeze
        for place in range(joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]):
            j = joints.islands[ISLAND_JOINTS, place]
            motor = joints.row_values[j, MOTOR_ROW]
            ready = ready and not (motor[ROW_MASS] != 0.0 and abs(motor[CONTACT_TARGET]) > DRIVING_SPEED
                                   and abs(joints.values[j, SPEED]) > DRIVING_SPEED)
        if not ready:
            continue
        for place in range(start[island], start[island + 1]):
            body = members[place]
            bodies.frozen[body] = True
            bodies.awake[body] = False
            bodies.velocity[body, :] = 0.0
            frozen += 1
    return frozen
