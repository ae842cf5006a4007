"""Scene files with a playground and vehicles: loading, validation errors, round trips."""
import copy
import logging

import numpy as np
import pytest

from vplayground_ros.scene import SceneError, load_world, save_world

WHEEL = {"mount": [1.3, 0.8, -0.3], "radius": 0.35, "mass": 20, "power_gain": 0.5, "steered": True,
         "spring_stiffness": 40000, "damper": 4000, "spring_length": 0.5,
         "static_friction": 1.0, "dynamic_friction": 0.8}
SCENE = {
    "version": 1,
    "settings": {"octree_depth": 6},
    "playground": {"mesh": "playground.obj", "position": [1.0, 2.0, 0.0], "rpy": [0, 0, 0.5], "scale": 1.5},
    "bodies": [{"name": "crate", "size": [1, 1, 1], "position": [0, 0, 3], "linear_velocity": [1, 0, 0]}],
    "vehicles": [{"name": "car", "position": [5, -9, 1], "rpy": [0, 0, 0.2],
                  "chassis": {"size": [4.0, 1.8, 0.6], "mass": 1200},
                  "engine_power": 6000, "brake_power": 9000, "max_steer": 0.6,
                  "wheels": [dict(WHEEL), dict(WHEEL), dict(WHEEL), dict(WHEEL)]}],
}


def write_obj(path, text):
    path.write_text(text)
    return path


def test_playground_is_placed_scaled_and_turned():
    world = load_world(SCENE)
    reference = load_world({"version": 1, "playground": {"mesh": "playground.obj"}})
    c, s = np.cos(0.5), np.sin(0.5)
    rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    expected = 1.5 * reference.playground_triangles @ rotation.T + [1.0, 2.0, 0.0]
    assert np.allclose(world.playground_triangles, expected)


def test_round_trip_with_playground_and_vehicle(tmp_path):
    world = load_world(SCENE)
    world.step(40)
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    assert again.body_names() == world.body_names()
    assert again.vehicle_names() == ["car"]
    assert again.vehicle("car") == world.vehicle("car")
    for name in world.body_names():
        assert again.body(name) == world.body(name)
    assert np.array_equal(again.playground_triangles, world.playground_triangles)
    assert again.playground_spec["mesh"] == world.playground_spec["mesh"]
    world.step(30)
    again.step(30)
    assert np.allclose(again.state()["positions"], world.state()["positions"], atol=1e-9)


def test_a_saved_scene_with_a_vehicle_saved_again_is_the_same_file(tmp_path):
    """The vehicle's keys in one order whatever its spec gave: its pose and velocities were
    written where the loaded spec had them, so the first save of a saved scene moved its
    quaternion (and every save of the default scene's car) and the files differed."""
    world = load_world(SCENE)
    world.step(10)
    save_world(world, tmp_path / "first.yaml")
    save_world(load_world(tmp_path / "first.yaml"), tmp_path / "second.yaml")
    assert (tmp_path / "second.yaml").read_text() == (tmp_path / "first.yaml").read_text()


def test_mesh_is_found_next_to_the_scene_file_first(tmp_path):
    write_obj(tmp_path / "tile.obj", "v 0 0 0\nv 4 0 0\nv 0 4 0\nf 1 2 3\n")
    (tmp_path / "scene.yaml").write_text("version: 1\nplayground: {mesh: tile.obj}\n")
    world = load_world(tmp_path / "scene.yaml")
    assert len(world.playground_triangles) == 1


def test_a_saved_scene_keeps_the_packages_mesh_beside_another_of_its_name(tmp_path):
    """A saved scene names the package's mesh as package://vplayground_ros/meshes/<file>: as a
    bare name, a file of that name beside the saved scene was taken instead on reloading."""
    write_obj(tmp_path / "playground.obj", "v 0 0 0\nv 4 0 0\nv 0 4 0\nf 1 2 3\n")
    world = load_world(SCENE)
    save_world(world, tmp_path / "saved.yaml")
    assert "mesh: package://vplayground_ros/meshes/playground.obj" in (tmp_path / "saved.yaml").read_text()
    again = load_world(tmp_path / "saved.yaml")
    assert np.array_equal(again.playground_triangles, world.playground_triangles)
    with pytest.raises(SceneError, match="the package has no mesh 'nothing.obj'"):
        load_world({"version": 1, "playground": {"mesh": "package://vplayground_ros/meshes/nothing.obj"}})
    with pytest.raises(SceneError, match="package:// names only this package's meshes"):
        load_world({"version": 1, "playground": {"mesh": "package://other_pkg/meshes/playground.obj"}})
    with pytest.raises(SceneError, match="the package has no mesh '../config/default_scene.yaml'"):
        load_world({"version": 1, "playground": {"mesh": "package://vplayground_ros/meshes/../config/default_scene.yaml"}})


