"""URDF robots as a ROS stack sees them (issue 38): joint_states, robot_description and the link
tree on /tf checked against the description by an independent reader (yourdfpy's forward
kinematics), commands on every command topic, a trajectory followed on the simulation's clock,
the Husky's differential drive with Clearpath's own controller settings, spawn and remove."""
import math
import os
import random
import re
from types import SimpleNamespace as NS

import numpy as np
import pytest
import yaml

from vplayground_ros.api import Requests
from vplayground_ros.interfaces import decoder
from vplayground_ros.scene import SceneError, load_world, world_to_scene
from vplayground_ros.simulation import Simulation
from vplayground_ros.frame_names import DEFAULT_FRAMES
from vplayground_ros.urdf_robots import RobotControl, WheelOdometry, add_robot_entry, drive_joints
from helpers import SPEC_CAR, wait_for
from test_robots import chain, start, tree

pybullet_data = pytest.importorskip("pybullet_data")
yourdfpy = pytest.importorskip("yourdfpy")

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
HUSKY = os.path.join(pybullet_data.getDataPath(), "husky", "husky.urdf")
ARM_JOINTS = [f"lbr_iiwa_joint_{k}" for k in range(1, 8)]
# Clearpath's husky_control (control.yaml): the Husky's diff_drive_controller settings, with
# the wheel radius of this description (its wheels' collision cylinders: 0.17775 m).
HUSKY_DRIVE = {"left_wheel_names": ["front_left_wheel", "rear_left_wheel"],
               "right_wheel_names": ["front_right_wheel", "rear_right_wheel"],
               "wheel_separation": 0.555, "wheel_radius": 0.17775, "wheel_separation_multiplier": 1.875}
# A small car with Ackermann steering, written here: steering hinges (revolute about z, each
# with a small collision sphere inside its wheel) carry the front wheels; the rear ones drive.
CAR_WHEEL = """
  <link name="{name}"><inertial><mass value="0.5"/><inertia ixx="0.0013" iyy="0.0025" izz="0.0013" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin rpy="1.5707963 0 0"/><geometry><cylinder radius="0.1" length="0.05"/></geometry></collision></link>"""
ACKERMANN_CAR = """<robot name="rc">
  <link name="base_link"><inertial><mass value="10"/><inertia ixx="0.24" iyy="0.87" izz="1.04" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="1.0 0.5 0.2"/></geometry></collision></link>""" + "".join(
    CAR_WHEEL.format(name=f"{side}_{end}_wheel") for side in ("left", "right") for end in ("front", "rear")) + "".join(f"""
  <link name="{side}_hinge"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><sphere radius="0.02"/></geometry></collision></link>
  <joint name="{side}_steering" type="revolute"><parent link="base_link"/><child link="{side}_hinge"/>
    <origin xyz="0.35 {y} -0.05"/><axis xyz="0 0 1"/><limit lower="-0.7" upper="0.7" effort="50" velocity="4"/></joint>
  <joint name="{side}_front_axle" type="continuous"><parent link="{side}_hinge"/><child link="{side}_front_wheel"/>
    <axis xyz="0 1 0"/></joint>
  <joint name="{side}_rear_axle" type="continuous"><parent link="base_link"/><child link="{side}_rear_wheel"/>
    <origin xyz="-0.35 {y} -0.05"/><axis xyz="0 1 0"/><limit effort="20" velocity="50"/></joint>""" for side, y in (
    ("left", 0.3), ("right", -0.3))) + "\n</robot>"
# ackermann_steering_controller's keys for it.
ACKERMANN = {"type": "ackermann", "front_wheels_names": ["left_steering", "right_steering"],
             "rear_wheels_names": ["left_rear_axle", "right_rear_axle"], "wheelbase": 0.7, "front_wheel_track": 0.6,
             "rear_wheel_track": 0.6, "rear_wheels_radius": 0.1}
SCENE = {"version": 1, "robots": [{"name": "kuka", "urdf": KUKA},
                                  {"name": "husky", "urdf": HUSKY, "position": [4, 0, 0.02], "drive": HUSKY_DRIVE}]}
JOINT_STATE = decoder("sensor_msgs/msg/JointState")
ODOMETRY = decoder("nav_msgs/msg/Odometry")
STRING = decoder("std_msgs/msg/String")
TF = decoder("tf2_msgs/msg/TFMessage")


@pytest.fixture
def run():
    started = []

    def go(scene=SCENE):
        # As fast as it goes, commands lag in simulated time: they do not lapse here.
        runtime, sink = start(scene, overrides={"cmd_vel_timeout": 1000.0})
        started.append(runtime)
        return runtime, sink
    yield go
    for runtime in started:
        runtime.stop()


def advance(runtime, seconds):
    start = runtime.sim.snapshot.time
    assert wait_for(lambda: runtime.sim.snapshot.time >= start + seconds, 120)


def latest(sink, key, decode=JOINT_STATE):
    return sink.of(key, decode)[-1][1]


def joint_command(names, position=(), velocity=(), effort=()):
    return NS(name=list(names), position=list(position), velocity=list(velocity), effort=list(effort))


def duration(seconds):
    return NS(sec=int(seconds), nanosec=int(round((seconds % 1) * 1e9)))


def trajectory(names, points, stamp=0.0):
    return NS(header=NS(stamp=duration(stamp), frame_id=""), joint_names=list(names),
              points=[NS(positions=list(p), velocities=list(v), accelerations=[], effort=[],
                         time_from_start=duration(t)) for t, p, v in points])


def fitted_circle(points):
    """(radius, spread of the points' distances from the centre) of the least-squares circle
    through 2D points."""
    points = np.asarray(points, dtype=float)
    a = np.c_[2 * points, np.ones(len(points))]
    cx, cy, k = np.linalg.lstsq(a, (points ** 2).sum(axis=1), rcond=None)[0]
    return math.sqrt(k + cx * cx + cy * cy), float(np.std(np.hypot(points[:, 0] - cx, points[:, 1] - cy)))


