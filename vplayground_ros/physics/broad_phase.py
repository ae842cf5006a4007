"""Broad phase: a linear (Morton-coded) octree over the world's root cube.

Each object (a box's AABB, a mesh triangle's AABB) lives at the deepest level, at most
`octree_depth`, whose cells are at least as large as the object, and so touches at most 2x2x2
cells there. A cell is the key `level_offset(L) + morton(x, y, z)`; entries are kept sorted by
key, so a cell's objects are one contiguous run, its ancestors are single keys and all of its
descendants at a finer level are one contiguous key range. Body pairs come from merging the
sorted entries of two levels (a cell's ancestor keys grow with its key), with no per-body
searches; a single box (a ray's, a body's against the mesh) is a binary search per cell.

Three indexes, rebuilt at different rates:
- moving: the awake bodies, rebuilt every step;
- static: frozen and immovable bodies, rebuilt only when enough of them changed (bodies that
  froze since wait in the moving index; woken ones are skipped by their `static_indexed` flag);
- mesh: the playground's triangles, built once.
Objects outside the root cube are clamped to its border cells: still correct, just less pruned.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .constants import MAX_OCTREE_DEPTH
from .sorting import radix_sort

OctreeIndex = namedtuple("OctreeIndex", [
    "keys",          # (M,) int64 cell keys, sorted
    "ids",           # (M,) int64 body slot or triangle index of each entry
    "count",         # (1,) int64 entries in use
    "level_mask",    # (1,) int64 bit L set when level L has entries
])

LEVEL_BITS = np.array([1 << level for level in range(MAX_OCTREE_DEPTH + 1)], dtype=np.int64)


def allocate_index(capacity):
    return OctreeIndex(np.zeros(capacity, np.int64), np.zeros(capacity, np.int64),
                       np.zeros(1, np.int64), np.zeros(1, np.int64))


BroadPhase = namedtuple("BroadPhase", [
    "moving", "static",   # OctreeIndex of the moving bodies (per step) and of the resting ones
    "moving_ids",         # (N,) the step's live bodies: slots outside the static index
    "colliding_ids",      # (N,) those of them that collide (bodies.collides)
    "stamp", "scratch",   # (N,) scratch of the ray casts' index queries
    "pair_a", "pair_b",   # (P,) candidate pairs
    "pair_count",         # (1,) pairs found in the last step
    "playground_body", "playground_triangle",  # (P,) candidate (body, playground triangle) pairs
    "playground_count",   # (1,) of those found in the last step
    "indexed",            # (1,) bodies put in the static index at its last rebuild
    "stale",              # (1,) static-index entries of bodies that have since woken or gone
    "force_rebuild",      # (1,) bool: the World changed resting bodies between calls
])

# A box touches at most 2x2x2 cells of its level.
MAX_CELLS_PER_OBJECT = 8


def allocate_broad_phase(body_capacity, pair_capacity):
    index_capacity = MAX_CELLS_PER_OBJECT * body_capacity
    return BroadPhase(
        moving=allocate_index(index_capacity), static=allocate_index(index_capacity),
        moving_ids=np.zeros(body_capacity, np.int64), colliding_ids=np.zeros(body_capacity, np.int64),
        stamp=np.full(body_capacity, -1, np.int64),
        scratch=np.zeros(body_capacity, np.int64), pair_a=np.zeros(pair_capacity, np.int64),
        pair_b=np.zeros(pair_capacity, np.int64), pair_count=np.zeros(1, np.int64),
        playground_body=np.zeros(pair_capacity, np.int64),
        playground_triangle=np.zeros(pair_capacity, np.int64),
        playground_count=np.zeros(1, np.int64),
        indexed=np.zeros(1, np.int64), stale=np.zeros(1, np.int64),
        force_rebuild=np.ones(1, np.bool_))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def level_offset(level):
    return ((1 << (3 * level)) - 1) // 7


def compact_bits(code):
    """Every third bit of Morton codes (numpy), packed: the inverse of spread_bits."""
    code = np.asarray(code, dtype=np.int64) & 0x09249249
    code = (code | (code >> 2)) & 0x030C30C3
    code = (code | (code >> 4)) & 0x0300F00F
    code = (code | (code >> 8)) & 0x030000FF
    code = (code | (code >> 16)) & 0x000003FF
    return code


def cell_centres(keys, depth, root_min, root_size):
    """The cells of index keys, [(level, centres (K, 3), edge)] per occupied level (numpy; for
    drawing the octree)."""
    cells = []
    for level in range(depth + 1):
        offset = level_offset(level)
        codes = keys[(keys >= offset) & (keys < offset + (1 << (3 * level)))] - offset
        if len(codes) == 0:
            continue
        xyz = np.stack([compact_bits(codes >> axis) for axis in range(3)], axis=1)
        edge = root_size / (1 << level)
        cells.append((level, root_min + (xyz + 0.5) * edge, edge))
    return cells


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def spread_bits(v):
    """Inserts two zero bits after each of the low 10 bits of v (Morton interleave)."""
    v &= 0x3FF
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    v = (v | (v << 2)) & 0x09249249
    return v


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def morton(x, y, z):
    return spread_bits(x) | (spread_bits(y) << 1) | (spread_bits(z) << 2)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def object_level(aabb_min, aabb_max, root_size, depth):
    extent = max(aabb_max[0] - aabb_min[0], aabb_max[1] - aabb_min[1], aabb_max[2] - aabb_min[2])
    level = 0
    cell = root_size
    while level < depth and cell * 0.5 >= extent:
        cell *= 0.5
        level += 1
    return level


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cell_coordinate(value, origin, cell_size, cells):
    c = int(np.floor((value - origin) / cell_size))
    return min(max(c, 0), cells - 1)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cell_box(aabb_min, aabb_max, level, root_min, root_size):
    """Inclusive cell coordinate ranges (x0, x1, y0, y1, z0, z1) the AABB touches at `level`."""
    cells = 1 << level
    size = root_size / cells
    return (cell_coordinate(aabb_min[0], root_min[0], size, cells),
            cell_coordinate(aabb_max[0], root_min[0], size, cells),
            cell_coordinate(aabb_min[1], root_min[1], size, cells),
            cell_coordinate(aabb_max[1], root_min[1], size, cells),
            cell_coordinate(aabb_min[2], root_min[2], size, cells),
            cell_coordinate(aabb_max[2], root_min[2], size, cells))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def build_index(index, ids, aabb_min, aabb_max, levels, root_min, root_size):
    """Indexes the objects `ids` (rows of aabb_min/aabb_max/levels, ascending). Returns False
    when the index arrays are too small (the caller grows them and calls again)."""
    n = 0
    capacity = len(index.keys)
    mask = 0
    for k in range(len(ids)):
        obj = ids[k]
        level = levels[obj]
        # The bounds as tuples: handed over as rows of the arrays, they cost 40 ns a body (two
        # array views built and reference-counted per call), as much as the rest of the key.
        x0, x1, y0, y1, z0, z1 = cell_box((aabb_min[obj, 0], aabb_min[obj, 1], aabb_min[obj, 2]),
                                          (aabb_max[obj, 0], aabb_max[obj, 1], aabb_max[obj, 2]),
                                          level, root_min, root_size)
        base = level_offset(level)
        mask |= 1 << level
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                for z in range(z0, z1 + 1):
                    if n >= capacity:
                        return False
                    index.keys[n] = base + morton(x, y, z)
                    index.ids[n] = obj
                    n += 1
    # Each cell's entries come in id order (the ids ascend), so a stable sort by cell alone
    # orders them by cell, then id: half the radix passes of sorting both.
    keys, sorted_ids = radix_sort(index.keys[:n].view(np.uint64), index.ids[:n])
    for k in range(n):  # (the sort may have left them in its spare arrays)
        index.keys[k] = keys[k]
        index.ids[k] = sorted_ids[k]
    index.count[0] = n
    index.level_mask[0] = mask
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def key_run(index, key_lo, key_hi):
    """Entries whose cell key lies in [key_lo, key_hi)."""
    keys = index.keys[:index.count[0]]
    return np.searchsorted(keys, key_lo), np.searchsorted(keys, key_hi)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def aabbs_overlap(min_a, max_a, min_b, max_b):
    return (min_a[0] <= max_b[0] and min_b[0] <= max_a[0] and min_a[1] <= max_b[1]
            and min_b[1] <= max_a[1] and min_a[2] <= max_b[2] and min_b[2] <= max_a[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cell_query_range(level, code, other_level, finer_too):
    """Key range at `other_level` that can hold objects overlapping cell (level, code): the
    ancestor cell when coarser, every descendant when finer (only asked for when `finer_too`)."""
    base = level_offset(other_level)
    if other_level <= level:
        ancestor = code >> (3 * (level - other_level))
        return base + ancestor, base + ancestor + 1
    if not finer_too:
        return 0, 0
    shift = 3 * (other_level - level)
    return base + (code << shift), base + ((code + 1) << shift)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def query_index(index, level, box, finer_too, stamp, query_id, out):
    """Objects of `index` in the cells `box` (from cell_box at `level`) and their ancestors (and
    descendants when `finer_too`), each once: `stamp[obj] == query_id` marks it as seen.
    Returns how many ids were written to `out`."""
    x0, x1, y0, y1, z0, z1 = box
    mask = index.level_mask[0]
    n = 0
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            for z in range(z0, z1 + 1):
                code = morton(x, y, z)
                for other in range(len(LEVEL_BITS)):
                    if not mask & LEVEL_BITS[other]:
                        continue
                    key_lo, key_hi = cell_query_range(level, code, other, finer_too)
                    if key_lo == key_hi:
                        continue
                    start, end = key_run(index, key_lo, key_hi)
                    for k in range(start, end):
                        obj = index.ids[k]
                        if stamp[obj] != query_id:
                            stamp[obj] = query_id
                            out[n] = obj
                            n += 1
    return n


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def level_entries(index, level):
    """Entries of `index` at `level`: keys of a level lie in [level_offset(L), level_offset(L+1))."""
    keys = index.keys[:index.count[0]]
    return np.searchsorted(keys, level_offset(level)), np.searchsorted(keys, level_offset(level + 1))


# Which bodies of a joined pair of indexes may pair up (at least one of them moves).
MOVING_MOVING, MOVING_STATIC, STATIC_MOVING = 0, 1, 2


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def join_levels(fine, fine_level, coarse, coarse_level, kind, aabb_min, aabb_max, awake,
                static_indexed, root_min, root_size, pair_a, pair_b, count):
    """Pairs between the entries of `fine` at fine_level and those of `coarse` at coarse_level
    (<= fine_level) in the ancestor cells, as a merge: walking the fine cells in key order, their
    ancestors' keys never decrease, so one cursor crosses the coarse entries once. Two bodies
    share up to 8 cells; the pair is reported only from the fine cell holding the low corner of
    their bounds' overlap, so once, with no marks to clear. The moving body of a pair comes
    first. Returns the new pair count, or -1 when pair_a/pair_b are full."""
    f0, f1 = level_entries(fine, fine_level)
    c0, c1 = level_entries(coarse, coarse_level)
    if f0 == f1 or c0 == c1:
        return count
    fine_base, coarse_base = level_offset(fine_level), level_offset(coarse_level)
    shift = 3 * (fine_level - coarse_level)
    cells = 1 << fine_level
    size = root_size / cells
    fine_keys, fine_ids = fine.keys, fine.ids
    coarse_keys, coarse_ids = coarse.keys, coarse.ids
    cursor = c0
    for e in range(f0, f1):
        key = fine_keys[e]
        ancestor = coarse_base + ((key - fine_base) >> shift)
        while cursor < c1 and coarse_keys[cursor] < ancestor:
            cursor += 1
        # Within one index and level, each unordered pair of a cell's entries once.
        first = max(cursor, e + 1) if kind == MOVING_MOVING and shift == 0 else cursor
        i = fine_ids[e]
        # i's flags and bounds in locals: read in the loop, they were read again after each pair
        # stored (the compiler cannot tell pair_a from the arrays it reads).
        awake_i, static_i = awake[i], static_indexed[i]
        lo0, lo1, lo2 = aabb_min[i, 0], aabb_min[i, 1], aabb_min[i, 2]
        hi0, hi1, hi2 = aabb_max[i, 0], aabb_max[i, 1], aabb_max[i, 2]
        for k in range(first, c1):
            if coarse_keys[k] != ancestor:
                break
            j = coarse_ids[k]
            if kind == MOVING_MOVING:
                if not (awake_i or awake[j]):
                    continue
            elif kind == MOVING_STATIC:
                if not (awake_i and static_indexed[j]):
                    continue
            elif not (static_i and awake[j]):
                continue
            if not (lo0 <= aabb_max[j, 0] and aabb_min[j, 0] <= hi0 and lo1 <= aabb_max[j, 1]
                    and aabb_min[j, 1] <= hi1 and lo2 <= aabb_max[j, 2] and aabb_min[j, 2] <= hi2):
                continue
            corner = morton(cell_coordinate(max(lo0, aabb_min[j, 0]), root_min[0], size, cells),
                            cell_coordinate(max(lo1, aabb_min[j, 1]), root_min[1], size, cells),
                            cell_coordinate(max(lo2, aabb_min[j, 2]), root_min[2], size, cells))
            if fine_base + corner != key:
                continue
            if count >= len(pair_a):
                return -1
            if kind == STATIC_MOVING:
                pair_a[count], pair_b[count] = j, i
            else:
                pair_a[count], pair_b[count] = i, j
            count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def find_body_pairs(moving, static, aabb_min, aabb_max, awake, static_indexed, root_min,
                    root_size, pair_a, pair_b):
    """Candidate body pairs whose AABBs overlap and at least one of which moves: the moving
    index against itself at every pair of levels, and against the static index at every pair of
    levels (static entries of bodies that have since woken are skipped). Returns the pair count,
    or -1 when pair_a/pair_b are full."""
    count = np.int64(0)  # a literal 0 compiled join_levels once more for it
    moving_levels, static_levels = moving.level_mask[0], static.level_mask[0]
    for fine in range(MAX_OCTREE_DEPTH + 1):
        for coarse in range(fine + 1):
            if (moving_levels >> fine) & (moving_levels >> coarse) & 1:
                count = join_levels(moving, fine, moving, coarse, MOVING_MOVING, aabb_min,
                                    aabb_max, awake, static_indexed, root_min, root_size, pair_a,
                                    pair_b, count)
            if count >= 0 and (moving_levels >> fine) & (static_levels >> coarse) & 1:
                count = join_levels(moving, fine, static, coarse, MOVING_STATIC, aabb_min,
                                    aabb_max, awake, static_indexed, root_min, root_size, pair_a,
                                    pair_b, count)
            # At one level the join above already paired them.
            if count >= 0 and coarse < fine and (static_levels >> fine) & (moving_levels >> coarse) & 1:
                count = join_levels(static, fine, moving, coarse, STATIC_MOVING, aabb_min,
                                    aabb_max, awake, static_indexed, root_min, root_size, pair_a,
                                    pair_b, count)
            if count < 0:
                return -1
    return count
