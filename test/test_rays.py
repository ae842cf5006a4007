"""Batches of rays against geometry with known answers: box faces, the ground, the playground."""
import math

import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.contact import GROUND, PLAYGROUND
from vplayground_ros.physics.ray_batch import NOTHING
from vplayground_ros.scene import load_world


def world_with(*bodies, ground=True):
    world = World(ground={"height": 0.0} if ground else None)
    for body in bodies:
        world.add_body(body)
    return world


def test_ray_onto_a_box_face_reads_the_distance_and_the_face_normal():
    world = world_with({"name": "b", "size": [1.0, 2.0, 3.0], "position": [5.0, 0.0, 2.0]})
    hits = world.cast_rays([[0.0, 0.3, 2.2], [10.0, 0.0, 2.0], [5.0, 0.0, 10.0]],
                           [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], 20.0)
    assert hits.distance == pytest.approx([4.5, 4.5, 6.5], abs=1e-3)
    assert hits.normal == pytest.approx(np.array([[-1, 0, 0], [1, 0, 0], [0, 0, 1]]), abs=1e-9)
    assert hits.point[0] == pytest.approx([4.5, 0.3, 2.2], abs=1e-3)
    assert list(hits.body) == [0, 0, 0]


def test_rotated_box_gives_the_rotated_face():
    yaw = 0.4
    world = world_with({"name": "b", "size": [1.0, 1.0, 1.0], "position": [3.0, 0.0, 0.5],
                        "rpy": [0.0, 0.0, yaw]})
    hits = world.cast_rays([[3.0 - 3 * math.cos(yaw), -3 * math.sin(yaw), 0.5]],
                           [[math.cos(yaw), math.sin(yaw), 0.0]], 10.0)
    assert hits.distance[0] == pytest.approx(2.5, abs=1e-3)
    assert hits.normal[0] == pytest.approx([-math.cos(yaw), -math.sin(yaw), 0.0], abs=1e-9)


def test_miss_gives_inf_and_ground_hits_report_the_ground():
    world = world_with({"name": "b", "size": [1.0, 1.0, 1.0], "position": [5.0, 0.0, 0.5]})
    hits = world.cast_rays([[0.0, 0.0, 2.0], [0.0, 0.0, 2.0], [0.0, 0.0, 2.0]],
                           [[0.0, 1.0, 0.0], [1.0, 0.0, -1.0], [1.0, 0.0, -0.001]], 10.0)
    assert hits.distance[0] == math.inf and hits.body[0] == NOTHING
    assert np.all(np.isnan(hits.point[0]))
    assert hits.distance[1] == pytest.approx(2.0 * math.sqrt(2.0), abs=1e-9)
    assert hits.body[1] == GROUND and hits.normal[1] == pytest.approx([0, 0, 1])
    # The ground lies 2,000 m away along that ray: out of range.
    assert hits.distance[2] == math.inf


def test_range_and_nearest_of_several_bodies():
    world = world_with({"name": "far", "size": [1.0, 1.0, 1.0], "position": [9.0, 0.0, 0.5]},
                       {"name": "near", "size": [1.0, 1.0, 1.0], "position": [4.0, 0.0, 0.5]})
    hits = world.cast_rays([[0.0, 0.0, 0.5]] * 2, [[1.0, 0.0, 0.0]] * 2, [20.0, 3.0])
    assert hits.distance[0] == pytest.approx(3.5, abs=1e-9)
    assert world.body_names()[hits.body[0]] == "near"
    assert hits.distance[1] == math.inf  # the near face is 3.5 m away, beyond 3 m


def test_excluded_body_is_seen_through():
    world = world_with({"name": "own", "size": [1.0, 1.0, 1.0], "position": [0.0, 0.0, 0.5]},
                       {"name": "other", "size": [1.0, 1.0, 1.0], "position": [6.0, 0.0, 0.5]})
    hits = world.cast_rays([[-3.0, 0.0, 0.5]], [[1.0, 0.0, 0.0]], 20.0, exclude=["own"])
    assert hits.distance[0] == pytest.approx(8.5, abs=1e-9)
    assert world.body_names()[hits.body[0]] == "other"
    with pytest.raises(KeyError, match="nobody"):
        world.cast_rays([[0.0, 0.0, 0.5]], [[1.0, 0.0, 0.0]], 20.0, exclude=["nobody"])