def pose_matrix(transform):
    t, q = transform.translation, transform.rotation
    x, y, z, w = q.x, q.y, q.z, q.w
    matrix = np.eye(4)
    matrix[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    matrix[:3, 3] = [t.x, t.y, t.z]
    return matrix


def test_joint_states_description_and_link_tree_agree_with_the_description(run):
    """joint_states carries the URDF's joint names; robot_description is the file as loaded; the
    links' transforms on /tf are what the description's kinematics give for those positions."""
    runtime, sink = run()
    runtime.inputs.handle("joint_commands", joint_command(ARM_JOINTS, [0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1]),
                          "/joint_commands")
    advance(runtime, 2.0)
    runtime.sim.stop()
    runtime.stop()
    assert latest(sink, "/robot_description", STRING).data == open(KUKA).read()
    husky = latest(sink, "/husky/robot_description", STRING).data  # xacro's $(optenv ...) expanded
    assert "$(" not in husky and "husky_robot" in husky and husky.count("<link ") == open(HUSKY).read().count("<link ")
    state = latest(sink, "/joint_states")
    assert list(state.name) == ARM_JOINTS
    assert list(latest(sink, "/husky/joint_states").name) == [
        "front_left_wheel", "front_right_wheel", "rear_left_wheel", "rear_right_wheel"]
    parent_of = tree(sink)
    assert chain(parent_of, "lbr_iiwa_link_7") == [f"lbr_iiwa_link_{k}" for k in range(7, -1, -1)] + ["world"]
    assert chain(parent_of, "husky/front_left_wheel_link") == [
        "husky/front_left_wheel_link", "husky/base_link", "husky/base_footprint", "husky/odom", "world"]
    assert parent_of["husky/imu_link"] == "husky/base_link"  # a lumped link: on /tf_static
    # The tip in the base by the published edges against yourdfpy's kinematics at the published
    # positions (the same snapshot: the last state round).
    edges = {t.child_frame_id: pose_matrix(t.transform) for t in latest(sink, "tf", TF).transforms}
    tip = np.eye(4)
    for k in range(1, 8):
        tip = tip @ edges[f"lbr_iiwa_link_{k}"]
    robot = yourdfpy.URDF.load(KUKA, load_meshes=False, build_collision_scene_graph=False)
    robot.update_cfg(dict(zip(state.name, state.position)))
    expected = robot.get_transform("lbr_iiwa_link_7", "lbr_iiwa_link_0")
    assert np.abs(tip[:3, 3] - expected[:3, 3]).max() < 1e-4
    assert np.abs(tip[:3, :3] - expected[:3, :3]).max() < 1e-4
    assert np.allclose(state.position, [0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1], atol=2e-3)  # the command held


def test_every_command_topic_moves_the_arm(run):
    runtime, sink = run({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA, "joints": ARM_JOINTS[::-1]}]})
    inputs = runtime.inputs
    targets = [0.2, -0.3, 0.4, -0.5, 0.3, -0.2, 0.1]
    inputs.handle("position_commands", NS(data=targets), "/position_commands")  # in `joints` order: 7 to 1
    advance(runtime, 2.0)
    assert np.allclose(latest(sink, "/joint_states").position, targets[::-1], atol=2e-3)
    inputs.handle("velocity_commands", NS(data=[0.5] + [0.0] * 6), "/velocity_commands")
    advance(runtime, 0.5)
    assert latest(sink, "/joint_states").velocity[6] == pytest.approx(0.5, abs=1e-3)
    inputs.handle("joint_commands", joint_command(["lbr_iiwa_joint_7"], velocity=[-0.25]), "/joint_commands")
    advance(runtime, 0.5)
    assert latest(sink, "/joint_states").velocity[6] == pytest.approx(-0.25, abs=1e-3)
    # Malformed commands change nothing: the arm's other joints hold still where they were.
    before = latest(sink, "/joint_states").position[:6]
    inputs.handle("position_commands", NS(data=[0.0] * 3), "/position_commands")
    inputs.handle("joint_commands", joint_command(["no_such_joint"], [1.0]), "/joint_commands")
    inputs.handle("joint_commands", joint_command(ARM_JOINTS, [float("nan")] * 7), "/joint_commands")
    advance(runtime, 0.5)
    assert np.allclose(latest(sink, "/joint_states").position[:6], before, atol=1e-3)
    assert runtime.sim.fault_count == 0


def test_an_effort_command_pushes_with_that_effort():
    """An effort is a constant torque (below the joint's speed limit): the joint reports it, and
    its speed grows linearly from rest."""
    world = load_world({"version": 1, "settings": {"gravity": [0, 0, 0]}, "robots": [{"name": "kuka", "urdf": KUKA}]})
    control = RobotControl()
    joint = ["kuka.lbr_iiwa_joint_7"]
    control.command(world, "kuka", "effort", ["lbr_iiwa_joint_7"], [0.02])
    world.step(8)
    _, first, efforts = world.joint_states(joint)
    world.step(8)
    _, second, _ = world.joint_states(joint)
    assert efforts[0] == pytest.approx(0.02, rel=1e-9)
    assert first[0] > 0.0 and second[0] == pytest.approx(2 * first[0], rel=0.02)
    # Beyond the URDF's limits (300 N m, 10 rad/s): the light last link turns at its speed limit.
    control.command(world, "kuka", "effort", ["lbr_iiwa_joint_7"], [-1e6])
    world.step(1)
    _, velocity, effort = world.joint_states(joint)
    assert velocity[0] == pytest.approx(-10.0, rel=1e-6) and -300.0 <= effort[0] < 0.0


def test_a_refused_command_leaves_a_trajectory_running_and_an_ended_one_holds():
    """A command refused for any of its joints (a NaN, an unknown joint) changes nothing: the
    trajectory it named a joint of goes on to its end and holds there (it had been dropped before
    the check, its motor's target moving on at the trajectory's speed for ever). A trajectory
    ended early (RobotControl.hold, as when a point cannot be taken) holds the joint where it is."""
    world = load_world({"version": 1, "settings": {"gravity": [0, 0, 0]}, "robots": [{"name": "kuka", "urdf": KUKA}]})
    control = RobotControl()
    joint = ARM_JOINTS[0]

    def run_for(seconds):
        for _ in range(round(seconds * 16)):
            control.before_batch(world)
            world.step(8)
        return world.joint_states(["kuka." + joint])

    control.follow(world, "kuka", [joint], None, [2.0], [[1.0]], None)
    run_for(1.0)
    with pytest.raises(ValueError, match="not finite"):
        control.command(world, "kuka", "position", [joint, ARM_JOINTS[1]], [0.0, float("nan")])
    with pytest.raises(ValueError, match="no_such_joint"):
        control.command(world, "kuka", "position", [joint, "no_such_joint"], [0.0, 0.0])
    position, velocity, _ = run_for(3.0)
    assert position[0] == pytest.approx(1.0, abs=math.radians(0.2)) and abs(velocity[0]) < 1e-3
    control.follow(world, "kuka", [joint], None, [2.0], [[0.0]], None)
    moving = run_for(1.0)[0][0]
    assert 0.2 < moving < 0.8
    control.hold(world, "kuka", [joint])
    position, velocity, _ = run_for(2.0)
    assert position[0] == pytest.approx(moving, abs=0.02) and abs(velocity[0]) < 1e-3
    # One stamped so that it ended before it came is refused, as joint_trajectory_controller
    # refuses it (run at once, it sent the joint to its last point at its velocity limit).
    with pytest.raises(ValueError, match="ended at .* before now"):
        control.follow(world, "kuka", [joint], world.time - 5.0, [1.0], [[1.5]], None)
    position, velocity, _ = run_for(1.0)
    assert position[0] == pytest.approx(moving, abs=0.02) and abs(velocity[0]) < 1e-3
    control.follow(world, "kuka", [joint], world.time - 0.5, [1.0], [[moving + 0.1]], None)  # still running
    assert run_for(1.0)[0][0] == pytest.approx(moving + 0.1, abs=math.radians(0.2))


def test_a_trajectory_is_followed_within_a_degree(run):
    """A joint_trajectory_controller-style trajectory (positions and velocities at 0.1 s) of a
    sine at 0.5 Hz on every joint, followed on the simulation's clock in the node's batches."""
    runtime, sink = run({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA}]})
    amplitude, omega = 0.4, 2 * math.pi * 0.5
    times = np.arange(1, 41) * 0.1
    points = [(t, [amplitude * math.sin(omega * t)] * 7, [amplitude * omega * math.cos(omega * t)] * 7) for t in times]
    start = runtime.sim.snapshot.time + 1.0  # the header's stamp: it starts then, held till then
    first = [(0.5, [0.0] * 7, [0.0] * 7)] + [(t + 0.5, p, v) for t, p, v in points]
    runtime.inputs.handle("joint_trajectory", trajectory(ARM_JOINTS, first, stamp=start), "/joint_trajectory")
    advance(runtime, 6.0)
    errors = []
    for seconds, state in sink.of("/joint_states", JOINT_STATE):
        t = seconds - start - 0.5
        if 0.5 <= t <= 4.0:  # past the first second of the sine's velocity jump from rest
            errors.append(np.abs(np.array(state.position) - amplitude * math.sin(omega * t)).max())
    assert len(errors) > 50
    assert max(errors) < math.radians(1.0)
    final = latest(sink, "/joint_states")
    assert np.allclose(final.position, points[-1][1], atol=math.radians(0.2))  # held at the last point


