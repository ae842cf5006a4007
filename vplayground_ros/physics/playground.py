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
    "edges",              # (T,) int64 which edges are concave creases (mesh_edges: CONCAVE bits)
    "creases",            # (T, 3, 4) across each concave edge, the neighbour's plane (normal, offset)
    "aabb_min", "aabb_max",  # (T, 3)
    "octree_level",       # (T,) int64
    "index",              # OctreeIndex of the triangles
    "stamp", "scratch",   # (T,) scratch of the pair queries
])

# Triangles with less area than this (m^2) are degenerate: no normal to speak of.
MIN_TRIANGLE_AREA = 1e-10

# The bit of Playground.edges for edge j of a triangle (from corner j to corner j + 1) is
# CONCAVE << j when one other triangle shares it, wound the same way round (it runs the edge the
# other way), and rises in front of this one's plane: a crease the mesh turns up at (a ramp
# meeting a floor, the half-pipe's strips).
CONCAVE = 1

# A neighbour rises in front of a plane when its far corner is in front by more than this
# share of its distance from the edge's first corner (~0.06 degrees): flatter seams are seams.
CREASE_SINE = 1e-3

# Corners closer than this (m) are one vertex of the mesh (an exporter's rounding).
WELD = 1e-6


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
    normals = cross / area2[:, None] if count else np.zeros((0, 3))
    playground = Playground(
        triangles=np.ascontiguousarray(triangles),
        normals=normals,
        **dict(zip(("edges", "creases"), mesh_edges(triangles, normals))),
        aabb_min=triangles.min(axis=1) if count else np.zeros((0, 3)),
        aabb_max=triangles.max(axis=1) if count else np.zeros((0, 3)),
        octree_level=np.zeros(count, np.int64),
        index=allocate_index(MAX_CELLS_PER_OBJECT * count),
        stamp=np.full(count, -1, np.int64),
        scratch=np.zeros(count, np.int64))
    return playground, int(np.count_nonzero(~keep))


def mesh_edges(triangles, normals):
    """(Playground.edges, Playground.creases) of triangles (T, 3, 3) with unit normals (T, 3):
    which triangles share an edge is found by where their corners are (a mesh may repeat a
    vertex, or round it: corners within WELD are one), whether it is a crease from the one other
    triangle on it (an edge of three or more triangles, a two-sided sheet's, is none)."""
    count = len(triangles)
    edges, creases = np.zeros(count, np.int64), np.zeros((count, 3, 4))
    if count == 0:
        return edges, creases
    # (Imported here: scipy's import is a tenth of a second, and only playgrounds need it.)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree
    corners = triangles.reshape(-1, 3)
    near = cKDTree(corners).query_pairs(WELD, output_type="ndarray")
    _, vertex = connected_components(coo_matrix((np.ones(len(near)), (near[:, 0], near[:, 1])),
                                                shape=(len(corners), len(corners))), directed=False)
    vertex = vertex.reshape(count, 3)
    start, end = vertex, np.roll(vertex, -1, axis=1)  # edge j: corner j to corner j + 1
    low, high = np.minimum(start, end).ravel(), np.maximum(start, end).ravel()
    order = np.lexsort((high, low))  # slots t * 3 + j, each edge's slots side by side
    first = np.r_[True, (low[order][1:] != low[order][:-1]) | (high[order][1:] != high[order][:-1])]
    run = np.cumsum(first) - 1
    sharing = np.bincount(run)[run]  # how many triangles have the edge of each sorted slot
    pairs = np.nonzero(first & (sharing == 2))[0]
    pairs = pairs[start.ravel()[order[pairs]] == end.ravel()[order[pairs + 1]]]  # wound alike
    for this, other in ((order[pairs], order[pairs + 1]), (order[pairs + 1], order[pairs])):
        t, j, neighbour = this // 3, this % 3, other // 3
        far = triangles[neighbour, (other % 3 + 2) % 3] - triangles[t, j]  # the neighbour's far corner
        rises = np.einsum("ij,ij->i", normals[t], far) > CREASE_SINE * np.linalg.norm(far, axis=1)
        t, j, neighbour = t[rises], j[rises], neighbour[rises]
        np.bitwise_or.at(edges, t, CONCAVE << j)  # (|= keeps one per triangle)
        creases[t, j, :3] = normals[neighbour]
        creases[t, j, 3] = np.einsum("ij,ij->i", normals[neighbour], triangles[neighbour, 0])
    return edges, creases


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def crease_rows(creases, t):
    """Triangle t's Playground.creases as a tuple of three (normal x, y, z, offset) tuples."""
    return ((creases[t, 0, 0], creases[t, 0, 1], creases[t, 0, 2], creases[t, 0, 3]),
            (creases[t, 1, 0], creases[t, 1, 1], creases[t, 1, 2], creases[t, 1, 3]),
            (creases[t, 2, 0], creases[t, 2, 1], creases[t, 2, 2], creases[t, 2, 3]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def past_crease(edges, creases, j, point):
    """Whether a triangle's edge j is a concave crease (`edges`, `creases`: the triangle's,
    crease_rows) with a body whose centre is at `point` in front of the triangle across it (the
    callers ask for a body beside the triangle at that edge): then the mesh goes on in front of
    this triangle's plane, between the two, and that plane holds up the body there too. (A body
    crossing the crease quickly is behind the plane by the step after, where a one-sided
    triangle gives no contact.) A body behind the other triangle (a fence rising from a floor,
    seen from outside) has nothing under it."""
    if not edges & (CONCAVE << j):
        return False
    plane = creases[j]
    return point[0] * plane[0] + point[1] * plane[1] + point[2] * plane[2] > plane[3]


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
