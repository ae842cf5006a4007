"""Freezing (the 2008 feature): bodies at rest stop being simulated and act as static.

A body slower than both thresholds for `freezing.time` seconds freezes. A frozen body wakes when
an awake body touches it moving faster than WAKE_SPEED_FACTOR x the linear threshold at the
contact (it was hit, or what it rests on moves), when a body it touches is removed or edited, and
when it is edited itself (those two are the World's job, between steps).
"""
import numpy as np
from numba import njit

from .constants import WAKE_SPEED_FACTOR
from .contact_solver import relative_velocity


@njit(cache=True, nogil=True)
def wake_body(bodies, i):
    bodies.frozen[i] = False
    bodies.freeze_timer[i] = 0.0
    bodies.awake[i] = not bodies.immovable[i]
    bodies.static_indexed[i] = False  # its static-index entry is now stale and skipped


@njit(cache=True, nogil=True)
def wake_touched(contacts, bodies, linear_threshold):
    """Wakes frozen bodies that an awake body touches fast enough. Returns how many woke."""
    limit = WAKE_SPEED_FACTOR * linear_threshold
    woken = 0
    for c in range(contacts.count[0]):
        a, b = contacts.body_a[c], contacts.body_b[c]
        if b < 0 or bodies.awake[a] == bodies.awake[b]:
            continue
        sleeper = b if bodies.awake[a] else a
        if not bodies.frozen[sleeper]:
            continue  # immovable, never woken
        v = relative_velocity(bodies.linear_velocity, bodies.angular_velocity, a, b,
                              contacts.r_a[c], contacts.r_b[c])
        if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > limit * limit:
            wake_body(bodies, sleeper)
            woken += 1
    return woken


@njit(cache=True, nogil=True)
def update_freezing(bodies, enabled, time_to_freeze, linear_threshold, angular_threshold, dt):
    """Advances the freeze timers of awake bodies and freezes those that stayed slow long enough.
    Returns how many froze."""
    frozen = 0
    lin_sq, ang_sq = linear_threshold * linear_threshold, angular_threshold * angular_threshold
    for i in range(len(bodies.active)):
        if not bodies.awake[i]:
            continue
        v, w = bodies.linear_velocity[i], bodies.angular_velocity[i]
        slow = (v[0] ** 2 + v[1] ** 2 + v[2] ** 2 < lin_sq and w[0] ** 2 + w[1] ** 2 + w[2] ** 2 < ang_sq)
        if not (enabled and bodies.allow_freezing[i] and slow):
            bodies.freeze_timer[i] = 0.0
            continue
        bodies.freeze_timer[i] += dt
        if bodies.freeze_timer[i] >= time_to_freeze:
            bodies.frozen[i] = True
            bodies.awake[i] = False
            v[:] = 0.0
            w[:] = 0.0
            frozen += 1
    return frozen