def test_the_husky_drives_a_commanded_circle_and_its_wheel_odometry_follows(run):
    """cmd_vel on the Husky's namespace, Clearpath's controller settings: 0.5 m/s at 0.2 rad/s is
    a 2.5 m circle; its wheel odometry (odom -> base_footprint) keeps near the truth."""
    runtime, sink = run()
    runtime.inputs.handle("cmd_vel", NS(linear=NS(x=0.5, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=0.2)),
                          "/husky/cmd_vel")
    advance(runtime, 3.0)
    positions = []
    start = runtime.sim.snapshot.time
    while runtime.sim.snapshot.time < start + 32.0:  # a whole circle
        snap = runtime.sim.snapshot
        positions.append(snap.state["positions"][snap.names.index("husky.base_footprint")][:2].copy())
        advance(runtime, 0.25)
    radius, spread = fitted_circle(positions)
    assert radius == pytest.approx(2.5, rel=0.03)
    assert spread < 0.05  # a circle, not a spiral
    runtime.sim.stop()
    runtime.stop()  # the last state goes out: odometry and the snapshot at one time
    odometry = latest(sink, "/husky/odom", ODOMETRY)
    snap = runtime.sim.snapshot
    assert odometry.header.stamp.sec + 1e-9 * odometry.header.stamp.nanosec == pytest.approx(snap.time, abs=1e-6)
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("husky/odom", "husky/base_footprint")
    assert odometry.twist.twist.linear.x == pytest.approx(0.5, rel=0.05)
    assert odometry.twist.twist.angular.z == pytest.approx(0.2, rel=0.05)
    truth = snap.state["positions"][snap.names.index("husky.base_footprint")]
    pose = odometry.pose.pose.position
    assert math.hypot(pose.x - truth[0], pose.y - truth[1]) < 0.1 * 2 * math.pi * 2.5  # within 10 % of the way


def test_an_ackermann_car_drives_a_commanded_circle_and_its_odometry_follows():
    """cmd_vel as ackermann_steering_controller maps it: 1 m/s at 0.25 rad/s is a 4 m circle,
    the inner front wheel steered more than the outer; odometry from the rear wheels and the
    steering joints follows the truth."""
    world = load_world({"version": 1, "robots": [{"name": "rc", "urdf": ACKERMANN_CAR, "position": [0, 0, 0.16],
                                                  "drive": ACKERMANN}]})
    control = RobotControl()
    joints = ["rc." + joint for joint in drive_joints(ACKERMANN)]
    world.step(64)
    odometry = WheelOdometry(ACKERMANN, (0.0, 0.0, 0.0), world.joint_states(joints)[0], world.time)
    control.drive(world, "rc", 1.0, 0.25, 0.0)
    track = []
    for k in range(int(30 * 128 / 8)):  # 30 m, past a whole circle
        world.step(8)
        odometry.update(world.joint_states(joints)[0], world.time)
        if k > 40:
            track.append(world.body("rc.base_link")["position"][:2])
    assert fitted_circle(track)[0] == pytest.approx(4.0, rel=0.02)
    left, right = world.joint_states(joints)[0][:2]
    assert left == pytest.approx(math.atan(0.7 / (4.0 - 0.3)), abs=2e-3)  # inner
    assert right == pytest.approx(math.atan(0.7 / (4.0 + 0.3)), abs=2e-3)  # outer
    truth = world.body("rc.base_link")["position"]
    assert math.hypot(odometry.x - truth[0], odometry.y - truth[1]) < 0.03 * 30.0
    assert odometry.linear == pytest.approx(1.0, rel=0.02) and odometry.angular == pytest.approx(0.25, rel=0.03)


# Two arms on a fixed base turning about z (gravity does not turn them): `follower` mimics
# `leader` as a steering linkage would, -0.5 x it + 0.1 rad.
ARM_LINK = """<link name="{name}"><inertial><origin xyz="0.25 0 0"/><mass value="1"/>
  <inertia ixx="0.001" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial>
  <collision><origin xyz="0.25 0 0"/><geometry><box size="0.5 0.05 0.05"/></geometry></collision></link>"""
MIMIC = ("""<robot name="linkage"><link name="base"><collision><geometry><box size="0.1 0.1 0.1"/></geometry>
  </collision></link>""" + ARM_LINK.format(name="a") + ARM_LINK.format(name="b") + """
  <joint name="leader" type="revolute"><parent link="base"/><child link="a"/><origin xyz="0 0 1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="50" velocity="2"/></joint>
  <joint name="follower" type="revolute"><parent link="base"/><child link="b"/><origin xyz="0 0 1.2"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="50" velocity="2"/>
    <mimic joint="leader" multiplier="-0.5" offset="0.1"/></joint></robot>""")


