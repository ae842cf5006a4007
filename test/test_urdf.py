"""Robots from URDF (issue 38): real descriptions no one here wrote (pybullet_data's KUKA iiwa
and Clearpath Husky), the mass properties they give, and what is refused."""
import math
import os
import re
import sys

import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.specs import SpecError
from vplayground_ros.urdf_import import UrdfError, add_robot, robot_model

pybullet_data = pytest.importorskip("pybullet_data")
KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
HUSKY = os.path.join(pybullet_data.getDataPath(), "husky", "husky.urdf")
RATE = 128


def loaded(path, name, **placement):
    world = World({"freezing": {"enabled": False}})
    model = robot_model(path, name, **placement)
    add_robot(world, model)
    return world, model


def test_kuka_loads_as_its_links_and_joints():
    world, model = loaded(KUKA, "kuka")
    assert world.body_names() == [f"kuka.lbr_iiwa_link_{k}" for k in range(8)]
    assert world.joint_names() == [f"kuka.lbr_iiwa_joint_{k}" for k in range(1, 8)]
    assert world.body("kuka.lbr_iiwa_link_0")["immovable"]  # its root has no mass: fixed
    joint = world.joint("kuka.lbr_iiwa_joint_2")
    assert joint["type"] == "revolute"
    assert (joint["lower"], joint["upper"]) == pytest.approx((-2.09439510239, 2.09439510239))
    assert joint["motor"]["max_effort"] == 300.0 and joint["motor"]["max_speed"] == 10.0
    link = world.body("kuka.lbr_iiwa_link_1")
    assert link["mass"] == 4.0  # as its inertial gives, not its mesh's volume
    # The link's frame where the joint chain puts it (joint 1 at z 0.1575 on the base).
    assert link["position"] == pytest.approx([0.0, 0.0, 0.1575], abs=1e-9)


def test_kuka_holds_a_pose_under_gravity_with_position_motors():
    world, model = loaded(KUKA, "kuka")
    target = [0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1]
    for joint, angle in zip(world.joint_names(), target):
        world.edit_joint(joint, motor={"mode": "position", "target": angle})
    world.step(RATE)
    for _ in range(3):
        world.step(RATE)
        for joint, angle in zip(world.joint_names(), target):
            assert math.degrees(abs(world.joint(joint)["position"] - angle)) < 0.01
    # Held against gravity: the shoulder's motor carries the arm's moment.
    assert abs(world.joint("kuka.lbr_iiwa_joint_2")["effort"]) > 10.0


def test_kuka_without_motors_falls_on_its_joints():
    world, model = loaded(KUKA, "kuka")
    start = world.body("kuka.lbr_iiwa_link_7")["position"]
    world.step(RATE)
    assert world.body("kuka.lbr_iiwa_link_7")["position"][2] < start[2] - 0.05
    # Every joint's anchors still meet (the joint reports where its child's anchor is; the
    # parent's is computed here from the model's pose the same way).
    for joint in world.joint_names():
        assert np.isfinite(world.joint(joint)["position"])


def test_husky_stands_on_its_wheels_and_drives_straight():
    world, model = loaded(HUSKY, "husky", position=[0, 0, 0.02])
    assert [b["name"] for b in model.bodies][0] == "husky.base_footprint"  # base_link lumped in
    assert not world.body("husky.base_footprint")["immovable"]
    world.step(RATE)
    base = world.body("husky.base_footprint")
    assert base["position"][2] == pytest.approx(0.0, abs=0.01)  # wheel radius over the ground
    speed = 0.6
    for joint in world.joint_names():
        world.edit_joint(joint, motor={"mode": "velocity", "target": speed / 0.17775, "max_effort": 100.0})
    world.step(2 * RATE)
    start = np.array(world.body("husky.base_footprint")["position"])
    world.step(2 * RATE)
    moved = np.array(world.body("husky.base_footprint")["position"]) - start
    assert moved[0] / 2.0 == pytest.approx(speed, rel=0.02)
    assert abs(moved[1]) < 0.01


