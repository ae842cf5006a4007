"""robot_description (issue 39): the default car's URDF, read back by an independent parser
(yourdfpy), has the decided tree and, at any joint values, the simulator's own transforms
(robots.wheel_transforms, sensor_messages.static_frames)."""
import io
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yourdfpy

from vplayground_ros import messages, robots, sensor_messages
from vplayground_ros.frame_names import DEFAULT_FRAMES
from vplayground_ros.physics import specs
from vplayground_ros.physics.math3d import quaternions_to_matrices, rpy_to_quat
from vplayground_ros.messages import WHEEL_WIDTH
from vplayground_ros.messages import joint_names
from vplayground_ros.robot_description import (AXLE_RPY, OPTICAL_RPY, STEER_LIMIT, robot_description,
                                               vehicle_from_description)
from vplayground_ros.scene import SceneError, load_world
from vplayground_ros.sensors import validate_sensor
from helpers import SPEC_CAR

SCENE = Path(__file__).resolve().parents[1] / "config" / "default_scene.yaml"
EXACT = 1e-12
# Spawned beside the scene's sensors (validated as ~/spawn validates them).
SPAWNED = [{"name": "rear_lidar", "type": "lidar_3d", "parent": "car", "pose": [-1.9, 0.1, 0.5, 0.01, -0.02, math.pi]},
           {"name": "rear_camera", "type": "camera", "parent": "car", "pose": [-2.0, -0.3, 0.3, 0.2, 0.1, 2.9]}]


def matrix(pose):
    """4 x 4 of a pose xyz + xyzw."""
    out = np.eye(4)
    out[:3, :3] = quaternions_to_matrices(np.asarray(pose[3:], float)[None])[0]
    out[:3, 3] = pose[:3]
    return out


@pytest.fixture(scope="module")
def car():
    world = load_world(str(SCENE))
    sensors = world.sensor_specs + [validate_sensor(raw, f"spawn[{k}]", {"car"}) for k, raw in enumerate(SPAWNED)]
    sensors.append({**sensors[-1], "name": "other_camera", "pose": [0.5, 0.5, 0.5, 0.0, 0.0, 0.0]})  # a plain pose
    sensors.append({**sensors[-1], "name": "on_a_box", "parent": "tower_1"})  # not the car's: left out
    vehicle = world.vehicle("car")
    text = robot_description(vehicle, sensors, "car")
    return SimpleNamespace(vehicle=vehicle, sensors=[s for s in sensors if s["parent"] == "car"], text=text,
                           urdf=yourdfpy.URDF.load(io.StringIO(text), load_meshes=False))


def test_the_document_is_valid_urdf(car):
    assert car.urdf.validate(), car.urdf._errors
    assert car.urdf.robot.name == "car"
    assert car.urdf.base_link == "base_link"
    assert ET.fromstring(car.text).tag == "robot"