def test_a_mimic_joint_follows_its_leader():
    world = load_world({"version": 1, "robots": [{"name": "linkage", "urdf": MIMIC}]})
    control = RobotControl()
    control.command(world, "linkage", "position", ["leader"], [0.6])
    with pytest.raises(ValueError, match="'follower' mimics 'leader': command that one"):
        control.command(world, "linkage", "position", ["follower"], [0.3])
    gaps = []
    for _ in range(64):  # the node's batches: the mimic servo is set before each
        control.before_batch(world)
        world.step(4)
        leader, follower = world.joint_states(["linkage.leader", "linkage.follower"])[0]
        gaps.append(abs(follower - (-0.5 * leader + 0.1)))
    assert leader == pytest.approx(0.6, abs=1e-3)
    assert follower == pytest.approx(-0.2, abs=1e-3)
    assert max(gaps) < 0.02  # in step while the leader swings there
    for _ in range(8 * 128 // 4):  # at rest it sleeps: the servo wakes nothing
        control.before_batch(world)
        world.step(4)
    assert all(world.body(name)["frozen"] for name in ("linkage.a", "linkage.b"))


RACECAR = os.path.join(pybullet_data.getDataPath(), "racecar", "racecar.urdf")
# Its description's geometry: steering hinges 0.325 m ahead of the rear axle, 0.2 m apart, wheels
# of 0.05 m radius, in ackermann_steering_controller's keys.
RACECAR_DRIVE = {"type": "ackermann", "front_wheels_names": ["left_steering_hinge_joint", "right_steering_hinge_joint"],
                 "rear_wheels_names": ["left_rear_wheel_joint", "right_rear_wheel_joint"], "wheelbase": 0.325,
                 "front_wheel_track": 0.2, "rear_wheel_track": 0.2, "rear_wheels_radius": 0.05}


def test_the_racecar_with_links_without_collision_geometry_drives_a_commanded_circle():
    """pybullet_data's racecar: its chassis and steering hinges have no collision geometry (each a
    body on a point-like sphere, with its inertial's mass); on its wheels it drives 1 m/s at
    0.5 rad/s round a 2 m circle."""
    world = load_world({"version": 1, "robots": [{"name": "rc", "urdf": RACECAR, "drive": RACECAR_DRIVE}]})
    assert world.body("rc.left_steering_hinge")["mass"] == pytest.approx(0.1)
    hinge = world.body("rc.left_steering_hinge")["parts"]
    assert len(hinge) == 1 and hinge[0]["shape"] == "sphere" and hinge[0]["radius"] <= 1e-3
    world.step(128)
    assert abs(world.body("rc.base_link")["position"][2]) < 1e-3  # on its wheels, base_link on the ground
    control = RobotControl()
    control.drive(world, "rc", 1.0, 0.5, 0.0)
    track = []
    for k in range(20 * 128 // 8):
        world.step(8)
        if k > 40:
            track.append(world.body("rc.base_link")["position"][:2])
    assert fitted_circle(track)[0] == pytest.approx(2.0, rel=0.02)


def test_robots_spawn_and_go_whole(run, tmp_path):
    runtime, sink = run({"version": 1, "bodies": [{"name": "crate", "position": [5, 5, 0.5]}]})
    requests = runtime.requests
    requests.scene_directories = [os.path.dirname(os.path.dirname(KUKA))]
    ok, message = requests.spawn(yaml.safe_dump({"name": "arm", "urdf": KUKA, "position": [1, 0, 0]}))
    assert ok, message
    assert requests.spawn(yaml.safe_dump({"name": "arm", "urdf": KUKA}))[1].startswith("NAME_NOT_UNIQUE")
    # The description as text: its meshes by absolute path (relative ones have no folder to start from).
    text = open(KUKA).read().replace('filename="meshes/', f'filename="{os.path.dirname(KUKA)}/meshes/')
    ok, message = requests.spawn(yaml.safe_dump({"name": "arm", "urdf": text, "position": [-1, 0, 0],
                                                 "allow_renaming": True}))
    assert (ok, message) == (True, "RESULT_OK: arm_2")
    robots = {r["name"]: r["namespace"] for r in runtime.sim.world.robot_specs}
    assert robots == {"arm": "", "arm_2": "arm_2"}
    assert wait_for(lambda: "/arm_2/joint_commands" in runtime.inputs.robot_inputs())
    assert wait_for(lambda: sink.of("/arm_2/robot_description"))
    (tmp_path / "robot.urdf").write_text(text)
    outside = requests.spawn(yaml.safe_dump({"name": "other", "urdf": str(tmp_path / "robot.urdf")}))
    assert not outside[0] and "outside the allowed directories" in outside[1]
    ok, message = requests.remove(yaml.safe_dump({"entity": "arm_2"}))
    assert ok and "arm_2.lbr_iiwa_link_7" in message
    assert [r["name"] for r in runtime.sim.world.robot_specs] == ["arm"]
    assert not any(name.startswith("arm_2.") for name in runtime.sim.world.body_names())
    assert wait_for(lambda: "/arm_2/joint_commands" not in runtime.inputs.robot_inputs())
    saved = world_to_scene(runtime.sim.world)
    assert [r["name"] for r in saved["robots"]] == ["arm"]
    count = len(runtime.sim.world.body_names())
    assert runtime.parameters.set({"max_bodies": count + 4})[0]  # room for 4 bodies: not for 8 links
    ok, message = requests.spawn(yaml.safe_dump({"name": "third", "urdf": text}))
    assert not ok and "(8 bodies)" in message and "max_bodies" in message
    assert len(runtime.sim.world.body_names()) == count


def test_the_cars_description_spawns_a_car_that_drives_on_its_namespace(run):
    """config/car.urdf (the built-in car's description) spawned over ~/spawn, as a file in the
    scene directories and as text: each is a vehicle (ray-cast wheels) named as asked, in its
    own namespace, and drives on its cmd_vel."""
    runtime, sink = run({"version": 1, "bodies": [{"name": "crate", "position": [5, 5, 0.5]}]})
    requests = runtime.requests
    car = os.path.join(os.path.dirname(__file__), "..", "config", "car.urdf")
    requests.scene_directories = [os.path.dirname(car)]
    ok, message = requests.spawn(yaml.safe_dump({"name": "red", "urdf": car, "position": [0, -10, 1]}))
    assert (ok, message) == (True, "RESULT_OK: red")
    ok, message = requests.spawn(yaml.safe_dump({"name": "blue", "urdf": open(car).read(), "namespace": "fleet/blue",
                                                 "position": [0, 10, 1]}))
    assert (ok, message) == (True, "RESULT_OK: blue")
    world = runtime.sim.world
    assert world.vehicle_names() == ["red", "blue"] and world.robot_specs == []
    assert {name: world.vehicle(name)["namespace"] for name in ("red", "blue")} == {"red": "", "blue": "fleet/blue"}
    assert world.vehicle("red")["wheels"] == load_world({"version": 1, "vehicles": [SPEC_CAR]}).vehicle("car")["wheels"]
    assert wait_for(lambda: "blue" in runtime.sim.snapshot.vehicle_specs)
    runtime.inputs.handle("cmd_vel", NS(linear=NS(x=3.0, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=0.0)),
                          "/fleet/blue/cmd_vel")
    advance(runtime, 2.0)
    assert runtime.sim.call(lambda world: world.body("blue")["position"][0]) > 1.0
    assert abs(runtime.sim.call(lambda world: world.body("red")["position"][0])) < 0.05
    assert not requests.spawn(yaml.safe_dump({"name": "green", "urdf": car, "hold": True}))[0]
    # By its bare name, as a scene's robots entry finds it: the package's config/ last.
    requests.scene_directories = []  # none: the package's own folders alone
    ok, message = requests.spawn(yaml.safe_dump({"name": "green", "urdf": "car.urdf", "position": [0, 20, 1]}))
    assert (ok, message) == (True, "RESULT_OK: green") and "green" in world.vehicle_names()
    # ... and never out of that folder: a request named any file there once (config/../setup.py).
    for name in ("../config/car.urdf", "../setup.py", "sub/../../config/car.urdf"):
        ok, message = requests.spawn(yaml.safe_dump({"name": "stray", "urdf": name}))
        assert not ok and "not found" in message, (name, message)


def test_a_robot_that_loses_a_link_or_a_joint_is_no_longer_one():
    world = load_world({"version": 1, "robots": [{"name": "a", "urdf": KUKA},
                                                 {"name": "b", "urdf": KUKA, "position": [2, 0, 0]}]})
    world.remove_joint("a.lbr_iiwa_joint_3")
    assert [r["name"] for r in world.robot_specs] == ["b"]
    world.remove_bodies(["b.lbr_iiwa_link_7"])
    assert world.robot_specs == []
    assert "a.lbr_iiwa_link_7" in world.body_names() and "a.lbr_iiwa_joint_4" in world.joint_names()
    saved = world_to_scene(world)
    assert "robots" not in saved and "a.lbr_iiwa_link_1" in [b["name"] for b in saved["bodies"]]


def test_commands_do_not_pass_to_another_robot_of_the_same_name():
    """A trajectory and a drive given to a robot end with it: a robot spawned under its name
    after it was removed stays as it was loaded."""
    world = load_world({"version": 1, "settings": {"gravity": [0, 0, 0]},
                        "robots": [{"name": "kuka", "urdf": KUKA}, {"name": "husky", "urdf": HUSKY,
                                                                     "position": [4, 0, 0.2], "drive": HUSKY_DRIVE}]})
    control = RobotControl()
    control.follow(world, "kuka", ARM_JOINTS[:1], None, [1.0], [[0.5]], None)
    control.drive(world, "husky", 1.0, 0.0, 100.0)
    for _ in range(8):  # batches, as the node steps
        control.before_batch(world)
        world.step(4)
    assert world.joint_states(["kuka.lbr_iiwa_joint_1"])[0][0] > 0.05
    for robot in list(world.robot_specs):
        world.remove_bodies(robot["bodies"])
        add_robot_entry(world, robot, robot["model"], "robots", DEFAULT_FRAMES)
    assert [r["name"] for r in world.robot_specs] == ["kuka", "husky"]
    for _ in range(16):
        control.before_batch(world)
        world.step(4)
    assert control.trajectories == {} and control.drive_deadlines == {}
    positions, velocities, _ = world.joint_states(["kuka.lbr_iiwa_joint_1", "husky.front_left_wheel"])
    assert abs(positions[0]) < 1e-6 and abs(velocities[1]) < 1e-3


@pytest.mark.parametrize("robot, message", [
    ({"joints": ["lbr_iiwa_joint_1", "elbow"]}, "robots[0].joints: 'elbow' is no revolute"),
    ({"drive": {**HUSKY_DRIVE, "left_wheel_names": ["lbr_iiwa_joint_1"], "right_wheel_names": ["x"]}},
     "robots[0].drive.right_wheel_names: 'x' is no revolute or continuous joint"),
    ({"drive": {"left_wheel_names": ["a"], "right_wheel_names": ["b"], "wheel_radius": 0.1}},
     "robots[0].drive.wheel_separation: missing"),
    ({"namespace": "a b"}, "robots[0].namespace: 'a b' is not a relative ROS namespace"),
    ({"drive": {**ACKERMANN, "front_wheels_names": ["lbr_iiwa_joint_1"]}},
     "robots[0].drive.front_wheels_names: expected two joints: left, right"),
    ({"drive": {**ACKERMANN, "wheel_radius": 0.1}}, "robots[0].drive.wheel_radius: unknown key (allowed: front_wheel_track"),
    ({"drive": {"type": "tank"}}, "robots[0].drive.type: 'tank': expected one of diff_drive, ackermann"),
])
def test_bad_robot_entries_are_refused_naming_the_key(robot, message):
    with pytest.raises(SceneError, match=re.escape(message)):
        load_world({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA, **robot}]})


