"""Compound bodies (issue 38): several shapes at poses in one body's frame, against analytic
answers: mass, centre of mass and inertia summed exactly; resting, tipping and carrying as one
rigid body; rays; their scene keys and errors; drawing."""
import math
import re

import numpy as np
import pytest

from vplayground_ros.messages import shape_marker_layout, shape_marker_poses
from vplayground_ros.physics import World, shapes
from vplayground_ros.physics.step_context import newest_contacts
from vplayground_ros.scene import load_world, save_world

WEIGHTLESS = {"gravity": [0.0, 0.0, 0.0]}
TOP, LEG = [1.2, 0.8, 0.05], [0.05, 0.05, 0.7]
# A table with its frame on the floor between its legs: the top's underside 0.7 m up.
TABLE = {"shape": "compound", "density": 600.0, "parts": [
    {"size": TOP, "position": [0.0, 0.0, 0.725]},
    *({"size": LEG, "position": [x, y, 0.35]} for x in (-0.55, 0.55) for y in (-0.35, 0.35))]}


def spin_response(world, name, angular_impulse):
    """The angular velocity an angular impulse gives the body at rest: I^-1 L, world axes."""
    world.apply_impulse(name, angular_impulse=angular_impulse)
    world.step(1)
    return world.state()["angular_velocities"][world.body_names().index(name)]


def box_inertia(mass, size):
    a, b, c = size
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def test_two_cubes_side_by_side_weigh_and_turn_as_one_box_about_their_middle():
    """Two 1 kg unit cubes at x = 0.5 and 1.5 of a frame are a 2 x 1 x 1 box of 2 kg whose
    centre is 1 m along the frame's x: spun, the frame's origin circles that centre."""
    world = World(ground=None, settings=WEIGHTLESS)
    world.add_body({"name": "pair", "shape": "compound", "position": [1.0, 2.0, 3.0], "parts": [
        {"size": [1, 1, 1], "position": [0.5, 0, 0], "mass": 1.0},
        {"size": [1, 1, 1], "position": [1.5, 0, 0], "mass": 1.0}]})
    assert world.body("pair")["mass"] == 2.0
    assert world.body("pair")["position"] == [1.0, 2.0, 3.0]
    w = spin_response(world, "pair", [0.0, 0.0, 1.0])
    assert w == pytest.approx(np.linalg.solve(box_inertia(2.0, [2, 1, 1]), [0, 0, 1.0]), rel=1e-12, abs=1e-15)
    for _ in range(64):
        world.step(1)
        frame = world.state()["positions"][0]
        assert np.linalg.norm(frame - [2.0, 2.0, 3.0]) == pytest.approx(1.0, abs=1e-9)
    assert frame[1] != pytest.approx(2.0, abs=0.1)  # it has turned
    # the frame's origin, 1 m from the axis, moves at w x r
    assert np.linalg.norm(world.state()["linear_velocities"][0]) == pytest.approx(w[2] * 1.0, rel=1e-9)


def test_a_box_with_a_sphere_on_top_sums_its_inertia_about_their_common_centre():
    """A 6 kg unit cube at the frame's origin and a 2 kg sphere of radius 0.5 on it at z = 1.5:
    the centre of mass is 2 * 1.5 / 8 = 0.375 up, and each inertia is the parts' own plus the
    parallel axis terms about it."""
    world = World(ground=None, settings=WEIGHTLESS)
    world.add_body({"name": "b", "shape": "compound", "parts": [
        {"size": [1, 1, 1], "mass": 6.0},
        {"shape": "sphere", "radius": 0.5, "position": [0, 0, 1.5], "mass": 2.0}]})
    across = 6.0 * 2 / 12 + 6.0 * 0.375 ** 2 + 0.4 * 2.0 * 0.25 + 2.0 * 1.125 ** 2
    upright = 6.0 * 2 / 12 + 0.4 * 2.0 * 0.25
    assert spin_response(world, "b", [1.0, 0.0, 1.0]) == pytest.approx([1 / across, 0.0, 1 / upright], rel=1e-12)