def test_links_and_joints(car):
    wheels = messages.WHEEL_NAMES
    chain = [f"{part}_{w}" for w in wheels for part in ("suspension", "steering", "wheel")]
    sensor_links = [s["name"] for s in car.sensors] + ["rear_camera_optical", "depth_camera_optical",
                                                       "camera_optical", "other_camera_optical"]
    assert sorted(car.urdf.link_map) == sorted(["base_link", *chain, *sensor_links])
    assert "on_a_box" not in car.urdf.link_map
    assert car.urdf.actuated_joint_names == joint_names()
    assert joint_names() == [f"{w}_{j}" for w in wheels for j in ("suspension", "steer", "spin")]
    for w, wheel in zip(wheels, car.vehicle["wheels"]):
        suspension, steer, spin = (car.urdf.joint_map[f"{w}_{j}"] for j in ("suspension", "steer", "spin"))
        assert (suspension.type, suspension.parent, suspension.child) == ("prismatic", "base_link", f"suspension_{w}")
        at_full_length = np.subtract(wheel["mount"], [0, 0, wheel["spring_length"]])
        np.testing.assert_array_equal(suspension.origin[:3, 3], at_full_length)
        np.testing.assert_array_equal(suspension.origin[:3, :3], np.eye(3))
        assert (suspension.limit.lower, suspension.limit.upper) == (0.0, wheel["spring_length"])
        assert (steer.type, steer.parent, steer.child) == ("revolute", f"suspension_{w}", f"steering_{w}")
        assert (steer.limit.lower, steer.limit.upper) == (-STEER_LIMIT, STEER_LIMIT) == (-math.pi / 2, math.pi / 2)
        assert (spin.type, spin.parent, spin.child) == ("continuous", f"steering_{w}", f"wheel_{w}")
        for joint, axis in ((suspension, [0, 0, 1]), (steer, [0, 0, 1]), (spin, [0, 1, 0])):
            np.testing.assert_array_equal(joint.axis, axis)
        for joint in (steer, spin):
            np.testing.assert_array_equal(joint.origin, np.eye(4))
        for name in (f"suspension_{w}", f"steering_{w}"):
            link = car.urdf.link_map[name]
            assert link.inertial is None and not link.visuals and not link.collisions
    for spec in car.sensors:
        joint = car.urdf.joint_map[f"{spec['name']}_joint"]
        assert (joint.type, joint.parent, joint.child) == ("fixed", "base_link", spec["name"])
        if spec["type"] in ("camera", "depth_camera"):
            optical = car.urdf.joint_map[f"{spec['name']}_optical_joint"]
            assert (optical.type, optical.parent, optical.child) == ("fixed", spec["name"], f"{spec['name']}_optical")


def test_geometry_masses_and_inertias(car):
    chassis = car.vehicle["chassis"]
    base = car.urdf.link_map["base_link"]
    for part in (base.visuals[0], base.collisions[0]):
        np.testing.assert_array_equal(part.geometry.box.size, chassis["size"])
        np.testing.assert_array_equal(part.origin, np.eye(4))
    a, b, c = chassis["size"]
    m = chassis["mass"]  # the chassis' own: the engine's body adds the wheels'
    assert base.inertial.mass == m == 1200.0
    np.testing.assert_allclose(base.inertial.inertia, np.diag([m * (b * b + c * c), m * (a * a + c * c),
                                                                m * (a * a + b * b)]) / 12, rtol=1e-15)
    for w, wheel in zip(messages.WHEEL_NAMES, car.vehicle["wheels"]):
        link = car.urdf.link_map[f"wheel_{w}"]
        for part in (link.visuals[0], link.collisions[0]):
            assert (part.geometry.cylinder.radius, part.geometry.cylinder.length) == (wheel["radius"], WHEEL_WIDTH)
            # The cylinder's axis (its z) turned onto the axle, y (either way).
            np.testing.assert_allclose(np.abs(part.origin[:3, :3] @ [0, 0, 1]), [0, 1, 0], rtol=0, atol=1e-16)
            np.testing.assert_array_equal(part.origin[:3, 3], [0, 0, 0])
        r, width, m = wheel["radius"], WHEEL_WIDTH, wheel["mass"]
        across = m * (3 * r * r + width * width) / 12
        assert link.inertial.mass == m
        np.testing.assert_allclose(link.inertial.inertia, np.diag([across, m * r * r / 2, across]), rtol=1e-15)
        np.testing.assert_array_equal(link.inertial.origin, np.eye(4))
    assert AXLE_RPY == (math.pi / 2, 0.0, 0.0)
    colours = {m.name: m.color.rgba for m in car.urdf.robot.materials}
    np.testing.assert_array_equal(colours["chassis"], messages.COLOURS["vehicle"])