def test_a_description_that_is_not_there_is_named_as_one():
    """A robot's description file that is not found is named so, in ~/spawn and a scene file
    alike (the lookup is a mesh's: its error had said "mesh file", as if the robot's mesh were
    missing)."""
    requests = Requests(Simulation(load_world({"version": 1})), scene_directories=[])
    ok, message = requests.spawn(yaml.safe_dump({"name": "lost", "urdf": "no_such_robot.urdf"}))
    assert not ok and message.startswith("MISSING_ASSETS: spawn.urdf: robot description 'no_such_robot.urdf' "
                                         "not found (looked in: "), message
    with pytest.raises(SceneError, match=re.escape("robots[0].urdf: robot description 'no_such_robot.urdf' not found")):
        load_world({"version": 1, "robots": [{"name": "lost", "urdf": "no_such_robot.urdf"}]})


def test_a_robot_may_not_take_a_namespace_that_is_taken():
    with pytest.raises(SceneError, match="robots\\[1\\].namespace: 'left' is the namespace of a already"):
        load_world({"version": 1, "robots": [{"name": "a", "urdf": KUKA, "namespace": "left"},
                                             {"name": "b", "urdf": KUKA, "namespace": "left", "position": [2, 0, 0]}]})


def test_a_sensor_may_not_publish_on_a_urdf_robots_topic():
    imu = {"name": "imu", "type": "imu", "parent": "kuka.lbr_iiwa_link_7", "topic": "joint_states"}
    with pytest.raises(SceneError, match="/joint_states is kuka's joint_states already"):
        load_world({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA}], "sensors": [imu]})
    load_world({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA}], "sensors": [{**imu, "topic": "arm_imu"}]})
    with pytest.raises(SceneError, match="the frame 'lbr_iiwa_link_7' is a link of the robot kuka"):
        load_world({"version": 1, "robots": [{"name": "kuka", "urdf": KUKA}],
                    "sensors": [{**imu, "topic": "arm_imu", "frame_id": "lbr_iiwa_link_7"}]})


ROVER = {"name": "rover", "urdf": "rover.urdf", "drive": {"left_wheel_names": ["left_wheel_joint"],
                                                          "right_wheel_names": ["right_wheel_joint"],
                                                          "wheel_separation": 0.48, "wheel_radius": 0.1}}


def test_no_body_or_sensor_takes_a_robots_link_frame_nor_a_robot_a_bodys_name():
    """A robot in the root namespace publishes its links' frames by their names (`left_wheel`,
    `lidar_link`): a body of that name (its frame on /tf when it carries a sensor, or with
    publish_body_frames) or a sensor would give that frame two parents. Refused whichever comes
    first, in a scene file, ~/spawn (allow_renaming picks another name for a body or a sensor)
    and a robot spawned where such a body is, naming both; what was there stays."""
    crate = {"name": "left_wheel", "size": [0.3, 0.3, 0.3], "position": [3, 0, 0.15]}
    imu = {"name": "wheel_imu", "type": "imu", "parent": "left_wheel"}
    with pytest.raises(SceneError, match=re.escape("robots[0].namespace: the robot rover's link 'left_wheel' would be "
                                                   "the frame 'left_wheel', which is the name of the body 'left_wheel'")):
        load_world({"version": 1, "robots": [ROVER], "bodies": [crate], "sensors": [imu]})
    with pytest.raises(SceneError, match=re.escape("the frame 'lidar_link' is a link of the robot rover")):
        load_world({"version": 1, "robots": [ROVER], "sensors": [{"name": "lidar_link", "type": "imu",
                                                                    "parent": "world"}]})
    # In the robot's own namespace its frames are rover/left_wheel...: the body may be left_wheel.
    load_world({"version": 1, "robots": [{**ROVER, "namespace": "rover"}], "bodies": [crate], "sensors": [imu]})

    requests = Requests(Simulation(load_world({"version": 1, "robots": [ROVER]})), scene_directories=[])
    before = requests.sim.world.body_names()
    pair = [{"name": "lidar_link", "size": [0.3, 0.3, 0.3], "position": [3, 0, 0.15]},
            {"name": "box_imu", "type": "imu", "parent": "lidar_link"}]
    ok, message = requests.spawn(yaml.safe_dump(pair))
    assert not ok and message.startswith("NAME_NOT_UNIQUE: [0].name: 'lidar_link' is a link of the robot rover, "
                                         "a frame the node publishes"), message
    ok, message = requests.spawn(yaml.safe_dump({"name": "left_wheel", "type": "imu", "parent": "world"}))
    assert not ok and message.startswith("NAME_NOT_UNIQUE: spawn.name: 'left_wheel' is a link of the robot rover"), message
    assert requests.sim.world.body_names() == before and requests.sim.world.sensor_specs == []
    renamed = [{**pair[0], "allow_renaming": True}, pair[1]]
    assert requests.spawn(yaml.safe_dump(renamed)) == (True, "RESULT_OK: lidar_link_2, box_imu")
    assert requests.sim.world.sensor_specs[0]["parent"] == "lidar_link_2"

    # The other way round: the robot comes second, into the root namespace (no vehicle has it).
    requests = Requests(Simulation(load_world({"version": 1, "bodies": [crate]})), scene_directories=[])
    ok, message = requests.spawn(yaml.safe_dump({"name": "rover", "urdf": "rover.urdf"}))
    assert not ok and message.startswith("NAME_NOT_UNIQUE: spawn.namespace: the robot rover's link 'left_wheel' would "
                                         "be the frame 'left_wheel', which is the name of the body 'left_wheel'"), message
    assert requests.sim.world.body_names() == ["left_wheel"] and requests.sim.world.robot_specs == []
    assert requests.spawn(yaml.safe_dump({"name": "rover", "urdf": "rover.urdf", "namespace": "rover"}))[0]
    # ... or where a sensor's frame is.
    requests = Requests(Simulation(load_world({"version": 1, "sensors": [{"name": "lidar_link", "type": "imu",
                                                                          "parent": "world"}]})), scene_directories=[])
    ok, message = requests.spawn(yaml.safe_dump({"name": "rover", "urdf": "rover.urdf"}))
    assert not ok and message.startswith("NAME_NOT_UNIQUE: spawn.namespace: the robot rover's link 'lidar_link' would "
                                         "be the frame 'lidar_link', which is the frame of the sensor lidar_link"), message
    assert requests.sim.world.body_names() == [] and [s["name"] for s in requests.sim.world.sensor_specs] == ["lidar_link"]


