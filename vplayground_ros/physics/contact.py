"""Contact points and manifolds of one step, and the warm start from the step before.

A manifold is the set of (at most 4) points between two objects; its points are contiguous.
`body_b` is a body slot, or GROUND / PLAYGROUND for the static world (physics.ids). Normals point from A to B,
`depth` is penetration (negative: a speculative contact still that far apart).
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .constants import WARM_START_MATCH_DISTANCE

# A solver row: the unit direction d, the lever arms r_A x d and r_B x d, and the angular
# responses I_A^-1 (r_A x d) and I_B^-1 (r_B x d), 3 each: 15 numbers instead of a 12-wide
# Jacobian and its response (24), so a sweep streams less memory.
DIRECTION, ARM_A, ARM_B, TURN_A, TURN_B = 0, 3, 6, 9, 12
ROW_SIZE = 15

Contacts = namedtuple("Contacts", [
    "count",              # (1,) points in use
    "body_a", "body_b",   # (K,) int64
    "point",              # (K, 3) world, halfway between the surfaces
    "normal",             # (K, 3) unit, from A to B
    "depth",              # (K,) m
    "local_a",            # (K, 3) the point in A's body frame: identity across steps
    # The solver's view: each point has three rows (normal, tangent 1, tangent 2), laid out as
    # DIRECTION ... TURN_B say: what the relative velocity along a row is made of, and what a
    # unit impulse along it does to the two bodies' velocities.
    "velocity_a", "velocity_b",  # (K,) rows of the velocity arrays (the static world's last row)
    "rows",               # (K, 3, ROW_SIZE)
    "row_inv_mass",       # (K, 2) A's and B's inverse mass in the solver (0 when static)
    "row_mass",           # (K, 3) effective mass 1 / (J M^-1 J^T) of each row
    "restitution",        # (K,) pair elasticity
    "friction_coefficient",  # (K,) pair static or dynamic coefficient, chosen per step
    "approach_speed",     # (K,) normal velocity before the collision pass (negative: closing)
    "collision_impulse", "collision_friction",  # (K,), (K, 2) accumulated in the collision pass
    "impulse", "friction",  # (K,), (K, 2) accumulated in the contact pass (warm-started)
    "friction_world",     # (K, 3) contact-pass friction impulse as a world vector, for next step
    "position_impulse",   # (K,) split-impulse accumulator of the position pass
    "collision_target", "contact_target", "position_target",  # (K,) normal velocity goals
    "solve_order",        # (K,) points in the order the sweeps visit them
    "sweep_points",       # (K,) scratch: the points of solve_order a pass solves (target set)
    # Shock propagation: the support points (normal within 60 degrees of gravity) grouped by
    # their upper body, bodies bottom to top; the one-sided impulses added on top of the
    # contact pass's.
    "support_count",      # (1,) support points in use
    "support_order",      # (K,) support points, grouped per upper body
    "support_body",       # (K,) velocity row of each point's upper body (-1: not a support)
    "support_mass",       # (K, 3) effective mass of each row with the upper body alone moving
    "support_impulse", "support_friction",  # (K,), (K, 2) (warm-started)
    "support_friction_world",  # (K, 3) the one-sided friction impulse as a world vector, for next step
    "manifold_count",     # (1,)
    "manifold_start", "manifold_size", "manifold_a", "manifold_b",  # (M,)
    "table_key", "table_manifold",  # open-addressing hash: pair key -> manifold, for warm start
    "table_slot", "table_count",  # (M,), (1,) the slots filled, so clearing them is all a refill clears
])


def allocate_contacts(points, manifolds):
    f = lambda *shape: np.zeros((points,) + shape)  # noqa: E731
    i = lambda n: np.zeros(n, np.int64)  # noqa: E731
    table = 1 << int(np.ceil(np.log2(2 * manifolds + 2)))
    return Contacts(
        count=i(1), body_a=i(points), body_b=i(points), point=f(3), normal=f(3), depth=f(),
        local_a=f(3), velocity_a=i(points), velocity_b=i(points), rows=f(3, ROW_SIZE),
        row_inv_mass=f(2), row_mass=f(3), restitution=f(), friction_coefficient=f(),
        approach_speed=f(), collision_impulse=f(), collision_friction=f(2), impulse=f(),
        friction=f(2), friction_world=f(3), position_impulse=f(), collision_target=f(),
        contact_target=f(), position_target=f(), solve_order=i(points), sweep_points=i(points),
        support_count=i(1),
        support_order=i(points), support_body=i(points), support_mass=f(3), support_impulse=f(),
        support_friction=f(2), support_friction_world=f(3), manifold_count=i(1),
        manifold_start=i(manifolds), manifold_size=i(manifolds), manifold_a=i(manifolds),
        manifold_b=i(manifolds), table_key=np.full(table, -1, np.int64), table_manifold=i(table),
        table_slot=i(manifolds), table_count=i(1))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def pair_key(a, b):
    """a is a body slot; b a body slot, GROUND, or a playground triangle's ids.triangle_key."""
    return a * (1 << 32) + (b + (1 << 31))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def table_slot(key, mask):
    # Fibonacci hashing (2**64 / golden ratio, as a signed int64) spreads neighbouring keys.
    return ((key * -7046029254386353131) >> 17) & mask


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def index_manifolds(contacts):
    """Fills the pair -> manifold hash table (read by the next step's warm start). Only the slots
    of its last filling are cleared: the table is sized for the largest pile the World held, and
    clearing all of it each step was most of the step of a world at rest."""
    keys = contacts.table_key
    for m in range(contacts.table_count[0]):
        keys[contacts.table_slot[m]] = -1
    mask = len(keys) - 1
    for m in range(contacts.manifold_count[0]):
        key = pair_key(contacts.manifold_a[m], contacts.manifold_b[m])
        slot = table_slot(key, mask)
        while keys[slot] != -1:
            slot = (slot + 1) & mask
        keys[slot] = key
        contacts.table_manifold[slot] = m
        contacts.table_slot[m] = slot
    contacts.table_count[0] = contacts.manifold_count[0]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def find_manifold(keys, manifolds, a, b):
    """The manifold of pair (a, b) in the hash table (table_key, table_manifold), or -1. Takes
    the two arrays, not the Contacts: Numba counts references to every array of a tuple handed
    to a call, and per manifold that was most of the warm start."""
    mask = len(keys) - 1
    key = pair_key(a, b)
    slot = table_slot(key, mask)
    while keys[slot] != -1:
        if keys[slot] == key:
            return manifolds[slot]
        slot = (slot + 1) & mask
    return -1


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def warm_start_from(previous, current):
    """Copies last step's contact-pass and shock-propagation impulses onto this step's points
    that are the same contact (same pair, within WARM_START_MATCH_DISTANCE in A's frame). Stacks
    then start each solve from nearly the answer, which the fixed iteration count alone could
    not reach."""
    limit_sq = WARM_START_MATCH_DISTANCE * WARM_START_MATCH_DISTANCE
    keys, manifolds = previous.table_key, previous.table_manifold
    for m in range(current.manifold_count[0]):
        start, size = current.manifold_start[m], current.manifold_size[m]
        for c in range(start, start + size):
            current.impulse[c] = current.support_impulse[c] = 0.0
            for e in range(3):
                current.friction_world[c, e] = current.support_friction_world[c, e] = 0.0
        old = find_manifold(keys, manifolds, current.manifold_a[m], current.manifold_b[m])
        if old < 0:
            continue
        old_start, old_size = previous.manifold_start[old], previous.manifold_size[old]
        for c in range(start, start + size):
            best, best_sq = -1, limit_sq
            for o in range(old_start, old_start + old_size):
                dx = current.local_a[c, 0] - previous.local_a[o, 0]
                dy = current.local_a[c, 1] - previous.local_a[o, 1]
                dz = current.local_a[c, 2] - previous.local_a[o, 2]
                d_sq = dx * dx + dy * dy + dz * dz
                if d_sq < best_sq:
                    best, best_sq = o, d_sq
            if best >= 0:
                current.impulse[c] = previous.impulse[best]
                current.support_impulse[c] = previous.support_impulse[best]
                for e in range(3):
                    current.friction_world[c, e] = previous.friction_world[best, e]
                    current.support_friction_world[c, e] = previous.support_friction_world[best, e]
