"""Small vector and quaternion kernels. Quaternions are (x, y, z, w), rotations are body -> world."""
import numpy as np
from numba import njit


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cross(a, b):
    """Returns a tuple: hot loops call this per contact, and tuples never touch the heap."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def quat_to_matrix(q, m):
    """Writes into m the rotation matrix whose columns are the body axes in the world."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    m[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[0, 1] = 2.0 * (x * y - z * w)
    m[0, 2] = 2.0 * (x * z + y * w)
    m[1, 0] = 2.0 * (x * y + z * w)
    m[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[1, 2] = 2.0 * (y * z - x * w)
    m[2, 0] = 2.0 * (x * z - y * w)
    m[2, 1] = 2.0 * (y * z + x * w)
    m[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def integrate_orientation(q, omega, dt):
    """q + dt/2 * (omega, 0) * q, renormalised: first order, exact enough at 128 steps/s."""
    ox, oy, oz = omega[0] * 0.5 * dt, omega[1] * 0.5 * dt, omega[2] * 0.5 * dt
    x, y, z, w = q[0], q[1], q[2], q[3]
    nx = x + ox * w + oy * z - oz * y
    ny = y - ox * z + oy * w + oz * x
    nz = z + ox * y - oy * x + oz * w
    nw = w - ox * x - oy * y - oz * z
    inv = 1.0 / np.sqrt(nx * nx + ny * ny + nz * nz + nw * nw)
    q[0], q[1], q[2], q[3] = nx * inv, ny * inv, nz * inv, nw * inv


def quaternions_to_matrices(q):
    """(N, 4) xyzw -> (N, 3, 3), vectorised (the compiled kernels use quat_to_matrix)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rpy_to_quat(rpy):
    """Roll, pitch, yaw (fixed axes X, Y, Z; REP-103) to an (x, y, z, w) quaternion."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array((sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy,
                     cr * cp * cy + sr * sp * sy))
