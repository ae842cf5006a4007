"""Body shapes. A body's shape is a code in `bodies.shape` and three numbers in
`bodies.dimensions` (what they mean is the shape module's: half extents of a box, a radius and
a half length); a convex body's hull is in the World's Hulls table at the body's slot, a
compound body's parts in its Parts table (compound.py). Every shape-dependent question is
answered here, by one dispatch each, from the shape's module.

Adding a shape: a module like box.py (spec keys, mass properties, bounds, support mapping and
supporting face for the narrow phase's convex path, ray cast; all in the body's frame) and a
row in SHAPES and in each dispatcher below. The compiled dispatchers take the hull table and
the body's slot (`hulls, h`) whatever the shape; only convex bodies read them. The narrow phase
asks a compound's parts one by one (each a shape of its own), so the convex path's dispatchers
never see a compound; the bounds and ray casts answer for one as a whole.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from ..math3d import body_frame_ray, quat_to_matrix
from .geometry import NO_HIT

from . import box, capsule, compound, convex, cylinder, sphere

BOX, SPHERE, CAPSULE, CYLINDER, CONVEX, COMPOUND = 0, 1, 2, 3, 4, 5

Shape = namedtuple("Shape", "code module")
SHAPES = {"box": Shape(BOX, box), "sphere": Shape(SPHERE, sphere),
          "capsule": Shape(CAPSULE, capsule), "cylinder": Shape(CYLINDER, cylinder),
          "convex": Shape(CONVEX, convex), "compound": Shape(COMPOUND, compound)}
SHAPE_NAMES = {shape.code: name for name, shape in SHAPES.items()}

# The most points a supporting face has: a cylinder's end, or up to this many corners of a
# hull's face (a face with more keeps this many, a convex part of it).
MAX_FACE_POINTS = 16


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def half_extents(kind, dims):
    """Half extents of the shape's bounding box in its own frame."""
    if kind == BOX:
        return box.half_extents(dims)
    if kind == SPHERE:
        return sphere.half_extents(dims)
    if kind == CAPSULE:
        return capsule.half_extents(dims)
    if kind == CYLINDER:
        return cylinder.half_extents(dims)
    return dims


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def world_extent(kind, dims, r, e):
    """Half the extent along world axis e of the shape turned by rotation r (3x3, columns the
    body axes): the exact bounding box, not the box around the body-frame one (a hull's and a
    compound's is the box around its body-frame bounding box)."""
    if kind == BOX or kind == CONVEX or kind == COMPOUND:  # a hull, the parts: their bounding box's
        return abs(r[e, 0]) * dims[0] + abs(r[e, 1]) * dims[1] + abs(r[e, 2]) * dims[2]
    if kind == SPHERE:
        return dims[0]
    if kind == CAPSULE:
        return abs(r[e, 2]) * dims[1] + dims[0]
    return abs(r[e, 2]) * dims[1] + dims[0] * np.sqrt(max(1.0 - r[e, 2] * r[e, 2], 0.0))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def bounds(kinds, dimensions, positions, orientations):
    """World bounding boxes (min, max), (N, 3) each, of N bodies."""
    n = len(kinds)
    lo, hi = np.empty((n, 3)), np.empty((n, 3))
    r = np.empty((3, 3))
    for i in range(n):
        quat_to_matrix(orientations[i], r)
        dims = (dimensions[i, 0], dimensions[i, 1], dimensions[i, 2])
        for e in range(3):
            extent = world_extent(kinds[i], dims, r, e)
            lo[i, e], hi[i, e] = positions[i, e] - extent, positions[i, e] + extent
    return lo, hi


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_radius(kind, dims):
    """Spheres and capsules are a core (point, segment) grown by this radius; the others 0."""
    if kind == SPHERE or kind == CAPSULE:
        return dims[0]
    return 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_support(kind, dims, hulls, h, d):
    """The point of the shape's core farthest along d (body frame)."""
    if kind == BOX:
        return box.support(dims, d)
    if kind == SPHERE:
        return sphere.core_support(dims, d)
    if kind == CAPSULE:
        return capsule.core_support(dims, d)
    if kind == CYLINDER:
        return cylinder.support(dims, d)
    return convex.support(hulls, h, d)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(kind, dims, hulls, h, d, out):
    """Writes to out (at least MAX_FACE_POINTS rows) the shape's feature facing d (body
    frame): a polygon counter-clockwise seen from outside, a segment or a point. Returns its
    point count."""
    if kind == BOX:
        return box.supporting_face(dims, d, out)
    if kind == SPHERE:
        return sphere.supporting_face(dims, d, out)
    if kind == CAPSULE:
        return capsule.supporting_face(dims, d, out)
    if kind == CYLINDER:
        return cylinder.supporting_face(dims, d, out)
    return convex.supporting_face(hulls, h, d, out)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(kind, dims, hulls, parts, h, o, d, reach):
    """The ray o + t d (body frame, d unit, 0 <= t <= reach) against the shape: (t, outward
    normal), t NO_HIT when it misses or starts inside (a compound: the nearest part it enters)."""
    if kind == COMPOUND:
        return compound_ray(hulls, parts, h, o, d, reach)
    return part_ray(kind, dims, hulls, h, o, d, reach)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def part_ray(kind, dims, hulls, h, o, d, reach):
    """ray() for every shape but a compound (what its parts are)."""
    if kind == CONVEX:
        return convex.ray(hulls, h, o, d, reach)
    return ray_without_hull(kind, dims, o, d, reach)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def compound_ray(hulls, parts, h, o, d, reach):
    """ray() of compound body h: each part asked in its own frame, the nearest hit kept."""
    best, normal = NO_HIT, (0.0, 0.0, 0.0)
    t = parts.rotation
    for k in range(parts.start[h], parts.start[h] + parts.count[h]):
        local_o, local_d = body_frame_ray(o, d, parts, k)
        dims = (parts.dimensions[k, 0], parts.dimensions[k, 1], parts.dimensions[k, 2])
        hit, n = part_ray(parts.shape[k], dims, hulls, parts.hull[k], local_o, local_d, min(best, reach))
        if hit < best:
            best = hit
            normal = (t[k, 0, 0] * n[0] + t[k, 0, 1] * n[1] + t[k, 0, 2] * n[2],
                      t[k, 1, 0] * n[0] + t[k, 1, 1] * n[1] + t[k, 1, 2] * n[2],
                      t[k, 2, 0] * n[0] + t[k, 2, 1] * n[1] + t[k, 2, 2] * n[2])
    return best, normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def ray_without_hull(kind, dims, o, d, reach):
    """ray() for every shape but convex: the sensors' ray loop asks these without handing the
    hull table to every test (Numba counts references to each of its arrays per inlined call)."""
    if kind == BOX:
        return box.ray(dims, o, d, reach)
    if kind == SPHERE:
        return sphere.ray(dims, o, d, reach)
    if kind == CAPSULE:
        return capsule.ray(dims, o, d, reach)
    return cylinder.ray(dims, o, d, reach)