def test_a_sensor_may_not_take_a_robots_odom_frame_under_the_nodes_frame_names():
    """A URDF robot with a drive publishes its odom frame under the odom_frame parameter's name
    (`rover/odometry` here): a sensor's frame_id there gives it two parents. A scene's sensors
    and a robot spawned onto a sensor's frame were checked against the default name alone
    (`rover/odom`, which nothing publishes here, refused; `rover/odometry` let through), where
    ~/spawn's sensors met the parameter's."""
    frames = DEFAULT_FRAMES._replace(odom="odometry")
    rover = {**ROVER, "namespace": "rover"}
    sensor = {"name": "s", "type": "imu", "parent": "world", "frame_id": "rover/odometry"}
    with pytest.raises(SceneError, match=re.escape("sensors: s.frame_id: the frame 'rover/odometry' is the odom "
                                                   "frame of the robot rover")):
        load_world({"version": 1, "robots": [rover], "sensors": [sensor]}, frames=frames)
    load_world({"version": 1, "robots": [rover], "sensors": [{**sensor, "frame_id": "rover/odom"}]}, frames=frames)

    requests = Requests(Simulation(load_world({"version": 1, "sensors": [sensor]}, frames=frames)),
                        scene_directories=[], settings={"world_frame": "world", "odom_frame": "odometry",
                                                        "footprint_frame": "base_footprint", "base_frame": "base_link"})
    ok, message = requests.spawn(yaml.safe_dump(rover))
    assert not ok and "the frame 'rover/odometry' is the odom frame of the robot rover" in message, message
    assert requests.sim.world.body_names() == [] and requests.sim.world.robot_specs == []


def test_a_body_or_sensor_after_a_robot_in_one_spawn_meets_its_frames_as_after_its_spawn():
    """A robot and, later in the same ~/spawn, a body or a sensor named like one of the robot's
    frames: answered as that body or sensor spawned once the robot is there (NAME_NOT_UNIQUE
    naming the frame, or another name with allow_renaming), the world unchanged when refused. A
    sensor's had been RESULT_OPERATION_FAILED about its frame_id, a body's refused whatever
    allow_renaming said. A body before the robot is what a robot spawned where it stands meets;
    in its own namespace (a vehicle of the request takes the root one) the robot's frames are
    rover/...: no clash."""
    crate = {"name": "left_wheel", "size": [0.3, 0.3, 0.3], "position": [3, 0, 0.15]}
    imu = {"name": "left_wheel", "type": "imu", "parent": "world"}
    link = "'left_wheel' is a link of the robot rover, a frame the node publishes"
    for request, answer in (
            ([ROVER, crate], f"NAME_NOT_UNIQUE: [1].name: {link} (allow_renaming: true picks a free name)"),
            ([ROVER, imu], f"NAME_NOT_UNIQUE: [1].name: {link} (sensor names are frames; allow_renaming: true"),
            ([ROVER, {**imu, "name": "probe", "frame_id": "left_wheel"}], f"NAME_NOT_UNIQUE: [1].frame_id: {link}"),
            ([crate, ROVER], "NAME_NOT_UNIQUE: [1].namespace: the robot rover's link 'left_wheel' would be the frame "
                             "'left_wheel', which is the name of the body 'left_wheel'"),
            ([ROVER, {**crate, "allow_renaming": True}], "RESULT_OK: left_wheel_2, rover"),
            ([ROVER, {**imu, "allow_renaming": True}], "RESULT_OK: rover, left_wheel_2"),
            ([{"name": "car", "urdf": "car.urdf", "position": [-5, 0, 1]}, ROVER, crate],
             "RESULT_OK: car, left_wheel, rover")):
        requests = Requests(Simulation(load_world({"version": 1})), scene_directories=[])
        ok, message = requests.spawn(yaml.safe_dump(request))
        assert (ok, message[:len(answer)]) == (answer.startswith("RESULT_OK"), answer), message
        if not ok:
            world = requests.sim.world
            assert (world.body_names(), world.sensor_specs, world.robot_specs) == ([], [], [])


def test_a_sensor_rides_a_link_a_fixed_joint_lumps_into_its_parent():
    """The rover's lidar_link is lumped into base_footprint's body by fixed joints (0.12 m up,
    then 0.2 forward and 0.1 up): a lidar on it, the most natural mount, had been refused as
    'no vehicle or body named rover.lidar_link'. It rides that body, its pose composed with the
    link's there, in a scene file, ~/spawn and ~/edit alike; saved so, it loads the same."""
    scan = {"name": "front_scan", "type": "lidar_2d", "parent": "rover.lidar_link", "pose": [0.05, 0, 0.02, 0, 0, 0.5]}
    world = load_world({"version": 1, "robots": [ROVER], "sensors": [scan]})
    (spec,) = world.sensor_specs
    assert spec["parent"] == "rover.base_footprint"
    assert spec["pose"] == pytest.approx([0.25, 0.0, 0.24, 0.0, 0.0, 0.5], abs=1e-12)
    again = load_world(world_to_scene(world))
    assert again.sensor_specs[0]["parent"] == spec["parent"] and again.sensor_specs[0]["pose"] == pytest.approx(spec["pose"])

    requests = Requests(Simulation(load_world({"version": 1, "robots": [ROVER]})), scene_directories=[])
    ok, message = requests.spawn(yaml.safe_dump(scan))
    assert ok, message
    assert requests.sim.world.sensor_specs[0]["pose"] == pytest.approx(spec["pose"], abs=1e-12)
    ok, message = requests.edit(yaml.safe_dump({"entity": "front_scan", "parent": "rover.base_link",
                                                "pose": [0, 0, 0, 0, 0, 0]}))
    assert ok, message
    edited = requests.sim.world.sensor_specs[0]
    assert edited["parent"] == "rover.base_footprint" and edited["pose"] == pytest.approx([0, 0, 0.12, 0, 0, 0], abs=1e-12)
    with pytest.raises(SceneError, match="no vehicle or body named 'rover.no_such_link'"):
        load_world({"version": 1, "robots": [ROVER], "sensors": [{**scan, "parent": "rover.no_such_link"}]})


def test_a_teleported_drive_starts_its_odometry_again_where_it_stands(run):
    """A URDF robot with a drive moved by ~/edit (it could not have driven there) starts its
    wheel odometry again at its true pose, world -> odom as at its spawn, as a vehicle's does:
    its wheels did not turn, and the odometry had stayed where it was left (odom jumped)."""
    runtime, sink = run({"version": 1, "robots": [ROVER]})
    advance(runtime, 0.5)

    def odom_in_world():
        edge = next(t for t in sink.of("tf", TF)[-1][1].transforms if t.child_frame_id == "odom")
        assert edge.header.frame_id == "world"
        return edge.transform.translation
    spawned = odom_in_world()
    start = runtime.sim.call(lambda world: world.body("rover.base_footprint")["position"])
    ok, message = runtime.requests.edit(yaml.safe_dump({"entity": "rover",
                                                        "position": [start[0] + 5.0, start[1] + 2.0, start[2]]}))
    assert ok, message
    advance(runtime, 0.5)
    truth = runtime.sim.call(lambda world: world.body("rover.base_footprint")["position"])
    assert wait_for(lambda: abs(latest(sink, "/odom", ODOMETRY).pose.pose.position.x - truth[0]) < 0.05,
                    explain=lambda: (latest(sink, "/odom", ODOMETRY).pose.pose.position, truth))
    odometry = latest(sink, "/odom", ODOMETRY).pose.pose.position
    assert math.hypot(odometry.x - truth[0], odometry.y - truth[1]) < 0.05
    moved = odom_in_world()
    assert math.hypot(moved.x - spawned.x, moved.y - spawned.y) < 0.05, (moved, spawned)


