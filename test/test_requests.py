"""The SPEC 6.3 request handlers, ROS-free (the node and the Foxglove server share them)."""
import json
import re
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from numba.core.compiler_lock import global_compiler_lock

from vplayground_ros.api import (INVALID_MAP_DATA, MAP_DOES_NOT_EXIST, MAP_SUCCESS, Requests)
from vplayground_ros.api.entity_queries import BOUNDS_BOX, OBJECT, ROBOT, category_of
from vplayground_ros.broadcast import TOPICS
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import NO_WORLD, PAUSED, PLAYING, STOPPED, Simulation
from helpers import SPEC_CAR

SCENE = {"version": 1, "bodies": [{"name": "a", "position": [0, 0, 0.5]},
                                  {"name": "b", "position": [3, 0, 0.5]}]}


@pytest.fixture
def requests():
    return Requests(Simulation(load_world(SCENE)))


def snapshot(world):
    return world.body_names(), {k: v.copy() for k, v in world.state().items()}


def unchanged(requests, before):
    names, state = snapshot(requests.sim.world)
    return names == before[0] and all(np.array_equal(state[k], before[1][k]) for k in state)


def test_spawn_one_and_a_list_all_or_nothing(requests):
    ok, message = requests.spawn("{name: c, size: [1, 1, 1], position: [0, 3, 2]}")
    assert ok and message == "RESULT_OK: c"
    before = snapshot(requests.sim.world)
    ok, message = requests.spawn("[{name: d}, {name: e, size: [1, -1, 1]}]")
    assert not ok and message.startswith("RESULT_OPERATION_FAILED: [1].size[1]: must be >= 0.001")
    assert unchanged(requests, before)
    ok, message = requests.spawn("[{name: d}, {name: e, initial_pose: {position: {x: 1, y: 2, z: 3}}}]")
    assert ok and message == "RESULT_OK: d, e"
    assert requests.sim.world.body("e")["position"] == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("payload, code", [
    ("{name: a}", "NAME_NOT_UNIQUE:"),
    ("{name: 'bad name!'}", "NAME_INVALID:"),
    ("{size: [1, 1", "RESULT_OPERATION_FAILED: request is not valid YAML/JSON"),
    ("[]", "RESULT_OPERATION_FAILED: nothing to spawn"),
    ("42", "RESULT_OPERATION_FAILED: spawn must be a mapping"),
    ("{mass: .nan}", "RESULT_OPERATION_FAILED: spawn.mass: must be finite"),
    ("{wheels: []}", "RESULT_OPERATION_FAILED: spawn.chassis: missing"),
    # Aliases that multiply the text (a 10,000-point hull repeated by 400 bodies: 40 KB of text,
    # 4 million values), or a compound that contains itself.
    ("- &b {shape: convex, position: [0, 0, 5], points: &p [" + ", ".join(["[0, 0, 0], [1, 0, 0], [0, 1, 0]"] * 3333)
     + ", [0, 0, 1]]}\n" + "- {shape: convex, position: [0, 0, 5], points: *p}\n" * 400,
     "RESULT_OPERATION_FAILED: request is not valid YAML/JSON: its aliases expand its 130,455 characters to more than"),
    ("&a {shape: compound, parts: [*a]}",
     "RESULT_OPERATION_FAILED: request is not valid YAML/JSON: an alias is inside the node it names"),
])
def test_bad_spawns_are_coded_and_change_nothing(requests, payload, code):
    before = snapshot(requests.sim.world)
    ok, message = requests.spawn(payload)
    assert not ok and message.startswith(code), message
    assert unchanged(requests, before)


def test_aliases_that_do_not_multiply_the_text_are_yaml_as_usual(requests):
    ok, message = requests.spawn("[{name: d, size: &s [1, 2, 1], static_friction: &f 0.9},"
                                 " {name: e, size: *s, static_friction: *f, position: [0, 5, 1]}]")
    assert ok, message
    assert requests.sim.world.body("e")["size"] == [1.0, 2.0, 1.0]


def test_spawn_with_renaming(requests):
    ok, message = requests.spawn("{name: a, allow_renaming: true}")
    assert ok and message == "RESULT_OK: a_2"


def test_edit_pose_twist_and_properties(requests):
    ok, message = requests.edit(yaml.safe_dump({
        "entity": "a", "state": {"pose": {"position": {"x": 1, "y": 2, "z": 3}},
                                 "twist": {"linear": [0, 0, 1]}}, "mass": 7.0}))
    assert ok, message
    body = requests.sim.world.body("a")
    assert body["position"] == [1.0, 2.0, 3.0] and body["linear_velocity"] == [0.0, 0.0, 1.0]
    assert body["mass"] == 7.0
    ok, _ = requests.edit("{entity: a, state: {pose: {position: [5, 5, 5]}}, set_pose: false}")
    assert ok and requests.sim.world.body("a")["position"] == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("payload, code", [
    ("{entity: nobody, mass: 1}", "RESULT_NOT_FOUND:"),
    # A missing entity is that, whatever the keys: not a key the body keys' list lacks.
    ("{entity: nobody, rate: 20}", "RESULT_NOT_FOUND: no entity named nobody"),
    ("{entity: nobody, state: {pose: {position: [0, .inf, 0]}}}", "RESULT_NOT_FOUND: no entity named nobody"),
    ("{entity: a, rate: 20}", "RESULT_OPERATION_FAILED: a.rate: unknown key"),
    ("{mass: 1}", "RESULT_OPERATION_FAILED: edit.entity"),
    ("{entity: a, state: {pose: {position: [0, .inf, 0]}}}", "INVALID_POSE:"),
    ("{entity: a, mass: 2, size: [1, 0, 1]}", "RESULT_OPERATION_FAILED: a.size[1]"),
    ("{entity: a, vehicle: {engine_power: 5}}", "RESULT_OPERATION_FAILED: a.vehicle: 'a' is not a vehicle"),
])
def test_bad_edits_are_coded_and_change_nothing(requests, payload, code):
    before = snapshot(requests.sim.world)
    ok, message = requests.edit(payload)
    assert not ok and message.startswith(code), message
    assert unchanged(requests, before)


