"""Batches of rays (the sensors' scans) against the ground, the playground and every body.

The wheels' single rays query the broad-phase octree with the ray's bounding box (raycast.py),
which is right for a half-metre ray but not for a 30 m lidar beam: a long diagonal ray's box
holds most of the yard. A scan is thousands of long rays at one instant, so it first files the
bodies and the playground's triangles into a uniform grid of cells around them (one pass,
~0.5 ms for a thousand bodies, once per instant for every sensor due then), then walks each ray
through that grid front to back (Amanatides-Woo), testing only the objects of the cells it
crosses, each object once per ray, and stops at the first cell that ends behind the nearest hit.
The exact tests are raycast.py's. Rays are cast in parallel chunks (Numba's threads): each ray's
result depends on that ray alone, so any thread count gives the same bytes.
"""
import os
from collections import namedtuple

import numpy as np
from numba import njit, prange

from .ids import GROUND, NOTHING, PLAYGROUND
from .math3d import quat_to_matrix
from . import shapes
from .raycast import NO_HIT, RayBodies, ray_body, ray_body_without_hull, ray_triangle

# Numba's OpenMP threads spin after each parallel batch by default: on a machine shared with the
# node's other threads (or other processes) that spinning took several times the casting's own
# CPU (bench/rays.py: 73 % of a core instead of 10 % for the sensor set). Idle threads sleep
# instead, unless the user chose a policy. Read when OpenMP loads, at the first parallel batch, so
# setting it here, after importing Numba, is in time.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


# A cell's edge is this many times the median object's size (the longest edge of its bounding
# box, bodies and triangles alike): an object then spans a few cells and a cell holds a few
# objects. Smaller cells cost a ray more steps, larger ones more exact tests.
CELL_PER_OBJECT = 1.5
# Grids never have more cells than this (memory and the filing pass); a scene spread wider gets
# coarser cells instead.
MAX_RAY_CELLS = 1 << 20
# Cells are grouped in blocks of BLOCK^3; a ray crosses an empty block in one jump (most of a
# yard is air: a lidar beam would otherwise step through every empty cell of its 30 m).
BLOCK = 4
# An object spanning more cells than this (a huge floor box) is tested by every ray instead of
# being filed in each cell.
MAX_CELLS_PER_ITEM = 512
# An object is filed in every cell it comes this close to (a fraction of the cell), so that a
# ray grazing a cell boundary, stepped into the neighbour by rounding, still finds it.
FILING_MARGIN = 1e-6
# Rays cast by one thread in a row (one mailbox of objects already tested, reset per chunk).
RAY_CHUNK = 1024

