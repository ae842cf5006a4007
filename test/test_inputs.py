"""The subscription handlers (SPEC 6.2), ROS-free: messages as the Foxglove server's JSON gives them."""
import json
import math
import warnings

import numpy as np
import pytest

from pathlib import Path

from test_requests import CAR_SCENE
from vplayground_ros.api import Requests
from vplayground_ros.api.descriptions import describe_robot
from vplayground_ros.broadcast import resolve
from vplayground_ros import throttle
from vplayground_ros.inputs import Inputs, from_json
from vplayground_ros.parameters import FRAMES, frames
from vplayground_ros.robots import robot
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import Simulation
from vplayground_ros.urdf_robots import RobotControl, publishing_view, robot_spec

CONFIG = Path(__file__).resolve().parent.parent / "config"

PARAMETERS = {**FRAMES, "cmd_vel_timeout": 1.2, "click_spawn_size": 0.5, "click_spawn_height": 2.0}


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(("info", text))

    def warning(self, text):
        self.lines.append(("warning", text))

    def warnings(self):
        return [text for level, text in self.lines if level == "warning"]


@pytest.fixture
def inputs():
    sim = Simulation(load_world(CAR_SCENE))  # not started: commands run as they are submitted
    def robots(snapshot):
        return [robot(spec, frames(PARAMETERS)) for spec in snapshot.vehicle_specs.values()]
    return Inputs(sim, Requests(sim), PARAMETERS, Log(), robots, resolve)


def message(**fields):
    return from_json(json.dumps(fields))


def click(inputs, frame, point=(0.0, 0.0, 0.0)):
    """The box a click drops, where it appears (None if none did)."""
    before = set(inputs.sim.world.body_names())
    inputs.handle("clicked_point", message(header={"frame_id": frame}, point=dict(zip("xyz", point))))
    new = set(inputs.sim.world.body_names()) - before
    return np.asarray(inputs.sim.world.body(new.pop())["position"]) if new else None


def test_clicks_in_the_frames_the_node_publishes(inputs):
    """The car is at (10, -10, 1) facing +y; its laser at (1.8, 0, 0.45) in base_link, its
    front-left wheel's frame at the wheel's centre (mount, down by the spring's length)."""
    world = inputs.sim.world
    car = np.asarray(world.body("car")["position"])
    drop = np.array([0.0, 0.0, 2.0 + 0.25])  # click_spawn_height + half the box
    assert np.allclose(click(inputs, "base_link", (1, 0, 0)), car + [0, 1, 0] + drop)
    assert np.allclose(click(inputs, "laser", (1, 0, 0)), car + [0, 2.8, 0.45] + drop)
    wheel = world.vehicle("car")["wheels"][0]
    centre = np.asarray(wheel["mount"]) - [0, 0, wheel["spring_length"] - world.vehicle_state("car")["compression"][0]]
    assert np.allclose(click(inputs, "wheel_front_left"), car + [-centre[1], centre[0], centre[2]] + drop)
    assert np.allclose(click(inputs, "cam"), np.asarray(world.body("a")["position"]) + [0, 0, 1] + drop)
    assert np.allclose(click(inputs, "beacon"), [5, 5, 5] + drop)
    assert np.allclose(click(inputs, "odom", (1, 2, 3)), [1, 2, 3] + drop)
    assert not inputs.log.warnings()
    assert click(inputs, "nowhere") is None and "unknown frame 'nowhere'" in inputs.log.warnings()[-1]