def test_a_removed_sensor_is_not_found_by_an_edit(requests):
    assert requests.spawn("{name: tmp_imu, type: imu, parent: world}")[0]
    assert requests.edit("{entity: tmp_imu, rate: 20}")[0]
    assert requests.remove("{entity: tmp_imu}")[0]
    assert requests.edit("{entity: tmp_imu, rate: 20}") == (False, "RESULT_NOT_FOUND: no entity named tmp_imu")


@pytest.mark.parametrize("payload, message", [
    ("{name: kimu, type: imu, parent: world, rate: 1.0e-320}", "spawn.rate: must be >= 0.001"),
    ("{name: kcam, type: camera, parent: world, horizontal_fov: 5.0e-324}", "spawn.horizontal_fov: must be >= 0.001"),
    ("[{name: kbox}, {name: kimu, type: imu, parent: kbox, rate: 1.0e-300}]", "[1].rate: must be >= 0.001"),
])
def test_sensors_with_tiny_rates_or_fields_of_view_are_refused(requests, payload, message):
    """Answered OK, these once killed the simulation thread (an overflow in the schedule, a
    division by zero in the camera's intrinsics), or never published; spawned or edited in,
    they are refused naming the key and the bound, and nothing changes."""
    assert requests.spawn("{name: kimu_ok, type: imu, parent: world}")[0]
    before = snapshot(requests.sim.world), list(requests.sim.world.sensor_specs)
    ok, reply = requests.spawn(payload)
    assert not ok and reply.startswith(f"RESULT_OPERATION_FAILED: {message}"), reply
    ok, reply = requests.edit("{entity: kimu_ok, rate: 1.0e-320}")
    assert (ok, reply.split(", got")[0]) == (False, "RESULT_OPERATION_FAILED: kimu_ok.rate: must be >= 0.001"), reply
    assert unchanged(requests, before[0]) and requests.sim.world.sensor_specs == before[1]


def test_remove_by_name_filter_and_all(requests):
    requests.spawn("[{name: crate_1}, {name: crate_2}, {name: barrel}]")
    assert requests.remove("{entity: barrel}") == (True, "RESULT_OK: barrel")
    assert requests.remove("{filter: '^crate_[0-9]+$'}") == (True, "RESULT_OK: crate_1, crate_2")
    assert requests.remove("{entity: barrel}")[1].startswith("RESULT_NOT_FOUND:")
    assert requests.remove("{filter: '('}")[1].startswith("RESULT_OPERATION_FAILED:")
    assert requests.remove("{all: true}") == (True, "RESULT_OK: a, b")
    assert requests.sim.world.body_names() == []


def test_pause_step_and_their_codes(requests):
    assert requests.step(1)[1].startswith("RESULT_INCORRECT_STATE:")
    assert requests.pause(True) == (True, "RESULT_OK: paused")
    assert requests.pause(True)[1].startswith("ALREADY_IN_TARGET_STATE:")
    assert requests.step(3)[0]
    assert requests.pause(False) == (True, "RESULT_OK: playing")


def test_reset_scopes(requests):
    world = requests.sim.world
    requests.spawn("{name: extra}")
    world.step(64)
    requests.edit("{entity: a, state: {pose: {position: [9, 9, 9]}}}")
    assert requests.reset(4)[0] and "extra" not in world.body_names()
    assert requests.reset(2)[0] and world.body("a")["position"] == [0.0, 0.0, 0.5]
    assert world.time > 0 and requests.reset(1)[0] and world.time == 0.0
    requests.spawn("{name: extra}")
    assert requests.reset(255)[0]
    assert requests.sim.world.body_names() == ["a", "b"]
    assert requests.reset(8)[1].startswith("RESULT_OPERATION_FAILED:")


def test_a_reset_of_the_state_restarts_a_cars_controller():
    """SCOPE_STATE (ResetSimulation's, and ~/reset's with reset_scope 2) puts a scene's car back
    as the scene starts it, its command, steering and speed loop too: they had stayed as the
    drive left them (the wheels turned, the loop's memory of the drive) and the car drove off
    again from where it was put back. Driven again, it goes where a car of a fresh world goes."""
    requests = Requests(Simulation(load_world({"version": 1, "vehicles": [SPEC_CAR]})))
    world = requests.sim.world
    as_added = world.vehicle_state("car")
    world.drive("car", 3.0, 0.5, timeout=100)
    world.step(3 * 128)
    assert requests.reset(2)[0]
    restarted = world.vehicle_state("car")
    assert [key for key in as_added if not np.array_equal(restarted[key], as_added[key])] == []
    world.step(2 * 128)
    assert world.body("car")["position"][:2] == pytest.approx(SPEC_CAR["position"][:2], abs=0.01)
    fresh = load_world({"version": 1, "vehicles": [SPEC_CAR]})
    fresh.step(2 * 128)
    for driven in (world, fresh):
        driven.drive("car", 2.0, 0.3, timeout=100)
        driven.step(2 * 128)
    assert world.body("car")["position"] == pytest.approx(fresh.body("car")["position"], abs=0.02)