def test_robots_are_drawn_by_their_visual_elements_locked_to_their_links(run):
    """~/robots/visuals (latched) draws each link's <visual> (meshes as triangles, in the
    description's colours) in the link's frame, frame-locked so /tf moves it; the robots' bodies
    (their collision shapes) are left out of the bodies' markers."""
    runtime, sink = run()
    advance(runtime, 0.5)
    runtime.sim.stop()
    runtime.stop()
    markers = latest(sink, "robot_visuals", decoder("visualization_msgs/msg/MarkerArray")).markers
    drawn = [m for m in markers if m.action == 0]
    robot = yourdfpy.URDF.load(KUKA, load_meshes=False, build_collision_scene_graph=False)
    kuka = [m for m in drawn if m.header.frame_id.startswith("lbr_iiwa_link_")]
    assert len(kuka) == sum(len(link.visuals) for link in robot.robot.links)
    assert all(m.frame_locked and m.type == 11 and len(m.points) % 3 == 0 and m.ns == m.header.frame_id for m in kuka)
    blue = {m.name: m.color.rgba for m in robot.robot.materials}["Blue"]
    link_1 = next(m for m in kuka if m.header.frame_id == "lbr_iiwa_link_1")
    assert [link_1.color.r, link_1.color.g, link_1.color.b, link_1.color.a] == pytest.approx(list(blue))
    assert any(m.header.frame_id == "husky/front_left_wheel_link" for m in drawn)
    body_markers = decoder("visualization_msgs/msg/MarkerArray")
    for key in ("body_markers", "resting_markers"):
        for _, message in sink.of(key, body_markers):
            assert not [m for m in message.markers if m.action == 0 and m.id in robot_marker_ids(runtime)]


def robot_marker_ids(runtime):
    names = [body for spec in runtime.sim.world.robot_specs for body in spec["bodies"]]
    return {runtime.broadcaster.marker_ids[name] for name in names if name in runtime.broadcaster.marker_ids}


def test_a_sensor_on_a_robots_link_hangs_from_that_link_in_its_namespace(run):
    """An IMU on the Husky's body: its frame is husky/<name> under husky/base_footprint (the
    body's link), it publishes on the robot's imu/data, and a request may name the link frame."""
    imu = {"name": "chassis_imu", "type": "imu", "parent": "husky.base_footprint", "pose": [0, 0, 0.3, 0, 0, 0],
           "rate": 50}
    held = [{**SCENE["robots"][0], "hold": True}, SCENE["robots"][1]]  # the arm holds still: a frame to spawn in
    runtime, sink = run({**SCENE, "robots": held, "sensors": [imu]})
    advance(runtime, 0.5)
    parent_of = tree(sink)
    assert chain(parent_of, "husky/chassis_imu")[:4] == ["husky/chassis_imu", "husky/base_footprint", "husky/odom",
                                                          "world"]
    readings = sink.of("sensor:husky/imu/data:sensor_msgs/msg/Imu", decoder("sensor_msgs/msg/Imu"))
    assert readings and readings[-1][1].header.frame_id == "husky/chassis_imu"
    ok, message = runtime.requests.spawn(yaml.safe_dump({
        "name": "on_the_arm", "size": [0.1, 0.1, 0.1], "immovable": True,
        "initial_pose": {"header": {"frame_id": "lbr_iiwa_link_7"}, "pose": {"position": {"x": 0, "y": 0, "z": 0.5}}}}))
    assert ok, message
    tip = runtime.sim.call(lambda world: world.body("kuka.lbr_iiwa_link_7"))
    placed = runtime.sim.call(lambda world: world.body("on_the_arm"))
    assert np.linalg.norm(np.subtract(placed["position"], tip["position"])) == pytest.approx(0.5, abs=0.01)


def test_the_example_scene_brings_a_rover_that_drives_and_an_arm_that_holds(run):
    """config/robots_scene.yaml (the README's example, with the package's own rover.urdf and
    arm.urdf): the rover in the root namespace drives on /cmd_vel and publishes /scan from a
    lidar on its base; the arm under /arm holds its joint positions."""
    scene = os.path.join(os.path.dirname(__file__), "..", "config", "robots_scene.yaml")
    runtime, sink = run(scene)
    assert {r["name"]: r["namespace"] for r in runtime.sim.world.robot_specs} == {"rover": "", "arm": "arm"}
    start = runtime.sim.call(lambda world: world.body("rover.base_footprint")["position"])
    runtime.inputs.handle("cmd_vel", NS(linear=NS(x=1.0, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=0.0)))
    advance(runtime, 2.0)
    moved = np.subtract(runtime.sim.call(lambda world: world.body("rover.base_footprint")["position"]), start)
    assert moved[0] > 1.5 and abs(moved[1]) < 0.05
    arm = latest(sink, "/arm/joint_states")
    assert list(arm.name) == ["yaw", "shoulder", "elbow"]
    assert np.allclose(arm.position, [0.5, 0.6, 1.2], atol=2e-3)
    scan = sink.of("sensor:scan:sensor_msgs/msg/LaserScan", decoder("sensor_msgs/msg/LaserScan"))
    assert scan and scan[-1][1].header.frame_id == "laser"
    assert tree(sink)["laser"] == "base_footprint"


def test_partial_resets_keep_the_scenes_robots_and_restore_them(run):
    """ResetSimulation's scopes with a scene's robots: SPAWNED keeps them (their links are the
    scene's), STATE puts their links and joints back as loaded, TIME forgets the commands given
    commands carry on on the new clock (a drive's deadline moves back with it)."""
    imu = {"name": "tip_imu", "type": "imu", "parent": "kuka.lbr_iiwa_link_7", "rate": 50}
    runtime, sink = run({**SCENE, "sensors": [imu]})
    requests = runtime.requests
    runtime.inputs.handle("joint_commands", joint_command(ARM_JOINTS, [0.3] * 7), "/joint_commands")
    advance(runtime, 1.0)
    assert requests.reset(4)[0]  # SPAWNED
    assert [r["name"] for r in runtime.sim.world.robot_specs] == ["kuka", "husky"]
    assert requests.reset(2)[0]  # STATE
    positions = runtime.sim.call(lambda world: world.joint_states([f"kuka.{j}" for j in ARM_JOINTS])[0])
    assert np.allclose(positions, 0.0, atol=1e-3)  # as loaded (it was at 0.3), and falling again since
    # The sensor on the arm's link is on the restored link (a new body) and goes on.
    restored = runtime.sim.snapshot.time
    advance(runtime, 0.2)
    assert [s["name"] for s in runtime.sim.world.sensor_specs] == ["tip_imu"]
    assert sink.of("sensor:imu/data:sensor_msgs/msg/Imu")[-1][0] > restored
    runtime.parameters.set({"cmd_vel_timeout": 0.5})
    runtime.inputs.handle("cmd_vel", NS(linear=NS(x=0.5, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=0.0)),
                          "/husky/cmd_vel")
    advance(runtime, 0.1)
    assert requests.reset(1)[0]  # TIME: 0.5 s of command left, counted on the new clock
    advance(runtime, 1.0)
    speeds = runtime.sim.call(lambda world: world.joint_states(["husky.front_left_wheel"])[1])
    assert abs(speeds[0]) < 0.1


