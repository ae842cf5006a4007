"""Spheres, capsules and cylinders against analytic answers: mass and inertia, rolling, resting,
rebounds, rays, mixed piles; and their scene keys."""
import math
import re

import numpy as np
import pytest

from vplayground_ros.messages import shape_marker_layout, shape_marker_poses
from vplayground_ros.physics import World
from vplayground_ros.physics import shapes
from vplayground_ros.scene import load_world, save_world
from helpers import rebound_apex

G = 9.81
ROUND = {"sphere": {"shape": "sphere", "radius": 0.4},
         "capsule": {"shape": "capsule", "radius": 0.3, "length": 0.8},
         "cylinder": {"shape": "cylinder", "radius": 0.4, "length": 0.6}}


def incline(theta, mu=1.0):
    """The ground as an incline: gravity tilted by theta about y, downhill along +x."""
    return World({"gravity": [G * math.sin(theta), 0, -G * math.cos(theta)]},
                 ground={"static_friction": mu, "dynamic_friction": mu, "elasticity": 0.0})


def roll_acceleration(world, steps=256):
    world.step(32)  # settle the contact
    v0 = world.state()["linear_velocities"][0, 0]
    world.step(steps)
    return (world.state()["linear_velocities"][0, 0] - v0) / (steps / 128)


@pytest.mark.parametrize("shape, volume, unit_inertia", [
    ({"shape": "sphere", "radius": 0.5}, 4 / 3 * math.pi * 0.125, (0.1, 0.1, 0.1)),
    ({"shape": "cylinder", "radius": 0.5, "length": 2.0}, math.pi * 0.25 * 2,
     ((3 * 0.25 + 4) / 12, (3 * 0.25 + 4) / 12, 0.125)),
    # a capsule of no length is a sphere
    ({"shape": "capsule", "radius": 0.5, "length": 0.0}, 4 / 3 * math.pi * 0.125, (0.1, 0.1, 0.1)),
])
def test_mass_and_inertia_follow_from_density(shape, volume, unit_inertia):
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "b", **shape, "density": 800.0})
    mass = world.body("b")["mass"]
    assert mass == pytest.approx(800.0 * volume)
    world.apply_impulse("b", angular_impulse=[1.0, 2.0, 3.0])
    world.step(1)
    omega = world.state()["angular_velocities"][0]
    assert omega == pytest.approx(np.array([1.0, 2.0, 3.0]) / (mass * np.array(unit_inertia)), rel=1e-9)


def test_capsule_inertia_is_its_cylinder_and_hemispheres():
    # Integrated numerically over a fine grid of the solid, against the closed form.
    r, length = 0.3, 0.8
    grid = np.linspace(-0.7, 0.7, 141)
    x, y, z = np.meshgrid(grid, grid, grid, indexing="ij")
    inside = x ** 2 + y ** 2 + (z - np.clip(z, -length / 2, length / 2)) ** 2 <= r * r
    ixx = np.mean((y[inside] ** 2 + z[inside] ** 2))
    izz = np.mean((x[inside] ** 2 + y[inside] ** 2))
    across, _, axial = shapes.capsule.unit_inertia(shapes.capsule.dimensions({"radius": r, "length": length}))
    assert across == pytest.approx(ixx, rel=0.01) and axial == pytest.approx(izz, rel=0.01)


@pytest.mark.parametrize("theta", [0.15, 0.3])
def test_a_sphere_rolls_down_an_incline_at_five_sevenths_g_sin(theta):
    world = incline(theta)
    world.add_body({"name": "ball", "shape": "sphere", "radius": 0.5, "position": [0, 0, 0.5],
                    "static_friction": 1.0, "dynamic_friction": 1.0, "elasticity": 0.0,
                    "allow_freezing": False})
    assert roll_acceleration(world) == pytest.approx(5 / 7 * G * math.sin(theta), rel=0.03)
    # Rolling, not sliding: the contact point is at rest (v = w r).
    s = world.state()
    assert s["angular_velocities"][0, 1] * 0.5 == pytest.approx(s["linear_velocities"][0, 0], rel=0.02)


