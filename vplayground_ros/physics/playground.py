"""The playground: a static triangle mesh that boxes roll and slide over (the 2008 program's
triangle model). Triangles are one-sided, facing where their counter-clockwise winding points;
they are indexed once in the octree (again only if the octree's root or depth changes).
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .broad_phase import (MAX_CELLS_PER_OBJECT, aabbs_overlap, allocate_index, build_index,
                          cell_box, object_level, query_index)

Playground = namedtuple("Playground", [
    "triangles",          # (T, 3, 3) vertices, world, counter-clockwise seen from the front
    "normals",            # (T, 3) unit front normals
    "aabb_min", "aabb_max",  # (T, 3)
    "octree_level",       # (T,) int64
    "index",              # OctreeIndex of the triangles
    "stamp", "scratch",   # (T,) scratch of the pair queries
])

# Triangles with less area than this (m^2) are degenerate: no normal to speak of.
MIN_TRIANGLE_AREA = 1e-10


def make_playground(vertices, faces):
    """A Playground from world-space vertices (V, 3) and triangle indices (T, 3). Degenerate
    triangles (repeated or collinear corners) are dropped; returns (playground, dropped count).
    Raises ValueError naming the problem for non-finite vertices or indices out of range."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if not np.all(np.isfinite(vertices)):
        bad = int(np.nonzero(~np.all(np.isfinite(vertices), axis=1))[0][0])
        raise ValueError(f"vertex {bad} is not finite: {vertices[bad].tolist()}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        bad = int(np.nonzero((faces < 0).any(axis=1) | (faces >= len(vertices)).any(axis=1))[0][0])
        raise ValueError(f"face {bad} refers to a vertex that does not exist "
                         f"({faces[bad].tolist()}, {len(vertices)} vertices)")
    triangles = vertices[faces]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    keep = area2 > 2.0 * MIN_TRIANGLE_AREA
    triangles, cross, area2 = triangles[keep], cross[keep], area2[keep]
    count = len(triangles)
    playground = Playground(
        triangles=np.ascontiguousarray(triangles),
        normals=cross / area2[:, None] if count else np.zeros((0, 3)),
        aabb_min=triangles.min(axis=1) if count else np.zeros((0, 3)),
        aabb_max=triangles.max(axis=1) if count else np.zeros((0, 3)),
        octree_level=np.zeros(count, np.int64),
        index=allocate_index(MAX_CELLS_PER_OBJECT * count),
        stamp=np.full(count, -1, np.int64),
        scratch=np.zeros(count, np.int64))
    return playground, int(np.count_nonzero(~keep))


EMPTY_PLAYGROUND_ARGS = (np.zeros((0, 3)), np.zeros((0, 3), np.int64))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def index_playground(playground, root_min, root_size, depth):
    """(Re)builds the triangles' octree index for the given root cube and depth."""
    for t in range(len(playground.triangles)):
        lo, hi = playground.aabb_min, playground.aabb_max
        playground.octree_level[t] = object_level((lo[t, 0], lo[t, 1], lo[t, 2]), (hi[t, 0], hi[t, 1], hi[t, 2]),
                                                  root_size, depth)
    ids = np.arange(len(playground.triangles))
    return build_index(playground.index, ids, playground.aabb_min, playground.aabb_max,
                       playground.octree_level, root_min, root_size)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def find_playground_pairs(playground, moving_ids, bodies, root_min, root_size, pair_body,
                          pair_triangle):
    """(awake body, triangle) pairs whose bounds overlap, from the triangles' octree. Returns the
    pair count, or -1 when the pair buffers are full."""
    if len(playground.triangles) == 0:
        return 0
    stamp, scratch = playground.stamp, playground.scratch
    stamp[:] = -1
    tri_min, tri_max = playground.aabb_min, playground.aabb_max
    body_min, body_max = bodies.aabb_min, bodies.aabb_max
    count = 0
    for k in range(len(moving_ids)):
        i = moving_ids[k]
        if not bodies.awake[i]:
            continue
        level = bodies.octree_level[i]
        box = cell_box((body_min[i, 0], body_min[i, 1], body_min[i, 2]),
                       (body_max[i, 0], body_max[i, 1], body_max[i, 2]), level, root_min, root_size)
        n = query_index(playground.index, level, box, True, stamp, i, scratch)
        for m in range(n):
            t = scratch[m]
            if aabbs_overlap(body_min[i], body_max[i], tri_min[t], tri_max[t]):
                if count >= len(pair_body):
                    return -1
                pair_body[count], pair_triangle[count] = i, t
                count += 1
    return count