def test_a_scene_saved_by_the_node_reloads_with_a_mesh_beside_its_start_scene(tmp_path, monkeypatch):
    """The node started with --scene elsewhere (its mesh beside it), saves to its working
    directory and loads that again: the saved file names the mesh by its path, which lies in
    the start scene's folder, so that folder is a scene directory (it was refused)."""
    from vplayground_ros.api import MAP_SUCCESS
    from vplayground_ros.cli import parse_args
    from vplayground_ros.runtime import Runtime
    from vplayground_ros.simulation import Simulation

    elsewhere, work = tmp_path / "scenes", tmp_path / "work"
    elsewhere.mkdir()
    work.mkdir()
    write_obj(elsewhere / "tile.obj", "v -9 -9 0\nv 9 -9 0\nv 0 9 0\nf 1 2 3\n")
    (elsewhere / "start.yaml").write_text("version: 1\nplayground: {mesh: tile.obj}\nbodies: [{name: crate}]\n")
    monkeypatch.chdir(work)
    options = parse_args(["--scene", str(elsewhere / "start.yaml"), "--no-record"])
    runtime = Runtime(Simulation(load_world(options.scene)), options, logging.getLogger("test_scene"))
    assert runtime.requests.save_scene("saved.yaml")[0]
    assert runtime.requests.load_scene("saved.yaml")[0] == MAP_SUCCESS


def test_degenerate_triangles_are_dropped_with_a_warning(tmp_path, caplog):
    write_obj(tmp_path / "tiles.obj", "v 0 0 0\nv 4 0 0\nv 0 4 0\nv 8 0 0\n"
                                      "f 1 2 3\nf 1 2 4\nf 1 1 3\n")
    with caplog.at_level(logging.WARNING):
        world = load_world({"version": 1, "playground": {"mesh": str(tmp_path / "tiles.obj")}})
    assert len(world.playground_triangles) == 1
    assert "dropped 2 degenerate triangles" in caplog.text


def broken(mutate):
    scene = copy.deepcopy(SCENE)
    mutate(scene)
    with pytest.raises(SceneError) as error:
        load_world(scene)
    return str(error.value)


@pytest.mark.parametrize("mutate, fragment", [
    (lambda s: s["playground"].update(mesh="nowhere.obj"), "playground.mesh: mesh file 'nowhere.obj' not found"),
    (lambda s: s["playground"].pop("mesh"), "playground.mesh: missing"),
    (lambda s: s["playground"].update(scale=0), "playground.scale: must be > 0"),
    (lambda s: s["playground"].update(rpy=[0, "x", 0]), "playground.rpy[1]: expected a number"),
    (lambda s: s["playground"].update(colour="red"), "playground.colour: unknown key"),
    (lambda s: s["vehicles"][0].pop("chassis"), "vehicles[0].chassis: missing"),
    (lambda s: s["vehicles"][0]["chassis"].update(mass=-5), "vehicles[0].chassis.mass: must be >= 1e-09"),
    (lambda s: s["vehicles"][0]["wheels"].pop(), "vehicles[0].wheels: expected 4 wheels"),
    (lambda s: s["vehicles"][0]["wheels"][2].update(radius=0), "vehicles[0].wheels[2].radius: must be >= 0.0005"),
    (lambda s: s["vehicles"][0]["wheels"][1].update(steered="yes"), "vehicles[0].wheels[1].steered: expected true or false"),
    (lambda s: s["vehicles"][0]["wheels"][3].pop("mount"), "vehicles[0].wheels[3].mount: missing"),
    (lambda s: s["vehicles"][0]["wheels"][0].update(static_friction=50), "vehicles[0].wheels[0].static_friction: must be <= 10"),
    (lambda s: s["vehicles"][0].update(max_steer=float("nan")), "vehicles[0].max_steer: must be finite"),
    (lambda s: s["vehicles"][0].update(name="crate"), "vehicles[0].name: duplicate name 'crate'"),
    (lambda s: s["vehicles"][0].update(turbo=True), "vehicles[0].turbo: unknown key"),
])
def test_playground_and_vehicle_errors_name_the_key(mutate, fragment):
    assert fragment in broken(mutate)


@pytest.mark.parametrize("text, fragment", [
    ("this is not a mesh\n", "line 1: unknown statement 'this'"),
    ("v 0 0 0\nv 1 0 0\n", "no triangles"),
    ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "line 2: 'nan' is not a finite number"),
])
def test_bad_mesh_files_are_refused_with_the_file_named(tmp_path, text, fragment):
    mesh = write_obj(tmp_path / "bad.obj", text)
    message = broken(lambda s: s["playground"].update(mesh=str(mesh)))
    assert "playground.mesh" in message and fragment in message