@pytest.mark.parametrize("seed", range(5))
def test_forward_kinematics_is_the_simulators(car, seed):
    """At joint values (compression, steer, spin) every link of the wheels' chains is where the
    node's /tf puts it."""
    rng = np.random.default_rng(seed)
    springs = np.array([w["spring_length"] for w in car.vehicle["wheels"]])
    state = {"compression": rng.uniform(0, 1, 4) * springs, "steer_angle": rng.uniform(-1.5, 1.5, 4),
             "spin_angle": rng.uniform(-50, 50, 4)}
    if seed == 0:
        state = {key: np.zeros(4) for key in state}
    keys = (("suspension", "compression"), ("steer", "steer_angle"), ("spin", "spin_angle"))
    car.urdf.update_cfg({f"{w}_{j}": state[key][k] for k, w in enumerate(messages.WHEEL_NAMES) for j, key in keys})
    robot = robots.robot(car.vehicle, DEFAULT_FRAMES)
    transforms = robots.wheel_transforms(robot, state, car.vehicle["wheels"])
    assert len(transforms) == 12
    for parent, child, pose in transforms:
        np.testing.assert_allclose(car.urdf.get_transform(child, parent), matrix(pose), rtol=0, atol=EXACT)
    # The wheel's centre and attitude in the chassis, composed: the mount lowered by the spring's
    # length less its compression, steered about z, then spun about y.
    for k, (w, wheel) in enumerate(zip(messages.WHEEL_NAMES, car.vehicle["wheels"])):
        centre = np.subtract(wheel["mount"], [0, 0, wheel["spring_length"] - state["compression"][k]])
        steer, spin = state["steer_angle"][k], state["spin_angle"][k]
        rotation = matrix([0, 0, 0, 0, 0, math.sin(steer / 2), math.cos(steer / 2)])[:3, :3] @ \
            matrix([0, 0, 0, 0, math.sin(spin / 2), 0, math.cos(spin / 2)])[:3, :3]
        got = car.urdf.get_transform(f"wheel_{w}", "base_link")
        np.testing.assert_allclose(got[:3, 3], centre, rtol=0, atol=EXACT)
        np.testing.assert_allclose(got[:3, :3], rotation, rtol=0, atol=EXACT)


def test_sensor_frames_are_the_simulators(car):
    car.urdf.update_cfg(np.zeros(len(joint_names())))
    static = sensor_messages.static_frames(car.sensors, lambda parent: "base_link")
    assert len(static) == len(car.sensors) + 4  # four cameras' optical frames
    for parent, child, pose in static:
        np.testing.assert_allclose(car.urdf.get_transform(child, parent), matrix(pose), rtol=0, atol=EXACT)
    # The poses are written to round-trip: the joint origin's numbers are the spec's.
    for spec in car.sensors:
        origin = ET.fromstring(car.text).find(f"joint[@name='{spec['name']}_joint']/origin")
        assert [float(v) for v in origin.get("xyz").split() + origin.get("rpy").split()] == spec["pose"]


def test_optical_rpy_round_trips():
    np.testing.assert_allclose(rpy_to_quat(OPTICAL_RPY), sensor_messages.OPTICAL_ROTATION, rtol=0, atol=1e-16)
    np.testing.assert_allclose(OPTICAL_RPY, (-math.pi / 2, 0.0, -math.pi / 2), rtol=0, atol=1e-15)


def test_frame_id(car):
    """A sensor's frame_id, when it has one, names its link and its optical frame's."""
    spec = {**car.sensors[-1], "frame_id": "front_camera_link"}
    urdf = yourdfpy.URDF.load(io.StringIO(robot_description(car.vehicle, [spec], "car")), load_meshes=False)
    assert urdf.joint_map["front_camera_link_joint"].child == "front_camera_link"
    assert urdf.joint_map["front_camera_link_optical_joint"].child == "front_camera_link_optical"
    assert "other_camera" not in urdf.link_map


def test_renamed_base_frame(car):
    """The root is the node's base frame (its base_frame parameter), as robots.robot_frames names it."""
    text = robot_description(car.vehicle, car.sensors, "car", DEFAULT_FRAMES._replace(base="chassis"))
    urdf = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False)
    assert urdf.base_link == "chassis" and "base_link" not in urdf.link_map
    assert urdf.joint_map["laser_joint"].parent == urdf.joint_map["front_left_suspension"].parent == "chassis"


