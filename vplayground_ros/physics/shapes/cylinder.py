"""Cylinder: `radius` and `length` along the body's z; dimensions = (radius, length / 2, 0).
Its flat ends are polygons of CAP_POINTS corners for the manifold (a cylinder standing on its
end rests on four points), its side a line."""
import math

import numpy as np
from numba import njit

from .geometry import NO_HIT, ray_side, unit_or

SPEC_KEYS = ("radius", "length")
DEFAULTS = {"radius": 0.5, "length": 1.0}

CAP_POINTS = 8


def dimensions(spec):
    return (float(spec["radius"]), 0.5 * float(spec["length"]), 0.0)


def spec_fields(dims):
    return {"radius": dims[0], "length": 2.0 * dims[1]}


def volume(dims):
    return math.pi * dims[0] ** 2 * 2.0 * dims[1]


def unit_inertia(dims):
    r, length = dims[0], 2.0 * dims[1]
    across = (3.0 * r * r + length * length) / 12.0
    return (across, across, r * r / 2.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def half_extents(dims):
    return (dims[0], dims[0], dims[1])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def support(dims, d):
    side = unit_or((d[0], d[1], 0.0), (0.0, 0.0, 0.0))
    return (dims[0] * side[0], dims[0] * side[1], dims[1] if d[2] >= 0.0 else -dims[1])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(dims, d, out):
    """The end facing d (a regular CAP_POINTS-gon, counter-clockwise seen from outside) when d
    is nearer the axis than the side, else the side's line facing d."""
    r, h = dims[0], dims[1]
    if abs(d[2]) >= np.sqrt(d[0] * d[0] + d[1] * d[1]):
        sign = 1.0 if d[2] >= 0.0 else -1.0
        for k in range(CAP_POINTS):
            angle = 2.0 * np.pi * k / CAP_POINTS
            out[k, 0], out[k, 1], out[k, 2] = r * np.cos(angle), sign * r * np.sin(angle), sign * h
        return CAP_POINTS
    side = unit_or((d[0], d[1], 0.0), (1.0, 0.0, 0.0))
    for k in range(2):
        out[k, 0], out[k, 1] = r * side[0], r * side[1]
        out[k, 2] = h if k == 0 else -h
    return 2


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(dims, o, d, reach):
    r, h = dims[0], dims[1]
    if abs(o[2]) <= h and o[0] * o[0] + o[1] * o[1] <= r * r:
        return NO_HIT, (0.0, 0.0, 0.0)  # starts inside
    t = ray_side(r, h, o, d, reach)
    if t < NO_HIT:
        p = (o[0] + t * d[0], o[1] + t * d[1])
        return t, (p[0] / r, p[1] / r, 0.0)
    if abs(o[2]) > h and o[2] * d[2] < 0.0:  # towards the end it is beyond
        end = h if o[2] > 0.0 else -h
        t = (end - o[2]) / d[2]
        x, y = o[0] + t * d[0], o[1] + t * d[1]
        if t <= reach and x * x + y * y <= r * r:
            return t, (0.0, 0.0, 1.0 if end > 0.0 else -1.0)
    return NO_HIT, (0.0, 0.0, 0.0)
