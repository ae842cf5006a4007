"""Contacts of spheres, capsules, cylinders and boxes (narrow_phase's dispatch, the analytic
cases and the convex path's GJK, EPA and face clipping) against answers worked out by hand and
against brute force over sampled directions."""
import numpy as np
import pytest

from vplayground_ros.physics.convex_contact import (MAX_CLIP_POINTS, SHRINK, allocate_scratch,
                                            shape_contact, triangle_weights)
from vplayground_ros.physics.math3d import quat_to_matrix, rpy_to_quat
from vplayground_ros.physics.narrow_phase import (box_box, collide_ground, collide_pair,
                                                  collide_triangle, reduce_manifold)
from vplayground_ros.physics.shapes import BOX, CAPSULE, CYLINDER, SPHERE
from vplayground_ros.physics.shapes.convex import pack_hulls

MARGIN = 0.02
SCRATCH = allocate_scratch()
NO_HULLS = pack_hulls([None])  # the hull table of a world without convex bodies (slot 0)
# Playground.edges and crease_rows of a triangle tested alone: no concave edge.
ALONE = (0, ((0.0,) * 4,) * 3)
POINTS, DEPTHS = np.empty((MAX_CLIP_POINTS, 3)), np.empty(MAX_CLIP_POINTS)
KINDS = (BOX, SPHERE, CAPSULE, CYLINDER)


def rotation(rpy=(0.0, 0.0, 0.0)):
    m = np.empty((3, 3))
    quat_to_matrix(rpy_to_quat(rpy), m)
    return tuple(tuple(float(x) for x in r) for r in m)


def vec(v):
    return tuple(float(x) for x in v)


def body(kind, position, rpy=(0.0, 0.0, 0.0), dims=(0.5, 0.5, 0.0)):
    """(kind, position, rotation rows, dims, slot) as the engine passes them: tuples of floats
and the slot (0: these bodies have no hull). rpy may be a 3x3 rotation instead."""
    rot = rotation(rpy) if np.shape(rpy) == (3,) else tuple(vec(r) for r in rpy)
    return kind, vec(position), rot, vec(dims), 0


def pair(a, b, margin=MARGIN, reduce=False):
    n, normal = collide_pair(NO_HULLS, *a, *b, margin, SCRATCH, POINTS, DEPTHS)
    return result(n, normal, reduce)


def ground(a, height=0.0, margin=MARGIN, reduce=False):
    n = collide_ground(NO_HULLS, *a, height, margin, SCRATCH, POINTS, DEPTHS)
    return result(n, (0.0, 0.0, -1.0), reduce)


def triangle(a, tri, margin=MARGIN):
    tri = np.asarray(tri, float)
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    normal /= np.linalg.norm(normal)
    n, normal = collide_triangle(NO_HULLS, *a, tuple(vec(v) for v in tri), vec(normal), *ALONE,
                                 margin, SCRATCH, POINTS, DEPTHS)
    return result(n, normal, False)


def result(n, normal, reduce):
    points, depths = POINTS[:n].copy(), DEPTHS[:n].copy()
    if reduce and n:
        keep = np.empty(4, np.int64)
        kept = reduce_manifold(points, depths, n, normal, keep)
        points, depths = points[keep[:kept]], depths[keep[:kept]]
    assert np.all(np.isfinite(points)) and np.all(np.isfinite(depths))
    assert np.all(np.isfinite(normal))
    return points, depths, np.array(normal)


def test_sphere_sphere_is_exact():
    points, depths, normal = pair(body(SPHERE, (1, 2, 3), dims=(0.5, 0, 0)),
                                  body(SPHERE, (1.6, 2.8, 3), dims=(0.3, 0, 0)), margin=0.5)
    assert normal == pytest.approx([0.6, 0.8, 0.0], abs=1e-12)
    assert depths == pytest.approx([0.8 - 1.0], abs=1e-12)  # 0.2 apart: speculative
    surface_a, surface_b = np.array([1.3, 2.4, 3]), np.array([1.6 - 0.18, 2.8 - 0.24, 3])
    assert points[0] == pytest.approx((surface_a + surface_b) / 2, abs=1e-12)
    points, depths, normal = pair(body(SPHERE, (0, 0, 0), dims=(0.5, 0, 0)),
                                  body(SPHERE, (0, 0, 0.9), dims=(0.5, 0, 0)))
    assert depths == pytest.approx([0.1]) and normal == pytest.approx([0, 0, 1])
    assert points[0] == pytest.approx([0, 0, 0.45])


