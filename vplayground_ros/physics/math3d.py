"""Small vector and quaternion kernels. Quaternions are (x, y, z, w), rotations are body -> world."""
import math

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
    """q turned by the world angular velocity omega for dt: the rotation of angle |omega| dt
    about omega, (sin(angle / 2) axis, cos(angle / 2)) * q, renormalised for rounding (a tuple).
    The first-order step q + dt/2 (omega, 0) q turned bodies by 2 atan(|omega| dt / 2) instead:
    0.4 % short at 28 rad/s (the Husky's wheels at 5 m/s, whose odometry reads their angles),
    15 % at 200 rad/s."""
    speed = np.sqrt(omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2])
    half = 0.5 * speed * dt
    if half < 0.05:
        # sin(half) / speed and cos(half) by their series, to rounding here (the next terms are
        # below 1e-15): most bodies turn slowly, and the two calls took as long as the rest of
        # the position update (at no turn the quotient is 0 / 0, too).
        h2 = half * half
        scale = 0.5 * dt * (1.0 - h2 / 6.0 * (1.0 - h2 / 20.0 * (1.0 - h2 / 42.0)))
        c = 1.0 - h2 / 2.0 * (1.0 - h2 / 12.0 * (1.0 - h2 / 30.0))
    else:
        scale, c = np.sin(half) / speed, np.cos(half)
    ox, oy, oz = omega[0] * scale, omega[1] * scale, omega[2] * scale
    x, y, z, w = q[0], q[1], q[2], q[3]
    nx = c * x + ox * w + oy * z - oz * y
    ny = c * y - ox * z + oy * w + oz * x
    nz = c * z + ox * y - oy * x + oz * w
    nw = c * w - ox * x - oy * y - oz * z
    inv = 1.0 / np.sqrt(nx * nx + ny * ny + nz * nz + nw * nw)
    return nx * inv, ny * inv, nz * inv, nw * inv


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def body_frame_ray(origin, direction, geometry, j):
    """A world ray (origin, direction) in frame j of `geometry` (its position (N, 3) and
    rotation (N, 3, 3) arrays: bodies, or a compound's parts), as tuples."""
    p, r = geometry.position, geometry.rotation
    v = (origin[0] - p[j, 0], origin[1] - p[j, 1], origin[2] - p[j, 2])
    o = (v[0] * r[j, 0, 0] + v[1] * r[j, 1, 0] + v[2] * r[j, 2, 0],
         v[0] * r[j, 0, 1] + v[1] * r[j, 1, 1] + v[2] * r[j, 2, 1],
         v[0] * r[j, 0, 2] + v[1] * r[j, 1, 2] + v[2] * r[j, 2, 2])
    d = (direction[0] * r[j, 0, 0] + direction[1] * r[j, 1, 0] + direction[2] * r[j, 2, 0],
         direction[0] * r[j, 0, 1] + direction[1] * r[j, 1, 1] + direction[2] * r[j, 2, 1],
         direction[0] * r[j, 0, 2] + direction[1] * r[j, 1, 2] + direction[2] * r[j, 2, 2])
    return o, d


def quaternions_to_matrices(q):
    """(N, 4) xyzw -> (N, 3, 3), vectorised (the compiled kernels use quat_to_matrix)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def axis_rotation(axis, angle):
    """The rotation matrix by `angle` about the unit `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def rpy_to_quat(rpy):
    """Roll, pitch, yaw (fixed axes X, Y, Z; REP-103) to an (x, y, z, w) quaternion."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array((sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy,
                     cr * cp * cy + sr * sp * sy))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def quat_multiply(a, b):
    """a * b as a tuple (x, y, z, w): rotation b, then a."""
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def quat_conjugate(q):
    """The inverse rotation of unit quaternion q, as a tuple."""
    return (-q[0], -q[1], -q[2], q[3])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def rotate(q, v):
    """Vector v turned by unit quaternion q, as a tuple: v + 2w (u x v) + 2 u x (u x v)."""
    u = (q[0], q[1], q[2])
    t = cross(u, v)
    t = (2.0 * t[0], 2.0 * t[1], 2.0 * t[2])
    s = cross(u, t)
    return (v[0] + q[3] * t[0] + s[0], v[1] + q[3] * t[1] + s[1], v[2] + q[3] * t[2] + s[2])



def matrix_to_quaternion(m):
    """(x, y, z, w) of a rotation matrix (Shepperd's method, the largest component first)."""
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)
    q = np.array(q)
    return q / np.linalg.norm(q)