def test_a_cylinder_on_its_side_rolls_at_two_thirds_g_sin():
    theta = 0.2
    world = incline(theta)
    # The axis along y: rolling downhill along x.
    world.add_body({"name": "can", "shape": "cylinder", "radius": 0.4, "length": 1.0,
                    "position": [0, 0, 0.4], "rpy": [math.pi / 2, 0, 0], "static_friction": 1.0,
                    "dynamic_friction": 1.0, "elasticity": 0.0, "allow_freezing": False})
    assert roll_acceleration(world) == pytest.approx(2 / 3 * G * math.sin(theta), rel=0.03)
    assert abs(world.state()["positions"][0, 1]) < 0.01  # straight downhill


def test_a_cylinder_on_its_end_stands_on_an_incline_below_its_friction_angle():
    world = incline(0.3, mu=0.8)
    world.add_body({"name": "can", "shape": "cylinder", "radius": 0.3, "length": 0.5,
                    "position": [0, 0, 0.25], "static_friction": 0.8, "dynamic_friction": 0.8,
                    "elasticity": 0.0, "allow_freezing": False})
    world.step(3 * 128)
    s = world.state()
    assert np.linalg.norm(s["positions"][0] - [0, 0, 0.25]) < 0.01
    assert np.linalg.norm(s["angular_velocities"][0]) < 0.01
    # A stable manifold over the end, not one point: several ground contacts spread over it.
    points = world.contacts()["points"]
    assert len(points) >= 3
    assert np.ptp(points[:, 0]) > 0.3 and np.ptp(points[:, 1]) > 0.3


@pytest.mark.parametrize("shape", list(ROUND))
def test_round_bodies_lie_still_on_the_ground(shape):
    spec = ROUND[shape]
    # capsules and cylinders lie on their sides, axis along x
    lying = {"rpy": [0, math.pi / 2, 0]} if shape != "sphere" else {}
    rest = spec["radius"]
    world = World()
    world.add_body({"name": "b", **spec, **lying, "position": [0, 0, rest], "allow_freezing": False})
    world.step(5 * 128)
    s = world.state()
    assert np.linalg.norm(s["positions"][0] - [0, 0, rest]) < 0.01
    assert np.linalg.norm(s["linear_velocities"][0]) < 1e-3
    assert np.linalg.norm(s["angular_velocities"][0]) < 1e-2


@pytest.mark.parametrize("elasticity", [0.4, 0.8])
def test_a_ball_dropped_on_a_ball_rebounds_per_its_elasticity(elasticity):
    drop = 1.5
    world = World(ground=None)
    world.add_body({"name": "base", "shape": "sphere", "radius": 0.5, "immovable": True,
                    "elasticity": 0.0})
    world.add_body({"name": "ball", "shape": "sphere", "radius": 0.25, "position": [0, 0, 0.75 + drop],
                    "elasticity": elasticity, "allow_freezing": False})
    bounced, apex = rebound_apex(world, 1, 0.75)
    assert bounced
    assert apex == pytest.approx(elasticity ** 2 * drop, rel=0.08)
    # Head on: no sideways kick.
    assert np.linalg.norm(world.state()["positions"][1, :2]) < 1e-6


MIXED = [{"size": [0.5, 0.4, 0.3]}, {"shape": "sphere", "radius": 0.25},
         {"shape": "capsule", "radius": 0.15, "length": 0.4},
         {"shape": "cylinder", "radius": 0.25, "length": 0.4}]


