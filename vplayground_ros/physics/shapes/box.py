"""Box: `size` (full edge lengths); dimensions = half extents (x, y, z). Local frame: centred,
edges along the axes. The SAT box/box and box/triangle manifolds stay in narrow_phase.py (the
fast special cases); these functions serve the general convex path and the ray casts."""
from numba import njit

from .geometry import NO_HIT, axis_vector

SPEC_KEYS = ("size",)
DEFAULTS = {"size": [1.0, 1.0, 1.0]}


def dimensions(spec):
    return tuple(0.5 * float(s) for s in spec["size"])


def spec_fields(dims):
    return {"size": [2.0 * h for h in dims]}


def volume(dims):
    return 8.0 * dims[0] * dims[1] * dims[2]


def unit_inertia(dims):
    """Principal inertia per kg: (b^2 + c^2) / 12, ... for full edges a, b, c."""
    a, b, c = (2.0 * h for h in dims)
    return ((b * b + c * c) / 12.0, (a * a + c * c) / 12.0, (a * a + b * b) / 12.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def half_extents(dims):
    return (dims[0], dims[1], dims[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def support(dims, d):
    return (dims[0] if d[0] >= 0.0 else -dims[0], dims[1] if d[1] >= 0.0 else -dims[1],
            dims[2] if d[2] >= 0.0 else -dims[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(dims, d, out):
    """The face whose outward normal is closest to d: 4 corners, counter-clockwise seen from
    outside."""
    axis = 0
    for k in range(1, 3):
        if abs(d[k]) > abs(d[axis]):
            axis = k
    sign = 1.0 if d[axis] >= 0.0 else -1.0
    u, v = (axis + 1) % 3, (axis + 2) % 3
    # (u, v, axis) is right-handed: corners counter-clockwise about +axis, reversed for -axis.
    for corner in range(4):
        su = 1.0 if corner == 0 or corner == 3 else -1.0
        sv = 1.0 if corner < 2 else -1.0
        out[corner, axis] = sign * dims[axis]
        out[corner, u] = su * dims[u]
        out[corner, v] = sv * dims[v] * sign
    return 4


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(dims, o, d, reach):
    """Slab test: (distance, outward normal), or NO_HIT when the ray misses or starts inside."""
    t_in, t_out = 0.0, reach
    axis_in, sign_in = -1, 1.0
    for k in range(3):
        if abs(d[k]) < 1e-12:
            if abs(o[k]) > dims[k]:
                return NO_HIT, (0.0, 0.0, 0.0)
            continue
        t0, t1 = (-dims[k] - o[k]) / d[k], (dims[k] - o[k]) / d[k]
        sign = -1.0
        if t0 > t1:
            t0, t1 = t1, t0
            sign = 1.0
        if t0 > t_in:
            t_in, axis_in, sign_in = t0, k, sign
        t_out = min(t_out, t1)
        if t_in > t_out:
            return NO_HIT, (0.0, 0.0, 0.0)
    if axis_in < 0:
        return NO_HIT, (0.0, 0.0, 0.0)
    return t_in, axis_vector(axis_in, sign_in)