def test_xml_special_characters():
    """Validated names cannot hold them; and names that did would still be text, not markup."""
    for bad in ("a<b", "a&b", 'a"b', "a'b", "a>b", "a\nb"):
        with pytest.raises(specs.SpecError):
            specs.name(bad, "name")
    name = "<car> & \"co\" 'x'"
    vehicle = specs.validate_vehicle({"chassis": {"size": [1, 1, 1], "mass": 1}, "wheels": [{"mount": [0, 0, 0]}] * 4})
    sensor = {"name": "c&<>", "type": "camera", "parent": name, "pose": [0.0] * 6}
    root = ET.fromstring(robot_description(vehicle, [sensor], name))
    assert root.get("name") == name
    assert {link.get("name") for link in root.iter("link")} >= {"c&<>", "c&<>_optical"}


CAR_URDF = SCENE.parent / "car.urdf"


def test_the_default_scenes_car_is_the_shipped_description_and_spec_5s_car():
    """config/car.urdf loads (through the default scene's robots entry) as exactly SPEC 5's car,
    and is what robot_description writes for that car: the two cannot drift apart."""
    world = load_world(str(SCENE))
    assert world.vehicle_names() == ["car"] and world.robot_specs == []
    assert world.vehicle("car") == load_world({"version": 1, "vehicles": [SPEC_CAR]}).vehicle("car")
    shipped = ET.tostring(ET.parse(CAR_URDF).getroot(), encoding="unicode")
    assert shipped == robot_description(world.vehicle("car"), [], "car")


@pytest.mark.parametrize("seed", range(3))
def test_any_vehicle_reads_back_from_its_description(seed):
    """robot_description's <vplayground> element and the links and joints give the vehicle back
    exactly (random sizes, springs, materials; a renamed base frame)."""
    rng = np.random.default_rng(seed)
    raw = {"chassis": {"size": rng.uniform(0.5, 5, 3).tolist(), "mass": float(rng.uniform(10, 3000)),
                       "elasticity": float(rng.uniform(0, 1)), "static_friction": float(rng.uniform(0, 2)),
                       "dynamic_friction": float(rng.uniform(0, 2)), "allow_freezing": bool(seed % 2)},
           "engine_power": float(rng.uniform(0, 1e5)), "brake_power": float(rng.uniform(0, 1e5)),
           "max_steer": float(rng.uniform(0, 1.5)),
           "wheels": [{"mount": rng.uniform(-2, 2, 3).tolist(), "radius": float(rng.uniform(0.05, 1)),
                       "mass": float(rng.uniform(1, 50)), "power_gain": float(rng.uniform(0, 1)),
                       "steered": bool(rng.integers(2)), "spring_stiffness": float(rng.uniform(1e3, 1e5)),
                       "damper": float(rng.uniform(0, 1e4)), "spring_length": float(rng.uniform(0.05, 1)),
                       "static_friction": float(rng.uniform(0, 2)), "dynamic_friction": float(rng.uniform(0, 2))}
                      for _ in range(4)]}
    vehicle = specs.validate_vehicle(raw)
    frames = DEFAULT_FRAMES._replace(base="chassis")
    back = vehicle_from_description(robot_description(vehicle, [], "v", frames), "v.urdf")
    assert specs.validate_vehicle(back) == vehicle