def test_hostile_robot_requests_change_nothing(run, tmp_path):
    """What a request may not do with a description: xacro (it reads environment variables and
    any file), meshes outside the scene directories, a robot named like a body (or a body like a
    robot), a link that would be the world frame in the root namespace; and a robot is moved
    whole or not at all. A trajectory for a mimic joint is refused; nothing pauses."""
    runtime, sink = run({"version": 1, "bodies": [{"name": "crate", "position": [5, 5, 0.5]}],
                         "robots": [{"name": "linkage", "urdf": MIMIC, "namespace": "lk"}]})
    requests = runtime.requests
    requests.scene_directories = [tmp_path]
    xacro = MIMIC.replace('<robot name="linkage">', '<robot name="linkage"><!-- $(env HOME) -->')
    ok, message = requests.spawn(yaml.safe_dump({"name": "x", "urdf": xacro}))
    assert not ok and message.startswith("RESOURCE_PARSE_ERROR") and "xacro" in message
    meshes = open(KUKA).read().replace('filename="meshes/', f'filename="{os.path.dirname(KUKA)}/meshes/')
    ok, message = requests.spawn(yaml.safe_dump({"name": "k", "urdf": meshes}))
    assert not ok and "outside the allowed directories" in message
    ok, message = requests.spawn(yaml.safe_dump({"name": "crate", "urdf": MIMIC}))
    assert not ok and message.startswith("NAME_NOT_UNIQUE")
    ok, message = requests.spawn(yaml.safe_dump({"name": "linkage", "size": [1, 1, 1], "position": [0, 5, 1]}))
    assert not ok and message.startswith("NAME_NOT_UNIQUE")
    rooted = MIMIC.replace('<link name="base">', '<link name="world">').replace('<parent link="base"/>',
                                                                           '<parent link="world"/>')
    ok, message = requests.spawn(yaml.safe_dump({"name": "w", "urdf": rooted, "namespace": ""}))
    assert not ok and "its link 'world' would be the frame 'world'" in message
    ok, message = requests.spawn(yaml.safe_dump({"name": "w", "urdf": rooted, "position": [3, 3, 0]}))
    assert ok, message  # in its own namespace: the frame w/world
    assert runtime.sim.call(lambda world: world.body("w.world")["immovable"])  # a root named world is fixed
    before = runtime.sim.call(lambda world: [world.body(b)["position"] for b in ("linkage.base", "linkage.a")])
    ok, message = requests.edit(yaml.safe_dump({"entity": "linkage", "position": [0, 0, 1999.9]}))
    assert not ok and "outside" in message
    after = runtime.sim.call(lambda world: [world.body(b)["position"] for b in ("linkage.base", "linkage.a")])
    assert np.allclose(before, after)
    runtime.inputs.handle("joint_trajectory", trajectory(["follower"], [(1.0, [0.3], [0.0])]), "/lk/joint_trajectory")
    advance(runtime, 0.5)
    assert not runtime.sim.paused and runtime.sim.fault_count == 0
    assert runtime.sim.world.robot_specs[0]["joints"] == ["leader"]  # a mimic joint is in no command order


def test_mimic_joints_take_no_place_in_commands_or_drives():
    with pytest.raises(SceneError, match="robots\\[0\\].joints: 'follower' mimics 'leader'"):
        load_world({"version": 1, "robots": [{"name": "linkage", "urdf": MIMIC, "joints": ["leader", "follower"]}]})


def test_a_limited_link_crushed_by_cars_gains_no_energy():
    """Three 1,200 kg cars spawned into one another beside the linkage: pushed apart, one climbs
    onto its 1 kg links and pins them at their limits. The cars part at a few m/s and the links
    end at their limits. The links' limit rows, solved before their joints' equalities with an
    effective mass through them, had taken energy from every sweep: a link reached 1,359 m/s
    within 0.7 s and threw the cars away."""
    cars = [{"name": f"car{k}", "urdf": "car.urdf", "position": [x, 0, 0.3]} for k, x in enumerate([2.81, 4.26, 2.06])]
    world = load_world({"version": 1, "robots": [{"name": "linkage", "urdf": MIMIC, "position": [0, 0, 0.3]}] + cars})
    fastest = 0.0
    for _ in range(3 * 128):
        world.step(1)
        fastest = max(fastest, np.linalg.norm(world.state()["linear_velocities"], axis=1).max())
    assert fastest < 10.0
    positions, velocities, _ = world.joint_states(["linkage.leader", "linkage.follower"])
    assert np.all(np.abs(positions) < 1.0 + 0.01) and np.all(np.abs(velocities) < 0.01)
    assert sorted(world.body_names()) == sorted(["car0", "car1", "car2", "linkage.base", "linkage.a", "linkage.b"])


def test_mutated_descriptions_and_hostile_commands_leave_the_world_whole(run):
    """Descriptions with random damage are refused or added whole, and commands with bad names,
    counts and values (NaN, inf, 1e9) on every command topic are refused or bounded: nothing
    raises, nothing pauses, every body stays finite, every robot keeps all its links."""
    runtime, sink = run({"version": 1, "robots": [{"name": "lk", "urdf": MIMIC, "namespace": "lk"},
                                                  {"name": "rc", "urdf": ACKERMANN_CAR, "position": [3, 0, 0.16],
                                                   "drive": ACKERMANN}]})
    rng = random.Random(5)
    tokens = ['"', "<", ">", "/", "0", "-1", "nan", "1e30", "inf", " ", "joint", "link", "mimic", "world", "wheel",
              "vehicle", "true"]
    car = open(os.path.join(os.path.dirname(__file__), "..", "config", "car.urdf")).read()  # a vehicle's
    added = 0
    for k in range(300):
        text = list(rng.choice([MIMIC, ACKERMANN_CAR, car]))
        for _ in range(rng.randrange(1, 6)):
            i = rng.randrange(len(text))
            if rng.random() < 0.5:
                del text[i:i + rng.randrange(1, 20)]
            else:
                text[i:i] = list(rng.choice(tokens))
        ok, message = runtime.requests.spawn(yaml.safe_dump({"name": f"m{k}", "urdf": "".join(text),
                                                             "position": [rng.uniform(-20, 20), 20.0, 0.3]}))
        added += ok
    values = [0.0, 1.0, -1.0, 1e9, -1e9, float("nan"), float("inf"), 1e6]
    names = ["leader", "follower", "left_steering", "right_rear_axle", "x", ""]
    for _ in range(2000):
        topic = rng.choice(["/lk/joint_commands", "/joint_commands", "/lk/position_commands", "/effort_commands",
                            "/lk/joint_trajectory", "/joint_trajectory", "/cmd_vel"])
        key, n = topic.split("/")[-1], rng.randrange(0, 4)
        if key == "joint_commands":
            message = NS(name=[rng.choice(names) for _ in range(n)],
                         position=[rng.choice(values) for _ in range(rng.choice([0, n]))],
                         velocity=[rng.choice(values) for _ in range(rng.choice([0, n, n + 1]))])
        elif key == "joint_trajectory":
            message = trajectory([rng.choice(names) for _ in range(n)],
                                 [(t, [rng.choice(values) for _ in range(n)], []) for t in range(1, rng.randrange(1, 4))])
        elif key == "cmd_vel":
            message = NS(linear=NS(x=rng.choice(values), y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=rng.choice(values)))
        else:
            message = NS(data=[rng.choice(values) for _ in range(n)])
        runtime.inputs.handle(key, message, topic)
    advance(runtime, 1.0)
    assert added > 0 and not runtime.sim.paused and runtime.sim.fault_count == 0
    world = runtime.sim.world

    def whole(world):
        names = set(world.body_names())
        return (all(np.all(np.isfinite(world.body(name)["position"])) for name in names)
                and all(set(robot["bodies"]) <= names for robot in world.robot_specs))
    assert runtime.sim.call(whole)
    assert {"lk", "rc"} <= {robot["name"] for robot in world.robot_specs}