Solid = namedtuple("Solid", "dimensions fields volume unit_inertia hull compound")


def solid(name, spec, path="body", density=None):
    """What a shape spec (its SPEC_KEYS, validated) makes: dimensions, the keys as a scene
    holds them, volume (m^3), inertia per kg (3, 3) about the centre of mass in the body frame,
    the hull (convex.Hull, convex bodies only) and the parts (compound.Compound, compound
    bodies only, whose parts without a mass or density of their own take `density`)."""
    if name == "convex":
        hull = convex.build_hull(spec["points"], f"{path}.points")
        return Solid(convex.dimensions(hull), convex.spec_fields(hull), hull.volume, hull.unit_inertia, hull, None)
    if name == "compound":
        parts = [compound.make_part(part, SHAPES[part["shape"]].code, solid(part["shape"], part, f"{path}.parts[{k}]"),
                                    density)
                 for k, part in enumerate(spec["parts"])]
        whole, dims, volume, unit_inertia = compound.combine(parts, half_extents, spec.get("inertial"))
        return Solid(dims, compound.spec_fields(whole), volume, unit_inertia, None, whole)
    module = SHAPES[name].module
    dims = module.dimensions(spec)
    return Solid(dims, module.spec_fields(dims), module.volume(dims), np.diag(module.unit_inertia(dims)), None, None)