def test_a_reset_of_the_state_keeps_a_scenes_frozen_body_frozen():
    """SCOPE_STATE puts a body the scene has frozen back frozen: a crate frozen in mid-air (a
    2008 playground's floating shelf) had been woken by the reset and fell."""
    requests = Requests(Simulation(load_world({"version": 1, "bodies": [
        {"name": "shelf", "position": [0, 0, 3], "frozen": True}]})))
    world = requests.sim.world
    world.edit_body("shelf", position=[2, 0, 3])  # woken: it falls
    world.step(32)
    assert requests.reset(2)[0]
    world.step(64)
    assert world.body("shelf")["frozen"] and world.body("shelf")["position"] == [0.0, 0.0, 3.0]


PENDULUM = {"version": 1, "bodies": [
    {"name": "pivot", "size": [0.2, 0.2, 0.2], "position": [0, 0, 3], "immovable": True},
    {"name": "bob", "size": [0.2, 0.2, 0.2], "position": [1, 0, 3]}],
    "joints": [{"name": "hinge", "type": "revolute", "parent": "pivot", "child": "bob",
                "anchor": [0, 0, 3], "axis": [0, 1, 0]}]}


def test_a_reset_of_the_state_brings_back_the_joints_of_a_scenes_body_removed_since():
    """SCOPE_STATE brings back a scene's body removed since with the scene's joints it took with
    it: the bob of a pendulum had come back unjointed and fallen to the ground."""
    requests = Requests(Simulation(load_world(PENDULUM)))
    world = requests.sim.world
    assert requests.remove("{entity: bob}")[0] and world.joint_names() == []
    assert requests.reset(2)[0]
    assert world.joint_names() == ["hinge"]
    fresh = load_world(PENDULUM)
    for swinging in (world, fresh):
        swinging.step(64)
    assert world.body("bob")["position"] == pytest.approx(fresh.body("bob")["position"], abs=1e-9)


def test_a_full_reset_makes_the_world_as_loaded_bit_for_bit():
    """~/reset 255 (ResetSimulation SCOPE_ALL, STOPPED) and a run after it step exactly as the
    scene loaded afresh: it had been made again from the loaded world saved as a scene, whose
    robot root poses and joint angles (measured) and hull inertia (from centred points) differ
    in their last bits, and a pile's rounding grows."""
    config = Path(__file__).resolve().parent.parent / "config"
    scene = {"version": 1, "robots": [{"name": "arm", "urdf": str(config / "arm.urdf"), "position": [3.0, 2.0, 0.0],
                                       "hold": True, "joint_positions": {"yaw": 0.5, "shoulder": 0.6, "elbow": 1.2}}],
             "bodies": [{"name": "wedge", "shape": "convex", "points": [[0, 0, 0], [0.5, 0, 0], [0, 0.3, 0],
                                                                       [0, 0, 0.4], [0.5, 0.3, 0.1]],
                         "position": [0.1, 0.0, 1.5], "rpy": [0.3, 0.2, 0.1]},
                        *({"name": f"box_{k}", "size": [0.4, 0.3, 0.2], "position": [0.05 * k, 0.02 * k, 0.3 + 0.35 * k],
                           "rpy": [0.1 * k, 0.0, 0.2]} for k in range(6))]}

    def stepped(world):
        world.step(200)
        return {key: value.tobytes() for key, value in world.state().items()}
    requests = Requests(Simulation(load_world(scene)))
    requests.sim.world.step(100)
    assert requests.reset(255)[0]
    assert stepped(requests.sim.world) == stepped(load_world(scene))


def test_load_and_save_scene(requests, tmp_path):
    requests.scene_directories = [tmp_path]
    path = tmp_path / "out.yaml"
    assert requests.save_scene(str(path)) == (True, f"RESULT_OK: {path}")
    assert requests.save_scene(str(path))[1].startswith("RESULT_OPERATION_FAILED:")  # no overwrite
    assert requests.save_scene(yaml.safe_dump({"path": str(path), "overwrite": True}, default_flow_style=True))[0]
    requests.remove("{entity: a}")
    assert requests.load_scene(str(path))[0] == MAP_SUCCESS
    assert requests.sim.world.body_names() == ["a", "b"]
    assert requests.load_scene(str(tmp_path / "missing.yaml"))[0] == MAP_DOES_NOT_EXIST
    (tmp_path / "bad.yaml").write_text("version: 9\n")
    before = requests.sim.world
    assert requests.load_scene(str(tmp_path / "bad.yaml"))[0] == INVALID_MAP_DATA
    assert requests.sim.world is before


def test_names_longer_than_the_system_takes_are_refused_in_words(requests, tmp_path):
    """A file name of more than 255 bytes made the system's refusal (ENAMETOOLONG) escape from
    the file checks: an internal error from load_scene and save_scene, a bare OSError from a
    spawn of a mesh or a URDF by that name."""
    requests.scene_directories = [tmp_path]
    long_name = str(tmp_path / ("a" * 300 + ".yaml"))
    result, message = requests.load_scene(long_name)
    assert result == MAP_DOES_NOT_EXIST and "a name in it is longer than 255 bytes" in message, message
    ok, message = requests.save_scene(long_name)
    assert not ok and "a name in it is longer than 255 bytes" in message, message
    for spawn in ({"shape": "convex", "mesh": "a" * 300 + ".obj"}, {"urdf": "a" * 300 + ".urdf"}):
        ok, message = requests.spawn(json.dumps(spawn))
        assert not ok and "not found" in message and "Errno" not in message, message


