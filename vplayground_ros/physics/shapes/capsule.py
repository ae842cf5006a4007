"""Capsule: `radius` and `length` (of the cylindrical part, along the body's z; the whole
capsule is length + 2 radius tall); dimensions = (radius, length / 2, 0). Its core for the
convex path is the segment between the two hemispheres' centres."""
import math

from numba import njit

from .geometry import NO_HIT, ray_side, ray_sphere, unit_or

SPEC_KEYS = ("radius", "length")
DEFAULTS = {"radius": 0.25, "length": 0.5}

# A capsule lies flat on a surface (its side gives a two-point face) while its axis is within
# this sine of the surface's plane; steeper, one hemisphere touches alone.
SIDE_FACE_SINE = 0.05


def dimensions(spec):
    return (float(spec["radius"]), 0.5 * float(spec["length"]), 0.0)


def spec_fields(dims):
    return {"radius": dims[0], "length": 2.0 * dims[1]}


def volume(dims):
    r, length = dims[0], 2.0 * dims[1]
    return math.pi * r * r * length + 4.0 / 3.0 * math.pi * r ** 3


def unit_inertia(dims):
    """Cylinder plus two hemispheres (each centred 3r/8 beyond its end of the cylinder)."""
    r, length = dims[0], 2.0 * dims[1]
    cylinder, spheres = math.pi * r * r * length, 4.0 / 3.0 * math.pi * r ** 3
    axial = cylinder * r * r / 2.0 + spheres * 0.4 * r * r
    across = (cylinder * (length * length / 12.0 + r * r / 4.0)
              + spheres * (0.4 * r * r + length * length / 4.0 + 3.0 * length * r / 8.0))
    total = cylinder + spheres
    return (across / total, across / total, axial / total)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def half_extents(dims):
    return (dims[0], dims[0], dims[1] + dims[0])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_support(dims, d):
    return (0.0, 0.0, dims[1] if d[2] >= 0.0 else -dims[1])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(dims, d, out):
    n = unit_or(d, (0.0, 0.0, 1.0))
    r, h = dims[0], dims[1]
    if abs(n[2]) < SIDE_FACE_SINE:
        side = unit_or((n[0], n[1], 0.0), (1.0, 0.0, 0.0))
        for k in range(2):
            out[k, 0], out[k, 1] = r * side[0], r * side[1]
            out[k, 2] = h if k == 0 else -h
        return 2
    end = h if n[2] >= 0.0 else -h
    out[0, 0], out[0, 1], out[0, 2] = r * n[0], r * n[1], end + r * n[2]
    return 1


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(dims, o, d, reach):
    r, h = dims[0], dims[1]
    z = min(max(o[2], -h), h)
    if o[0] * o[0] + o[1] * o[1] + (o[2] - z) ** 2 <= r * r:
        return NO_HIT, (0.0, 0.0, 0.0)  # starts inside
    t = min(ray_side(r, h, o, d, reach), ray_sphere((0.0, 0.0, h), r, o, d, reach),
            ray_sphere((0.0, 0.0, -h), r, o, d, reach))
    if t == NO_HIT:
        return NO_HIT, (0.0, 0.0, 0.0)
    p = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
    z = min(max(p[2], -h), h)
    return t, unit_or((p[0], p[1], p[2] - z), (0.0, 0.0, 1.0))