def test_sphere_capsule_and_sphere_box():
    capsule = body(CAPSULE, (0, 0, 0), (np.pi / 2, 0, 0), (0.2, 0.5, 0))  # axis along -y
    points, depths, normal = pair(body(SPHERE, (0, 0.3, 0.45), dims=(0.3, 0, 0)), capsule)
    assert normal == pytest.approx([0, 0, -1]) and depths == pytest.approx([0.05])
    box = body(BOX, (0, 0, 0), (0, 0, 0.3), (0.5, 0.4, 0.3))
    # Above the top face, then past a vertical edge, then inside near the top face.
    points, depths, normal = pair(body(SPHERE, (0.1, 0.1, 0.55), dims=(0.3, 0, 0)), box)
    assert normal == pytest.approx([0, 0, -1]) and depths == pytest.approx([0.05])
    corner = np.array(rotation((0, 0, 0.3))) @ [0.5, 0.4, 0.0]
    outward = corner / np.linalg.norm(corner)
    points, depths, normal = pair(box, body(SPHERE, corner + 0.25 * outward, dims=(0.3, 0, 0)))
    assert normal == pytest.approx(outward) and depths == pytest.approx([0.05])
    points, depths, normal = pair(box, body(SPHERE, (0, 0, 0.25), dims=(0.1, 0, 0)))
    assert normal == pytest.approx([0, 0, 1]) and depths == pytest.approx([0.15])
    assert points[0] == pytest.approx([0, 0, (0.3 + 0.15) / 2])  # the face and the sphere's bottom


def test_parallel_capsules_touch_at_two_points():
    a = body(CAPSULE, (0, 0, 0), (0, np.pi / 2, 0), (0.2, 0.5, 0))  # axis along x
    b = body(CAPSULE, (0.4, 0, 0.39), (0, np.pi / 2, 0), (0.2, 0.5, 0))
    points, depths, normal = pair(a, b)
    assert normal == pytest.approx([0, 0, 1])
    assert depths == pytest.approx([0.01, 0.01])
    assert sorted(points[:, 0]) == pytest.approx([-0.1, 0.5])  # the overlap of the two axes
    # Crossing capsules touch at one point.
    crossing = body(CAPSULE, (0, 0, 0.39), (np.pi / 2, 0, 0), (0.2, 0.5, 0))
    points, depths, normal = pair(a, crossing)
    assert len(points) == 1 and depths == pytest.approx([0.01])


@pytest.mark.parametrize("box_rpy, cylinder_rpy", [
    ((0, 0, 0), (0, 0, 0)), ((0, 0, 0.7), (0, 0, 0)), ((0.3, -0.2, 1.0), (0, 0, 0)),
    ((0, 0, 0), (0.4, 0, 0)), ((0, 0, 0), (np.pi / 2, 0, 0.3)), ((0.1, 0.2, 0.3), (1.2, 0, 0))])
@pytest.mark.parametrize("separation", [0.001, 0.05, 0.7])
def test_gjk_distance_of_a_box_below_a_cylinder(box_rpy, cylinder_rpy, separation):
    """The cylinder's lowest point straight above the box's highest: the horizontal plane
    between them separates them by exactly their vertical distance."""
    half = np.array([0.3, 0.2, 0.1])
    box_rotation = np.array(rotation(box_rpy))
    highest = box_rotation @ (np.sign(box_rotation[2]) * half)
    r, h = 0.4, 0.6
    cylinder_rotation = np.array(rotation(cylinder_rpy))
    down = cylinder_rotation[2] * -1.0  # -z in the cylinder's frame
    side = np.hypot(down[0], down[1])
    lowest = cylinder_rotation @ [r * down[0] / side if side > 1e-9 else 0.0,
                                  r * down[1] / side if side > 1e-9 else 0.0, h * np.sign(down[2])]
    cylinder = body(CYLINDER, highest - lowest + [0, 0, separation], cylinder_rpy, (r, h, 0))
    box = body(BOX, (0, 0, 0), box_rpy, half)
    found, normal, point_a, point_b, depth = shape_contact(NO_HULLS, *box, *cylinder, 1.0, SCRATCH)
    assert found and -depth == pytest.approx(separation, abs=1e-6)