def test_get_entity_and_features(requests):
    ok, text = requests.get_entity("{entity: b}")
    entity = yaml.safe_load(text)
    assert ok and entity["frame"] == "world" and entity["pose"]["position"] == [3.0, 0.0, 0.5]
    assert requests.get_entity("{entity: zz}")[1].startswith("RESULT_NOT_FOUND:")


def msg_constants(path):
    """name -> value of the integer constants (`uint8 NAME = 3`) of a .msg file."""
    return {match["name"]: int(match["value"]) for match in
            re.finditer(r"^u?int\d+\s+(?P<name>[A-Z0-9_]+)\s*=\s*(?P<value>\d+)", path.read_text(), re.MULTILINE)}


def pose_and_twist(requests, name):
    entity = yaml.safe_load(requests.get_entity(f"{{entity: {name}}}")[1])
    return entity["pose"]["position"], entity["twist"]["linear"]


# What shows each feature honoured, through the handlers (SPEC 6.3): in order, on one world.
HONOURED = {
    "SPAWNING": lambda r: r.spawn("{name: c, position: [0, 3, 0.5]}")[0] and "c" in r.sim.world.body_names(),
    "DELETING": lambda r: r.remove("{entity: c}")[0] and "c" not in r.sim.world.body_names(),
    "ENTITY_STATE_GETTING": lambda r: pose_and_twist(r, "b") == ([3.0, 0.0, 0.5], [0.0, 0.0, 0.0]),
    "ENTITY_STATE_SETTING": lambda r: (r.edit("{entity: b, state: {pose: {position: [3, 1, 2]}, twist: {linear: [0, 0, 4]}}}")[0]
                                       and pose_and_twist(r, "b") == ([3.0, 1.0, 2.0], [0.0, 0.0, 4.0])),
    "SIMULATION_STATE_GETTING": lambda r: ("~/state", "std_msgs/msg/UInt8") in {(t.name, t.type) for t in TOPICS}
                                          and r.sim.state == PLAYING,
    "SIMULATION_STATE_PAUSE": lambda r: r.pause(True)[0] and r.sim.state == PAUSED,
    "STEP_SIMULATION_SINGLE": lambda r: r.step(1)[0] and r.sim.pending_steps == 1,
    "STEP_SIMULATION_MULTIPLE": lambda r: r.step(5)[0] and r.sim.pending_steps == 6,
    "SIMULATION_STATE_SETTING": lambda r: r.pause(False)[0] and r.sim.state == PLAYING,
    "SIMULATION_RESET_STATE": lambda r: r.reset(2)[0] and pose_and_twist(r, "b") == ([3.0, 0.0, 0.5], [0.0, 0.0, 0.0]),
    "SIMULATION_RESET_SPAWNED": lambda r: (r.spawn("{name: d}")[0] and r.reset(4)[0]
                                           and "d" not in r.sim.world.body_names()),
    "SIMULATION_RESET_TIME": lambda r: (r.sim.world.step(3) or True) and r.reset(1)[0] and r.sim.world.time == 0.0,
    "SIMULATION_RESET": lambda r: r.remove("{entity: a}")[0] and r.reset(255)[0] and r.sim.world.body_names() == ["a", "b"],
    "ENTITY_BOUNDS": lambda r: r.entity("b")["bounds"]["size"] == r.sim.world.state()["sizes"][1].tolist(),
    "ENTITY_INFO_GETTING": lambda r: category_of(r.entity("a")) == OBJECT,
    "ENTITY_CATEGORIES": lambda r: selected(r, categories=[OBJECT]) == ["a", "b"] and selected(r, categories=[ROBOT]) == [],
    "ENTITY_BOUNDS_BOX": lambda r: selected(r, bounds_type=BOUNDS_BOX, points=[(2.5, -1, 0), (3.5, 1, 1)]) == ["b"],
    "SPAWNING_RESOURCE_STRING": lambda r: (r.spawn_entities({"name": "e", "position": [0, 6, 0.5]})[0]
                                           and "e" in r.sim.world.body_names()),
    "SPAWNING_ENTITIES": lambda r: (r.spawn("[{name: f, position: [0, 9, 0.5]}, {name: g, position: [0, 12, 0.5]}]")[0]
                                    and {"f", "g"} <= set(r.sim.world.body_names())),
    "AVAILABLE_WORLDS": lambda r: [scene_file(r)] == [path for path, _ in r.available_worlds()],
    "WORLD_LOADING": lambda r: (r.load_scene(str(scene_file(r)), stopped=True)[0] == MAP_SUCCESS
                                and r.sim.world.body_names() == ["a", "b"] and r.sim.state == STOPPED),
    "WORLD_INFO_GETTING": lambda r: r.current_world() == (str(scene_file(r)), ""),
    "WORLD_UNLOADING": lambda r: r.unload_world()[0] and r.sim.state == NO_WORLD and r.current_world() is None,
    "WORLD_RESOURCE_STRING": lambda r: (r.load_scene_text(yaml.safe_dump(SCENE))[0] == MAP_SUCCESS
                                        and r.sim.world.body_names() == ["a", "b"]),
}


def selected(requests, **filters):
    table, rows = requests.entities_filtered(**filters)
    return [table.names[k] for k in rows]


def scene_file(requests):
    """SCENE as the one scene file of a scene directory of the test's own."""
    if not hasattr(requests, "test_scene"):
        directory = Path(tempfile.mkdtemp(prefix="vplayground_worlds_"))
        requests.test_scene = (directory / "two.yaml").resolve()
        requests.test_scene.write_text(yaml.safe_dump(SCENE))
        requests.scene_directories = [directory]
    return requests.test_scene