def test_inertial_gives_the_mass_properties():
    world = World()
    tensor = [[0.6022, -0.02364, -0.1197], [-0.02364, 1.7386, -0.001544], [-0.1197, -0.001544, 2.0296]]
    world.add_body({"name": "b", "shape": "compound", "position": [0, 0, 1],
                    "parts": [{"size": [1.0, 0.57, 0.27], "position": [0, 0, 0.12]}],
                    "inertial": {"mass": 33.455, "centre": [-0.087, -0.0008, 0.099], "inertia": tensor}})
    body = world.body("b")
    assert body["mass"] == 33.455
    slot = world._slots["b"]
    np.testing.assert_allclose(world._bodies.inv_inertia[slot], np.linalg.inv(tensor), rtol=1e-12)
    # The engine moves the centre of mass; the frame is where the spec put it.
    np.testing.assert_allclose(world._bodies.position[slot], [-0.087, -0.0008, 1.099], atol=1e-12)
    assert body["position"] == pytest.approx([0, 0, 1], abs=1e-12)


@pytest.mark.parametrize("inertial, message", [
    ({"mass": 1.0, "centre": [0, 0, 0]}, "inertial.inertia: missing"),
    ({"mass": 1.0, "centre": [0, 0, 0], "inertia": [[1, 0, 0], [0, 1, 0], [0, 0, 3]]},
     "not a real body's"),
    ({"mass": 1.0, "centre": [0, 0, 0], "inertia": [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]}, "is not symmetric"),
    ({"mass": 0.0, "centre": [0, 0, 0], "inertia": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, "inertial.mass: must be >="),
])
def test_bad_inertials_are_refused(inertial, message):
    with pytest.raises(SpecError, match=message):
        World().add_body({"shape": "compound", "parts": [{}], "inertial": inertial})


def test_editing_an_inertial_changes_the_mass():
    world = World()
    inertial = {"mass": 1.0, "centre": [0, 0, 0], "inertia": (0.1 * np.eye(3)).tolist()}
    world.add_body({"name": "b", "shape": "compound", "parts": [{}], "inertial": inertial})
    world.edit_body("b", inertial={**inertial, "mass": 5.0, "inertia": (0.5 * np.eye(3)).tolist()})
    assert world.body("b")["mass"] == 5.0
    np.testing.assert_allclose(world._bodies.inv_inertia[world._slots["b"]], 2.0 * np.eye(3), rtol=1e-12)


def test_inertial_is_a_compounds_and_excludes_a_mass():
    with pytest.raises(SpecError, match="a box has no inertial"):
        World().add_body({"inertial": {"mass": 1, "centre": [0, 0, 0], "inertia": np.eye(3).tolist()}})
    with pytest.raises(SpecError, match="body.mass: the inertial gives the mass"):
        World().add_body({"shape": "compound", "parts": [{}], "mass": 2.0,
                          "inertial": {"mass": 1, "centre": [0, 0, 0], "inertia": np.eye(3).tolist()}})


ARM = """<robot name="arm">
  <link name="base"><collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision>
    <inertial><mass value="2"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><collision><geometry><cylinder radius="0.05" length="0.5"/></geometry></collision>
    <inertial><mass value="{mass}"/><inertia ixx="0.02" iyy="0.02" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="{kind}"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="2"/></joint>
</robot>"""


@pytest.mark.parametrize("text, message", [
    (ARM.format(mass=0, kind="revolute"), "link 'upper': no inertial, or a mass of 0"),
    (ARM.format(mass=1, kind="revolute").replace("</robot>", '<link name="upper"/></robot>'),
     "two links are named 'upper'"),
    (ARM.format(mass=-1, kind="revolute"), "link 'upper': mass -1 kg is not physical"),
    (ARM.format(mass=1, kind="floating"), "joint 'shoulder': type 'floating' is not supported"),
    (ARM.format(mass=1, kind="revolute").replace('<child link="upper"/>', '<child link="elbow"/>'),
     "joint 'shoulder': no link named 'elbow'"),
    (ARM.format(mass=1, kind="revolute").replace("</robot>", '<joint name="back" type="fixed"><parent link="upper"/>'
                                                             '<child link="base"/></joint></robot>'),
     "no root link (a loop)"),
    (ARM.format(mass=1, kind="revolute").replace('<box size="0.2 0.2 0.2"/>', '<mesh filename="gone.stl"/>'),
     "link 'base': mesh 'gone.stl' not found"),
    ("<robot", "not well-formed XML: unclosed token: line 1, column 0"),
    # Numbers the physics cannot take, refused naming the element (numpy's and LAPACK's errors
    # had come out: a shape mismatch, "Eigenvalues did not converge").
    (ARM.format(mass=1, kind="revolute").replace('<axis xyz="0 1 0"/>', '<axis xyz="0 1"/>'),
     "joint 'shoulder': axis 0 1 is not three finite numbers"),
    (ARM.format(mass=1, kind="revolute").replace('<axis xyz="0 1 0"/>', '<axis xyz="0 nan 1"/>'),
     "joint 'shoulder': axis 0 nan 1 is not three finite numbers"),
    (ARM.format(mass=1, kind="revolute").replace('izz="0.001"', 'izz="nan"'),
     "link 'upper': its inertial's inertia or origin is not finite"),
    (ARM.format(mass=1, kind="revolute").replace('<mass value="1"/>', '<origin xyz="inf 0 0"/><mass value="1"/>'),
     "link 'upper': its inertial's inertia or origin is not finite"),
])
def test_bad_descriptions_name_the_link_or_joint(text, message):
    with pytest.raises(UrdfError, match=re.escape(message)):
        robot_model(text, "arm")


@pytest.mark.parametrize("scale, mesh, message", [
    ("1 1 1", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", "mesh 'part.obj' has no volume"),
    ("0 0 0", None, "mesh 'part.obj': scale 0 0 0 is not three finite numbers, none zero"),
    ("1 1", None, "mesh 'part.obj': scale 1 1 is not three finite numbers, none zero"),
    ("nan 1 1", None, "mesh 'part.obj': scale nan 1 1 is not three finite numbers, none zero"),
])
def test_bad_collision_meshes_name_the_link_and_mesh(tmp_path, scale, mesh, message):
    """A flat collision mesh (qhull's whole report had come out of a spawn as an internal
    error) or a scale of the wrong size, zero or NaN."""
    (tmp_path / "part.obj").write_text(mesh or "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n")
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.format(mass=1, kind="revolute").replace(
        '<box size="0.2 0.2 0.2"/>', f'<mesh filename="part.obj" scale="{scale}"/>'))
    with pytest.raises(UrdfError, match=re.escape(f"link 'base': {message}")):
        robot_model(str(path), "arm")


def test_descriptions_in_any_declared_encoding_load(tmp_path):
    """The XML declaration's encoding is the file's (`<?xml ... encoding="utf-8"?>`, as URDF
    exporters write, had made every such description unreadable: the XML reader refuses text
    that declares one); a file in another encoding without a declaration is refused in words,
    and so is one larger than a scene may be."""
    arm = ARM.format(mass=1, kind="revolute").replace('name="upper"', 'name="über"').replace(
        'link="upper"', 'link="über"')
    plain = robot_model(arm, "arm")
    for encoding in ("utf-8", "ISO-8859-1", "UTF-16"):
        path = tmp_path / f"{encoding}.urdf"
        path.write_bytes(f'<?xml version="1.0" encoding="{encoding}"?>\n{arm}'.encode(encoding))
        model = robot_model(str(path), "arm")
        assert model.bodies == plain.bodies and model.joint_names == plain.joint_names
    assert robot_model(f'<?xml version="1.0" encoding="utf-8"?>{arm}', "arm").bodies == plain.bodies  # as text
    path = tmp_path / "latin.urdf"
    path.write_bytes(arm.encode("ISO-8859-1"))
    with pytest.raises(UrdfError, match=r"latin.urdf: byte \d+ is not utf-8 text \(a file in another encoding says"):
        robot_model(str(path), "arm")
    path = tmp_path / "huge.urdf"
    with open(path, "wb") as stream:
        stream.truncate((16 << 20) + 1)
    with pytest.raises(UrdfError, match="huge.urdf: the description has 16777217 bytes, more than the 16777216 allowed"):
        robot_model(str(path), "arm")


def test_xacro_without_the_package_is_refused_clearly(monkeypatch):
    monkeypatch.setitem(sys.modules, "xacro", None)  # import xacro raises ImportError
    with pytest.raises(UrdfError, match="the xacro package is not installed: pip install xacro"):
        robot_model(HUSKY, "husky")


def test_a_robot_is_added_whole_or_not_at_all():
    world = World()
    world.add_body({"name": "arm.upper", "position": [5, 0, 1]})
    with pytest.raises(UrdfError, match="a body named 'arm.upper' already exists"):
        add_robot(world, robot_model(ARM.format(mass=1, kind="revolute"), "arm"))
    assert world.body_names() == ["arm.upper"] and world.joint_names() == []
    model = robot_model(ARM.format(mass=1, kind="revolute"), "arm2", position=[0, 0, 5000.0])
    with pytest.raises(ValueError, match="outside the world"):
        add_robot(world, model)
    assert world.body_names() == ["arm.upper"] and world.joint_names() == []


def test_links_do_not_collide_with_each_other_unless_asked():
    world, model = loaded(KUKA, "kuka")
    assert len(world._joints.arrays.excluded_pairs) == 8 * 7 // 2  # every pair of its 8 links
    world = World()
    add_robot(world, robot_model(KUKA, "kuka", self_collide=True))
    assert len(world._joints.arrays.excluded_pairs) == 7  # the jointed pairs alone


def test_bodies_kept_apart_pass_through_each_other_and_nothing_else():
    world = World({"gravity": [0, 0, 0]}, ground=None)
    world.add_body({"name": "a", "position": [0, 0, 0]})
    world.add_body({"name": "b", "position": [0.5, 0, 0]})
    world.add_body({"name": "c", "position": [-0.6, 0, 0], "linear_velocity": [1.0, 0, 0]})
    world.disable_collisions(["a", "b"])
    world.step(RATE // 4)
    assert world.body("b")["position"][0] == pytest.approx(0.5, abs=1e-12)  # a and b overlap on
    assert world.body("a")["linear_velocity"][0] > 0.1  # c still hit a
    world.remove_body("b")
    assert len(world._joints.arrays.excluded_pairs) == 0


def test_kuka_follows_a_joint_trajectory_within_a_degree():
    """Every joint swings 0.4 rad at 0.5 Hz about a pose (1.26 rad/s at most), its position
    motor given the trajectory's position and velocity each step, as a trajectory controller
    interpolating a JointTrajectory would."""
    world, model = loaded(KUKA, "kuka")
    joints = world.joint_names()
    pose = np.array([0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1])
    amplitude, omega, phase = 0.4, math.pi, np.arange(7) * 0.7
    for joint, angle in zip(joints, pose + amplitude * np.sin(phase)):
        world.edit_joint(joint, motor={"mode": "position", "target": angle})
    world.step(RATE)  # at the trajectory's start
    worst = 0.0
    for k in range(1, 4 * RATE + 1):
        t = k / RATE
        for joint, angle, speed in zip(joints, pose + amplitude * np.sin(omega * t + phase),
                                       amplitude * omega * np.cos(omega * t + phase)):
            world.edit_joint(joint, motor={"target": angle, "velocity": speed})
        world.step(1)
        if k > RATE // 2:  # after the start's jump in velocity
            reached = np.array([world.joint(joint)["position"] for joint in joints])
            worst = max(worst, np.abs(reached - (pose + amplitude * np.sin(omega * t + phase))).max())
    assert math.degrees(worst) < 1.0


def robot_scene(**robot):
    return {"version": 1, "settings": {"freezing": {"enabled": False}},
            "bodies": [{"name": "crate", "position": [2, 0, 0.5]}],
            "robots": [{"name": "kuka", "urdf": KUKA, "position": [0, 0, 0], **robot}]}


def test_scene_robots_load_and_save_as_robots(tmp_path):
    from vplayground_ros.scene import load_world, save_world, world_to_scene
    world = load_world(robot_scene(joint_positions={"lbr_iiwa_joint_2": 0.5, "lbr_iiwa_joint_4": -1.0}))
    assert world.joint("kuka.lbr_iiwa_joint_2")["position"] == pytest.approx(0.5)
    # The links stand where the joint positions put them: joint 2 turns about y at 0.36 m.
    elbow = world.joint("kuka.lbr_iiwa_joint_4")["anchor"]
    assert elbow[0] == pytest.approx(0.42 * math.sin(0.5), abs=1e-9)  # 0.78 - 0.36 m up the arm
    assert elbow[2] == pytest.approx(0.36 + 0.42 * math.cos(0.5), abs=1e-9)
    world.step(RATE // 4)  # it falls a little, limp
    scene = world_to_scene(world)
    assert [b["name"] for b in scene["bodies"]] == ["crate"] and "joints" not in scene
    saved = scene["robots"][0]
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    assert again.joint_names() == world.joint_names()
    for joint in world.joint_names():
        assert again.joint(joint)["position"] == pytest.approx(world.joint(joint)["position"], abs=1e-9)
    # The links where they were, up to how far the moving joints' anchors are apart (a step's
    # centripetal offset, ~0.1 mm at the limp arm's speed; reloaded, they meet exactly).
    for body in world.body_names():
        np.testing.assert_allclose(again.body(body)["position"], world.body(body)["position"], atol=1e-3)
    assert saved["joint_positions"]["lbr_iiwa_joint_2"] == pytest.approx(world.joint("kuka.lbr_iiwa_joint_2")["position"])


def test_a_robot_saved_against_a_joint_limit_loads_again(tmp_path):
    """A limp arm falls onto a joint limit, which the solver lets give by a little: saved
    there, it loads again as a scene's joint does (the loader had refused the saved scene:
    "'lbr_iiwa_joint_2' at 2.0944 is outside its limits [-2.0944, 2.0944]")."""
    from vplayground_ros.scene import load_world, save_world
    world = load_world(robot_scene(joint_positions={"lbr_iiwa_joint_2": 0.6, "lbr_iiwa_joint_4": -1.2}))

    def past_a_limit():
        return [joint for joint in map(world.joint, world.joint_names())
                if not joint["lower"] <= joint["position"] <= joint["upper"]]
    for _ in range(2 * RATE // 16):
        world.step(16)
        if past_a_limit():
            break
    assert past_a_limit()
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    for joint in world.joint_names():
        assert again.joint(joint)["position"] == pytest.approx(world.joint(joint)["position"], abs=1e-9)


@pytest.mark.parametrize("robot, message", [
    ({"urdf": None}, "robots[0].urdf: expected a file name or the description's text"),
    ({"joint_positions": {"elbow": 1.0}}, "joint_positions: no revolute, continuous or prismatic joint named 'elbow'"),
    ({"name": "crate.x"}, None),
    ({"urdf": "missing.urdf"}, "robots[0].urdf"),
])
def test_scene_robot_errors_name_the_entry(robot, message):
    from vplayground_ros.scene import SceneError, load_world
    if message is None:  # a dotted robot name is fine: its bodies are crate.x.<link>
        assert "crate.x.lbr_iiwa_link_0" in load_world(robot_scene(**robot)).body_names()
        return
    with pytest.raises(SceneError, match=re.escape(message)):
        load_world(robot_scene(**robot))


def test_a_sensor_rides_on_a_robot_link():
    """An IMU on the KUKA's last link, the arm held by its motors at a pose: at rest it reads
    gravity's reaction along the link's axes."""
    from vplayground_ros.scene import load_world
    from vplayground_ros.sensors import Sensors
    scene = robot_scene()
    scene["sensors"] = [{"name": "wrist_imu", "type": "imu", "parent": "kuka.lbr_iiwa_link_7", "rate": 50}]
    world = load_world(scene)
    for joint in world.joint_names():
        world.edit_joint(joint, motor={"mode": "position", "target": 0.0})
    sensors = Sensors()
    world.step(RATE)
    world.step(sensors.steps_until_due(world))
    reading = {s.name: r for s, r in sensors.sample(world)}["wrist_imu"]
    # Upright at every joint 0, the last link's z is up: +g along it.
    assert reading["linear_acceleration"] == pytest.approx([0.0, 0.0, 9.81], abs=0.05)


def test_a_robot_starts_within_its_joint_limits():
    """Past a limit, a joint's correction launched it across its range (the KUKA's joint 4 put
    at 2.9 rad ended at -2.09): a position outside the limits is refused, and a description
    whose zero lies outside them (pybullet_data's a1: its calves' range is [-2.70, -0.92])
    starts at the nearest limit instead of being thrown to the far one at -5 rad/s."""
    with pytest.raises(UrdfError, match=r"'lbr_iiwa_joint_4' at 2.9 is outside its limits \[-2.0944, 2.0944\]"):
        robot_model(KUKA, "k", joint_positions={"lbr_iiwa_joint_4": 2.9})
    world = World({"freezing": {"enabled": False}}, ground=None)
    add_robot(world, robot_model(os.path.join(pybullet_data.getDataPath(), "a1", "a1.urdf"), "a1"))
    for _ in range(8):
        for name in world.joint_names():
            joint = world.joint(name)
            assert joint["lower"] - 1e-6 <= joint["position"] <= joint["upper"] + 1e-6, name
            assert abs(joint["velocity"]) < 1.0, name
        world.step(1)
    assert world.joint("a1.FR_lower_joint")["position"] == pytest.approx(-0.916, abs=1e-2)


def test_a_held_robot_holds_where_its_joints_start():
    """`hold: true` drives each joint's position motor to where it starts: for the a1 whose
    calves start at their upper limit (their zero lies outside it), that limit, not 0 beyond it
    (its motors would push into the limit at full effort for ever)."""
    from vplayground_ros.scene import load_world
    a1 = os.path.join(pybullet_data.getDataPath(), "a1", "a1.urdf")
    world = load_world({"version": 1, "robots": [{"name": "a1", "urdf": a1, "position": [0, 0, 0.5], "hold": True}]})
    joint = world.joint("a1.FR_lower_joint")
    assert joint["motor"]["mode"] == "position" and joint["motor"]["target"] == pytest.approx(joint["upper"])


def test_pybullet_conventions_that_pybullet_data_relies_on():
    """The Franka Panda names its meshes `package://meshes/...` beside its description (PyBullet
    reads the package as a folder there); it had been refused for a mesh not found. A description
    that is not well-formed XML is refused naming the line (the humanoid's NUL after its end had
    given yourdfpy's 'reading file objects must return bytes objects'; now read past)."""
    panda = robot_model(os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf"), "panda")
    assert len(panda.joints) == 9 and all(body["parts"] for body in panda.bodies)
    with pytest.raises(UrdfError, match="not well-formed XML: junk after document element: line 1, column 40"):
        robot_model('<robot name="x"><link name="a"/></robot><junk/>', "r")
    humanoid = os.path.join(pybullet_data.getDataPath(), "humanoid", "humanoid.urdf")
    with pytest.raises(UrdfError, match="Unknown tag: capsule"):  # PyBullet's own geometry, past the NUL
        robot_model(humanoid, "h")