def test_parts_turned_in_the_frame_turn_their_inertia_and_give_products_of_inertia():
    world = World(ground=None, settings=WEIGHTLESS)
    # A 1 x 2 x 3 box turned a quarter about z is a 2 x 1 x 3 box.
    world.add_body({"name": "turned", "shape": "compound", "parts": [
        {"size": [1, 2, 3], "rpy": [0, 0, math.pi / 2], "mass": 3.0}]})
    assert spin_response(world, "turned", [1.0, 1.0, 1.0]) == pytest.approx(
        np.linalg.solve(box_inertia(3.0, [2, 1, 3]), [1.0, 1.0, 1.0]), rel=1e-9)
    # Two small spheres on a diagonal of the xy plane: I_xy = -sum m x y, so an impulse about x
    # alone spins the body about y too, as I^-1 L says.
    world.add_body({"name": "diagonal", "shape": "compound", "position": [10, 0, 0], "parts": [
        {"shape": "sphere", "radius": 0.1, "position": [1, 1, 0], "mass": 1.0},
        {"shape": "sphere", "radius": 0.1, "position": [-1, -1, 0], "mass": 1.0}]})
    own = 0.4 * 0.01
    inertia = np.array([[2 + 2 * own, -2.0, 0], [-2.0, 2 + 2 * own, 0], [0, 0, 4 + 2 * own]])
    assert spin_response(world, "diagonal", [1.0, 0.0, 0.0]) == pytest.approx(
        np.linalg.solve(inertia, [1.0, 0, 0]), rel=1e-9)


def test_parts_take_their_own_mass_or_density_else_the_bodys():
    world = World(ground=None, settings=WEIGHTLESS)
    world.add_body({"name": "c", "shape": "compound", "density": 100.0, "parts": [
        {"size": [1, 1, 1]},                              # the body's 100 kg/m^3
        {"size": [1, 1, 1], "position": [2, 0, 0], "density": 300.0},
        {"shape": "sphere", "radius": 0.5, "position": [4, 0, 0], "mass": 7.0}]})
    body = world.body("c")
    assert [part["mass"] for part in body["parts"]] == [100.0, 300.0, 7.0]
    assert body["mass"] == 407.0
    # A body's mass scales the parts' shares: twice the mass, half the spin.
    world.add_body({"name": "heavy", "shape": "compound", "mass": 814.0, "position": [0, 10, 0],
                    "parts": body["parts"]})
    light = spin_response(world, "c", [0, 0, 1.0])
    assert spin_response(world, "heavy", [0, 0, 1.0]) == pytest.approx(0.5 * light, rel=1e-12)


def frame_heights(world, name, seconds):
    row = world.body_names().index(name)
    heights = []
    for _ in range(int(seconds * world.settings["steps_per_second"])):
        world.step(1)
        heights.append(world.state()["positions"][row, 2])
    return np.array(heights)


def test_a_table_stands_on_its_legs_without_sinking_and_freezes():
    world = World()
    world.add_body({**TABLE, "name": "table"})
    heights = frame_heights(world, "table", 3.0)
    assert np.abs(heights).max() < 1e-3
    assert world.state()["frozen"][0]
    assert world.body("table")["mass"] == pytest.approx(600.0 * (1.2 * 0.8 * 0.05 + 4 * 0.05 * 0.05 * 0.7))
    # Each leg is a manifold of its own with the ground, with a warm-start key of its own.
    world.wake_all()
    world.step(1)
    contacts = newest_contacts(world._contacts)
    m = int(contacts.manifold_count[0])
    keys = set(zip(contacts.manifold_a[:m].tolist(), contacts.manifold_b[:m].tolist()))
    assert m == 4 and len(keys) == 4


def test_a_table_stands_on_a_playground_across_its_seam():
    world = World(ground=None)
    world.set_playground(np.array([[-4.0, -4.0, 0.0], [4.0, -4.0, 0.0], [4.0, 4.0, 0.0], [-4.0, 4.0, 0.0]]),
                         np.array([[0, 1, 2], [0, 2, 3]]))  # the diagonal seam runs under the table
    world.add_body({**TABLE, "name": "table", "rpy": [0, 0, 0.3]})
    heights = frame_heights(world, "table", 3.0)
    assert np.abs(heights).max() < 1e-3
    assert world.state()["frozen"][0]


def test_a_box_dropped_on_the_table_rests_on_its_top_not_in_it():
    world = World()
    world.add_body({**TABLE, "name": "table"})
    world.add_body({"name": "box", "size": [0.3, 0.3, 0.3], "position": [0.2, 0.1, 1.3]})
    frame_heights(world, "table", 4.0)
    s = world.state()
    assert s["positions"][0] == pytest.approx([0, 0, 0], abs=1e-3)
    assert s["positions"][1, 2] == pytest.approx(0.75 + 0.15, abs=3e-3)  # on the top, 0.75 m up
    assert s["frozen"].all()