def test_features_are_listed_by_their_simulation_interfaces_numbers_and_honoured(requests):
    """The numbers ~/get_simulator_features lists are simulation_interfaces' (its
    SimulatorFeatures.msg, vendored in interfaces/) of exactly the features the handlers honour."""
    constants = msg_constants(Path(__file__).parent.parent / "interfaces" / "simulation_interfaces" / "msg"
                              / "SimulatorFeatures.msg")
    assert len(constants) == 32 and constants["SPAWNING_RESOURCE_STRING"] == 9  # the whole table was read
    names = {number: name for name, number in constants.items()}
    ok, text = requests.features()
    listed = yaml.safe_load(text)["features"]
    assert ok and listed == sorted(set(listed)) and set(listed) <= set(names), listed
    assert {names[number] for number in listed} == set(HONOURED), sorted(names[number] for number in listed)
    for name, honoured in HONOURED.items():
        assert honoured(requests), name
    # The SimulateSteps action only where a ROS node serves it (through rclpy in
    # test_standard_services.py): listed once the node says so.
    requests.actions_served = True
    assert constants["STEP_SIMULATION_ACTION"] in yaml.safe_load(requests.features()[1])["features"]


def test_runner_steps_in_real_time_and_applies_commands_between_batches():
    sim = Simulation(load_world(SCENE), real_time_factor=0.0, duration=1.0)
    seen = []
    sim.add_listener(lambda snap: seen.append(snap.time))
    sim.start()
    assert sim.wait(30)
    assert sim.world.time == pytest.approx(1.0)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0)


def test_a_new_real_time_factor_counts_from_when_it_is_set():
    """The factor had been applied back to the last anchor: 1 -> 0.5 after a while stood the
    simulation still (it was "ahead"), and 0 (as fast as possible) -> 1 froze it until the wall
    clock caught up with the time run ahead; a higher factor ran a debt of late ticks."""
    sim = Simulation(load_world(SCENE), real_time_factor=1.0)
    sim.start()
    try:
        def advance_over(seconds):
            start = sim.world.time
            time.sleep(seconds)
            return sim.world.time - start
        time.sleep(1.0)
        sim.real_time_factor = 0.5
        assert advance_over(1.0) == pytest.approx(0.5, abs=0.15)
        sim.real_time_factor = 0.0
        time.sleep(0.3)  # far ahead of the wall clock
        sim.real_time_factor = 1.0
        assert advance_over(1.0) == pytest.approx(1.0, abs=0.2)
        late = sim.late_ticks
        sim.real_time_factor = 2.0
        assert advance_over(1.0) == pytest.approx(2.0, abs=0.3) and sim.late_ticks - late < 20
    finally:
        sim.stop()


def test_a_slow_first_batch_is_start_up_not_late_ticks():
    # A cold Numba cache makes a world's first step take about a minute; real time starts after
    # it. Later slow batches are still counted.
    world = load_world(SCENE)
    step = world.step
    slow = [0.6, 0.0, 0.6]  # seconds the 1st, 2nd and 3rd batches stall

    def stalling_step(count):
        time.sleep(slow.pop(0) if slow else 0.0)
        step(count)
    world.step = stalling_step
    sim = Simulation(world, real_time_factor=1.0)
    sim.start()
    try:
        deadline = time.monotonic() + 10
        while slow and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(1.0)  # the third stall ends and the loop counts it
    finally:
        sim.stop()
    # Only the third stall (0.6 s = 77 steps at 128/s, less the batch that runs) is late; the
    # first one too would make it ~150. The margin is for a loaded machine's own hiccups.
    assert 50 <= sim.late_ticks <= 120, sim.late_ticks


def test_a_command_waits_out_a_compile_but_not_another_stall():
    # On a first run the node's first batch compiles the engine for minutes, and a
    # ~/load_scene made meanwhile answered 255: the command's 10 s ran out while it waited.
    world = load_world(SCENE)
    step, stalls = world.step, [(1.5, 0.0)]  # (s in Numba's compiler, s outside it) per batch
    stalling = threading.Event()

    def stalling_step(count):
        if stalls:
            compiling, idle = stalls.pop()
            stalling.set()
            if compiling:
                with global_compiler_lock:
                    time.sleep(compiling)  # as a kernel's compile holds Numba's compiler
            time.sleep(idle)
        step(count)
    world.step = stalling_step
    sim = Simulation(world, real_time_factor=1.0)
    sim.start()

    def stall(compiling, idle):
        stalling.clear()
        stalls.append((compiling, idle))
        assert stalling.wait(600)  # (long for a cold Numba cache: the steps compile for minutes)
    try:
        assert stalling.wait(600)
        assert sim.call(lambda w: w.step_count, timeout=0.2) > 0  # taken after the compile
        # Kernels compile one after the other, with Python between them: a wait that ends in
        # such a gap still had a compile in it (the compile ends at 0.5 s, the wait at 1 s).
        stall(0.5, 1.0)
        assert sim.call(lambda w: w.step_count, timeout=1.0) > 0
        # A batch that stalls otherwise still times the command out, and the command is
        # withdrawn: nothing it would do happens.
        stall(0.0, 1.5)
        ran = []
        with pytest.raises(TimeoutError, match="did not take the command within 0.2 s"):
            sim.call(lambda w: ran.append(w.step_count), timeout=0.2)
        time.sleep(1.5)
        assert ran == []
    finally:
        sim.stop()