def mixed_pile(count, seed=3, kinds=MIXED):
    """The kinds (boxes, spheres, capsules and cylinders) in turn, on a jittered grid in random
    orientations, in a pen of four immovable walls (a ball rolling on a flat floor would roll
    for ever: rigid bodies have no rolling resistance)."""
    rng = np.random.default_rng(seed)
    world = World()
    side = 4
    for k in range(count):
        x, y, z = k % side, (k // side) % side, k // (side * side)
        world.add_body({"name": f"b{k}", **kinds[k % len(kinds)], "elasticity": 0.3,
                        "position": [(x - 1.5) * 0.9 + rng.uniform(-0.1, 0.1),
                                     (y - 1.5) * 0.9 + rng.uniform(-0.1, 0.1), 0.6 + 0.9 * z],
                        "rpy": list(rng.uniform(-math.pi, math.pi, 3))})
    for k, (x, y, sx, sy) in enumerate([(2.4, 0, 0.2, 5), (-2.4, 0, 0.2, 5), (0, 2.4, 5, 0.2), (0, -2.4, 5, 0.2)]):
        world.add_body({"name": f"wall{k}", "size": [sx, sy, 1.5], "position": [x, y, 0.75], "immovable": True})
    return world


def energies(world):
    """(translational kinetic, potential) energy of the movable bodies, J."""
    s, masses = world.state(), np.array([world.body(n)["mass"] for n in world.body_names()])
    movable = ~s["immovable"]
    kinetic = 0.5 * np.sum((masses * np.sum(s["linear_velocities"] ** 2, axis=1))[movable])
    return kinetic, np.sum((masses * G * s["positions"][:, 2])[movable])


def settle(world, seconds=10):
    """Steps the pile; returns its energy at the start, the largest rise above it seen, and the
    deepest contact seen."""
    start = sum(energies(world))
    worst_gain, deepest = -np.inf, 0.0
    for _ in range(seconds * 16):
        world.step(8)
        worst_gain = max(worst_gain, sum(energies(world)) - start)
        depths = world.contacts()["depths"]
        deepest = max(deepest, float(depths.max()) if len(depths) else 0.0)
    return start, worst_gain, deepest


def test_a_mixed_pile_comes_to_rest_without_interpenetration_or_energy_gain():
    world = mixed_pile(48)
    start, worst_gain, deepest = settle(world)
    # Rotation is left out: the measured energy never exceeds the true total, which starts
    # with none, so a rise above the start is a real gain.
    assert worst_gain <= 1e-9 * abs(start)
    assert deepest < 0.03
    kinetic, potential = energies(world)
    assert kinetic < 1e-3 * (start - potential)  # all but a trace of the fall's energy is gone
    assert world.state()["positions"][:, 2].min() > 0.1  # nothing sank through the ground


@pytest.mark.parametrize("shape, origin, direction, distance, normal", [
    ("sphere", [3, 0, 0], [-1, 0, 0], 2.6, [1, 0, 0]),
    ("capsule", [0, 0, 5], [0, 0, -1], 5 - 0.7, [0, 0, 1]),      # the upper hemisphere's top
    ("capsule", [3, 0, 0.3], [-1, 0, 0], 2.7, [1, 0, 0]),        # the side
    ("cylinder", [0.2, 0, 5], [0, 0, -1], 5 - 0.3, [0, 0, 1]),   # the flat end
    ("cylinder", [3, 0, 0.1], [-1, 0, 0], 2.6, [1, 0, 0]),       # the side
    ("cylinder", [0.45, 0, 5], [0, 0, -1], math.inf, [0, 0, 0]),  # just past the rim
])
def test_rays_hit_round_shapes_at_their_surfaces(shape, origin, direction, distance, normal):
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "b", **ROUND[shape], "position": [0, 0, 0]})
    hits = world.cast_rays(np.array([origin], float), np.array([direction], float), 10.0)
    assert hits.distance[0] == pytest.approx(distance)
    if math.isfinite(distance):
        assert hits.normal[0] == pytest.approx(normal, abs=1e-9)


def test_rays_see_a_turned_cylinder_in_its_frame():
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "b", "shape": "cylinder", "radius": 0.4, "length": 2.0,
                    "position": [0, 0, 1], "rpy": [0, math.pi / 2, 0]})  # axis along x
    hits = world.cast_rays(np.array([[0.9, 0, 5]]), np.array([[0, 0, -1.0]]), 10.0)
    assert hits.distance[0] == pytest.approx(5 - 1.4)
    hits = world.cast_rays(np.array([[1.1, 0, 5]]), np.array([[0, 0, -1.0]]), 10.0)
    assert math.isinf(hits.distance[0])  # beyond the end (the length is along x now)


def test_shapes_save_and_reload(tmp_path):
    world = World()
    for k, spec in enumerate(ROUND.values()):
        world.add_body({"name": f"b{k}", **spec, "position": [2.0 * k, 0, 1.0], "density": 300.0})
    save_world(world, tmp_path / "shapes.yaml")
    again = load_world(tmp_path / "shapes.yaml")
    for name in world.body_names():
        assert again.body(name) == world.body(name)
    capsule = again.body("b1")
    assert (capsule["shape"], capsule["radius"], capsule["length"]) == ("capsule", 0.3, 0.8)
    assert "size" not in capsule