@pytest.mark.parametrize("arm_height, tips", [(0.05, False), (0.95, True)])
def test_an_l_tips_over_when_its_centre_of_mass_is_beyond_its_foot(arm_height, tips):
    """A 1 m post on a 0.1 m square foot with a 1 m arm reaching out from it, at its foot (an
    L, lying on the arm: its centre of mass over the arm) or at its top (a gallows standing on
    the post alone, its centre of mass 0.3 m beside its foot)."""
    world = World()
    world.add_body({"name": "l", "shape": "compound", "parts": [
        {"size": [0.1, 0.1, 1.0], "position": [0, 0, 0.5]},
        {"size": [1.0, 0.1, 0.1], "position": [0.55, 0, arm_height]}]})
    frame_heights(world, "l", 2.0)
    s = world.state()
    upright = abs(s["quaternions"][0, 3])  # cos of half the angle turned
    if tips:
        assert upright < math.cos(0.5 * 0.5)  # fallen by more than half a radian
    else:
        assert upright > math.cos(0.5 * 1e-3) and s["frozen"][0]


def test_rays_hit_an_offset_part_at_its_surface():
    world = World(ground=None, settings=WEIGHTLESS)
    # A sphere 2 m along the frame's x, the frame turned a quarter about z: the sphere is at
    # (0, 2, 1) in the world; the frame's origin holds only a small cube.
    world.add_body({"name": "c", "shape": "compound", "position": [0, 0, 1], "rpy": [0, 0, math.pi / 2],
                    "parts": [{"size": [0.1, 0.1, 0.1]}, {"shape": "sphere", "radius": 0.3, "position": [2, 0, 0]}]})
    hits = world.cast_rays(np.array([[0, 5, 1.0], [5, 0, 1.0], [0, 2.2, 5.0]]),
                           np.array([[0, -1, 0], [-1, 0, 0], [0, 0, -1.0]]), 10.0)
    assert hits.distance[0] == pytest.approx(5 - 2 - 0.3, abs=1e-12)
    assert hits.normal[0] == pytest.approx([0, 1, 0], abs=1e-12) and hits.body[0] == 0
    assert hits.distance[1] == pytest.approx(5 - 0.05, abs=1e-12)  # the cube; the sphere is not on x
    assert hits.distance[2] == pytest.approx(4 - math.sqrt(0.09 - 0.04), abs=1e-12)


def test_a_car_stands_on_a_compound_platform_through_its_wheel_rays():
    world = World()
    world.add_body({"name": "deck", "shape": "compound", "immovable": True, "parts": [
        {"size": [3, 2, 0.2], "position": [0, 0, 0.5]}, {"size": [3, 2, 0.2], "position": [3, 0, 0.5]}]})
    bare = World()
    for w in (world, bare):
        w.add_vehicle({"name": "car", "position": [1.5, 0, 1.6],
                       "chassis": {"size": [2.0, 1.0, 0.4], "mass": 400.0},
                       "wheels": [{"mount": [x, y, -0.2], "radius": 0.25} for x in (0.7, -0.7) for y in (0.5, -0.5)]})
    for w in (world, bare):
        w.step(3 * 128)
    # On the deck, whose top is 0.6 m up, it stands 0.6 m higher than on the ground.
    height = world.state()["positions"][1, 2] - bare.state()["positions"][0, 2]
    assert height == pytest.approx(0.6, abs=2e-3)


def test_scene_round_trip_keeps_the_frame_the_parts_and_the_masses(tmp_path):
    world = World()
    world.add_body({**TABLE, "name": "table", "position": [1.0, 2.0, 0.0], "rpy": [0, 0, 0.4],
                    "static_friction": 0.9})
    world.add_body({"name": "gem", "shape": "compound", "mass": 5.0, "position": [0, 0, 3], "parts": [
        {"shape": "convex", "points": [[x, y, z] for x in (0, 0.4) for y in (0, 0.3) for z in (0, 0.2)],
         "position": [0.1, 0, 0], "rpy": [0.3, 0, 0]},
        {"shape": "capsule", "radius": 0.1, "length": 0.5, "position": [0, 0.5, 0], "quaternion": [0, 0, 0, 1]},
        {"shape": "cylinder", "radius": 0.2, "length": 0.1, "position": [0, -0.5, 0], "density": 50}]})
    world.step(40)
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    for name in ("table", "gem"):
        before, after = world.body(name), again.body(name)
        assert after["parts"] == before["parts"] and after["mass"] == before["mass"]
        assert after["position"] == pytest.approx(before["position"], abs=1e-12)
        assert after["quaternion"] == before["quaternion"]
        assert after["linear_velocity"] == pytest.approx(before["linear_velocity"], abs=1e-12)
    assert again.body("table")["static_friction"] == 0.9
    assert np.array_equal(again._bodies.inv_inertia[:2], world._bodies.inv_inertia[:2])


