"""Batches of rays against geometry with known answers: box faces, the ground, the playground."""
import math

import numba
import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.ids import GROUND, NOTHING, PLAYGROUND
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


def nearest_triangle_hits(origins, directions, triangles, reach):
    """Moeller-Trumbore against every triangle's front face, in numpy: the nearest t or inf."""
    best = np.full(len(origins), math.inf)
    for a, b, c in triangles:
        e1, e2 = b - a, c - a
        facing = directions @ np.cross(e1, e2) < 0.0
        p = np.cross(directions, e2)
        det = p @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            s = origins - a
            u = np.einsum("ij,ij->i", s, p) / det
            q = np.cross(s, e1)
            v = np.einsum("ij,ij->i", directions, q) / det
            t = q @ e2 / det
        ok = facing & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= reach)
        best = np.where(ok, np.minimum(best, t), best)
    return best


def tilted_triangles_and_small_boxes(seed):
    """A playground of large triangles at every tilt, beside small boxes that make the grid's
    cells much smaller than the triangles (each spans many cells, most of its bounding box not).
    Rays cast with exclude=world.body_names() see only the triangles."""
    rng = np.random.default_rng(seed)
    world = World(ground=None)
    centres = rng.uniform(-10.0, 10.0, (40, 3))
    corners = centres[:, None, :] + rng.uniform(-4.0, 4.0, (40, 3, 3))
    world.set_playground(corners.reshape(-1, 3), np.arange(120).reshape(40, 3))
    for k in range(200):
        world.add_body({"size": [0.2, 0.2, 0.2], "position": rng.uniform(20.0, 24.0, 3).tolist(),
                        "immovable": True})
    return world, corners, rng