@pytest.mark.parametrize("spec, problem", [
    ({"shape": "sphere", "size": [1, 1, 1]}, "body.size: a sphere has no size (its keys: radius)"),
    ({"shape": "box", "radius": 1.0}, "body.radius: a box has no radius (its keys: size)"),
    ({"shape": "cylinder", "radius": 1.0, "length": 0.0}, "body.length: must be >= 0.001 for a cylinder, got 0"),
    ({"shape": "sphere", "radius": -1.0}, "body.radius: must be >= 0.0005, got -1"),
    ({"shape": "cone"}, "body.shape: unsupported shape 'cone' (supported: box, sphere, capsule, cylinder, convex, compound)"),
])
def test_bad_shape_keys_are_refused_naming_the_key(spec, problem):
    world = World()
    with pytest.raises(ValueError) as error:
        world.add_body(spec)
    assert str(error.value) == problem
    assert world.body_names() == []


def test_editing_a_radius_keeps_the_mass_and_changes_the_inertia():
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "b", "shape": "sphere", "radius": 0.5, "mass": 10.0})
    world.edit_body("b", radius=1.0)
    assert world.body("b")["radius"] == 1.0 and world.body("b")["mass"] == 10.0
    world.apply_impulse("b", angular_impulse=[0, 0, 4.0])
    world.step(1)
    assert world.state()["angular_velocities"][0, 2] == pytest.approx(4.0 / (0.4 * 10.0 * 1.0))
    with pytest.raises(ValueError, match="a sphere has no length"):
        world.edit_body("b", length=2.0)


def test_markers_draw_each_shape():
    codes = np.array([shapes.BOX, shapes.SPHERE, shapes.CAPSULE, shapes.CYLINDER])
    dims = np.array([[0.5, 0.25, 0.1], [0.4, 0, 0], [0.3, 0.4, 0], [0.4, 0.3, 0]])
    poses = np.array([[0, 0, 0, 0, 0, 0, 1.0]] * 3 + [[0, 0, 0, 0, math.sin(math.pi / 4), 0, math.cos(math.pi / 4)]])
    poses[2, :3] = [5, 0, 1]
    layout = shape_marker_layout(codes, dims, np.array([1, 2, 3, 4]))
    rows, types, ids, where, scales = layout.rows, layout.types, layout.ids, shape_marker_poses(layout, poses), layout.scales
    # CUBE, SPHERE, CYLINDER (a capsule's middle), CYLINDER, then the capsule's two end spheres
    assert list(types) == [1, 2, 3, 3, 2, 2] and list(rows) == [0, 1, 2, 3, 2, 2]
    assert len(set(ids)) == 6
    assert scales[:4].tolist() == [[1.0, 0.5, 0.2], [0.8, 0.8, 0.8], [0.6, 0.6, 0.8], [0.8, 0.8, 0.6]]
    assert where[4:, :3].tolist() == [[5, 0, 1.4], [5, 0, 0.6]]


# ---------------------------------------------------------------- convex hulls
BRICK = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.25, 0.25) for z in (-0.1, 0.1)]
OCTAHEDRON_OBJ = """# a regular octahedron of radius 0.5, with an interior point the hull drops
v 0.5 0 0
v -0.5 0 0
v 0 0.5 0
v 0 -0.5 0
v 0 0 0.5
v 0 0 -0.5
f 1 3 5
f 3 2 5
f 2 4 5
f 4 1 5
f 3 1 6
f 2 3 6
f 4 2 6
f 1 4 6
"""


def test_a_convex_hull_has_the_mass_and_inertia_of_its_solid():
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    # The hull of a brick's corners and points inside it, placed off the origin: the body is
    # centred on the hull's centre of mass.
    inside = np.random.default_rng(1).uniform(-0.09, 0.09, (20, 3))
    points = np.vstack([BRICK, inside]) + [2.0, -1.0, 0.5]
    world.add_body({"name": "c", "shape": "convex", "points": points.tolist(), "density": 400.0,
                    "position": [0, 0, 3]})
    body = world.body("c")
    assert body["mass"] == pytest.approx(400.0 * 1.0 * 0.5 * 0.2)
    assert sorted(map(tuple, np.round(body["points"], 12))) == sorted(map(tuple, BRICK))
    world.apply_impulse("c", angular_impulse=[1.0, 2.0, 3.0])
    world.step(1)
    box = np.array([0.25 + 0.04, 1.0 + 0.04, 1.0 + 0.25]) / 12 * body["mass"]
    assert world.state()["angular_velocities"][0] == pytest.approx(np.array([1.0, 2.0, 3.0]) / box, rel=1e-9)


