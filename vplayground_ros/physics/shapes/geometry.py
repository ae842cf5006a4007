"""Small helpers the shape modules share (tuples in, tuples out: no heap in hot loops)."""
import numpy as np
from numba import njit

NO_HIT = np.inf  # a ray's distance when it hits nothing


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def axis_vector(axis, sign):
    if axis == 0:
        return (sign, 0.0, 0.0)
    if axis == 1:
        return (0.0, sign, 0.0)
    return (0.0, 0.0, sign)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def unit_or(d, fallback):
    """d normalised, or `fallback` when d is (nearly) zero."""
    length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if length < 1e-12:
        return fallback
    return (d[0] / length, d[1] / length, d[2] / length)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray_sphere(centre, radius, o, d, reach):
    """Entry distance of the ray o + t d (d unit) into the sphere, or NO_HIT when it misses or
    starts inside."""
    m = (o[0] - centre[0], o[1] - centre[1], o[2] - centre[2])
    b = m[0] * d[0] + m[1] * d[1] + m[2] * d[2]
    c = m[0] * m[0] + m[1] * m[1] + m[2] * m[2] - radius * radius
    if c <= 0.0 or b > 0.0:
        return NO_HIT  # inside, or outside and pointing away
    disc = b * b - c
    if disc < 0.0:
        return NO_HIT
    t = -b - np.sqrt(disc)
    return t if t <= reach else NO_HIT


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray_side(radius, half_length, o, d, reach):
    """Entry distance of the ray into the side of the infinite cylinder x^2 + y^2 = r^2 within
    |z| <= half_length, or NO_HIT (caps and ends are the caller's)."""
    a = d[0] * d[0] + d[1] * d[1]
    if a < 1e-14:
        return NO_HIT
    b = o[0] * d[0] + o[1] * d[1]
    c = o[0] * o[0] + o[1] * o[1] - radius * radius
    if c <= 0.0 or b > 0.0:
        return NO_HIT  # inside the infinite cylinder (a cap may still be hit), or leaving
    disc = b * b - a * c
    if disc < 0.0:
        return NO_HIT
    t = (-b - np.sqrt(disc)) / a
    z = o[2] + t * d[2]
    return t if t <= reach and abs(z) <= half_length else NO_HIT