def test_triangles_filed_by_their_extent_are_hit_wherever_a_brute_force_finds_them():
    world, corners, rng = tilted_triangles_and_small_boxes(5)
    origins = rng.uniform(-14.0, 14.0, (3000, 3))
    directions = rng.normal(size=(3000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    # Rays aimed at points 1e-6 of the way in from each corner and edge of the triangles: they
    # cross the triangle where it barely enters a cell, the case filing by true extent could miss.
    weights = np.array([[1 - 2e-6, 1e-6, 1e-6], [1e-6, 1 - 2e-6, 1e-6], [1e-6, 1e-6, 1 - 2e-6],
                        [0.5 - 1e-6, 0.5 - 1e-6, 2e-6]])
    targets = np.einsum("wk,tkj->twj", weights, corners).reshape(-1, 3)
    aimed_from = targets + rng.normal(size=targets.shape) * 6.0
    aimed = targets - aimed_from
    aimed /= np.linalg.norm(aimed, axis=1)[:, None]
    origins, directions = np.concatenate([origins, aimed_from]), np.concatenate([directions, aimed])
    hits = world.cast_rays(origins, directions, 40.0, exclude=world.body_names())
    expected = nearest_triangle_hits(origins, directions, world.playground_triangles, 40.0)
    assert np.isfinite(expected[3000:]).mean() > 0.3  # the aimed rays do reach their triangles
    assert np.array_equal(np.isinf(hits.distance), np.isinf(expected))
    finite = np.isfinite(expected)
    assert hits.distance[finite] == pytest.approx(expected[finite], abs=1e-9)
    assert np.all(hits.body[finite] == PLAYGROUND)


def test_rays_along_cell_boundaries_find_what_a_brute_force_finds():
    """Rays that start on and run along the grid's cell planes (where a walk may step into the
    neighbouring cell by rounding) still see every triangle they cross."""
    world, corners, rng = tilted_triangles_and_small_boxes(6)
    grid = world.ray_scene()._grid  # the cell planes of this instant's grid
    lower, cell = grid.lower, grid.cell_size[0]
    planes = lower + cell * rng.integers(1, grid.dims, (8000, 3))
    origins = rng.uniform(-14.0, 14.0, (8000, 3))
    directions = rng.normal(size=(8000, 3))
    axis = rng.integers(0, 3, 8000)
    rows = np.arange(8000)
    origins[rows, axis] = planes[rows, axis]  # on a cell plane of one axis ...
    directions[rows, axis] = 0.0  # ... and staying in it
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    hits = world.cast_rays(origins, directions, 40.0, exclude=world.body_names())
    expected = nearest_triangle_hits(origins, directions, world.playground_triangles, 40.0)
    assert np.isfinite(expected).sum() > 150
    assert np.array_equal(np.isinf(hits.distance), np.isinf(expected))
    finite = np.isfinite(expected)
    assert hits.distance[finite] == pytest.approx(expected[finite], abs=1e-9)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two Numba threads")
def test_any_thread_count_gives_the_same_bytes():
    world, _, rng = tilted_triangles_and_small_boxes(7)
    origins = rng.uniform(-14.0, 14.0, (20_000, 3))
    directions = rng.normal(size=(20_000, 3))
    by_threads = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            by_threads.append(world.cast_rays(origins, directions, 40.0))
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    for one, two in zip(*by_threads):
        assert np.array_equal(one, two, equal_nan=True)


def test_one_origin_and_one_range_serve_every_ray_and_out_is_filled_in_place():
    world = world_with({"name": "b", "size": [1.0, 1.0, 1.0], "position": [5.0, 0.0, 0.5]})
    directions = [[1.0, 0.0, 0.0], [1.0, 0.0, -0.1], [0.0, 1.0, 0.0]] * 700  # several chunks
    one = world.cast_rays([0.0, 0.0, 0.5], directions, 20.0)
    each = world.cast_rays([[0.0, 0.0, 0.5]] * 2100, directions, [20.0] * 2100)
    for a, b in zip(one, each):
        assert np.array_equal(a, b, equal_nan=True)
    assert one.distance[:3] == pytest.approx([4.5, 4.5 / math.cos(math.atan(0.1)), math.inf])
    scene = world.ray_scene()
    out = scene.cast([0.0, 0.0, 0.5], directions, 20.0)
    again = scene.cast([0.0, 0.0, 0.5], np.negative(directions), 20.0, out=out)
    assert again is out and np.all(out.distance[0::3] == math.inf)
    with pytest.raises(ValueError, match="out holds 2100 rays, not 3"):
        scene.cast([0.0, 0.0, 0.5], directions[:3], 20.0, out=out)
    with pytest.raises(ValueError, match="2 ranges for 3 rays"):
        scene.cast([0.0, 0.0, 0.5], directions[:3], [20.0, 20.0])


def test_a_triangle_corner_poking_a_little_into_a_cell_is_found_in_that_cell():
    """Each triangle reaches across a cell plane by a thousandth of a cell at one corner only, and a
    ray ending just behind that corner never leaves the cell: only filing the triangle in the cell
    it barely enters lets the ray see it."""
    rng = np.random.default_rng(8)
    world = World(ground=None)
    # Small boxes set the cell size (the median object); two at the corners fix the grid's corner.
    for position in [*rng.uniform(-6.0, 6.0, (200, 3)), (-8.0, -8.0, -8.0), (8.0, 8.0, 8.0)]:
        world.add_body({"size": [0.2, 0.2, 0.2], "position": list(position), "immovable": True})
    grid = world.ray_scene()._grid
    lower, cell = grid.lower.copy(), grid.cell_size[0]
    steps = np.floor((np.array([-4.0, -5.0, -5.0]) - lower) / cell)
    corners = []
    for k in range(30):
        plane, y, z = lower + (steps + rng.integers(0, 30, 3) + (0.0, 0.5, 0.5)) * cell
        poke = (plane + 1e-3 * cell, y, z)  # just inside the cell beyond the plane
        spread = rng.uniform(0.5, 1.0, 2)
        # Counter-clockwise seen from +x: facing the rays, which come from there.
        corners.append([poke, (plane - 1.5, y - spread[0], z - spread[1]),
                        (plane - 1.5, y + spread[0], z - spread[1])])
    corners = np.array(corners)
    world.set_playground(corners.reshape(-1, 3), np.arange(90).reshape(30, 3))
    after = world.ray_scene()._grid
    assert np.array_equal(after.lower, lower) and after.cell_size[0] == cell  # the same cells
    targets = np.einsum("v,tvj->tj", [1 - 2e-6, 1e-6, 1e-6], corners)
    directions = -np.column_stack([np.ones(30), rng.uniform(-0.3, 0.3, (30, 2))])
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = targets - 2.0 * directions
    hits = world.cast_rays(origins, directions, 2.0 + 1e-4 * cell, exclude=world.body_names())
    assert hits.distance == pytest.approx(np.full(30, 2.0), abs=1e-9)
    assert np.all(hits.body == PLAYGROUND)