def test_frozen_immovable_and_far_apart_bodies_are_all_hit():
    """Bodies in the static index and bodies many grid cells apart, each hit at its face."""
    world = world_with({"name": "pillar", "size": [1.0, 1.0, 4.0], "position": [0.0, 20.0, 2.0],
                        "immovable": True},
                       {"name": "sleeper", "size": [1.0, 1.0, 1.0], "position": [-30.0, 0.0, 0.5],
                        "frozen": True},
                       {"name": "floor", "size": [400.0, 400.0, 0.2], "position": [0.0, 0.0, -0.1],
                        "immovable": True})
    world.step(3)
    hits = world.cast_rays([[0.0, 0.0, 0.5]] * 3, [[0, 1, 0], [-1, 0, 0], [0, 0, -1]], 100.0)
    assert hits.distance == pytest.approx([19.5, 29.5, 0.5], abs=1e-6)
    assert [world.body_names()[b] for b in hits.body] == ["pillar", "sleeper", "floor"]


def test_rays_find_the_playground_ramp():
    """The shipped ramp rises from (8, y, 0) to (16, y, 2): straight down at x = 12 it is 1 m high."""
    world = load_world({"version": 1, "playground": {"mesh": "playground.obj"}})
    hits = world.cast_rays([[12.0, 0.0, 5.0], [12.0, 0.0, 5.0]], [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]], 20.0)
    assert hits.body[0] == PLAYGROUND
    assert hits.distance[0] == pytest.approx(4.0, abs=1e-3)
    assert hits.normal[0] == pytest.approx(np.array([-2.0, 0.0, 8.0]) / math.hypot(2, 8), abs=1e-6)
    assert hits.body[1] == NOTHING


def test_batch_agrees_with_brute_force_over_a_random_pile():
    """Every ray of a random batch hits what testing every box analytically gives."""
    rng = np.random.default_rng(3)
    world = World(ground={"height": 0.0})
    for k in range(150):
        world.add_body({"size": rng.uniform(0.2, 1.5, 3).tolist(),
                        "position": rng.uniform([-8, -8, 0.5], [8, 8, 6]).tolist(),
                        "rpy": rng.uniform(-1, 1, 3).tolist(), "immovable": True})
    origins = rng.uniform([-12, -12, 0.2], [12, 12, 8], (2000, 3))
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    hits = world.cast_rays(origins, directions, 25.0)
    s = world.state()
    expected = np.full(2000, math.inf)
    for p, q, size in zip(s["positions"], s["quaternions"], s["sizes"]):
        x, y, z, w = q
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        o, d = (origins - p) @ r, directions @ r
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (-size / 2 - o) / d, (size / 2 - o) / d
        near = np.nanmax(np.minimum(t0, t1), axis=1)
        far = np.nanmin(np.maximum(t0, t1), axis=1)
        ok = (near <= far) & (near > 0) & (near <= 25.0)
        expected = np.where(ok, np.minimum(expected, near), expected)
    with np.errstate(divide="ignore"):
        ground = np.where(directions[:, 2] < 0, -origins[:, 2] / directions[:, 2], math.inf)
    expected = np.minimum(expected, np.where(ground <= 25.0, ground, math.inf))
    assert np.array_equal(np.isinf(hits.distance), np.isinf(expected))
    finite = np.isfinite(expected)
    assert hits.distance[finite] == pytest.approx(expected[finite], abs=1e-9)


def test_bad_batches_are_refused():
    world = world_with()
    with pytest.raises(ValueError, match="2 origins but 1 directions"):
        world.cast_rays([[0, 0, 1], [0, 0, 1]], [[1, 0, 0]], 5.0)
    with pytest.raises(ValueError, match="non-zero"):
        world.cast_rays([[0, 0, 1]], [[0, 0, 0]], 5.0)
