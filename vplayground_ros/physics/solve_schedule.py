"""How two threads share a solver pass: the pass's points split into tasks that touch disjoint
bodies, and the tasks into phases that run one after another.

The world is cut in two by a vertical plane through the median contact point (along the
horizontal axis the points spread most along); each moving body belongs to the side its centre is
on. Points whose moving bodies all lie on one side are that side's interior; the two interiors
share no body, so two threads solve them at once (phase 0). The points across the cut (the
boundary) are cut again, along the other horizontal axis: those whose two bodies lie on the same
side of the second cut form two more independent tasks (phase 1), and the few left (phase 2) are
one task. Static bodies (the ground, the playground, frozen and immovable bodies) never tie two
points together: the solver does not write to them.

Why a cut and not Box2D v3's graph colouring: inside a task the points keep the sweep order of
the serial solve (bottom to top along gravity, then top to bottom), which is what stacks and
walls need; a body's points all lie in one interior or on the boundary, so a cluster of bodies
the cut does not cross (a tower, a wall beside the cut) gets bit for bit the serial result. And
each phase ends in one wait of one thread for the other, about a microsecond on a quiet 2-core
machine: a colouring (or a level schedule that keeps the exact order) needs a wait per colour
(level) per sweep, a few hundred to a few thousand a step. The split depends on the points and the
bodies alone, never on the thread count, so one thread running every task gets the same bytes as
two.
"""
import numpy as np
from numba import njit

# The tasks, and the phases that run them (the tasks of a phase run at once).
INTERIOR_LOW, INTERIOR_HIGH, BOUNDARY_LOW, BOUNDARY_HIGH, ACROSS = range(5)
TASKS = 5
PHASES = 3
PHASE_OF_TASK = (0, 0, 1, 1, 2)

# Bins of the histograms that place the cuts: the halves differ by at most about one bin's share
# of the points (1/128 of them where they spread evenly).
CUT_BINS = 128

# A static side of a point: no body the solver moves.
STATIC = -1


@njit(cache=True, nogil=True)
def median_cut(values, count):
    """A value that about half of values[:count] lie below (a histogram's, O(count))."""
    lo, hi = np.inf, -np.inf
    for k in range(count):
        lo, hi = min(lo, values[k]), max(hi, values[k])
    if not hi > lo:
        return hi
    bins = np.zeros(CUT_BINS, np.int64)
    scale = CUT_BINS / (hi - lo)
    for k in range(count):
        bins[min(int((values[k] - lo) * scale), CUT_BINS - 1)] += 1
    seen = 0
    for k in range(CUT_BINS):
        seen += bins[k]
        if 2 * seen >= count:
            return lo + (k + 1) / scale
    return hi


@njit(cache=True, nogil=True)
def horizontal_axes(gravity, coordinates, points, count):
    """The two world axes across gravity (x and y under the usual gravity), the one the points
    spread more along first."""
    down = 0
    for e in range(3):
        if abs(gravity[e]) > abs(gravity[down]):
            down = e
    first, second = (down + 1) % 3, (down + 2) % 3
    lo1 = lo2 = np.inf
    hi1 = hi2 = -np.inf
    for k in range(count):
        p = coordinates[points[k]]
        lo1, hi1 = min(lo1, p[first]), max(hi1, p[first])
        lo2, hi2 = min(lo2, p[second]), max(hi2, p[second])
    return (first, second) if hi1 - lo1 >= hi2 - lo2 else (second, first)


@njit(cache=True, nogil=True)
def side(body, inv_mass, position, axis, cut):
    if inv_mass == 0.0:
        return STATIC
    return 1 if position[body, axis] >= cut else 0


@njit(cache=True, nogil=True)
def split_points(points, count, contacts, position, gravity, items, task_start):
    """Sorts points[:count] (a pass's points in sweep order) into the tasks: items[:count] holds
    them task by task, each task in sweep order; task t is items[task_start[t]:task_start[t + 1]]."""
    rows_a, rows_b, inv_mass = contacts.velocity_a, contacts.velocity_b, contacts.row_inv_mass
    task = np.empty(count, np.int64)
    values = np.empty(count)
    first, second = horizontal_axes(gravity, contacts.point, points, count)
    for k in range(count):
        values[k] = contacts.point[points[k], first]
    cut = median_cut(values, count)
    boundary = 0
    for k in range(count):
        c = points[k]
        side_a = side(rows_a[c], inv_mass[c, 0], position, first, cut)
        side_b = side(rows_b[c], inv_mass[c, 1], position, first, cut)
        if side_a == STATIC or side_b == STATIC or side_a == side_b:
            task[k] = INTERIOR_HIGH if max(side_a, side_b) == 1 else INTERIOR_LOW
        else:
            task[k] = ACROSS
            values[boundary] = contacts.point[c, second]
            boundary += 1
    cut = median_cut(values, boundary)
    for k in range(count):
        if task[k] == ACROSS:
            c = points[k]
            side_a = side(rows_a[c], inv_mass[c, 0], position, second, cut)
            side_b = side(rows_b[c], inv_mass[c, 1], position, second, cut)
            if side_a == side_b:
                task[k] = BOUNDARY_HIGH if side_a == 1 else BOUNDARY_LOW
    # Stable counting sort by task.
    task_start[:] = 0
    for k in range(count):
        task_start[task[k] + 1] += 1
    for t in range(TASKS):
        task_start[t + 1] += task_start[t]
    filled = task_start[:TASKS].copy()
    for k in range(count):
        items[filled[task[k]]] = points[k]
        filled[task[k]] += 1


@njit(cache=True, nogil=True)
def plan_groups(task_start, sweeps, phase_tasks, phase_task_count, group_phase, group_first_sweep,
                group_sweeps):
    """The order the phases run in over `sweeps` sweeps: upward sweeps run phases 0, 1, 2 and
    downward ones 2, 1, 0 (each task backwards), the serial solve's sweep order kept inside every
    task. Phases without points are left out, and a phase that ends one sweep and begins the next
    runs as one group (a task then does its two sweeps back to back): there is a wait between
    groups only. Fills phase_tasks (PHASES, 2) with each phase's non-empty tasks and returns the
    number of groups."""
    phases = np.empty(PHASES, np.int64)
    used = 0
    for p in range(PHASES):
        phase_task_count[p] = 0
    for t in range(TASKS):
        if task_start[t + 1] > task_start[t]:
            p = PHASE_OF_TASK[t]
            phase_tasks[p, phase_task_count[p]] = t
            phase_task_count[p] += 1
    for p in range(PHASES):
        if phase_task_count[p] > 0:
            phases[used] = p
            used += 1
    groups = 0
    for sweep in range(sweeps):
        for q in range(used):
            p = phases[q] if sweep % 2 == 0 else phases[used - 1 - q]
            if groups > 0 and group_phase[groups - 1] == p:
                group_sweeps[groups - 1] += 1
            else:
                group_phase[groups] = p
                group_first_sweep[groups] = sweep
                group_sweeps[groups] = 1
                groups += 1
    return groups