def test_results_are_bit_identical_run_to_run():
    def run():
        world = World()
        world.add_body({**TABLE, "name": "table", "position": [0, 0, 0.3], "rpy": [0.1, 0.05, 0.3]})
        world.add_body({"name": "box", "size": [0.3, 0.3, 0.3], "position": [0.2, 0.1, 1.5]})
        world.add_body({"name": "ball", "shape": "sphere", "radius": 0.2, "position": [-0.3, 0.1, 2.0]})
        world.step(256)
        return world.state()
    first, second = run(), run()
    for key in ("positions", "quaternions", "linear_velocities", "angular_velocities"):
        assert first[key].tobytes() == second[key].tobytes()


def test_a_convex_part_takes_its_points_from_a_mesh(tmp_path):
    (tmp_path / "wedge.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    (tmp_path / "scene.yaml").write_text(
        "version: 1\nbodies:\n  - {name: c, shape: compound, parts: [{size: [1, 1, 1]}, "
        "{shape: convex, mesh: wedge.obj, position: [2, 0, 0]}]}\n")
    part = load_world(tmp_path / "scene.yaml").body("c")["parts"][1]
    assert "mesh" not in part and sorted(map(tuple, part["points"])) == [(0, 0, 0), (0, 0, 1), (0, 1, 0), (1, 0, 0)]
    with pytest.raises(ValueError, match=re.escape("bodies[0].parts[0].mesh: only a convex body takes a mesh")):
        load_world({"version": 1, "bodies": [{"shape": "compound", "parts": [{"mesh": "wedge.obj"}]}]})


@pytest.mark.parametrize("parts, problem", [
    ("a box", "bodies[1].parts: expected a list of 1 to 64 parts"),
    ([], "bodies[1].parts: expected a list of 1 to 64 parts"),
    ([{"size": [1, 1, 1]}, {"shape": "sphere", "size": [1, 1, 1]}],
     "bodies[1].parts[1].size: a sphere has no size (its keys: radius)"),
    ([{"size": [1, 1, -1]}], "bodies[1].parts[0].size[2]: must be >= 0.001, got -1"),
    ([{"shape": "compound", "parts": [{}]}], "bodies[1].parts[0].parts: unknown key"),
    ([{"shape": "compound"}], "bodies[1].parts[0].shape: a part is one shape"),
    ([{"size": [1, 1, 1], "colour": "red"}], "bodies[1].parts[0].colour: unknown key"),
    ([{"size": [1, 1, 1], "position": [0, 0, 1e5]}], "bodies[1].parts[0].position[2]: must be <= 10000"),
    ([{"shape": "convex"}], "bodies[1].parts[0].points: missing"),
    ([{"size": [1, 1, 1], "rpy": [0, 0, 0], "quaternion": [0, 0, 0, 1]}],
     "bodies[1].parts[0]: give either rpy or quaternion, not both"),
    ([{"size": [1, 1, 1], "mass": 0}], "bodies[1].parts[0].mass: must be >= 1e-09"),
])
def test_bad_parts_are_refused_naming_the_key(parts, problem):
    scene = {"version": 1, "bodies": [{"name": "fine"}, {"name": "c", "shape": "compound", "parts": parts}]}
    with pytest.raises(ValueError, match=re.escape(problem)):
        load_world(scene)


def test_a_compound_needs_parts_and_its_own_keys():
    world = World()
    with pytest.raises(ValueError, match=re.escape("body.parts: missing")):
        world.add_body({"shape": "compound"})
    with pytest.raises(ValueError, match=re.escape("body.size: a compound has no size (its keys: parts, inertial)")):
        world.add_body({"shape": "compound", "size": [1, 1, 1], "parts": [{}]})
    assert world.body_names() == []