def test_a_turned_convex_body_turns_its_full_inertia_tensor():
    # A tetrahedron's inertia is not diagonal in its mesh frame: an impulse about x alone
    # spins it about another axis too, exactly as I^-1 L says.
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "t", "shape": "convex", "points": points.tolist(), "mass": 6.0})
    world.apply_impulse("t", angular_impulse=[1.0, 0, 0])
    world.step(1)
    # The unit tetrahedron's inertia about its centroid (1/4, 1/4, 1/4), per kg.
    centred = points - 0.25
    covariance = (np.einsum("i,j->ij", centred.sum(0), centred.sum(0)) + centred.T @ centred) / 20.0
    inertia = 6.0 * (np.trace(covariance) * np.eye(3) - covariance)
    assert world.state()["angular_velocities"][0] == pytest.approx(np.linalg.solve(inertia, [1.0, 0, 0]), rel=1e-9)


def test_rays_hit_a_convex_body_on_its_faces():
    world = World(ground=None, settings={"gravity": [0, 0, 0]})
    world.add_body({"name": "c", "shape": "convex", "points": BRICK, "position": [0, 0, 1],
                    "rpy": [0, 0, math.pi / 2]})  # its long side along y now
    hits = world.cast_rays(np.array([[0, 3, 1.0], [0.3, 0, 5.0], [0.2, 0, 5.0]]),
                           np.array([[0, -1, 0], [0, 0, -1], [0, 0, -1.0]]), 10.0)
    assert hits.distance[0] == pytest.approx(2.5) and hits.normal[0] == pytest.approx([0, 1, 0], abs=1e-12)
    assert math.isinf(hits.distance[1])  # beyond its 0.25 m half width along x
    assert hits.distance[2] == pytest.approx(3.9) and hits.normal[2] == pytest.approx([0, 0, 1], abs=1e-12)


def test_a_scene_takes_a_convex_mesh_and_saves_its_hull(tmp_path):
    (tmp_path / "gem.obj").write_text(OCTAHEDRON_OBJ)
    scene = tmp_path / "scene.yaml"
    scene.write_text("version: 1\nbodies:\n  - {name: gem, shape: convex, mesh: gem.obj, position: [0, 0, 1]}\n")
    world = load_world(scene)
    assert world.body("gem")["mass"] == pytest.approx(500.0 * 4 / 3 * 0.5 ** 3)  # 8 tetrahedra
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    assert again.body("gem") == world.body("gem")


