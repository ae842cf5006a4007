"""Broad and narrow phase against brute force and geometry worked out by hand."""
import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.math3d import rpy_to_quat
from vplayground_ros.physics.narrow_phase import MAX_CLIP_POINTS, box_box
from vplayground_ros.physics.math3d import quaternions_to_matrices


def brute_force_pairs(world):
    b = world._bodies
    slots = np.nonzero(b.active)[0]
    pairs = set()
    for i in slots:
        for j in slots:
            if i < j and (b.awake[i] or b.awake[j]) and np.all(b.aabb_min[i] <= b.aabb_max[j]) \
                    and np.all(b.aabb_min[j] <= b.aabb_max[i]):
                pairs.add((i, j))
    return pairs


@pytest.mark.parametrize("depth", [1, 3, 5, 8])
def test_octree_finds_exactly_the_overlapping_pairs(depth):
    """Mixed sizes (so several octree levels), some frozen (static index), any octree depth."""
    rng = np.random.default_rng(depth)
    world = World({"octree_depth": depth, "gravity": [0, 0, 0]}, ground=None)
    for k in range(300):
        size = rng.choice([0.2, 0.7, 3.0], p=[0.5, 0.4, 0.1])
        world.add_body({"size": [size] * 3, "position": list(rng.uniform(-8, 8, 3)),
                        "rpy": list(rng.uniform(-3, 3, 3)), "frozen": bool(rng.random() < 0.4),
                        "linear_velocity": list(rng.uniform(-5, 5, 3))})
    world.step(1)
    broad = world._broad
    found = {tuple(sorted(p)) for p in zip(broad.pair_a[:broad.pair_count[0]], broad.pair_b[:broad.pair_count[0]])}
    assert len(found) == broad.pair_count[0]  # each pair once
    # step(1) moved the bodies after detection: compare with the bounds the step detected with.
    expected = brute_force_pairs(world)
    assert found == expected
    assert len(expected) > 50


def manifold(size_a, pose_a, size_b, pose_b, margin=0.02):
    pa, qa = np.array(pose_a[0], float), rpy_to_quat(pose_a[1])
    pb, qb = np.array(pose_b[0], float), rpy_to_quat(pose_b[1])
    ra, rb = quaternions_to_matrices(np.array([qa, qb]))
    poly_a, poly_b = np.empty((MAX_CLIP_POINTS, 3)), np.empty((MAX_CLIP_POINTS, 3))
    points, depths = np.empty((MAX_CLIP_POINTS, 3)), np.empty(MAX_CLIP_POINTS)
    n, normal = box_box(pa, ra, np.array(size_a) / 2, pb, rb, np.array(size_b) / 2, margin,
                        poly_a, poly_b, points, depths)
    return points[:n], depths[:n], np.array(normal)


def test_box_resting_on_a_larger_box_gives_its_four_corners():
    points, depths, normal = manifold([2, 2, 1], ([0, 0, 0], [0, 0, 0]),
                                      [1, 1, 1], ([0.2, 0.1, 0.99], [0, 0, 0.3]))
    assert len(points) == 4
    assert normal == pytest.approx([0, 0, 1])
    assert depths == pytest.approx([0.01] * 4)
    # The corners of the upper box's bottom face, yawed by 0.3 rad about its centre.
    c, s = np.cos(0.3), np.sin(0.3)
    corners = {(round(0.2 + c * x - s * y, 6), round(0.1 + s * x + c * y, 6))
               for x in (-0.5, 0.5) for y in (-0.5, 0.5)}
    assert {(round(p[0], 6), round(p[1], 6)) for p in points} == corners
    assert points[:, 2] == pytest.approx([0.495] * 4)  # halfway between the faces


def test_overhanging_box_is_clipped_to_the_support():
    points, depths, _ = manifold([1, 1, 1], ([0, 0, 0], [0, 0, 0]), [1, 1, 1], ([0.6, 0, 0.999], [0, 0, 0]))
    assert len(points) == 4
    assert points[:, 0].min() == pytest.approx(0.1) and points[:, 0].max() == pytest.approx(0.5)


def test_crossed_edges_give_one_point_on_both_edges():
    # Two unit cubes rotated 45 degrees about different axes meet edge to edge.
    d = np.sqrt(2) / 2
    points, depths, normal = manifold([1, 1, 1], ([0, 0, 0], [np.pi / 4, 0, 0]),
                                      [1, 1, 1], ([0, 0, 2 * d - 0.01], [0, np.pi / 4, 0]))
    assert len(points) == 1
    assert normal == pytest.approx([0, 0, 1], abs=1e-9)
    assert depths[0] == pytest.approx(0.01, abs=1e-6)  # SAT pads radii by 1e-9 per term
    assert points[0] == pytest.approx([0, 0, d - 0.005], abs=1e-9)


def test_separated_boxes_give_nothing():
    points, _, _ = manifold([1, 1, 1], ([0, 0, 0], [0, 0, 0]), [1, 1, 1], ([1.1, 0.3, 0], [0, 0, 0.2]))
    assert len(points) == 0


def test_octree_cells_cover_every_body():
    rng = np.random.default_rng(5)
    world = World({"octree_depth": 4, "gravity": [0, 0, 0]}, ground=None)
    for k in range(40):
        world.add_body({"size": [rng.choice([0.3, 2.0])] * 3, "position": list(rng.uniform(-6, 6, 3))})
    world.step(1)
    cells = world.octree_cells()
    assert cells and all(0 <= level <= 4 for level, _, _ in cells)
    centres = np.concatenate([c for _, c, _ in cells])
    edges = np.concatenate([[e] * len(c) for _, c, e in cells])
    for p in world.state()["positions"]:  # every body's centre lies in some occupied cell
        inside = np.all(np.abs(centres - p) <= edges[:, None] / 2 + 0.05, axis=1)
        assert inside.any()