def test_explicit_names_win_over_generated_ones_wherever_they_stand(tmp_path):
    """Unnamed entries get the World's box_<n> / car_<n> names, skipping every name the file
    gives, even one given further down; the file's order is kept and survives a round trip."""
    vehicle = copy.deepcopy(SCENE["vehicles"][0])
    del vehicle["name"]
    world = load_world({"version": 1, "bodies": [{"position": [0, 0, 1]}, {"name": "box_1", "position": [3, 0, 1]},
                                                 {"position": [6, 0, 1]}, {"name": "car_4", "position": [9, 0, 1]}],
                        "vehicles": [vehicle]})
    assert world.body_names() == ["box_2", "box_1", "box_3", "car_4", "car_5"]
    assert world.vehicle_names() == ["car_5"]
    save_world(world, tmp_path / "saved.yaml")
    assert load_world(tmp_path / "saved.yaml").body_names() == world.body_names()
    # Without explicit names the generated ones are as before.
    unnamed = load_world({"version": 1, "bodies": [{"position": [0, 0, 1]}], "vehicles": [vehicle]})
    assert unnamed.body_names() == ["box_1", "car_2"]


@pytest.mark.parametrize("key, value, found", [
    ("bodies", False, "bool"), ("bodies", 0, "int"), ("bodies", {}, "dict"), ("bodies", "", "str"),
    ("vehicles", "", "str"), ("vehicles", {"name": "car"}, "dict"),
])
def test_top_level_lists_of_the_wrong_type_are_refused(key, value, found):
    message = broken(lambda s: s.update({key: value}))
    assert f"<scene>: {key}: expected a list, got {found}" in message


def test_missing_or_null_top_level_lists_are_empty():
    assert load_world({"version": 1, "bodies": None, "vehicles": None}).body_names() == []
    assert load_world({"version": 1}).body_names() == []


@pytest.mark.parametrize("scene, message", [
    ({"bodies": [{}, {"position": [5000.0, 0.0, 1.0]}]}, "<scene>: bodies[1].position: "),
    ({"vehicles": [{**SCENE["vehicles"][0], "position": [0.0, 5000.0, 1.0]}]}, "<scene>: vehicles[0].position: "),
    ({"bodies": [{"shape": "convex", "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}]},
     "<scene>: bodies[0].points: the points are flat"),
])
def test_errors_found_while_building_the_world_name_the_scenes_key(scene, message):
    """They read `bodies[0]: body.points: ...` and `vehicles[0]: body.position: ...`."""
    with pytest.raises(SceneError) as error:
        load_world({"version": 1, **scene})
    assert str(error.value).startswith(message), str(error.value)


def test_numbers_in_exponent_form_are_numbers(tmp_path):
    """`mass: 1e4` is a number in YAML 1.2 and JSON; PyYAML's 1.1 made it the string '1e4', and
    the scene was refused with "expected a number, got str"."""
    path = tmp_path / "exponents.yaml"
    path.write_text("version: 1\nbodies:\n  - {name: heavy, mass: 1e4, size: [2E0, 1e0, 5e-1], position: [0, 0, 1]}\n")
    world = load_world(path)
    assert world.body("heavy")["mass"] == 1e4 and world.body("heavy")["size"] == [2.0, 1.0, 0.5]


@pytest.mark.parametrize("text, fragment", [
    ("version: 1\nbodies:\n  - &a {shape: compound, parts: [*a]}\n", "an alias is inside the node it names"),
    ("version: 1\nbodies:\n  - &b {name: b}\n" + "  - *b\n" * 100 + "x: &l [" + "0, " * 5000 + "0]\ny: [" +
     ", ".join(["*l"] * 200) + "]\n", "its aliases expand its [0-9,]+ characters to more than"),
])
def test_yaml_aliases_that_build_more_than_the_text_are_refused(tmp_path, text, fragment):
    """A scene's size limit bounds its work only while the text is what it holds: aliases may
    repeat what is written (a material, a size), not multiply it (a thousand-value list
    repeated 200 times), nor put a node inside itself (a compound that is its own part
    recursed without end)."""
    path = tmp_path / "aliases.yaml"
    path.write_text(text)
    with pytest.raises(SceneError, match=f"aliases.yaml: not valid YAML: {fragment}"):
        load_world(path)


def test_a_key_given_twice_is_refused_and_merge_keys_still_merge(tmp_path):
    """YAML keeps the last of a key given twice: a scene with two `bodies:` lists had lost the
    first without a word."""
    path = tmp_path / "twice.yaml"
    path.write_text("version: 1\nbodies: [{name: a}]\nbodies: [{name: b, position: [3, 0, 0.5]}]\n")
    with pytest.raises(SceneError, match="twice.yaml: not valid YAML: the key 'bodies' is given twice in one mapping"):
        load_world(path)
    path.write_text("version: 1\nbodies:\n  - &crate {name: a, size: [1, 1, 1], mass: 2}\n"
                    "  - {<<: *crate, name: b, position: [3, 0, 0.5]}\n")
    world = load_world(path)
    assert world.body("b")["mass"] == 2.0 and world.body("b")["position"] == [3.0, 0.0, 0.5]