def test_a_convex_body_saved_again_is_saved_the_same(tmp_path):
    """Its hull is saved centred on its centre of mass, which loaded again is the origin but
    for rounding: that rounding had been taken off the points at every load, so each save of a
    saved scene wrote other points (-0.275 as -0.2750000000000001, then -0.27499999999999997)."""
    world = World()
    world.add_body({"name": "wedge", "shape": "convex", "position": [0, 0, 2],
                    "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.3, 0.9]]})
    save_world(world, tmp_path / "first.yaml")
    again = load_world(tmp_path / "first.yaml")
    save_world(again, tmp_path / "second.yaml")
    assert (tmp_path / "second.yaml").read_text() == (tmp_path / "first.yaml").read_text()
    assert again.body("wedge") == world.body("wedge")


@pytest.mark.parametrize("body, problem", [
    ({"shape": "convex"}, "body.points: missing"),
    ({"shape": "convex", "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]},
     "points: the points are flat or degenerate"),
    ({"shape": "convex", "points": [[math.cos(a) * math.sin(b), math.sin(a) * math.sin(b), math.cos(b)]
                                    for a in np.linspace(0, 6, 12) for b in np.linspace(0.2, 2.9, 8)]},
     "points: the convex hull has 96 vertices, more than the 64 allowed"),
    ({"shape": "convex", "points": [[0, 0, 0]] * 3}, "body.points: expected a list of 4 to"),
    ({"shape": "sphere", "points": BRICK}, "body.points: a sphere has no points"),
])
def test_bad_convex_bodies_are_refused_naming_the_problem(body, problem):
    world = World()
    with pytest.raises(ValueError, match=re.escape(problem)):
        world.add_body(body)
    assert world.body_names() == []


def test_a_mesh_on_another_shape_is_refused(tmp_path):
    (tmp_path / "gem.obj").write_text(OCTAHEDRON_OBJ)
    from vplayground_ros.scene import SceneError
    with pytest.raises(SceneError, match=re.escape("bodies[0].mesh: only a convex body takes a mesh")):
        load_world({"version": 1, "bodies": [{"shape": "box", "mesh": "gem.obj"}]})


def test_a_convex_body_is_drawn_as_its_hull_triangles():
    world = World()
    world.add_body({"name": "c", "shape": "convex", "points": BRICK})
    world.add_body({"name": "b", "size": [1, 1, 1], "position": [3, 0, 1]})
    props = world.body_properties()
    layout = shape_marker_layout(props["shapes"], props["dimensions"], np.array([1, 2]), world.hull_triangles())
    assert list(layout.types) == [11, 1] and layout.scales[0].tolist() == [1, 1, 1]
    points = layout.points
    assert points[1] is None and points[0].shape == (36, 3)  # a brick's 12 triangles
    assert np.allclose(np.abs(points[0]), [0.5, 0.25, 0.1])  # its corners, in its frame


# Convex bodies collide through the narrow phase's general path (GJK/EPA and face clipping).
TETRAHEDRON = [[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5]]


def world_points(world, k, points):
    """The hull points (body frame) of body row k in the world."""
    from vplayground_ros.physics.math3d import quat_to_matrix
    s, r = world.state(), np.empty((3, 3))
    quat_to_matrix(s["quaternions"][k], r)
    return np.asarray(points) @ r.T + s["positions"][k]


def assert_at_rest(world, k):
    s = world.state()
    assert np.linalg.norm(s["linear_velocities"][k]) < 1e-3
    assert np.linalg.norm(s["angular_velocities"][k]) < 1e-2


def test_a_convex_brick_lies_still_on_the_ground_like_a_box():
    world = World()
    world.add_body({"name": "hull", "shape": "convex", "points": BRICK, "position": [0, 0, 0.1],
                    "rpy": [0, 0, 0.4], "allow_freezing": False})
    world.add_body({"name": "box", "size": [1.0, 0.5, 0.2], "position": [3, 0, 0.1],
                    "rpy": [0, 0, 0.4], "allow_freezing": False})
    world.step(3 * 128)
    s = world.state()
    assert np.linalg.norm(s["positions"][0] - [0, 0, 0.1]) < 0.005
    assert s["positions"][0, 2] == pytest.approx(s["positions"][1, 2], abs=1e-3)
    assert_at_rest(world, 0)
    # Resting on its face: four ground contacts at its bottom corners.
    contacts = world.contacts()
    bottom = contacts["points"][contacts["body_a"] == 0]
    assert len(bottom) == 4 and np.ptp(bottom[:, 0]) > 0.5


def test_a_convex_brick_sits_on_a_box():
    world = World()
    world.add_body({"name": "base", "size": [2.0, 2.0, 0.4], "position": [0, 0, 0.2]})
    world.add_body({"name": "hull", "shape": "convex", "points": BRICK,
                    "position": [0.2, -0.1, 0.5 + 0.05], "rpy": [0, 0, 0.7],
                    "allow_freezing": False})
    world.step(3 * 128)
    s = world.state()
    assert np.linalg.norm(s["positions"][1] - [0.2, -0.1, 0.5]) < 0.01
    assert_at_rest(world, 1)
    assert world_points(world, 1, BRICK)[:, 2].min() > 0.4 - 0.01


def test_a_convex_brick_sits_on_a_playground_across_its_seam():
    world = World(ground=None)
    world.set_playground(np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0.0]]),
                         np.array([[0, 1, 2], [0, 2, 3]]))  # the seam along the diagonal
    world.add_body({"name": "hull", "shape": "convex", "points": BRICK, "position": [0.1, 0, 0.15],
                    "rpy": [0, 0, 0.3], "allow_freezing": False})
    world.step(3 * 128)
    s = world.state()
    assert np.linalg.norm(s["positions"][0] - [0.1, 0, 0.1]) < 0.005
    assert_at_rest(world, 0)


def test_convex_bricks_stand_stacked():
    # Hull on hull: no shrunk copies, so their resting overlap goes through EPA every step.
    world = World()
    for k in range(3):
        world.add_body({"name": f"h{k}", "shape": "convex", "points": BRICK,
                        "position": [0.02 * k, 0, 0.1 + 0.2 * k], "rpy": [0, 0, 0.2 * k],
                        "allow_freezing": False})
    world.step(4 * 128)
    s = world.state()
    for k in range(3):
        assert np.linalg.norm(s["positions"][k] - [0.02 * k, 0, 0.1 + 0.2 * k]) < 0.01
        assert_at_rest(world, k)


