"""Helpers shared by the tests: waiting for a condition, and the scene builders of the physics tests."""
import time

import numpy as np

from vplayground_ros.physics import World

# Long enough for a loaded 2-core machine (a node's first batch can wait on Numba's cache load);
# a condition that holds returns at once, so the timeout costs nothing when tests pass.
WAIT_TIMEOUT = 30.0


def wait_for(condition, timeout=WAIT_TIMEOUT, explain=None):
    """Polls `condition` until it holds (returns True) or `timeout` s pass: the test fails then,
    with what `explain()` says (the state a timeout should show, read when it happens)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out after {timeout} s" + (f": {explain()}" if explain else ""))
        time.sleep(0.005)
    return True


def rebound_apex(world, row, rest_height, seconds=3):
    """Steps `world` until body `row` has bounced and starts to fall again: (whether it bounced,
    the highest it rose above rest_height after the bounce)."""
    bounced, apex = False, 0.0
    for _ in range(seconds * 128):
        world.step(1)
        height = world.state()["positions"][row, 2] - rest_height
        vz = world.state()["linear_velocities"][row, 2]
        bounced = bounced or vz > 0.0
        if bounced:
            apex = max(apex, height)
            if vz < 0.0:
                break
    return bounced, apex


def kinetic_energy(world):
    s = world.state()
    v, w, m, size = s["linear_velocities"], s["angular_velocities"], s["masses"], s["sizes"]
    # Box inertia about the centre; the rotational part is a bound (axes not rotated), enough
    # for "does it grow" comparisons.
    inertia = m[:, None] / 12.0 * (size[:, [1, 0, 0]] ** 2 + size[:, [2, 2, 1]] ** 2)
    return float(0.5 * np.sum(m * np.sum(v * v, axis=1)) + 0.5 * np.sum(inertia * w * w))


def tower(count, size=1.0, settings=None, **material):
    """`count` cubes stacked exactly face on face; `material` holds body keys (mass, elasticity...)."""
    world = World(settings)
    for k in range(count):
        world.add_body({"name": f"t{k}", "size": [size] * 3, "position": [0, 0, size * (0.5 + k)],
                        **material})
    return world


def brick_wall(rows=10, length=1.0, depth=0.5, height=0.5, settings=None, **material):
    """Running-bond wall: even rows of 6 bricks, odd rows of 5 offset by half a brick (55)."""
    world = World(settings)
    for row in range(rows):
        count = 6 if row % 2 == 0 else 5
        offset = 0.0 if row % 2 == 0 else 0.5 * length
        for k in range(count):
            world.add_body({"name": f"b{row}_{k}", "size": [length, depth, height],
                            "position": [offset + k * length - 2.5 * length, 0, height * (0.5 + row)],
                            **material})
    return world


def pyramid(rows, size=1.0, settings=None, **material):
    """A 2D pyramid of cubes: `rows` at the bottom, one fewer per row up, each row offset by half
    a cube so every cube stands on two (rows (rows + 1) / 2 cubes)."""
    world = World(settings, capacity=rows * (rows + 1) // 2)
    for row in range(rows):
        count = rows - row
        for k in range(count):
            world.add_body({"name": f"p{row}_{k}", "size": [size] * 3,
                            "position": [size * (k - 0.5 * (count - 1)), 0, size * (0.5 + row)],
                            **material})
    return world


def pile(count, seed=1, size=0.5, spacing=0.75, settings=None):
    """Boxes on a jittered grid above the ground, falling into a pile."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count / 4)))
    world = World(settings)
    for k in range(count):
        ix, iy, iz = k % side, (k // side) % side, k // (side * side)
        jitter = rng.uniform(-0.1, 0.1, 3)
        world.add_body({"name": f"p{k}", "size": [size] * 3,
                        "position": [(ix - side / 2) * spacing + jitter[0],
                                     (iy - side / 2) * spacing + jitter[1],
                                     1.0 + iz * spacing + jitter[2]],
                        "rpy": list(rng.uniform(-0.5, 0.5, 3)), "density": 500})
    return world


def max_drift(world, start):
    return float(np.max(np.linalg.norm(world.state()["positions"] - start, axis=1)))


def drift_every_second(world, seconds):
    """Steps `seconds` simulated seconds; the largest distance (m) of any body from its start,
    sampled at every whole second."""
    start = world.state()["positions"].copy()
    drift = 0.0
    for _ in range(seconds):
        world.step(world.settings["steps_per_second"])
        drift = max(drift, max_drift(world, start))
    return drift


# SPEC 5's car as the default scene had it as a `vehicles` entry before config/car.urdf.
SPEC_CAR = {"name": "car", "position": [10.0, -10.0, 1.0], "rpy": [0.0, 0.0, 0.0],
            "chassis": {"size": [4.0, 1.8, 0.6], "mass": 1200}, "engine_power": 6000, "brake_power": 9000,
            "max_steer": 0.6, "wheels": [
                {"mount": mount, "radius": 0.35, "mass": 20, "power_gain": gain, "steered": steered,
                 "spring_stiffness": 40000, "damper": 4000, "spring_length": 0.5, "static_friction": 1.0,
                 "dynamic_friction": 0.8}
                for mount, gain, steered in (([1.3, 0.8, -0.3], 0.0, True), ([1.3, -0.8, -0.3], 0.0, True),
                                             ([-1.3, 0.8, -0.3], 0.5, False), ([-1.3, -0.8, -0.3], 0.5, False))]}
