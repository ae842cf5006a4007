"""How two threads share a solver pass and still get the serial solve's result bit for bit.

The serial solve visits the pass's points in one order (bottom to top along gravity, then top to
bottom, sweep after sweep), and a point reads and writes only its two bodies' velocities. Any
schedule in which every point runs after the earlier points (in that order) that share a moving
body with it therefore computes the same numbers. Here the points go into two chains, each kept
in the serial order, and a point waits for the other chain only where the two share a body:

- The world is cut by a vertical plane through the median contact point (across the horizontal
  axis the points spread most along); a moving body belongs to the side its centre is on. Points
  whose moving bodies lie on one side go to that side's chain; points across the cut go to the
  shorter chain so far. Static bodies (the ground, the playground, frozen and immovable bodies)
  never tie points together: the solver does not write to them.
- For every point, `need` says how far the other chain must have got before it may run: past the
  last point before it (this sweep) that shares a body with it, or, when there is none this
  sweep, past the other chain's last such point of the sweep before. Points that share no body
  with the other chain never wait, so a world the cut does not cross (bodies landing apart, two
  stacks side by side) runs its two halves with no wait at all.
- Each chain publishes its progress (points done since the pass began) after the points the other
  chain waits for, and runs the points between them in one go.

Why not Box2D v3's graph colouring: it changes the order in which the points are solved (the
stacks and walls depend on the height order) and needs a wait per colour per sweep; a level
schedule keeps the order but needs a wait per level (tens to hundreds a sweep on a pile). Two
chains wait only at the bodies the cut crosses.

Shock propagation is one pass, not sweeps, and each of its groups writes one body: there a
level schedule (shock_levels) pays, a wait per level of the pile, a storey each.
"""
import numpy as np
from numba import njit

# `need` of a point that shares no body with the other chain: never waits.
NO_WAIT = -(1 << 62)