@pytest.mark.parametrize("separation", [0.001, 0.03, 0.5])
def test_gjk_distance_of_a_box_beside_a_cylinder(separation):
    """A 45-degree yawed square box's vertical edge facing the cylinder's side."""
    reach = 0.6 / np.sqrt(2)
    box = body(BOX, (0.5 + reach + separation, 0, 0.1), (0, 0, np.pi / 4), (0.3, 0.3, 0.2))
    cylinder = body(CYLINDER, (0, 0, 0), dims=(0.5, 0.5, 0))
    found, normal, point_a, point_b, depth = shape_contact(NO_HULLS, *cylinder, *box, 1.0, SCRATCH)
    assert found and -depth == pytest.approx(separation, abs=1e-6)
    assert normal == pytest.approx([1, 0, 0], abs=1e-5)


@pytest.mark.parametrize("overlap", [0.0005, 0.01, 0.1])
def test_epa_depth_of_a_box_overlapping_a_cylinder(overlap):
    cylinder = body(CYLINDER, (0, 0, 0), dims=(0.5, 0.5, 0))
    on_top = body(BOX, (0.1, 0, 0.5 + 0.2 - overlap), (0, 0, 0.4), (0.3, 0.4, 0.2))
    found, normal, _, _, depth = shape_contact(NO_HULLS, *cylinder, *on_top, MARGIN, SCRATCH)
    assert found and depth == pytest.approx(overlap, abs=1e-4)
    assert normal == pytest.approx([0, 0, 1], abs=1e-4)
    beside = body(BOX, (0.5 + 0.3 - overlap, 0, 0), dims=(0.3, 0.4, 0.2))
    found, normal, _, _, depth = shape_contact(NO_HULLS, *cylinder, *beside, MARGIN, SCRATCH)
    assert found and depth == pytest.approx(overlap, abs=1e-4)
    assert normal == pytest.approx([1, 0, 0], abs=1e-4)
    below = body(BOX, (0, 0.2, -0.5 - 1.0 + overlap), dims=(2, 2, 1))
    found, normal, _, _, depth = shape_contact(NO_HULLS, *below, *cylinder, MARGIN, SCRATCH)
    assert found and depth == pytest.approx(overlap, abs=1e-4)
    assert normal == pytest.approx([0, 0, 1], abs=1e-4)


def assert_spread_over_end(points, centre, radius):
    """At least 3 points on the end's rim, not on a line, around its centre."""
    assert len(points) >= 3
    offsets = points[:, :2] - centre[:2]
    assert np.linalg.norm(offsets, axis=1) == pytest.approx([radius] * len(points), abs=1e-6)
    span = offsets[1:] - offsets[0]
    areas = span[:, None, 0] * span[None, :, 1] - span[:, None, 1] * span[None, :, 0]
    assert np.max(np.abs(areas)) > 0.5 * radius ** 2
    assert np.linalg.norm(offsets.mean(axis=0)) < 0.5 * radius


