"""The benchmark scenes as plain box lists, so every engine builds exactly the same world.
A box is (size (3,), position (3,), quaternion xyzw (4,), mass)."""
import numpy as np

DENSITY = 500.0  # kg/m^3


def box(size, position, quaternion=(0.0, 0.0, 0.0, 1.0)):
    size = np.asarray(size, dtype=float)
    return size, np.asarray(position, dtype=float), np.asarray(quaternion, dtype=float), DENSITY * float(np.prod(size))


def yaw_pitch_roll_quaternion(rpy):
    r, p, y = (0.5 * a for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def pile(count, seed=1):
    """0.5 m boxes on a jittered grid (0.8 m spacing, 8 per layer area unit), tilted a little."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count / 8)))
    boxes = []
    for k in range(count):
        ix, iy, iz = k % side, (k // side) % side, k // (side * side)
        jitter = rng.uniform(-0.1, 0.1, 3)
        position = ((ix - side / 2) * 0.8 + jitter[0], (iy - side / 2) * 0.8 + jitter[1],
                    0.5 + iz * 0.8 + jitter[2])
        boxes.append(box((0.5, 0.5, 0.5), position, yaw_pitch_roll_quaternion(rng.uniform(-0.3, 0.3, 3))))
    return boxes


def loose_pile(count, seed=1, layers=10, spacing=0.8):
    """Issue 20's loose pile: 0.5 m boxes on a spread grid of `layers` layers (0.8 m apart: a yawed box spans up to 0.71 m; the
    lowest 0.75 m up), each with a random yaw and a small tilt (up to 0.1 rad about x and y)."""
    rng = np.random.default_rng(seed)
    per_layer = int(np.ceil(count / layers))
    side = int(np.ceil(np.sqrt(per_layer)))
    boxes = []
    for k in range(count):
        ix, iy, iz = k % side, (k // side) % side, k // per_layer
        tilt = rng.uniform(-0.1, 0.1, 2)
        position = ((ix - (side - 1) / 2) * spacing, (iy - (side - 1) / 2) * spacing, 0.75 + iz * spacing)
        boxes.append(box((0.5, 0.5, 0.5), position,
                         yaw_pitch_roll_quaternion((tilt[0], tilt[1], rng.uniform(-np.pi, np.pi)))))
    return boxes


def resting_columns(columns, size=0.5, gap=0.25):
    """Columns of two boxes standing exactly on each other and on the ground, on a square grid."""
    side = int(np.ceil(np.sqrt(columns)))
    boxes = []
    for k in range(columns):
        x, y = (k % side - side / 2) * (size + gap), (k // side - side / 2) * (size + gap)
        boxes += [box((size,) * 3, (x, y, size * (0.5 + level))) for level in range(2)]
    return boxes


def tower(count, size=1.0):
    return [box((size,) * 3, (0.0, 0.0, size * (0.5 + k))) for k in range(count)]


def brick_wall(rows=10, length=1.0, depth=0.5, height=0.5):
    """Running bond: even rows of 6 bricks, odd rows of 5 offset by half a brick (55)."""
    boxes = []
    for row in range(rows):
        count, offset = (6, 0.0) if row % 2 == 0 else (5, 0.5 * length)
        for k in range(count):
            boxes.append(box((length, depth, height), (offset + (k - 2.5) * length, 0.0, height * (0.5 + row))))
    return boxes