def test_the_first_batch_is_not_step_time():
    # The mean step time on /diagnostics and the status line once read 225 ms on a first run:
    # the first batch's Numba compile was averaged in.
    world = load_world(SCENE)
    step, stalls = world.step, [3.0]

    def stalling_step(count):
        time.sleep(stalls.pop() if stalls else 0.0)
        step(count)
    world.step = stalling_step
    sim = Simulation(world, real_time_factor=0.0, duration=1.0)
    sim.start()
    assert sim.wait(60)
    assert sim.timed_steps > 0 and sim.timed_steps < world.step_count
    assert sim.step_seconds < 1.5, sim.step_seconds  # the 3 s stall is left out
    assert sim.mean_step_ms == pytest.approx(1e3 * sim.step_seconds / sim.timed_steps)


def test_a_full_world_is_served_in_linear_time():
    # 10,000 bodies (the default max_bodies): spawn, list and remove stay well under a second
    # each; a per-entity scan of the vehicles made ~/get_entities quadratic (~10 s).
    requests = Requests(Simulation(load_world({"version": 1})))
    items = [{"position": [k % 100 - 50, k // 100 - 50, 1]} for k in range(10_000)]
    started = time.perf_counter()
    assert requests.spawn(json.dumps(items))[0]
    assert len(requests.entities()) == 10_000
    assert requests.remove("{all: true}")[0]
    assert time.perf_counter() - started < 5.0


def test_bulk_removal_wakes_what_removal_one_by_one_wakes():
    def frozen_row():  # two rows of touching frozen boxes, far apart
        return load_world({"version": 1, "bodies": [
            {"name": f"b{k}", "position": [k + (50.0 if k >= 10 else 0.0), 0, 0.5], "frozen": True}
            for k in range(20)]})
    one, bulk = frozen_row(), frozen_row()
    doomed = ["b3", "b12", "b15", "b19"]
    for name in doomed:
        one.remove_body(name)
    bulk.remove_bodies(doomed)
    assert bulk.body_names() == one.body_names()
    frozen = bulk.state()["frozen"]
    assert np.array_equal(frozen, one.state()["frozen"]) and 0 < frozen.sum() < len(frozen)
    with pytest.raises(KeyError, match="nobody"):
        bulk.remove_bodies(["b0", "nobody"])
    assert "b0" in bulk.body_names()


def test_renaming_keeps_names_valid_and_stays_linear(requests):
    long = "n" * 64  # the longest name: its _2 must not make it 66 characters
    assert requests.spawn(f"{{name: {long}}}")[0]
    ok, message = requests.spawn(f"{{name: {long}, allow_renaming: true}}")
    assert ok and message == f"RESULT_OK: {'n' * 62}_2"
    started = time.perf_counter()
    ok, message = requests.spawn(json.dumps([{"name": "a", "allow_renaming": True}] * 5000))
    assert ok and message.endswith("a_5001") and time.perf_counter() - started < 5.0


def test_a_resting_world_shares_its_motion_state_until_a_command(requests):
    """With every body frozen a batch moves nothing: its snapshot shares the last one's motion
    arrays (read-only, no copy per batch). A command shows in the next snapshot, even one that
    moves a body and leaves it frozen, and a moving body ends the sharing."""
    sim = requests.sim
    names = sim.world.body_names()
    sim.call(lambda world: [world.edit_body(name, frozen=True) for name in names])

    def batch():
        sim.world.step(4)
        sim._publish()
        return sim.snapshot.state

    first, second = batch(), batch()
    assert second["positions"] is first["positions"] and second["frozen"] is first["frozen"]
    with pytest.raises(ValueError):
        second["positions"][0, 0] = 1.0
    sim.call(lambda world: world.edit_body(names[0], position=[4.0, 5.0, 6.0], frozen=True))
    moved = batch()
    assert moved["positions"] is not first["positions"]
    assert moved["positions"][0].tolist() == [4.0, 5.0, 6.0] and moved["frozen"].all()
    assert batch()["positions"] is moved["positions"]
    sim.call(lambda world: world.edit_body(names[0], frozen=False))
    falling = batch()
    assert batch()["positions"][0, 2] < falling["positions"][0, 2]


def test_snapshots_follow_every_change_of_the_bodies(requests, tmp_path):
    """Names, vehicles and sizes, masses and flags are taken once per layout, not every batch:
    each spawn, edit, removal (slots reused out of order) and scene load shows in the snapshot
    that follows it, every row still the named body's."""
    sim = requests.sim

    def rows(key):
        return dict(zip(sim.snapshot.names, sim.snapshot.state[key].tolist()))

    def rows_are_the_bodies():
        world = sim.world
        assert sim.snapshot.names == world.body_names()
        assert rows("positions") == {name: world.body(name)["position"] for name in world.body_names()}
        assert list(sim.snapshot.vehicles) == world.vehicle_names()

    assert rows("sizes") == {"a": [1.0, 1.0, 1.0], "b": [1.0, 1.0, 1.0]}
    assert requests.spawn("{name: c, size: [1, 2, 3], position: [6, 0, 2]}")[0]
    assert rows("sizes")["c"] == [1.0, 2.0, 3.0]
    assert requests.edit("{entity: b, size: [2, 2, 2], mass: 9, immovable: true}")[0]
    assert rows("sizes")["b"] == [2.0, 2.0, 2.0] and rows("masses")["b"] == 9.0 and rows("immovable")["b"]
    assert requests.remove("{entity: a}")[0]
    rows_are_the_bodies()
    assert requests.spawn("{name: d, position: [-6, 0, 2]}")[0]  # takes a's slot: rows out of slot order
    assert sim.snapshot.names == ["d", "b", "c"]
    rows_are_the_bodies()
    car = load_world("config/default_scene.yaml").vehicle("car")
    assert requests.spawn(json.dumps({**car, "position": [0, 12, 1]}))[0]
    assert list(sim.snapshot.vehicles) == ["car"]
    rows_are_the_bodies()
    with pytest.raises(ValueError):
        sim.snapshot.state["sizes"][0] = 5.0  # shared by the snapshots of this layout
    # Another world whose layout_version is this one's (one per body added): its own names.
    requests.scene_directories = [tmp_path]
    others = [f"other_{k}" for k in range(sim.world.layout_version)]
    scene = {"version": 1, "bodies": [{"name": name, "position": [2.0 * k, 0, 0.5]} for k, name in enumerate(others)]}
    (tmp_path / "other.yaml").write_text(yaml.safe_dump(scene))
    versions = sim.world.layout_version
    assert requests.load_scene(str(tmp_path / "other.yaml"))[0] == MAP_SUCCESS
    assert sim.world.layout_version == versions and sim.snapshot.names == others
    rows_are_the_bodies()


# ---------------------------------------------------------------- names and frames (SPEC 6.1, 6.3)
CAR = {**SPEC_CAR, "position": [10.0, -10.0, 1.0], "rpy": [0.0, 0.0, np.pi / 2]}  # facing +y
CAR_SCENE = {"version": 1, "bodies": [{"name": "a", "position": [0, 0, 0.5]}], "vehicles": [CAR],
             "sensors": [{"name": "laser", "type": "lidar_2d", "parent": "car", "pose": [1.8, 0.0, 0.45, 0, 0, 0]},
                         {"name": "cam", "type": "camera", "parent": "a", "pose": [0, 0, 1, 0, 0, 0]},
                         {"name": "beacon", "type": "imu", "parent": "world", "pose": [5, 5, 5, 0, 0, 0]}]}


@pytest.fixture
def car_requests():
    return Requests(Simulation(load_world(CAR_SCENE)))


@pytest.mark.parametrize("name", ["world", "odom", "base_link", "wheel_front_left", "wheel_rear_right", "cam_optical"])
def test_bodies_and_sensors_may_not_take_the_node_frames(car_requests, name):
    """A body's name is its /tf frame and a sensor's too: one named like a frame the node
    publishes would give /tf a loop or a frame with two parents."""
    before = snapshot(car_requests.sim.world)
    ok, message = car_requests.spawn(f"{{name: {name}}}")
    assert not ok and message.startswith(f"NAME_NOT_UNIQUE: spawn.name: '{name}' is ") and "frame" in message, message
    ok, message = car_requests.spawn(f"{{name: {name}, type: imu, parent: world}}")
    assert not ok and message.startswith(f"NAME_NOT_UNIQUE: spawn.name: '{name}' is "), message
    assert unchanged(car_requests, before) and len(car_requests.sim.world.sensor_specs) == 3
    assert car_requests.spawn(f"{{name: {name}, allow_renaming: true}}") == (True, f"RESULT_OK: {name}_2")


def test_sensors_take_allow_renaming_and_ride_the_bodies_of_their_request(car_requests):
    """A sensor's name may be renamed like a body's (it was refused with allow_renaming), also
    when only its optical frame is taken; a sensor of a list rides the body of the list its
    parent names, under that body's new name; initial_pose is a body's, refused clearly."""
    assert car_requests.spawn("{name: laser, type: imu, parent: world, allow_renaming: true}") == (True, "RESULT_OK: laser_2")
    assert car_requests.spawn("{name: lens_optical, type: imu, parent: world}")[0]
    assert car_requests.spawn("{name: lens, type: camera, parent: world}")[1].startswith(
        "NAME_NOT_UNIQUE: spawn.name: 'lens_optical' is ")
    assert car_requests.spawn("{name: lens, type: camera, parent: world, allow_renaming: true}") == (True, "RESULT_OK: lens_2")
    ok, message = car_requests.spawn("[{name: a, allow_renaming: true}, {name: a_imu, type: imu, parent: a}]")
    assert (ok, message) == (True, "RESULT_OK: a_2, a_imu")
    assert car_requests.sim.world.sensor_specs[-1]["parent"] == "a_2"
    before = snapshot(car_requests.sim.world)
    ok, message = car_requests.spawn("{name: s, type: imu, parent: world, initial_pose: {position: {x: 1}}}")
    assert not ok and message.startswith("INVALID_POSE: spawn.initial_pose: a sensor is placed by `pose`"), message
    assert unchanged(car_requests, before)


def test_the_frame_names_are_the_parameters():
    requests = Requests(Simulation(load_world(SCENE)),
                        settings={"world_frame": "world_map", "odom_frame": "odom", "footprint_frame": "base_footprint",
                                  "base_frame": "chassis"})
    assert requests.spawn("{name: world_map}")[1].startswith("NAME_NOT_UNIQUE: spawn.name: 'world_map' is the "
                                                             "world_frame")
    assert requests.spawn("{name: chassis}")[1].startswith("NAME_NOT_UNIQUE: spawn.name: 'chassis' is the base_frame")
    assert requests.spawn("{name: base_link}") == (True, "RESULT_OK: base_link")
    requests.spawn("{name: cam, type: camera, parent: base_link}")
    assert requests.spawn("{name: cam_optical}")[1].startswith("NAME_NOT_UNIQUE: spawn.name: 'cam_optical' is the "
                                                               "optical frame of cam")


def position_of(requests, name):
    return np.asarray(requests.sim.world.body(name)["position"])


def test_spawn_and_edit_poses_are_taken_in_their_frame(car_requests):
    """A frame_id the node publishes is resolved: base_link and the car's name are the car
    (here at (10, -10, 1) facing +y), odom is the world, a sensor's frame is its mount."""
    world = car_requests.sim.world
    car = position_of(car_requests, "car")
    ok, message = car_requests.spawn("{name: r, initial_pose: {header: {frame_id: base_link}, "
                                     "pose: {position: {x: 1, y: 0, z: 2}}}}")
    assert ok, message
    assert np.allclose(position_of(car_requests, "r"), car + [0, 1, 2])
    assert np.allclose(world.body("r")["quaternion"], world.body("car")["quaternion"])  # turned with the car
    ok, message = car_requests.edit("{entity: r, state: {header: {frame_id: car}, pose: {position: [2, 0, 3]}, "
                                    "twist: {linear: [1, 0, 0], angular: [0, 0, 1]}}}")
    assert ok, message
    assert np.allclose(position_of(car_requests, "r"), car + [0, 2, 3])
    assert np.allclose(world.body("r")["linear_velocity"], [0, 1, 0])  # expressed in the car's axes
    assert np.allclose(world.body("r")["angular_velocity"], [0, 0, 1])
    assert car_requests.spawn("{name: s, initial_pose: {header: {frame_id: laser}, pose: {position: [0, 0, 1]}}}")[0]
    assert np.allclose(position_of(car_requests, "s"), car + [0, 1.8, 1.45])
    for frame in ("", "world", "odom"):
        assert car_requests.edit(f"{{entity: s, state: {{header: {{frame_id: '{frame}'}}, "
                                 "pose: {position: [1, 2, 3]}}}")[0]
        assert np.allclose(position_of(car_requests, "s"), [1, 2, 3])


@pytest.mark.parametrize("call, payload", [
    ("spawn", "{name: r, initial_pose: {header: {frame_id: nowhere}, pose: {position: [1, 0, 0]}}}"),
    ("edit", "{entity: a, state: {header: {frame_id: nowhere}, pose: {position: [1, 0, 0]}}}"),
    ("edit", "{entity: a, state: {header: {frame_id: nowhere}, twist: {linear: [1, 0, 0]}}}"),
    ("edit", "{entity: a, state: {pose: {header: {frame_id: nowhere}, pose: {position: [1, 0, 0]}}}}"),
])
def test_poses_in_unknown_frames_are_refused(car_requests, call, payload):
    before = snapshot(car_requests.sim.world)
    ok, message = getattr(car_requests, call)(payload)
    assert not ok and message.startswith("INVALID_POSE: ") and "'nowhere' is not a frame" in message, message
    assert unchanged(car_requests, before)


def test_accelerations_cannot_be_set(car_requests):
    """simulation_interfaces 2.1.0 SetEntityState: `set_acceleration` chooses whether the
    state's acceleration is set; this simulator cannot set one, so it says so."""
    before = snapshot(car_requests.sim.world)
    ok, message = car_requests.edit("{entity: a, state: {acceleration: {linear: [1, 0, 0]}}}")
    assert not ok and message.startswith("RESULT_OPERATION_FAILED: edit.state.acceleration: accelerations "
                                         "cannot be set"), message
    assert not car_requests.edit("{entity: a, state: {pose: {position: [0, 0, 2]}}, set_acceleration: true}")[0]
    assert unchanged(car_requests, before)
    assert car_requests.edit("{entity: a, state: {pose: {position: [0, 0, 2]}, acceleration: {linear: [0, 0, 0]}}, "
                             "set_acceleration: false}")[0]
    assert np.allclose(position_of(car_requests, "a"), [0, 0, 2])


def test_remove_all_removes_the_sensors_too(car_requests):
    """~/get_entities lists sensors, a fixed one (parent: world) too: `all` is all of them."""
    assert [name for name, _ in car_requests.entities()][-3:] == ["laser", "cam", "beacon"]
    ok, message = car_requests.remove("{all: true}")
    assert ok and set(message.removeprefix("RESULT_OK: ").split(", ")) == {"a", "car", "laser", "cam", "beacon"}
    assert car_requests.entities() == [] and car_requests.sim.world.sensor_specs == []


def test_the_reset_scope_parameter_takes_what_reset_takes(requests):
    """One rule: a scope ~/reset refuses is refused when the parameter is set (SPEC 6.4)."""
    import argparse

    from vplayground_ros.parameters import Parameters, parameter_table
    options = argparse.Namespace(scene="", real_time_factor=1.0, start_paused=False, duration=None, record=None,
                                 record_split_size=0, foxglove=None)
    parameters = Parameters(parameter_table(requests.sim.world.settings, options, [], 10))
    for scope in (8, 100, 254, -1, 256):
        ok, reason = parameters.set({"reset_scope": scope})
        assert not ok and reason.startswith("reset_scope: ") and parameters["reset_scope"] == 255, (scope, reason)
        assert not requests.reset(scope)[0]
    for scope in (1, 2, 3, 4, 5, 6, 7, 255, 0):  # 0: simulation_interfaces' SCOPE_DEFAULT, ALL
        assert parameters.set({"reset_scope": scope}) == (True, "") and parameters["reset_scope"] == scope
        assert requests.reset(scope)[0], scope
    assert "8 is not a combination of 1 TIME, 2 STATE, 4 SPAWNED" in parameters.set({"reset_scope": 8})[1]