def test_cylinder_standing_on_its_end():
    cylinder = body(CYLINDER, (0.3, 0.2, 0.497), (0, 0, 0.1), (0.4, 0.5, 0))
    points, depths, normal = ground(cylinder, reduce=True)
    assert len(points) == 4 and depths == pytest.approx([0.003] * 4)
    assert points[:, 2] == pytest.approx([-0.0015] * 4)
    assert_spread_over_end(points, np.array([0.3, 0.2]), 0.4)
    table = body(BOX, (0, 0, -0.5), dims=(1, 1, 0.5))
    points, depths, normal = pair(table, cylinder, reduce=True)
    assert len(points) == 4 and depths == pytest.approx([0.003] * 4)
    assert normal == pytest.approx([0, 0, 1])
    assert_spread_over_end(points, np.array([0.3, 0.2]), 0.4)
    # Cylinder on cylinder, the upper one's end sticking out beyond the lower one's.
    upper = body(CYLINDER, (0.5, 0, 1.49), dims=(0.3, 0.5, 0))
    points, depths, normal = pair(body(CYLINDER, (0, 0, 0.5), dims=(0.4, 0.5, 0)), upper,
                                  reduce=True)
    assert len(points) >= 3 and depths == pytest.approx([0.01] * len(points))
    assert normal == pytest.approx([0, 0, 1])


def test_cylinder_lying_on_its_side():
    cylinder = body(CYLINDER, (0, 0, 0.395), (0, np.pi / 2, 0), (0.4, 0.5, 0))  # axis along x
    points, depths, normal = ground(cylinder)
    assert depths == pytest.approx([0.005, 0.005])
    assert sorted(points[:, 0]) == pytest.approx([-0.5, 0.5])
    assert points[:, 1] == pytest.approx([0, 0], abs=1e-12)
    table = body(BOX, (0, 0, -0.5), dims=(1, 1, 0.5))
    points, depths, normal = pair(cylinder, table)
    assert normal == pytest.approx([0, 0, -1], abs=1e-9)
    assert depths == pytest.approx([0.005, 0.005])
    assert sorted(points[:, 0]) == pytest.approx([-0.5, 0.5])


def test_capsule_lying_on_a_box_and_on_the_ground():
    capsule = body(CAPSULE, (0.1, 0, 0.295), (0, np.pi / 2, 0.3), (0.2, 0.4, 0))
    table = body(BOX, (0, 0, 0.05), dims=(1, 1, 0.05))
    points, depths, normal = pair(table, capsule)
    assert normal == pytest.approx([0, 0, 1], abs=1e-9)
    assert depths == pytest.approx([0.005, 0.005], abs=1e-9)
    assert np.linalg.norm(points[0] - points[1]) == pytest.approx(0.8, abs=1e-9)
    points, depths, normal = ground(capsule, height=0.1)
    assert depths == pytest.approx([0.005, 0.005])