# Bins of the histogram that places the cut: the halves differ by about one bin's share of the
# points at most (1/128 of them where they spread evenly).
CUT_BINS = 128


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def split_chains(points, count, contacts, position, gravity, items, chain_start, need_up,
                 need_down, publish_up, publish_down):
    """Puts points[:count] (a pass's points in sweep order) into the two chains: chain c is
    items[chain_start[c]:chain_start[c + 1]], in sweep order. For the item in slot i: need_up[i]
    and need_down[i] (upward and downward sweeps), each relative to the other chain's progress
    at the start of the sweep (sweep x its length); publish_up[i], publish_down[i]: the other
    chain waits for it in an upward (downward) sweep, or the sweep after. Returns how many
    points may wait (in an upward sweep). Six passes over the points (this runs before every
    shared pass, on one thread)."""
    rows_a, rows_b, inv_mass, point = contacts.velocity_a, contacts.velocity_b, contacts.row_inv_mass, contacts.point
    # Per body (velocity row): which chains touch it (bits), and per chain the first and last
    # upward position of its points on it and the latest in the current walk. Only this pass's
    # bodies' entries are set, so a large world with few contacts pays for its contacts alone.
    rows = len(position) + 1
    touch = np.empty(rows, np.int64)
    first_up = np.empty((2, rows), np.int64)
    last_up = np.empty((2, rows), np.int64)
    latest = np.empty((2, 2, rows), np.int64)  # [walk direction, chain, body]
    # What the passes need of each point, gathered once in sweep order (the points lie all over
    # the contact arrays): its moving bodies (-1: a static side) and where it is across gravity.
    moving = np.empty((count, 2), np.int64)
    across = np.empty((count, 2))
    # The cut: across the horizontal axis the points spread more along (a cut along gravity
    # would split stacks into top and bottom), through their median (a histogram's).
    down = 0
    for e in range(3):
        if abs(gravity[e]) > abs(gravity[down]):
            down = e
    first, second = (down + 1) % 3, (down + 2) % 3
    lo1 = lo2 = np.inf
    hi1 = hi2 = -np.inf
    for k in range(count):
        c = points[k]
        a = rows_a[c] if inv_mass[c, 0] != 0.0 else -1
        b = rows_b[c] if inv_mass[c, 1] != 0.0 else -1
        moving[k, 0], moving[k, 1] = a, b
        touch[rows_a[c]] = touch[rows_b[c]] = 0
        x1, x2 = point[c, first], point[c, second]
        across[k, 0], across[k, 1] = x1, x2
        lo1, hi1 = min(lo1, x1), max(hi1, x1)
        lo2, hi2 = min(lo2, x2), max(hi2, x2)
    along, axis, lo, hi = (0, first, lo1, hi1) if hi1 - lo1 >= hi2 - lo2 else (1, second, lo2, hi2)
    cut = hi
    if hi > lo:
        bins = np.zeros(CUT_BINS, np.int64)
        scale = CUT_BINS / (hi - lo)
        for k in range(count):
            f = (across[k, along] - lo) * scale
            # Clamped, a non-finite one too: an index out of the bins would write anywhere.
            bins[0 if not f > 0.0 else (int(f) if f < CUT_BINS - 1 else CUT_BINS - 1)] += 1
        seen = 0
        for k in range(CUT_BINS):
            seen += bins[k]
            if 2 * seen >= count:
                cut = lo + (k + 1) / scale
                break
    # The chains: a side's interior, points across the cut to the shorter chain so far.
    chain = np.empty(count, np.int64)
    lengths = np.zeros(2, np.int64)
    for k in range(count):
        a, b = moving[k, 0], moving[k, 1]
        side_a = -1 if a < 0 else int(position[a, axis] >= cut)
        side_b = -1 if b < 0 else int(position[b, axis] >= cut)
        if side_a >= 0 and side_b >= 0 and side_a != side_b:
            chain[k] = 0 if lengths[0] <= lengths[1] else 1
        else:
            chain[k] = max(side_a, side_b, 0)
        lengths[chain[k]] += 1
    chain_start[0], chain_start[1], chain_start[2] = 0, lengths[0], count
    place = np.empty(count, np.int64)  # each point's position in its chain (upward order)
    filled = np.zeros(2, np.int64)
    for k in range(count):
        own = chain[k]
        here = place[k] = filled[own]
        filled[own] += 1
        slot = chain_start[own] + here
        items[slot] = points[k]
        publish_up[slot] = publish_down[slot] = False
        for side in range(2):
            body = moving[k, side]
            if body < 0:
                continue
            if touch[body] & (1 << own) == 0:
                touch[body] |= 1 << own
                first_up[own, body] = here
                latest[0, own, body] = latest[1, own, body] = -1
            last_up[own, body] = here
    # Upward sweeps walk the points in sweep order, downward ones backwards (`latest` holds
    # positions in the walk's direction); only bodies both chains touch tie points together.
    waiting = 0
    for direction in range(2):
        need_of = need_up if direction == 0 else need_down
        for step in range(count):
            k = step if direction == 0 else count - 1 - step
            own = chain[k]
            slot = chain_start[own] + place[k]
            need_of[slot] = NO_WAIT
            a, b = moving[k, 0], moving[k, 1]
            shared_a = a >= 0 and touch[a] == 3
            shared_b = b >= 0 and touch[b] == 3
            if not (shared_a or shared_b):
                continue
            other = 1 - own
            other_length = chain_start[other + 1] - chain_start[other]
            here = place[k] if direction == 0 else lengths[own] - 1 - place[k]
            need = NO_WAIT
            for side in range(2):
                if not (shared_a if side == 0 else shared_b):
                    continue
                body = a if side == 0 else b
                before = latest[direction, other, body]
                if before >= 0:  # the other chain's last point on the body, this sweep
                    need = max(need, before + 1)
                    if direction == 0:
                        publish_up[chain_start[other] + before] = True
                    else:
                        publish_down[chain_start[other + 1] - 1 - before] = True
                elif direction == 0:  # ... the sweep before (downward): its first upward one
                    need = max(need, -first_up[other, body])
                    publish_down[chain_start[other] + first_up[other, body]] = True
                else:  # ... the sweep before (upward)
                    need = max(need, last_up[other, body] + 1 - other_length)
                    publish_up[chain_start[other] + last_up[other, body]] = True
                latest[direction, own, body] = here
            need_of[slot] = need
            waiting += direction == 0
    return waiting


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def support_groups(order, supports, support_body, group_start):
    """Shock propagation's groups: order[:supports] holds each upper body's support points
    together (contact_solver.order_supports). Fills group_start[:groups + 1] (each group's
    first place in order, then `supports`) and returns how many groups there are."""
    groups = 0
    k = 0
    while k < supports:
        group_start[groups] = k
        groups += 1
        upper = support_body[order[k]]
        k += 1
        while k < supports and support_body[order[k]] == upper:
            k += 1
    group_start[groups] = supports
    return groups


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def shock_levels(order, support_body, velocity_a, velocity_b, rows, group_start, groups, by_level,
                 level_start):
    """Shock propagation's schedule on two threads (its own, not the chains above): the groups
    (support_groups, one per upper body) in levels such that the groups of one level share no
    body that one of them writes. A group writes only its upper body's velocity and reads its
    supports' (bodies below, or static ones, which nothing writes), so it goes one level above
    every earlier group (in the serial order) that wrote a body it reads or read the body it
    writes: each group then reads what it read in the serial pass, in whatever order a level's
    groups run, and the result is the serial one bit for bit. A pile's landing has a few levels
    of hundreds of groups (each stack a level per storey), a tower one level per box.

    Fills by_level[:groups] (the groups level by level, each level in serial order) and
    level_start[:levels + 1]; returns levels. `rows`: velocity rows (bodies + 1)."""
    # The level of the last group (1-based; 0: none) that wrote each body, and the highest
    # level that read it. Only the bodies of these points are set.
    written = np.empty(rows, np.int64)
    read = np.empty(rows, np.int64)
    for k in range(group_start[groups]):
        c = order[k]
        written[velocity_a[c]] = written[velocity_b[c]] = 0
        read[velocity_a[c]] = read[velocity_b[c]] = 0
    level = np.empty(groups, np.int64)
    levels = 0
    for g in range(groups):
        upper = support_body[order[group_start[g]]]
        lv = read[upper]
        for k in range(group_start[g], group_start[g + 1]):
            c = order[k]
            other = velocity_b[c] if velocity_a[c] == upper else velocity_a[c]
            lv = max(lv, written[other])
        lv += 1
        level[g] = lv
        written[upper] = lv
        for k in range(group_start[g], group_start[g + 1]):
            c = order[k]
            other = velocity_b[c] if velocity_a[c] == upper else velocity_a[c]
            read[other] = max(read[other], lv)
        levels = max(levels, lv)
    # The groups by level (a counting sort: each level keeps the serial order).
    level_start[:levels + 1] = 0
    for g in range(groups):
        level_start[level[g]] += 1
    for lv in range(levels):
        level_start[lv + 1] += level_start[lv]
    cursor = level_start[:levels].copy()
    for g in range(groups):
        lv = level[g] - 1
        by_level[cursor[lv]] = g
        cursor[lv] += 1
    return levels