def broken(old, new):
    text = CAR_URDF.read_text()
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize("text, message", [
    (broken('mount="1.3 0.8 -0.3"', 'mount="1.3 0.8 -0.2"'),
     "<vplayground><vehicle><wheel> 1: mount '1.3 0.8 -0.2' is not where its suspension joint puts it"),
    (broken('suspension="front_right_suspension"', 'suspension="front_right_steer"'),
     "<wheel> 2: suspension 'front_right_steer' is no prismatic joint"),
    (broken('<chassis link="base_link"', '<chassis link="wheel_rear_left"'),
     "<chassis>: link 'wheel_rear_left' needs a box collision and an inertial mass"),
    (broken('<box size="4.0 1.8 0.6" />\n      </geometry>\n    </collision>',
            '<box size="4.0 1.8" />\n      </geometry>\n    </collision>'), "size '4.0 1.8': expected 3 numbers"),
    (broken('steered="false"', 'steered="no"'), "<wheel> 3: steered 'no': expected true or false"),
    (broken('engine_power="6000.0"', 'engine_power="lots"'), "engine_power 'lots' is not a number"),
    (broken('<origin xyz="1.3 0.8 -0.8"', '<origin xyz="1.3 0.8 nan"'), "<wheel> 1: mount '1.3 0.8 -0.3' is not where"),
])
def test_a_broken_vehicle_description_is_refused_naming_the_element(text, message):
    with pytest.raises(SceneError, match=re.escape(message)):
        load_world({"version": 1, "robots": [{"name": "car", "urdf": text}]})


def test_a_vehicles_robot_entry_takes_the_vehicle_keys_alone():
    entry = {"name": "car", "urdf": str(CAR_URDF), "namespace": "fleet/a", "localization": "none",
             "odometry": {"seed": 3}}
    world = load_world({"version": 1, "robots": [entry]})
    assert world.vehicle("car")["namespace"] == "fleet/a" and world.vehicle("car")["odometry"]["seed"] == 3
    with pytest.raises(SceneError, match=re.escape("robots[0].hold: unknown key (allowed: ")):
        load_world({"version": 1, "robots": [{**entry, "hold": True}]})
    with pytest.raises(SceneError, match=re.escape("robots[0].odometry.sed: unknown key")):
        load_world({"version": 1, "robots": [{**entry, "odometry": {"sed": 3}}]})


def test_a_vehicles_description_from_a_request_is_not_expanded_and_names_its_entry(tmp_path):
    """A scene a service loads (scene directories given) does not expand xacro in a vehicle's
    description (it reads environment variables and any file); errors name the robots entry;
    max_bodies counts the vehicles robots entries make; a copy of the default scene elsewhere
    still finds the package's car.urdf."""
    text = broken('engine_power="6000.0"', 'engine_power="$(env HOME)"')
    with pytest.raises(SceneError, match=re.escape("robots[0].urdf: it uses xacro, which is expanded only")):
        load_world({"version": 1, "robots": [{"name": "car", "urdf": text}]}, directories=[str(tmp_path)])
    car = {"name": "car", "urdf": str(CAR_URDF)}
    sensor = {"name": "car", "type": "imu", "parent": "world"}
    with pytest.raises(SceneError, match=re.escape("sensors[0].name: duplicate name 'car': already robots[1]'s name")):
        load_world({"version": 1, "robots": [{**car, "name": "other"}, car], "sensors": [sensor]})
    with pytest.raises(SceneError, match=re.escape("robots[1].namespace")):
        load_world({"version": 1, "robots": [{**car, "namespace": "a"}, {**car, "name": "b", "namespace": "a"}]})
    with pytest.raises(SceneError, match=re.escape("robots[0].name: missing")):
        load_world({"version": 1, "robots": [{"urdf": str(CAR_URDF)}]})
    three = {"version": 1, "robots": [{**car, "name": f"c{k}", "position": [5.0 * k, 0, 1]} for k in range(3)]}
    with pytest.raises(SceneError, match=re.escape("the scene has 3 bodies (vehicles and the robots' links counted), "
                                                   "more than max_bodies (2)")):
        load_world(three, max_bodies=2)
    copied = tmp_path / "my_scene.yaml"
    copied.write_text(SCENE.read_text())
    assert load_world(str(copied)).vehicle("car") == load_world(str(SCENE)).vehicle("car")
