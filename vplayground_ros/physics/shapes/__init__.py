"""Body shapes. A body's shape is a code in `bodies.shape` and three numbers in
`bodies.dimensions` (what they mean is the shape module's: half extents of a box, a radius and
a half length); every shape-dependent question is answered here, by one dispatch each, from the
shape's module.

Adding a shape: a module like box.py (spec keys, mass properties, bounds, support mapping and
supporting face for the narrow phase's convex path, ray cast; all in the body's frame) and a
row in SHAPES and in each dispatcher below.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from ..math3d import quat_to_matrix

from . import box, capsule, cylinder, sphere
from .geometry import NO_HIT, unit_or

BOX, SPHERE, CAPSULE, CYLINDER = 0, 1, 2, 3

Shape = namedtuple("Shape", "code module")
SHAPES = {"box": Shape(BOX, box), "sphere": Shape(SPHERE, sphere),
          "capsule": Shape(CAPSULE, capsule), "cylinder": Shape(CYLINDER, cylinder)}
SHAPE_NAMES = {shape.code: name for name, shape in SHAPES.items()}

# The most points a supporting face has (a cylinder's end).
MAX_FACE_POINTS = cylinder.CAP_POINTS


@njit(cache=True, nogil=True)
def half_extents(kind, dims):
    """Half extents of the shape's bounding box in its own frame."""
    if kind == BOX:
        return box.half_extents(dims)
    if kind == SPHERE:
        return sphere.half_extents(dims)
    if kind == CAPSULE:
        return capsule.half_extents(dims)
    return cylinder.half_extents(dims)


@njit(cache=True, nogil=True)
def world_extent(kind, dims, r, e):
    """Half the extent along world axis e of the shape turned by rotation r (3x3, columns the
    body axes): the exact bounding box, not the box around the body-frame one."""
    if kind == BOX:
        return abs(r[e, 0]) * dims[0] + abs(r[e, 1]) * dims[1] + abs(r[e, 2]) * dims[2]
    if kind == SPHERE:
        return dims[0]
    if kind == CAPSULE:
        return abs(r[e, 2]) * dims[1] + dims[0]
    return abs(r[e, 2]) * dims[1] + dims[0] * np.sqrt(max(1.0 - r[e, 2] * r[e, 2], 0.0))


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def core_radius(kind, dims):
    """Spheres and capsules are a core (point, segment) grown by this radius; the others 0."""
    if kind == SPHERE or kind == CAPSULE:
        return dims[0]
    return 0.0


@njit(cache=True, nogil=True)
def core_support(kind, dims, d):
    """The point of the shape's core farthest along d (body frame)."""
    if kind == BOX:
        return box.support(dims, d)
    if kind == SPHERE:
        return sphere.core_support(dims, d)
    if kind == CAPSULE:
        return capsule.core_support(dims, d)
    return cylinder.support(dims, d)


@njit(cache=True, nogil=True)
def support(kind, dims, d):
    """The point of the whole shape farthest along d (body frame)."""
    p = core_support(kind, dims, d)
    r = core_radius(kind, dims)
    if r == 0.0:
        return p
    n = unit_or(d, (0.0, 0.0, 1.0))
    return (p[0] + r * n[0], p[1] + r * n[1], p[2] + r * n[2])


@njit(cache=True, nogil=True)
def supporting_face(kind, dims, d, out):
    """Writes to out the shape's feature facing d (body frame): a polygon counter-clockwise seen
    from outside, a segment or a point. Returns its point count."""
    if kind == BOX:
        return box.supporting_face(dims, d, out)
    if kind == SPHERE:
        return sphere.supporting_face(dims, d, out)
    if kind == CAPSULE:
        return capsule.supporting_face(dims, d, out)
    return cylinder.supporting_face(dims, d, out)


@njit(cache=True, nogil=True)
def ray(kind, dims, o, d, reach):
    """The ray o + t d (body frame, d unit, 0 <= t <= reach) against the shape: (t, outward
    normal), t NO_HIT when it misses or starts inside."""
    if kind == BOX:
        return box.ray(dims, o, d, reach)
    if kind == SPHERE:
        return sphere.ray(dims, o, d, reach)
    if kind == CAPSULE:
        return capsule.ray(dims, o, d, reach)
    return cylinder.ray(dims, o, d, reach)


def mass_properties(name, dims, mass=None, density=None):
    """(mass kg, principal inertia kg m^2 (3,) in the body frame) from a mass or a density."""
    module = SHAPES[name].module
    if mass is None:
        mass = density * module.volume(dims)
    return mass, tuple(mass * i for i in module.unit_inertia(dims))
