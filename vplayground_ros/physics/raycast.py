"""Ray casts (the wheels' contact with the world): against the ground plane, the playground's
triangles and the bodies, each found through the octree rather than by testing everything."""
from collections import namedtuple

import numpy as np
from numba import njit

from . import shapes
from .broad_phase import cell_box, object_level, query_index
from .ids import GROUND, PLAYGROUND
from .math3d import body_frame_ray

NO_HIT = np.inf

# What a ray needs of the bodies: their poses and shapes (flat: a parallel loop takes no nested
# tuples; a convex body's hull comes in the shapes.Hulls table beside it).
RayBodies = namedtuple("RayBodies", "position rotation half_extents shape dimensions")


# The exact tests take the arrays and an index rather than one body's rows, and are inlined
# where they are called: a scan runs them millions of times a second, and every row view handed
# to a call costs Numba reference counting that would outweigh the test itself.
@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def ray_body(origin, direction, reach, geometry, hulls, parts, j):
    """The ray against body j of RayBodies `geometry` (and the hull and parts tables):
    (distance, outward normal in the world), NO_HIT when it misses or starts inside. Every
    shape is asked in its own frame (physics.shapes)."""
    o, d = body_frame_ray(origin, direction, geometry, j)
    dims = (geometry.dimensions[j, 0], geometry.dimensions[j, 1], geometry.dimensions[j, 2])
    return world_normal(shapes.ray(geometry.shape[j], dims, hulls, parts, j, o, d, reach), geometry.rotation, j)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def ray_body_without_hull(origin, direction, reach, geometry, j):
    """ray_body for a body that is not convex (see shapes.ray_without_hull)."""
    o, d = body_frame_ray(origin, direction, geometry, j)
    dims = (geometry.dimensions[j, 0], geometry.dimensions[j, 1], geometry.dimensions[j, 2])
    return world_normal(shapes.ray_without_hull(geometry.shape[j], dims, o, d, reach), geometry.rotation, j)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def world_normal(hit, r, j):
    """(t, the body-frame normal) -> (t, the world normal); a miss stays NO_HIT."""
    t, n = hit
    if t == NO_HIT:
        return NO_HIT, (0.0, 0.0, 0.0)
    return t, (r[j, 0, 0] * n[0] + r[j, 0, 1] * n[1] + r[j, 0, 2] * n[2],
               r[j, 1, 0] * n[0] + r[j, 1, 1] * n[1] + r[j, 1, 2] * n[2],
               r[j, 2, 0] * n[0] + r[j, 2, 1] * n[1] + r[j, 2, 2] * n[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def ray_triangle(origin, direction, reach, triangles, normals, j):
    """Moeller-Trumbore against triangle j's front face only (playground triangles are
    one-sided): the distance, or NO_HIT."""
    tri, normal = triangles, normals
    if direction[0] * normal[j, 0] + direction[1] * normal[j, 1] + direction[2] * normal[j, 2] >= 0.0:
        return NO_HIT
    e1 = (tri[j, 1, 0] - tri[j, 0, 0], tri[j, 1, 1] - tri[j, 0, 1], tri[j, 1, 2] - tri[j, 0, 2])
    e2 = (tri[j, 2, 0] - tri[j, 0, 0], tri[j, 2, 1] - tri[j, 0, 1], tri[j, 2, 2] - tri[j, 0, 2])
    pv = (direction[1] * e2[2] - direction[2] * e2[1], direction[2] * e2[0] - direction[0] * e2[2],
          direction[0] * e2[1] - direction[1] * e2[0])
    det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2]
    if abs(det) < 1e-14:
        return NO_HIT
    inv = 1.0 / det
    s = (origin[0] - tri[j, 0, 0], origin[1] - tri[j, 0, 1], origin[2] - tri[j, 0, 2])
    u = (s[0] * pv[0] + s[1] * pv[1] + s[2] * pv[2]) * inv
    if u < 0.0 or u > 1.0:
        return NO_HIT
    q = (s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0])
    v = (direction[0] * q[0] + direction[1] * q[1] + direction[2] * q[2]) * inv
    if v < 0.0 or u + v > 1.0:
        return NO_HIT
    t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv
    return t if 0.0 <= t <= reach else NO_HIT


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cast_ray(origin, direction, reach, exclude, query_id, bodies, hulls, parts, broad, playground, s):
    """Nearest hit of the segment origin + t direction, 0 <= t <= reach (direction unit), with
    anything in the world of the StepContext's parts (`s` its Settings) but body `exclude`: (t,
    what: a body slot, GROUND or PLAYGROUND, normal), t NO_HIT when nothing is hit. `query_id`
    (negative, unique per ray in a step) marks objects seen. (The parts, not the context: a
    kernel handed the context compiles a wrapper unboxing its ~200 arrays, seconds each.)"""
    ground_enabled, ground_height = s.ground_enabled, s.ground_height
    root_min, root_size, depth = s.root_min, s.root_size, s.octree_depth
    geometry = RayBodies(bodies.position, bodies.rotation, bodies.half_extents, bodies.shape,
                         bodies.dimensions)
    best, hit, best_normal = NO_HIT, GROUND, (0.0, 0.0, 1.0)
    if ground_enabled and direction[2] < 0.0:
        t = (ground_height - origin[2]) / direction[2]
        if 0.0 <= t <= reach:
            best = t
    end = (origin[0] + reach * direction[0], origin[1] + reach * direction[1], origin[2] + reach * direction[2])
    lo = (min(origin[0], end[0]), min(origin[1], end[1]), min(origin[2], end[2]))
    hi = (max(origin[0], end[0]), max(origin[1], end[1]), max(origin[2], end[2]))
    level = object_level(lo, hi, root_size, depth)
    box = cell_box(lo, hi, level, root_min, root_size)
    for index in (broad.moving, broad.static):
        n = query_index(index, level, box, True, broad.stamp, query_id, broad.scratch)
        for m in range(n):
            j = broad.scratch[m]
            if j == exclude or not bodies.active[j] or not bodies.collides[j]:
                continue  # (a static entry can outlive an edit that made its body collide with nothing)
            t, normal = ray_body(origin, direction, reach, geometry, hulls, parts, j)
            if t < best:
                best, hit, best_normal = t, j, normal
    if len(playground.triangles):
        n = query_index(playground.index, level, box, True, playground.stamp, query_id,
                        playground.scratch)
        for m in range(n):
            tri = playground.scratch[m]
            t = ray_triangle(origin, direction, reach, playground.triangles, playground.normals, tri)
            if t < best:
                nt = playground.normals[tri]
                best, hit, best_normal = t, PLAYGROUND, (nt[0], nt[1], nt[2])
    return best, hit, best_normal