def rx(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rz(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize("tilt", [0.3, 0.6, 1.2])
@pytest.mark.parametrize("spin", [0.0, 0.2, np.pi / 8])
def test_tilted_cylinder_on_its_rim(tilt, spin):
    """The end's 8-gon touches with its corners near the rim's lowest point, and the lowest
    point itself joins them when it lies between two corners: 1 to 3 points, the deepest exact,
    the others no farther along the rim than the margin allows."""
    r, h = 0.4, 0.5
    lowest = h * np.cos(tilt) + r * np.sin(tilt)
    pose = rx(tilt) @ rz(spin)  # spun about its axis, so the corners sit anywhere on the rim
    cylinder = body(CYLINDER, (0, 0, lowest - 0.004), pose, (r, h, 0))
    bottom = rx(tilt) @ [0, -r, -h] + [0, 0, lowest - 0.004]  # the rim's lowest point
    # A rim point at angle phi from the lowest one is r sin(tilt) (1 - cos phi) higher.
    phi = np.arccos(1 - (MARGIN + 0.004) / (r * np.sin(tilt)))
    reach = 2 * r * np.sin(phi / 2) + 1e-9
    points, depths, normal = ground(cylinder, reduce=True)
    assert 1 <= len(points) <= 3 and max(depths) == pytest.approx(0.004, abs=1e-9)
    assert np.all(np.linalg.norm(points - bottom, axis=1) < reach)
    table = body(BOX, (0, 0, -0.5), dims=(1, 1, 0.5))
    points, depths, normal = pair(table, cylinder, reduce=True)
    assert 1 <= len(points) <= 3 and max(depths) == pytest.approx(0.004, abs=1e-6)
    assert normal == pytest.approx([0, 0, 1], abs=1e-4)
    assert np.all(np.linalg.norm(points - bottom, axis=1) < reach)


SEAM = [[(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(1, 0, 0), (1, 1, 0), (0, 1, 0)]]  # edge x + y = 1


@pytest.mark.parametrize("kind, dims", [(SPHERE, (0.2, 0, 0)), (CAPSULE, (0.2, 0.2, 0)),
                                        (CYLINDER, (0.2, 0.2, 0))])
def test_rolling_over_a_seam_keeps_the_face_normal(kind, dims):
    """A body rolling across the shared edge of two coplanar triangles, sunk a little: every
    contact has the face normal (none points into the neighbour), one is as deep as the
    sinking, and all lie on the line it rolls about (its lowest), which stands still while it
    rolls: a point ahead of it would be moving down, and the solver would bump the body up."""
    rpy = (np.pi / 2, 0, np.pi / 4) if kind != SPHERE else (0, 0, 0)  # lying along the seam
    rolling = np.array([1, 1, 0]) / np.sqrt(2)
    for t in np.linspace(0.3, 0.7, 9):
        centre = np.array([t, t, 0.2 - 0.004])
        deepest = []
        for tri in SEAM:
            points, depths, normal = triangle(body(kind, centre, rpy, dims), tri)
            if len(points):
                assert normal == pytest.approx([0, 0, -1])
                assert (points - centre) @ rolling == pytest.approx([0] * len(points), abs=1e-9)
                deepest.append(depths.max())
        assert max(deepest) == pytest.approx(0.004, abs=1e-9)


def test_sphere_beside_a_step_gets_the_edge_normal():
    """Deeper than the seam tolerance below a triangle's plane, the edge pushes sideways."""
    top = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    points, depths, normal = triangle(body(SPHERE, (-0.1, 0.3, -0.05), dims=(0.2, 0, 0)), top)
    assert len(points) == 0  # behind the plane: one-sided
    points, depths, normal = triangle(body(SPHERE, (-0.15, 0.3, 0.01), dims=(0.2, 0, 0)), top)
    assert normal == pytest.approx(np.array([0.15, 0, -0.01]) / np.hypot(0.15, 0.01))
    assert depths == pytest.approx([0.2 - np.hypot(0.15, 0.01)])


def test_degenerate_simplices_divide_by_nothing():
    """Coinciding corners (GJK met a capsule's end twice, lying on a triangle) have no edge
    to project on: the corner itself is the closest point."""
    assert triangle_weights((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), (4.0, 5.0, 6.0)) == (1.0, 0.0, 0.0)
    assert triangle_weights((1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (1.0, 2.0, 3.0)) == (1.0, 0.0, 0.0)
    assert triangle_weights((4.0, 5.0, 6.0), (1.0, 2.0, 3.0), (1.0, 2.0, 3.0))[0] == 0.0
    capsule = (CAPSULE, (-7.90653532629521, -0.9987272268885038, 0.2021571252939717),
               ((0.8929457611581519, 0.45016426242333185, -6.683222403269795e-05),
                (-0.002926033117740451, 0.005655619987950611, -0.999979725940854),
                (-0.4501547577887881, 0.892927853076277, 0.006367357435235754)), (0.2, 0.2, 0.0), 0)
    points, depths, normal = triangle(capsule, [(-8, -2, 0), (-7.5, -2, 0), (-7.5, 2, 0)])
    assert normal == pytest.approx([0, 0, -1])


def test_cylinder_standing_on_a_triangle():
    tri = [(-2, -2, 0), (2, -2, 0), (0, 2, 0)]
    points, depths, normal = triangle(body(CYLINDER, (0, 0, 0.497), dims=(0.4, 0.5, 0)), tri)
    assert len(points) == 8 and depths == pytest.approx([0.003] * 8)
    assert normal == pytest.approx([0, 0, -1])


@pytest.mark.parametrize("kind_a", KINDS)
@pytest.mark.parametrize("kind_b", KINDS)
def test_shapes_beyond_the_margin_do_not_touch(kind_a, kind_b):
    dims = {BOX: (0.3, 0.3, 0.3), SPHERE: (0.3, 0, 0), CAPSULE: (0.3, 0.2, 0),
            CYLINDER: (0.3, 0.3, 0)}
    reach = {BOX: 0.3, SPHERE: 0.3, CAPSULE: 0.3, CYLINDER: 0.3}  # along x, axis-aligned
    gap = MARGIN + 0.005
    a = body(kind_a, (0, 0, 0), dims=dims[kind_a])
    b = body(kind_b, (reach[kind_a] + reach[kind_b] + gap, 0, 0), dims=dims[kind_b])
    assert len(pair(a, b)[0]) == 0
    b = body(kind_b, (reach[kind_a] + reach[kind_b] + MARGIN - 0.005, 0, 0), dims=dims[kind_b])
    points, depths, normal = pair(a, b)
    assert len(points) >= 1 and normal == pytest.approx([1, 0, 0], abs=1e-6)
    assert depths.max() == pytest.approx(-(MARGIN - 0.005), abs=1e-6)
    lifted = body(kind_a, (0, 0, (0.5 if kind_a == CAPSULE else 0.3) + gap), dims=dims[kind_a])
    assert len(ground(lifted)[0]) == 0


def test_box_pairs_are_box_box():
    rng = np.random.default_rng(3)
    poly_a, poly_b = np.empty((MAX_CLIP_POINTS, 3)), np.empty((MAX_CLIP_POINTS, 3))
    points, depths = np.empty((MAX_CLIP_POINTS, 3)), np.empty(MAX_CLIP_POINTS)
    for _ in range(200):
        a = body(BOX, rng.uniform(-0.3, 0.3, 3), rng.uniform(-3, 3, 3), rng.uniform(0.1, 0.5, 3))
        b = body(BOX, rng.uniform(-0.3, 0.3, 3) + [0, 0, 0.6], rng.uniform(-3, 3, 3),
                 rng.uniform(0.1, 0.5, 3))
        n, normal = box_box(*a[1:4], *b[1:4], MARGIN, poly_a, poly_b, points, depths)
        got_points, got_depths, got_normal = pair(a, b)
        assert len(got_points) == n and tuple(got_normal) == normal
        assert np.array_equal(got_points, points[:n]) and np.array_equal(got_depths, depths[:n])


def support_value(kind, position, rot, dims, slot, directions):
    """max over the shape of x . d, for each row d of `directions` (numpy, independent of the
    engine's support mappings)."""
    rot = np.array(rot)
    local = directions @ rot  # rows: R^T d
    base = directions @ np.array(position)
    if kind == BOX:
        return base + np.abs(local) @ np.array(dims)
    along = np.abs(local[:, 2])
    if kind == SPHERE:
        return base + dims[0]
    if kind == CAPSULE:
        return base + dims[1] * along + dims[0]
    return base + dims[1] * along + dims[0] * np.sqrt(np.maximum(1 - along ** 2, 0))


def random_body(rng, kind):
    dims = {BOX: rng.uniform(0.05, 0.6, 3), SPHERE: (rng.uniform(0.05, 0.5), 0, 0),
            CAPSULE: (rng.uniform(0.05, 0.4), rng.uniform(0.05, 0.5), 0),
            CYLINDER: (rng.uniform(0.05, 0.5), rng.uniform(0.02, 0.5), 0)}[kind]
    return body(kind, rng.uniform(-0.6, 0.6, 3), rng.uniform(-np.pi, np.pi, 3), dims)


def refined_overlap(a, b, d, rng):
    """The least overlap h_A(d) + h_B(-d) (the penetration depth, or minus the distance) found
    by random local search from the unit direction d."""
    best = (support_value(*a, d[None]) + support_value(*b, -d[None]))[0]
    for scale in np.geomspace(0.05, 1e-9, 40):
        trials = d + scale * rng.normal(size=(40, 3))
        trials /= np.linalg.norm(trials, axis=1)[:, None]
        overlap = support_value(*a, trials) + support_value(*b, -trials)
        k = np.argmin(overlap)
        if overlap[k] < best:
            best, d = overlap[k], trials[k]
    return best


def test_random_poses_agree_with_sampled_directions():
    """The overlap of two shapes along a direction, h_A(d) + h_B(-d), is least (minus their
    distance, or their penetration depth) along the contact normal: no sampled direction beats
    the reported depth, and a local search from the normal does not improve on it by more than
    the tolerance. The contact points lie in their shapes (a shallow overlap's, measured on the
    shrunk shapes, within SHRINK of them). Every manifold is finite."""
    rng = np.random.default_rng(19)
    directions = rng.normal(size=(5000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    checked = {"separated": 0, "overlapping": 0}
    for trial in range(400):
        a = random_body(rng, KINDS[trial % 4])
        b = random_body(rng, KINDS[(trial // 4) % 4])
        found, normal, point_a, point_b, depth = shape_contact(NO_HULLS, *a, *b, 10.0, SCRATCH)
        pair(a, b)  # finite (result() checks)
        assert found
        overlap = support_value(*a, directions) + support_value(*b, -directions)
        assert overlap.min() >= depth - 1e-9
        separated = depth < 0
        assert refined_overlap(a, b, np.array(normal), rng) == pytest.approx(
            depth, abs=1e-6 if separated else 0.2 * SHRINK)
        if separated:
            assert np.linalg.norm(np.subtract(point_b, point_a)) == pytest.approx(-depth, abs=1e-12)
        beside = 1e-9 if separated else SHRINK
        assert np.all(directions @ point_a <= support_value(*a, directions) + beside)
        assert np.all(directions @ point_b <= support_value(*b, directions) + beside)
        checked["separated" if separated else "overlapping"] += 1
    assert min(checked.values()) > 50


def test_shallow_overlaps_of_random_poses():
    """Shapes moved into each other by up to 15 mm along their separating normal (their
    overlap along it, an upper bound of the penetration): the depth along the new normal is
    never below the least overlap over directions (found by local search from it) and within
    a fifth of SHRINK above it."""
    rng = np.random.default_rng(5)
    shallow = 0
    for trial in range(400):
        a = random_body(rng, KINDS[trial % 4])
        b = random_body(rng, KINDS[(trial // 4) % 4])
        found, normal, _, _, depth = shape_contact(NO_HULLS, *a, *b, 10.0, SCRATCH)
        if depth >= 0.0:
            continue
        push = rng.uniform(0.0005, 0.015)
        b = (b[0], vec(np.array(b[1]) - (push - depth) * np.array(normal)), b[2], b[3], b[4])
        found, normal, _, _, depth = shape_contact(NO_HULLS, *a, *b, 10.0, SCRATCH)
        least = refined_overlap(a, b, np.array(normal), rng)
        assert least - 1e-9 <= depth <= least + 0.2 * SHRINK
        assert depth <= push + 0.2 * SHRINK
        shallow += 1
    assert shallow > 200


def test_degenerate_and_random_poses_never_fail():
    """Coinciding centres, parallel and square axes, exact contact, thin shapes, triangles
    through the body: every pair, triangle and ground job returns finite points within the
    margin and a unit normal (a Numba ZeroDivisionError would stop the whole step)."""
    rng = np.random.default_rng(7)
    angles = np.array([0.0, np.pi / 2, np.pi, np.pi / 4, -np.pi / 2])

    def choose(values, random):
        return rng.choice(values, 3) if rng.random() < 0.5 else random

    def dims(kind):
        if kind == BOX:
            return choose([0.01, 0.1, 0.5], rng.uniform(0.01, 1, 3))
        radius = rng.choice([0.01, 0.1, 0.5])
        half = 0.0 if kind == SPHERE else rng.choice([0.005, 0.1, 0.5])
        return radius, half, 0.0

    for trial in range(3000):
        ka, kb = KINDS[trial % 4], KINDS[(trial // 4) % 4]
        a = body(ka, choose([0.0, 0.5, -0.5], rng.uniform(-1, 1, 3)),
                 choose(angles, rng.uniform(-np.pi, np.pi, 3)), dims(ka))
        position = choose([0.0, 0.5, -0.5], rng.uniform(-1, 1, 3))
        rpy = choose(angles, rng.uniform(-np.pi, np.pi, 3))
        b = body(kb, a[1] if trial % 7 == 0 else position, a[2] if trial % 5 == 0 else rpy,
                 dims(kb))
        margin = float(rng.choice([0.0, 0.02, 0.5]))
        tri = choose([-1.0, 0.0, 0.5], rng.uniform(-1, 1, 3)), rng.uniform(-1, 1, 3), \
            rng.uniform(-1, 1, 3)
        jobs = [pair(a, b, margin), ground(a, float(rng.uniform(-1, 1)), margin)]
        if np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0])) > 1e-3:
            jobs.append(triangle(a, tri, margin))
        for points, depths, normal in jobs:
            if len(points):
                assert np.linalg.norm(normal) == pytest.approx(1.0)
                assert np.all(depths >= -margin - 1e-12)


def test_the_hull_of_a_box_touches_like_the_box():
    """A convex body whose hull is a box's corners (its dims are then the box's half extents):
    against random shapes its deepest contact (GJK, or EPA when they overlap: a hull is not
    shrunk) is the box's, by sampled directions, and its manifolds are finite."""
    from vplayground_ros.physics.shapes import CONVEX
    from vplayground_ros.physics.shapes.convex import build_hull
    rng = np.random.default_rng(11)
    directions = rng.normal(size=(5000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    for trial in range(200):
        half = rng.uniform(0.05, 0.6, 3)
        corners = [[x * half[0], y * half[1], z * half[2]] for x in (-1, 1) for y in (-1, 1)
                   for z in (-1, 1)]
        hulls = pack_hulls([None, build_hull(corners)])  # the hull at slot 1
        box = body(BOX, rng.uniform(-0.6, 0.6, 3), rng.uniform(-np.pi, np.pi, 3), half)
        hull = (CONVEX,) + box[1:4] + (1,)
        other = random_body(rng, KINDS[trial % 4])
        found, normal, point_a, point_b, depth = shape_contact(hulls, *hull, *other, 10.0, SCRATCH)
        assert found
        overlap = support_value(*box, directions) + support_value(*other, -directions)
        assert overlap.min() >= depth - 1e-9
        exact = refined_overlap(box, other, np.array(normal), rng)
        assert depth == pytest.approx(exact, abs=1e-6 if depth < 0 else 0.2 * SHRINK)
        n, pair_normal = collide_pair(hulls, *hull, *other, MARGIN, SCRATCH, POINTS, DEPTHS)
        result(n, pair_normal, False)
        n = collide_ground(hulls, *hull, float(rng.uniform(-1, 1)), MARGIN, SCRATCH, POINTS, DEPTHS)
        result(n, (0.0, 0.0, -1.0), False)


def test_a_hull_brick_on_the_ground_and_on_a_triangle_gives_its_four_corners():
    from vplayground_ros.physics.shapes import CONVEX
    from vplayground_ros.physics.shapes.convex import build_hull
    corners = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.25, 0.25) for z in (-0.1, 0.1)]
    hulls = pack_hulls([build_hull(corners)])
    brick = (CONVEX, (0.0, 0.0, 0.098), rotation((0, 0, 0.3)), (0.5, 0.25, 0.1), 0)
    n = collide_ground(hulls, *brick, 0.0, MARGIN, SCRATCH, POINTS, DEPTHS)
    assert n == 4 and DEPTHS[:4] == pytest.approx([0.002] * 4)
    tri = ((-3.0, -3.0, 0.0), (3.0, -3.0, 0.0), (0.0, 3.0, 0.0))
    n, normal = collide_triangle(hulls, *brick, tri, (0.0, 0.0, 1.0), *ALONE, MARGIN, SCRATCH,
                                 POINTS, DEPTHS)
    assert n == 4 and DEPTHS[:4] == pytest.approx([0.002] * 4)
    assert normal == pytest.approx((0, 0, -1))