RayGrid = namedtuple("RayGrid", [
    "lower",        # (3,) min corner of the grid, world
    "cell_size",    # (1,) edge of a cell, m
    "dims",         # (3,) int64 cells per axis (all zero when there is nothing to hit)
    "cell_start",   # (C + 1,) int64: cell c holds items[cell_start[c]:cell_start[c + 1]]
    "items",        # body slot, or body capacity + triangle index
    "wide",         # items tested by every ray
    "block_items",  # (B,) int64 items filed in each block of BLOCK^3 cells
    "rotation",     # (N, 3, 3) body rotations now (the step's copy may predate edits)
])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def filed_range(lo, hi, lower, cell, dims):
    """Inclusive cell ranges (x0, x1, y0, y1, z0, z1) an AABB (grown by the filing margin)
    overlaps, clamped to the grid, and whether that is too many cells to file it in (it is then
    tested by every ray)."""
    r = np.empty(6, np.int64)
    pad = FILING_MARGIN * cell
    for k in range(3):
        r[2 * k] = min(max(int(np.floor((lo[k] - pad - lower[k]) / cell)), 0), dims[k] - 1)
        r[2 * k + 1] = min(max(int(np.floor((hi[k] + pad - lower[k]) / cell)), 0), dims[k] - 1)
    return r, (r[1] - r[0] + 1) * (r[3] - r[2] + 1) * (r[5] - r[4] + 1) > MAX_CELLS_PER_ITEM


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def separated_on(ax, ay, az, v0, v1, v2, half):
    """Whether axis a separates the triangle (vertices v, relative to the box centre) from the
    cube of half edge `half` centred on the origin."""
    p0 = ax * v0[0] + ay * v0[1] + az * v0[2]
    p1 = ax * v1[0] + ay * v1[1] + az * v1[2]
    p2 = ax * v2[0] + ay * v2[1] + az * v2[2]
    radius = half * (abs(ax) + abs(ay) + abs(az))
    return min(p0, p1, p2) > radius or max(p0, p1, p2) < -radius


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def triangle_meets_cell(triangles, t, centre, half):
    """Separating-axis test of triangle t against the cube (centre, half edge): the cube's axes,
    the triangle's normal and the nine edge-by-axis cross products (Akenine-Moeller)."""
    v0 = (triangles[t, 0, 0] - centre[0], triangles[t, 0, 1] - centre[1], triangles[t, 0, 2] - centre[2])
    v1 = (triangles[t, 1, 0] - centre[0], triangles[t, 1, 1] - centre[1], triangles[t, 1, 2] - centre[2])
    v2 = (triangles[t, 2, 0] - centre[0], triangles[t, 2, 1] - centre[1], triangles[t, 2, 2] - centre[2])
    for k in range(3):
        if min(v0[k], v1[k], v2[k]) > half or max(v0[k], v1[k], v2[k]) < -half:
            return False
    e0 = (v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2])
    e1 = (v2[0] - v1[0], v2[1] - v1[1], v2[2] - v1[2])
    e2 = (v0[0] - v2[0], v0[1] - v2[1], v0[2] - v2[2])
    nx, ny, nz = e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2], e0[0] * e1[1] - e0[1] * e1[0]
    if separated_on(nx, ny, nz, v0, v1, v2, half):
        return False
    for e in (e0, e1, e2):
        # The edge crossed with the cube's x, y and z axes.
        if (separated_on(0.0, -e[2], e[1], v0, v1, v2, half)
                or separated_on(e[2], 0.0, -e[0], v0, v1, v2, half)
                or separated_on(-e[1], e[0], 0.0, v0, v1, v2, half)):
            return False
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def file_items(used, item_min, item_max, capacity, triangles, lower, cell, dims, counts, items, fill,
               wide, write):
    """One filing pass over the used items: with write False it counts each cell's items into
    counts[c + 1] and returns how many are wide; with write True it writes them into items
    (fill[c]: cell c's next free place) and the wide ones into `wide`. A body is filed in every
    cell of its bounding box, a triangle only in the cells it passes through."""
    half = 0.5 * cell * (1.0 + FILING_MARGIN)
    centre = np.empty(3)
    wide_count = 0
    for i in range(len(used)):
        if not used[i]:
            continue
        r, too_wide = filed_range(item_min[i], item_max[i], lower, cell, dims)
        if too_wide:
            if write:
                wide[wide_count] = i
            wide_count += 1
            continue
        for x in range(r[0], r[1] + 1):
            for y in range(r[2], r[3] + 1):
                for z in range(r[4], r[5] + 1):
                    if i >= capacity:
                        centre[0] = lower[0] + (x + 0.5) * cell
                        centre[1] = lower[1] + (y + 0.5) * cell
                        centre[2] = lower[2] + (z + 0.5) * cell
                        if not triangle_meets_cell(triangles, i - capacity, centre, half):
                            continue
                    c = (x * dims[1] + y) * dims[2] + z
                    if write:
                        items[fill[c]] = i
                        fill[c] += 1
                    else:
                        counts[c + 1] += 1
    return wide_count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def build_ray_grid(active, position, orientation, half_extents, triangles, tri_min, tri_max):
    """The RayGrid of the active bodies (at their current poses) and the playground triangles."""
    n, capacity = len(active), len(active)
    rotation = np.zeros((n, 3, 3))
    item_min = np.empty((n + len(triangles), 3))
    item_max = np.empty((n + len(triangles), 3))
    used = np.zeros(n + len(triangles), np.bool_)
    lower = np.full(3, np.inf)
    upper = np.full(3, -np.inf)
    for i in range(n):
        # A body whose state went non-finite is removed after the step; nothing can hit it.
        if not (active[i] and np.all(np.isfinite(position[i])) and np.all(np.isfinite(orientation[i]))):
            continue
        quat_to_matrix(orientation[i], rotation[i])
        for k in range(3):
            e = (abs(rotation[i, k, 0]) * half_extents[i, 0] + abs(rotation[i, k, 1]) * half_extents[i, 1]
                 + abs(rotation[i, k, 2]) * half_extents[i, 2])
            item_min[i, k], item_max[i, k] = position[i, k] - e, position[i, k] + e
        used[i] = True
    for t in range(len(triangles)):
        for k in range(3):  # not row by row: see prepare_contacts' solve_order
            item_min[capacity + t, k], item_max[capacity + t, k] = tri_min[t, k], tri_max[t, k]
        used[capacity + t] = True
    sizes = np.empty(len(used))
    count = 0
    for i in range(len(used)):
        if used[i]:
            sizes[count] = 0.0
            for k in range(3):
                lower[k] = min(lower[k], item_min[i, k])
                upper[k] = max(upper[k], item_max[i, k])
                sizes[count] = max(sizes[count], item_max[i, k] - item_min[i, k])
            count += 1
    dims = np.zeros(3, np.int64)
    if count == 0:
        return RayGrid(np.zeros(3), np.ones(1), dims, np.zeros(1, np.int64),
                       np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(1, np.int64), rotation)
    extent = upper - lower
    cell = max(CELL_PER_OBJECT * np.median(sizes[:count]), 1e-3,
               (extent[0] * extent[1] * extent[2] / MAX_RAY_CELLS) ** (1.0 / 3.0))
    while True:
        for k in range(3):
            dims[k] = max(1, int(np.ceil(extent[k] / cell)))
        if dims[0] * dims[1] * dims[2] <= MAX_RAY_CELLS:
            break
        cell *= 1.1  # a flat scene: the volume estimate undercounts the cells of thin axes
    counts = np.zeros(dims[0] * dims[1] * dims[2] + 1, np.int64)
    no_items = np.zeros(0, np.int64)
    wide_count = file_items(used, item_min, item_max, capacity, triangles, lower, cell, dims, counts,
                            no_items, no_items, no_items, False)
    cell_start = np.cumsum(counts)
    items = np.empty(cell_start[-1], np.int64)
    wide = np.empty(wide_count, np.int64)
    file_items(used, item_min, item_max, capacity, triangles, lower, cell, dims, counts, items,
               cell_start[:-1].copy(), wide, True)
    by, bz = (dims[1] + BLOCK - 1) // BLOCK, (dims[2] + BLOCK - 1) // BLOCK
    block_items = np.zeros(((dims[0] + BLOCK - 1) // BLOCK) * by * bz, np.int64)
    for x in range(dims[0]):
        for y in range(dims[1]):
            for z in range(dims[2]):
                c = (x * dims[1] + y) * dims[2] + z
                block_items[((x // BLOCK) * by + y // BLOCK) * bz + z // BLOCK] += cell_start[c + 1] - cell_start[c]
    return RayGrid(lower, np.array((cell,)), dims, cell_start, items, wide, block_items, rotation)


ASK_HULL = -1.0  # test_item's answer for a convex or compound body: ask ray_body with the tables


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def test_item(item, o, d, limit, excluded, geometry, triangles, normals):
    """(t, what, normal) of grid item `item` (a body slot, or capacity + a triangle) if the ray
    hits it nearer than `limit`, else t NO_HIT; t ASK_HULL for a convex or compound body the ray
    may hit, which the caller tests with the hull and parts tables (handed to this inlined test,
    their arrays' reference counts cost every item a quarter of the rays' speed)."""
    capacity = len(excluded)
    if item < capacity:
        if excluded[item]:
            return NO_HIT, item, (0.0, 0.0, 0.0)
        # Most bodies a ray meets in its cells it passes by: the bounding sphere rules those out
        # without the exact test (with a margin for the rounding of a far body).
        position, half_extents = geometry.position, geometry.half_extents
        vx, vy, vz = position[item, 0] - o[0], position[item, 1] - o[1], position[item, 2] - o[2]
        along = vx * d[0] + vy * d[1] + vz * d[2]
        h = (half_extents[item, 0], half_extents[item, 1], half_extents[item, 2])
        radius2, away2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2], vx * vx + vy * vy + vz * vz
        if away2 - along * along > radius2 + 1e-9 * (radius2 + away2):
            return NO_HIT, item, (0.0, 0.0, 0.0)
        if geometry.shape[item] == shapes.CONVEX or geometry.shape[item] == shapes.COMPOUND:
            return ASK_HULL, item, (0.0, 0.0, 0.0)
        t, face = ray_body_without_hull(o, d, limit, geometry, item)
        return t, item, face
    tri = item - capacity
    t = ray_triangle(o, d, limit, triangles, normals, tri)
    return t, PLAYGROUND, (normals[tri, 0], normals[tri, 1], normals[tri, 2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def boundary_t(c, step, lower, cell, o, inverse_d):
    """t at which the ray leaves cell c along one axis (NO_HIT when it does not move along it);
    inverse_d is 1 / the direction's component (multiplying: the walk is mostly this)."""
    if step > 0:
        return (lower + (c + 1) * cell - o) * inverse_d
    if step < 0:
        return (lower + c * cell - o) * inverse_d
    return NO_HIT


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def clip_slab(o, step, inverse_d, lo, hi, t0, t1):
    """[t0, t1] narrowed to where the ray lies between lo and hi along one axis (empty: t0 > t1)."""
    if step == 0:
        return (t0, t1) if lo <= o <= hi else (1.0, 0.0)
    a, b = (lo - o) * inverse_d, (hi - o) * inverse_d
    return max(t0, min(a, b)), min(t1, max(a, b))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def axis_step(d):
    return 1 if d > 1e-12 else (-1 if d < -1e-12 else 0)


# error_model "numpy": no zero-division checks (every division here is guarded or meant to give
# inf), which cost the walk a branch each.
@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, error_model="numpy")
def cast_chunk(start, stop, origins, directions, max_range, excluded, grid, geometry, hulls, parts,
               triangles, normals, ground_enabled, ground_height, row_of_slot, distance, point, normal, hit):
    """cast_ray_batch for rays start..stop; returns how many of them were invalid (a zero or
    non-finite direction, a non-finite origin, a NaN range): those are left unwritten."""
    lower, cell, dims = grid.lower, grid.cell_size[0], grid.dims
    cell_start, items, wide, block_items = grid.cell_start, grid.items, grid.wide, grid.block_items
    nx, ny, nz = dims[0], dims[1], dims[2]
    by, bz = (ny + BLOCK - 1) // BLOCK, (nz + BLOCK - 1) // BLOCK
    lx, ly, lz = lower[0], lower[1], lower[2]
    inverse_cell = 1.0 / cell
    # The ray that last tested each item: an object filed in several cells is tested once a ray.
    tested_by = np.full(len(excluded) + len(triangles), -1, np.int64)
    invalid = 0
    # One origin or one range may serve every ray (a sensor's scan): row 0 then.
    origin_step, range_step = min(len(origins) - 1, 1), min(len(max_range) - 1, 1)
    for i in range(start, stop):
        j = i * origin_step
        o = (origins[j, 0], origins[j, 1], origins[j, 2])
        length = np.sqrt(directions[i, 0] ** 2 + directions[i, 1] ** 2 + directions[i, 2] ** 2)
        reach = max_range[i * range_step]
        if not (length > 0.0 and np.isfinite(length) and np.isfinite(o[0]) and np.isfinite(o[1])
                and np.isfinite(o[2]) and not np.isnan(reach)):
            invalid += 1
            continue
        d = (directions[i, 0] / length, directions[i, 1] / length, directions[i, 2] / length)
        best, what, n = NO_HIT, NOTHING, (0.0, 0.0, 0.0)
        if ground_enabled and d[2] < 0.0:
            t = (ground_height - o[2]) / d[2]
            if 0.0 <= t <= reach:
                best, what, n = t, GROUND, (0.0, 0.0, 1.0)
        limit = min(best, reach)
        for k in range(len(wide)):
            t, obj, face = test_item(wide[k], o, d, limit, excluded, geometry, triangles, normals)
            if t == ASK_HULL:
                t, face = ray_body(o, d, limit, geometry, hulls, parts, obj)
            if t < limit:
                best, limit, what, n = t, t, obj, face
        # The ray's part inside the grid box, [t0, t1]. Per axis the direction of travel and
        # 1 / the direction (unused along an axis it does not move along).
        sx, sy, sz = axis_step(d[0]), axis_step(d[1]), axis_step(d[2])
        ix = 1.0 / d[0] if sx else 0.0
        iy = 1.0 / d[1] if sy else 0.0
        iz = 1.0 / d[2] if sz else 0.0
        t0, t1 = 0.0, limit
        if nx == 0:
            t1 = -1.0
        t0, t1 = clip_slab(o[0], sx, ix, lx, lx + nx * cell, t0, t1)
        t0, t1 = clip_slab(o[1], sy, iy, ly, ly + ny * cell, t0, t1)
        t0, t1 = clip_slab(o[2], sz, iz, lz, lz + nz * cell, t0, t1)
        if t0 > t1:
            t1 = -1.0  # nothing to walk
        # Amanatides-Woo from the entry point: the cell, and per axis the t of the next cell
        # boundary and the t between boundaries.
        cx = min(max(int(np.floor((o[0] + t0 * d[0] - lx) * inverse_cell)), 0), nx - 1)
        cy = min(max(int(np.floor((o[1] + t0 * d[1] - ly) * inverse_cell)), 0), ny - 1)
        cz = min(max(int(np.floor((o[2] + t0 * d[2] - lz) * inverse_cell)), 0), nz - 1)
        next_x, next_y = boundary_t(cx, sx, lx, cell, o[0], ix), boundary_t(cy, sy, ly, cell, o[1], iy)
        next_z = boundary_t(cz, sz, lz, cell, o[2], iz)
        delta_x = cell * abs(ix) if sx else NO_HIT
        delta_y = cell * abs(iy) if sy else NO_HIT
        delta_z = cell * abs(iz) if sz else NO_HIT
        while t1 >= 0.0:
            if block_items[((cx // BLOCK) * by + cy // BLOCK) * bz + cz // BLOCK] == 0:
                # An empty block: jump to where the ray leaves it, in the cell beyond.
                ex = boundary_t(cx // BLOCK, sx, lx, BLOCK * cell, o[0], ix)
                ey = boundary_t(cy // BLOCK, sy, ly, BLOCK * cell, o[1], iy)
                ez = boundary_t(cz // BLOCK, sz, lz, BLOCK * cell, o[2], iz)
                leave = min(ex, ey, ez)
                if leave > t1 or limit <= leave:
                    break
                # The other two axes stay within the block (clamped against rounding): a cell
                # of the empty block visited again only costs another jump.
                x0, y0, z0 = (cx // BLOCK) * BLOCK, (cy // BLOCK) * BLOCK, (cz // BLOCK) * BLOCK
                cx = min(max(int(np.floor((o[0] + leave * d[0] - lx) * inverse_cell)), x0), x0 + BLOCK - 1)
                cy = min(max(int(np.floor((o[1] + leave * d[1] - ly) * inverse_cell)), y0), y0 + BLOCK - 1)
                cz = min(max(int(np.floor((o[2] + leave * d[2] - lz) * inverse_cell)), z0), z0 + BLOCK - 1)
                if ex == leave:
                    cx = x0 + BLOCK if sx > 0 else x0 - 1
                elif ey == leave:
                    cy = y0 + BLOCK if sy > 0 else y0 - 1
                else:
                    cz = z0 + BLOCK if sz > 0 else z0 - 1
                if cx < 0 or cx >= nx or cy < 0 or cy >= ny or cz < 0 or cz >= nz:
                    break
                next_x, next_y = boundary_t(cx, sx, lx, cell, o[0], ix), boundary_t(cy, sy, ly, cell, o[1], iy)
                next_z = boundary_t(cz, sz, lz, cell, o[2], iz)
                continue
            c = (cx * ny + cy) * nz + cz
            for k in range(cell_start[c], cell_start[c + 1]):
                item = items[k]
                if tested_by[item] == i:
                    continue  # its nearest hit, if any nearer than the limit then, is counted
                tested_by[item] = i
                t, obj, face = test_item(item, o, d, limit, excluded, geometry, triangles, normals)
                if t == ASK_HULL:
                    t, face = ray_body(o, d, limit, geometry, hulls, parts, obj)
                if t < limit:
                    best, limit, what, n = t, t, obj, face
            cell_exit = min(next_x, next_y, next_z)
            # Anything nearer than this cell's far side has been seen: objects of later cells
            # start behind it.
            if limit <= cell_exit or cell_exit > t1:
                break
            if next_x <= next_y and next_x <= next_z:
                cx += sx
                next_x += delta_x
                if cx < 0 or cx >= nx:
                    break
            elif next_y <= next_z:
                cy += sy
                next_y += delta_y
                if cy < 0 or cy >= ny:
                    break
            else:
                cz += sz
                next_z += delta_z
                if cz < 0 or cz >= nz:
                    break
        distance[i], hit[i] = best, row_of_slot[what] if what >= 0 else what
        normal[i, 0], normal[i, 1], normal[i, 2] = n[0], n[1], n[2]
        if best < NO_HIT:
            point[i, 0], point[i, 1], point[i, 2] = o[0] + best * d[0], o[1] + best * d[1], o[2] + best * d[2]
        else:
            point[i, 0], point[i, 1], point[i, 2] = np.nan, np.nan, np.nan
    return invalid


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, parallel=True, error_model="numpy")
def cast_ray_batch(origins, directions, max_range, excluded, grid, geometry, hulls, parts, triangles,
                   normals, ground_enabled, ground_height, row_of_slot, distance, point, normal,
                   hit):
    """Nearest hit of each ray origins[i] + t directions[i] (normalised here), 0 <= t <=
    max_range[i] (origins or max_range may have one row for all rays), with the ground, the
    playground or a body not `excluded` (bool per slot). Writes distance (NO_HIT for nothing),
    the hit point (NaN for nothing), the surface normal and what was hit (row_of_slot of the body
    slot, GROUND, PLAYGROUND or NOTHING). Returns the count of invalid rays (see cast_chunk)."""
    chunks = (len(directions) + RAY_CHUNK - 1) // RAY_CHUNK
    invalid = np.zeros(chunks, np.int64)
    for chunk in prange(chunks):
        invalid[chunk] = cast_chunk(chunk * RAY_CHUNK, min(len(directions), (chunk + 1) * RAY_CHUNK),
                                    origins, directions, max_range, excluded, grid, geometry,
                                    hulls, parts, triangles, normals, ground_enabled, ground_height,
                                    row_of_slot, distance, point, normal, hit)
    return invalid.sum()


RayHits = namedtuple("RayHits", [
    "distance",  # (R,) m along the ray, inf for no hit within its range
    "point",     # (R, 3) world, NaN for no hit
    "normal",    # (R, 3) unit outward surface normal at the hit (zero for no hit)
    "body",      # (R,) row of World.state() hit, or GROUND, PLAYGROUND, NOTHING
])


class RayScene:
    """What rays can hit at one instant (World.ray_scene()): the grid is filed once, and any
    number of batches (the sensors due at that instant) cast through it. Bodies that collide
    with nothing are not in it: rays pass through them as other bodies do."""

    def __init__(self, bodies, hulls, parts, playground, ground, slots):
        self._bodies, self._playground, self._slots = bodies, playground, slots
        self._ground = ground
        self._grid = build_ray_grid(bodies.active & bodies.collides, bodies.position, bodies.orientation,
                                    bodies.half_extents, playground.triangles,
                                    playground.aabb_min, playground.aabb_max)
        self._geometry = RayBodies(bodies.position, self._grid.rotation, bodies.half_extents,
                                   bodies.shape, bodies.dimensions)
        self._hulls, self._parts = hulls, parts
        self._row_of_slot = np.cumsum(bodies.active) - 1

    def cast(self, origins, directions, max_range, exclude=(), out=None):
        """RayHits of the rays origins (R, 3, or one point (3,) for all) + t directions (R, 3;
        normalised here), 0 <= t <= max_range (a number or (R,)), ignoring the bodies named in
        `exclude` (a sensor's parent). One compiled call for the whole batch. `out`: RayHits of
        R rows to fill and return instead of new arrays (a sensor reuses its own every scan)."""
        directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        count = len(directions)
        origins = np.ascontiguousarray(origins, dtype=np.float64)
        origins = origins.reshape(1, 3) if origins.shape == (3,) else origins.reshape(-1, 3)
        if len(origins) != count and origins.shape != (1, 3):
            raise ValueError(f"cast_rays: {len(origins)} origins but {count} directions")
        max_range = np.ascontiguousarray(max_range, dtype=np.float64).reshape(-1)
        if len(max_range) not in (1, count):
            raise ValueError(f"cast_rays: {len(max_range)} ranges for {count} rays")
        excluded = np.zeros(len(self._bodies.active), np.bool_)
        for name in exclude:
            if name not in self._slots:
                raise KeyError(f"cast_rays: no body named {name!r} to exclude")
            excluded[self._slots[name]] = True
        if out is None:
            out = RayHits(np.empty(count), np.empty((count, 3)), np.empty((count, 3)),
                          np.empty(count, np.int64))
        elif len(out.distance) != count:
            raise ValueError(f"cast_rays: out holds {len(out.distance)} rays, not {count}")
        g = self._ground
        invalid = cast_ray_batch(origins, directions, max_range, excluded, self._grid,
                                 self._geometry, self._hulls, self._parts, self._playground.triangles,
                                 self._playground.normals, g is not None,
                                 float(g["height"]) if g else 0.0, self._row_of_slot, *out)
        if invalid:
            raise ValueError(f"cast_rays: {invalid} rays with a zero or non-finite direction, a "
                             "non-finite origin or a NaN range: every direction must be non-zero and "
                             "every value finite")
        return out
