"""Sphere: `radius`; dimensions = (radius, 0, 0). Its core for the convex path is its centre."""
import math

from numba import njit

from .geometry import NO_HIT, ray_sphere, unit_or

SPEC_KEYS = ("radius",)
DEFAULTS = {"radius": 0.5}


def dimensions(spec):
    return (float(spec["radius"]), 0.0, 0.0)


def spec_fields(dims):
    return {"radius": dims[0]}


def volume(dims):
    return 4.0 / 3.0 * math.pi * dims[0] ** 3


def unit_inertia(dims):
    i = 0.4 * dims[0] ** 2
    return (i, i, i)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def half_extents(dims):
    return (dims[0], dims[0], dims[0])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_support(dims, d):
    return (0.0, 0.0, 0.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(dims, d, out):
    n = unit_or(d, (0.0, 0.0, 1.0))
    for e in range(3):
        out[0, e] = dims[0] * n[e]
    return 1


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(dims, o, d, reach):
    t = ray_sphere((0.0, 0.0, 0.0), dims[0], o, d, reach)
    if t == NO_HIT:
        return NO_HIT, (0.0, 0.0, 0.0)
    r = 1.0 / dims[0]
    return t, ((o[0] + t * d[0]) * r, (o[1] + t * d[1]) * r, (o[2] + t * d[2]) * r)