def test_refused_inputs_are_logged(inputs):
    """What the simulation thread refuses is logged, not left in a Future nobody reads."""
    world = inputs.sim.world
    before = world.body("car")["position"]
    pose = {"position": {"x": 5000.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}
    inputs.handle("initial_pose", message(header={"frame_id": "world"}, pose={"pose": pose}))
    assert world.body("car")["position"] == before
    assert len(inputs.log.warnings()) == 1 and "initialpose ignored: pose.position: [5000.0" in inputs.log.warnings()[0]
    assert "outside the world" in inputs.log.warnings()[0]
    inputs.handle("initial_pose", message(header={"frame_id": "nowhere"}, pose={"pose": pose}))
    assert "initialpose ignored" in inputs.log.warnings()[-1] and "'nowhere'" in inputs.log.warnings()[-1]
    wrench = {"force": {"x": 1.0, "y": 0.0, "z": 0.0}, "torque": {"x": 0.0, "y": 0.0, "z": 0.0}}
    inputs.handle("push", message(header={"frame_id": "nobody"}, wrench=wrench))
    assert inputs.log.warnings()[-1] == "~/push ignored: no body named 'nobody'"
    assert click(inputs, "world", (5000.0, 0.0, 0.0)) is None
    assert inputs.log.warnings()[-1].startswith("clicked_point: INVALID_POSE: ")


def test_initialpose_in_base_link_turns_with_the_car(inputs):
    """A pose in base_link: 2 m ahead of the car (facing +y), turned a further quarter turn."""
    world = inputs.sim.world
    car = np.asarray(world.body("car")["position"])
    pose = {"position": {"x": 2.0, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0, "y": 0, "z": math.sin(math.pi / 4), "w": math.cos(math.pi / 4)}}
    inputs.handle("initial_pose", message(header={"frame_id": "base_link"}, pose={"pose": pose}))
    assert not inputs.log.warnings()
    moved = world.body("car")
    assert np.allclose(moved["position"][:2], car[:2] + [0, 2])
    assert np.allclose(np.abs(moved["quaternion"]), [0, 0, 1, 0], atol=1e-9)  # facing -x


def test_an_initialpose_quaternion_of_any_length_is_its_direction(inputs):
    """A quaternion so long that its squares overflow is a direction all the same (numpy's
    overflow warning had gone to raw stderr, and the orientation was the identity)."""
    world = inputs.sim.world
    pose = {"position": {"x": 3.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0, "y": 0, "z": 1e308, "w": 1e308}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        inputs.handle("initial_pose", message(header={"frame_id": "world"}, pose={"pose": pose}))
    assert not inputs.log.warnings()
    yaw = math.pi / 2  # z = w: a quarter turn
    assert np.allclose(np.abs(world.body("car")["quaternion"]), [0, 0, math.sin(yaw / 2), math.cos(yaw / 2)], atol=1e-9)


def test_a_flood_of_refused_inputs_is_logged_a_few_lines_at_a_time(inputs):
    """Anyone on the domain may send a thousand NaN commands a second: each had been a log
    line. A few of each input's warnings go out in a while; the next after it says how many
    were held back. A refusal too large for a float (a JSON integer of 400 digits) is a
    malformed message, not a simulator error."""
    nan = {"linear": {"x": float("nan"), "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}
    for _ in range(200):
        inputs.handle("cmd_vel", from_json(json.dumps(nan)))
    assert 1 <= len(inputs.log.warnings()) <= throttle.BURST
    huge = from_json('{"header": {"frame_id": "world"}, "point": {"x": 1' + "0" * 400 + ', "y": 0, "z": 0}}')
    inputs.handle("clicked_point", huge)
    assert "clicked_point: malformed message ignored" in inputs.log.warnings()[-1]
    assert inputs.sim.fault_count == 0


def test_a_throttle_lets_a_burst_through_then_counts_what_it_holds_back():
    now = [0.0]
    gate = throttle.Throttle(period=10.0, burst=3, clock=lambda: now[0])
    assert [gate.admit("a") for _ in range(5)] == [0, 0, 0, None, None]
    assert gate.admit("b") == 0  # kinds apart
    now[0] = 9.9
    assert gate.admit("a") is None
    now[0] = 10.0
    assert gate.admit("a") == 3  # the window over: the three held back are told with the next
    assert throttle.held_note(3) == " (3 more like it in the 10 s before were not logged)"


def test_initialpose_puts_a_urdf_robot_in_the_root_namespace_there_on_the_ground():
    """The rover of robots_scene.yaml (a URDF robot, the root namespace's, no vehicle in the
    scene): the pose-estimate tool teleports it as it does the car (it had been ignored, logged
    as "no robot in the root namespace"). Its links move as one, upright, facing the pose's
    heading, its lowest point on the pose's height; it stops, and stands there."""
    sim = Simulation(load_world(str(CONFIG / "robots_scene.yaml")))
    control = RobotControl()
    sim.controllers.append(control.before_batch)

    def urdf_robots(snapshot):  # as the Broadcaster sees them
        rows = {name: row for row, name in enumerate(snapshot.names)}
        return [publishing_view(spec, rows) for spec in snapshot.robot_specs]
    inputs = Inputs(sim, Requests(sim), PARAMETERS, Log(), lambda snapshot: [], resolve, urdf_robots, control)
    world = sim.world
    rover = robot_spec(world, "rover")
    before = {body: world.body(body) for body in rover["bodies"]}
    root = before[rover["bodies"][0]]
    control.drive(world, "rover", 0.5, 0.0, 1.2)
    heading = math.pi / 2
    pose = {"position": {"x": 1.0, "y": -2.0, "z": 0.0},
            "orientation": {"x": 0, "y": 0, "z": math.sin(heading / 2), "w": math.cos(heading / 2)}}
    inputs.handle("initial_pose", message(header={"frame_id": "world"}, pose={"pose": pose}))
    assert not inputs.log.warnings(), inputs.log.warnings()
    moved_root = world.body(rover["bodies"][0])
    assert np.allclose(moved_root["position"][:2], [1.0, -2.0])
    assert np.allclose(np.abs(moved_root["quaternion"]), [0, 0, math.sin(heading / 2), math.cos(heading / 2)], atol=1e-9)
    turn = np.array([[0.0, -1.0], [1.0, 0.0]])  # a quarter turn about z, from facing +x
    for body, was in before.items():  # every link where the same rigid move puts it
        now = world.body(body)
        offset = np.asarray(was["position"]) - root["position"]
        assert np.allclose(np.asarray(now["position"][:2]) - moved_root["position"][:2], turn @ offset[:2], atol=1e-9)
        assert math.isclose(now["position"][2] - moved_root["position"][2], offset[2], abs_tol=1e-9)
    low = describe_robot(world, rover)["bounds"]["low"][2]
    assert math.isclose(moved_root["position"][2] + low, 0.0, abs_tol=1e-9)  # its lowest point on the ground
    assert all(v == 0.0 for v in moved_root["linear_velocity"] + moved_root["angular_velocity"])
    world.step(256)  # 2 s: the drive was stopped, so it stays where it was put
    assert np.allclose(world.body(rover["bodies"][0])["position"][:2], [1.0, -2.0], atol=0.02)