def test_editing_a_compound_keeps_its_frame_where_it_is():
    world = World(ground=None, settings=WEIGHTLESS)
    world.add_body({"name": "c", "shape": "compound", "position": [1, 0, 0], "parts": [
        {"size": [1, 1, 1], "mass": 1.0}, {"size": [1, 1, 1], "position": [2, 0, 0], "mass": 1.0}]})
    world.edit_body("c", rpy=[0, 0, math.pi / 2])
    assert world.body("c")["position"] == pytest.approx([1, 0, 0], abs=1e-12)
    world.edit_body("c", parts=[{"size": [1, 1, 1], "mass": 1.0}, {"size": [1, 1, 1], "position": [4, 0, 0], "mass": 3.0}])
    assert world.body("c")["position"] == pytest.approx([1, 0, 0], abs=1e-12)
    world.edit_body("c", position=[0, 0, 5])
    hits = world.cast_rays(np.array([[0, 10, 5.0]]), np.array([[0, -1, 0.0]]), 20.0)
    assert hits.distance[0] == pytest.approx(10 - 4.5, abs=1e-12)  # the far cube's face at y = 4.5
    # Set spinning, it turns about its frame's origin, which a linear velocity would move.
    world.edit_body("c", angular_velocity=[0, 0, 2.0])
    assert world.body("c")["linear_velocity"] == pytest.approx([0, 0, 0], abs=1e-12)
    world.step(1)  # (the centre of mass steps along its circle's tangent: (w dt)^2 r / 2 = 4e-4 m off it)
    assert world.body("c")["position"] == pytest.approx([0, 0, 5], abs=1e-3)  # not the w r dt = 0.05 m a still centre gives


def test_a_compound_is_drawn_as_its_parts_on_its_frame():
    world = World()
    world.add_body({"name": "b", "size": [1, 1, 1], "position": [5, 0, 1]})
    world.add_body({"name": "c", "shape": "compound", "position": [0, 0, 1], "rpy": [0, 0, math.pi / 2], "parts": [
        {"size": [0.4, 0.2, 0.1], "position": [1, 0, 0]},
        {"shape": "capsule", "radius": 0.1, "length": 0.6, "position": [0, 0, 0.5]},
        {"shape": "convex", "points": [[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.3]], "position": [-1, 0, 0]}]})
    props, motion = world.body_properties(), world.motion_state()
    layout = shape_marker_layout(props["shapes"], props["dimensions"], np.array([7, 8]), world.hull_triangles(),
                                 world.compound_parts())
    poses = shape_marker_poses(layout, np.concatenate([motion["positions"], motion["quaternions"]], axis=1))
    # the box, the parts (CUBE, CYLINDER, TRIANGLE_LIST), the capsule part's two end spheres
    assert list(layout.types) == [1, 1, 3, 11, 2, 2] and list(layout.rows) == [0, 1, 1, 1, 1, 1]
    assert len(set(layout.ids.tolist())) == 6 and (layout.ids[1:] & 0x7FFFFF == 8).all()
    assert layout.scales[1].tolist() == pytest.approx([0.4, 0.2, 0.1])
    assert poses[1, :3] == pytest.approx([0, 1, 1], abs=1e-12)     # 1 m along the turned x
    assert poses[2, :3] == pytest.approx([0, 0, 1.5], abs=1e-12)
    assert poses[4, :3] == pytest.approx([0, 0, 1.8], abs=1e-12)   # the capsule's upper end
    assert layout.points[3].shape == (12, 3) and layout.points[1] is None
    # the hull's points about its centre, 1 m along the frame's -x: (0, -1, 1) in the world
    hull_centre = np.array([0.075, 0.075, 0.075])
    assert poses[3, :3] == pytest.approx([-hull_centre[1], -1 + hull_centre[0], 1 + hull_centre[2]], abs=1e-12)


def test_a_compound_is_bounded_by_a_box_about_its_frame():
    """~/get_entities' box (bounds.size) is centred on an entity's pose: a compound's holds its
    parts however it turns about its frame. Its corners (bounds.low, high: GetEntityBounds')
    are where the parts are in that frame."""
    from vplayground_ros.api.descriptions import describe
    world = World(ground=None, settings=WEIGHTLESS)
    world.add_body({"name": "pair", "shape": "compound", "parts": [
        {"size": [1, 1, 1], "position": [0.5, 0, 0]}, {"size": [1, 1, 1], "position": [1.5, 0, 0]}]})
    # the parts span x = 0..2 about a centre of mass at x = 1: 1 m either side of it, 2 of the frame
    bounds = describe(world, "pair")["bounds"]
    assert bounds["size"] == pytest.approx([4, 1, 1])
    assert bounds["low"] == pytest.approx([0, -0.5, -0.5]) and bounds["high"] == pytest.approx([2, 0.5, 0.5])
    assert world.body_properties()["sizes"][0] == pytest.approx([4, 1, 1])