@pytest.mark.parametrize("rpy", [[0.3, 0.5, 0.1], [2.5, -0.4, 1.0], [math.pi, 0.2, 0.0]])
def test_a_dropped_tetrahedron_comes_to_rest_on_a_face(rpy):
    world = World()
    world.add_body({"name": "t", "shape": "convex", "points": TETRAHEDRON, "position": [0, 0, 0.6],
                    "rpy": rpy, "elasticity": 0.2})
    for _ in range(5 * 16):
        world.step(8)
        corners = world_points(world, 0, world.body("t")["points"])
        assert corners[:, 2].min() > -0.01  # never sunk more than a centimetre
    corners = world_points(world, 0, world.body("t")["points"])
    heights = np.sort(corners[:, 2])
    assert np.all(np.abs(heights[:3]) < 0.005) and heights[3] > 0.2  # three corners down
    # Its centre of mass stands above that face by the face's distance from it.
    base = corners[np.argsort(corners[:, 2])[:3]]
    normal = np.cross(base[1] - base[0], base[2] - base[0])
    normal /= np.linalg.norm(normal)
    distance = abs(np.dot(world.state()["positions"][0] - base[0], normal))
    assert world.state()["positions"][0, 2] == pytest.approx(distance, abs=0.005)
    assert_at_rest(world, 0)


def test_a_mixed_pile_with_convex_bodies_comes_to_rest():
    octahedron = [[0.3, 0, 0], [-0.3, 0, 0], [0, 0.3, 0], [0, -0.3, 0], [0, 0, 0.3], [0, 0, -0.3]]
    kinds = MIXED + [{"shape": "convex", "points": (np.array(BRICK) * 0.6).tolist()},
                     {"shape": "convex", "points": TETRAHEDRON},
                     {"shape": "convex", "points": octahedron}]
    count = 42
    world = mixed_pile(count, kinds=kinds)
    start, worst_gain, deepest = settle(world)
    s = world.state()
    assert all(np.isfinite(s[key]).all() for key in ("positions", "quaternions", "linear_velocities",
                                                     "angular_velocities"))
    assert worst_gain <= 1e-9 * abs(start)
    assert deepest < 0.03
    kinetic, potential = energies(world)
    assert kinetic < 1e-3 * (start - potential)
    # The convex bodies are still (what moves at the end is a ball rolling in the pen).
    convex = [k for k in range(count) if k % len(kinds) >= len(MIXED)]
    assert np.abs(s["linear_velocities"][convex]).max() < 0.01
    others = [k for k in range(count) if k not in convex]
    assert s["positions"][others, 2].min() > 0.1  # nothing sank through the ground
    for k in convex:
        assert world_points(world, k, world.body(f"b{k}")["points"])[:, 2].min() > -0.01


@pytest.mark.parametrize("gap", [0.5, 0.49, 0.51])
def test_a_head_on_elastic_hit_is_square_whatever_the_gap(gap):
    """A cylinder flying cap-first into a standing one, e = 1, no gravity: they swap velocities
    with no spin. At a gap of exactly 0.5 m the two points of the contact had equal depth, v dt,
    rounding let one bounce and not the other, and the hitter left at 0.33 m/s, spinning."""
    world = World({"gravity": [0, 0, 0], "freezing": {"enabled": False}}, ground=None)
    world.add_body({"shape": "cylinder", "radius": 0.25, "length": 0.5, "rpy": [0, math.pi / 2, 0], "name": "a",
                    "position": [-gap, 0, 0], "mass": 1.0, "elasticity": 1.0, "linear_velocity": [2, 0, 0]})
    world.add_body({"shape": "cylinder", "radius": 0.25, "length": 0.5, "name": "b", "position": [0.5, 0, 0],
                    "mass": 1.0, "elasticity": 1.0})
    world.step(128)
    s = world.state()
    assert s["linear_velocities"][0] == pytest.approx([0, 0, 0], abs=0.02)
    assert s["linear_velocities"][1] == pytest.approx([2, 0, 0], abs=0.02)
    assert np.abs(s["angular_velocities"]).max() < 0.02
