"""Robots in a ROS 2 stack (issue 39): REP 105 frames owned on purpose, namespaced robots with
commands of their own, /tf_static sent when it changes, bodies off /tf. Through a running
Runtime whose every message is collected, as the bag and the ROS publishers get them."""
import json
import logging
import time
from types import SimpleNamespace

import numpy as np
import pytest

from vplayground_ros import api
from vplayground_ros.cli import parse_args
from vplayground_ros.interfaces import decoder
from vplayground_ros.runtime import Runtime
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import Simulation
from helpers import wait_for
from test_broadcast import CAR, Collector

TF = decoder("tf2_msgs/msg/TFMessage")
ODOMETRY = decoder("nav_msgs/msg/Odometry")
LIDAR = {"name": "roof_scan", "type": "lidar_2d", "parent": "car", "pose": [0.5, 0, 0.5, 0, 0, 0], "rate": 10}
POST = {"name": "post_imu", "type": "imu", "parent": "post", "pose": [0, 0, 0.6, 0, 0, 0]}
SCENE = {"version": 1, "bodies": [{"name": "crate", "position": [10, 0, 0.5]},
                                  {"name": "post", "position": [-10, 0, 0.5], "immovable": True}],
         "vehicles": [CAR], "sensors": [LIDAR, POST]}
WHEELS = ("front_left", "front_right", "rear_left", "rear_right")


def start(scene=SCENE, *args, overrides=None):
    options = parse_args(["--no-record", "--real-time-factor", "0", *args])
    sim = Simulation(load_world(scene), real_time_factor=0.0, start_paused=options.start_paused,
                     duration=options.duration)
    runtime = Runtime(sim, options, logging.getLogger("test_robots"))
    if overrides:
        runtime.parameters.override(overrides)
    sink = Collector()
    runtime.broadcaster.add_sink(sink)
    runtime.start()
    return runtime, sink


@pytest.fixture
def run():
    started = []

    def go(*args, **kwargs):
        runtime, sink = start(*args, **kwargs)
        started.append(runtime)
        return runtime, sink
    yield go
    for runtime in started:
        runtime.stop()


def tree(sink, extra=()):
    """{child: parent} of the last /tf and every /tf_static message (and `extra` edges, another
    node's), checked as tf2 would: no frame with two parents, none its own parent."""
    edges = list(extra)
    for _, message in sink.of("tf_static", TF):
        edges += [(t.header.frame_id, t.child_frame_id) for t in message.transforms]
    edges += [(t.header.frame_id, t.child_frame_id) for t in sink.of("tf", TF)[-1][1].transforms]
    parent_of = {}
    for parent, child in edges:
        assert parent != child, f"{child} is its own parent"
        assert parent_of.get(child, parent) == parent, f"{child} has two parents: {parent_of[child]} and {parent}"
        parent_of[child] = parent
    return parent_of


def root(parent_of, frame):
    seen = set()
    while frame in parent_of:
        assert frame not in seen, f"a loop through {frame}"
        seen.add(frame)
        frame = parent_of[frame]
    return frame


def chain(parent_of, frame):
    out = [frame]
    while frame in parent_of:
        frame = parent_of[frame]
        out.append(frame)
    return out


def test_rep_105_frames_with_ground_truth_localization(run):
    runtime, sink = run(SCENE, "--duration", "0.5")
    runtime.sim.wait(60)
    runtime.stop()
    parent_of = tree(sink)
    assert chain(parent_of, "base_link") == ["base_link", "base_footprint", "odom", "world"]
    for wheel in WHEELS:
        assert chain(parent_of, f"wheel_{wheel}")[:4] == [f"wheel_{wheel}", f"steering_{wheel}",
                                                          f"suspension_{wheel}", "base_link"]
    assert parent_of["roof_scan"] == "base_link"  # a robot's sensor hangs from its base_link
    assert chain(parent_of, "post_imu") == ["post_imu", "post", "world"]  # a body carrying a sensor is on /tf
    assert "crate" not in parent_of and "car" not in parent_of  # other bodies are not (publish_body_frames)


def test_the_footprint_is_level_under_the_car_and_odometry_is_in_it(run):
    runtime, sink = run(SCENE, "--duration", "2.0")
    runtime.sim.call(lambda world: world.drive("car", 2.0, 0.5, timeout=100))
    runtime.sim.wait(60)
    runtime.stop()
    transforms = {t.child_frame_id: t.transform for t in sink.of("tf", TF)[-1][1].transforms}
    footprint, base = transforms["base_footprint"], transforms["base_link"]
    q = footprint.rotation
    assert abs(q.x) < 1e-12 and abs(q.y) < 1e-12  # heading only
    assert 0.3 < base.translation.z < 1.2 and abs(base.translation.x) < 1e-9 and abs(base.translation.y) < 1e-9
    # The car at rest on flat ground: its footprint on the ground, within a few cm.
    truth = sink.of("/vplayground/car/ground_truth", ODOMETRY)[-1][1]
    assert footprint.translation.z == pytest.approx(truth.pose.pose.position.z - base.translation.z)
    assert abs(footprint.translation.z) < 0.05
    odom = sink.of("/odom", ODOMETRY)[-1][1]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_footprint")
    assert odom.pose.pose.position.x == pytest.approx(footprint.translation.x)
    # In its own axes: forward, and sideways as a point 1.3 m ahead of the rear axle turns.
    twist = odom.twist.twist
    assert twist.linear.x > 1.0 and twist.linear.y == pytest.approx(1.3 * twist.angular.z, abs=0.1)
    assert (truth.header.frame_id, truth.child_frame_id) == ("world", "base_link")


@pytest.mark.parametrize("localization, publish_odom_tf", [("none", True), ("ground_truth", False), ("none", False)])
def test_what_another_node_owns_is_left_to_it(run, localization, publish_odom_tf):
    """localization none: nothing above odom, where a SLAM node's map -> odom goes;
    publish_odom_tf false: odom -> base_footprint is an EKF's to publish."""
    runtime, sink = run(SCENE, "--duration", "0.3",
                        overrides={"localization": localization, "publish_odom_tf": publish_odom_tf})
    runtime.sim.wait(60)
    runtime.stop()
    ours = tree(sink)
    assert ("odom" in ours) == (localization == "ground_truth")
    assert ("base_footprint" in ours) == publish_odom_tf
    others = ([("map", "odom")] if localization == "none" else []) + \
             ([("odom", "base_footprint")] if not publish_odom_tf else [])
    parent_of = tree(sink, others)  # no frame gets two parents with the other nodes' edges
    assert root(parent_of, "base_link") == ("map" if localization == "none" else "world")


def test_a_localiser_beside_pause_play_reset_and_a_new_scene_keeps_one_tree(run, tmp_path):
    """A stand-in localiser publishing map -> odom beside the node as it pauses, plays, resets
    and loads a scene: /tf_static goes out once (each re-send made every tf2 listener start its
    static buffer again), odom never gets a second parent, the car is reachable from map."""
    runtime, sink = run(SCENE, overrides={"localization": "none"})
    requests = runtime.requests
    assert wait_for(lambda: sink.of("tf"))
    for call in (lambda: requests.pause(True), lambda: requests.step(3), lambda: requests.pause(False),
                 lambda: requests.reset(api.SCOPE_ALL)):
        ok, message = call()
        assert ok, message
        assert wait_for(lambda: sink.of("tf"))
    parent_of = tree(sink, [("map", "odom")])
    assert root(parent_of, "roof_scan") == "map"
    assert len(sink.of("tf_static", TF)) == 1
    scene = tmp_path / "other.yaml"
    scene.write_text("version: 1\nvehicles:\n  - {name: car, position: [0, 0, 1.6], localization: none,\n"
                     "     chassis: {size: [3, 1.6, 0.5], mass: 900},\n     wheels: ["
                     + ", ".join(f"{{mount: [{x}, {y}, -0.25]}}" for x, y in ((1, .7), (1, -.7), (-1, .7), (-1, -.7)))
                     + "]}\n")
    requests.scene_directories = [tmp_path]
    result, message = requests.load_scene(str(scene))
    assert result == api.MAP_SUCCESS, message
    assert wait_for(lambda: len(sink.of("tf_static", TF)) == 2)  # the sensors went with the old scene
    assert sink.of("tf_static", TF)[-1][1].transforms == []
    assert wait_for(lambda: "roof_scan" not in {t.child_frame_id for t in sink.of("tf", TF)[-1][1].transforms})
    assert root(tree(sink, [("map", "odom")]), "base_link") == "map"


def test_two_namespaced_cars_drive_apart_on_their_own_commands(run):
    """Each vehicle after the first stands in its name's namespace: its own cmd_vel, odom,
    joint_states and prefixed frames (`car_b/odom`, ...), and two command streams drive two
    cars independently."""
    other = {**CAR, "name": "car_b", "position": [0, 10, 1.6]}
    runtime, sink = run({"version": 1, "vehicles": [CAR, other]})
    inputs = runtime.inputs
    assert inputs.command_topics() == {"/cmd_vel": "car", "/car_b/cmd_vel": "car_b"}

    def twist(speed, yaw_rate):
        return SimpleNamespace(linear=SimpleNamespace(x=speed, y=0.0, z=0.0),
                               angular=SimpleNamespace(x=0.0, y=0.0, z=yaw_rate))
    runtime.parameters.set({"cmd_vel_timeout": 100.0})  # as fast as it goes, commands can lag in sim time
    inputs.handle("cmd_vel", twist(3.0, 0.0))  # the root namespace's: car
    inputs.handle("cmd_vel", twist(-2.0, 0.0), "/car_b/cmd_vel")
    start_time = runtime.sim.snapshot.time
    assert wait_for(lambda: runtime.sim.snapshot.time > start_time + 4.0, 60)
    a = sink.of("/odom", ODOMETRY)[-1][1]
    b = sink.of("/car_b/odom", ODOMETRY)[-1][1]
    assert (b.header.frame_id, b.child_frame_id) == ("car_b/odom", "car_b/base_footprint")
    assert a.twist.twist.linear.x > 1.5 and b.twist.twist.linear.x < -1.0
    assert sink.of("/car_b/joint_states") and sink.of("/vplayground/car_b/ground_truth")
    parent_of = tree(sink)
    assert chain(parent_of, "car_b/wheel_rear_left")[-5:] == ["car_b/suspension_rear_left", "car_b/base_link",
                                                                "car_b/base_footprint", "car_b/odom", "world"]


def test_a_vehicle_namespace_is_its_own_and_refused_when_taken():
    world = load_world({"version": 1, "vehicles": [{**CAR, "namespace": "r1"}]})
    world.add_vehicle({**CAR, "name": "r2.x", "position": [0, 9, 1.6]})
    assert [world.vehicle(n)["namespace"] for n in world.vehicle_names()] == ["r1", ""]  # the root was free
    world.add_vehicle({**CAR, "name": "r3-y", "position": [0, 18, 1.6]})
    assert world.vehicle("r3-y")["namespace"] == "r3_y"  # a name's '-' is no namespace's
    with pytest.raises(ValueError, match="vehicle.namespace: 'r1' is the namespace of car already"):
        world.add_vehicle({**CAR, "name": "r4", "namespace": "r1", "position": [0, 27, 1.6]})
    with pytest.raises(ValueError, match="is not a relative ROS namespace"):
        world.add_vehicle({**CAR, "name": "r5", "namespace": "/abs", "position": [0, 36, 1.6]})


@pytest.mark.parametrize("overrides, fragment", [
    ({"world_frame": "odom"}, "odom_frame and world_frame are both 'odom'"),
    ({"base_frame": "base_footprint"}, "base_frame and footprint_frame are both 'base_footprint'"),
    ({"odom_frame": ""}, "odom_frame: '' is not a frame name"),
    ({"localization": "amcl"}, "localization: 'amcl' is not one of ground_truth, none"),
])
def test_frame_settings_that_would_break_the_tree_are_refused(overrides, fragment):
    options = parse_args(["--no-record"])
    runtime = Runtime(Simulation(load_world(SCENE)), options, logging.getLogger("test_robots"))
    with pytest.raises(ValueError) as error:
        runtime.parameters.override(overrides)
    assert fragment in str(error.value)


@pytest.mark.parametrize("name", ["map", "earth", "base_footprint", "suspension_front_left", "steering_rear_right"])
def test_bodies_may_not_take_the_frames_of_a_stack(name):
    with pytest.raises(ValueError, match=f"bodies\\[0\\].name: '{name}' is"):
        load_world({"version": 1, "bodies": [{"name": name}]})


def test_body_frames_on_tf_when_asked(run):
    runtime, sink = run(SCENE, "--duration", "0.2", overrides={"publish_body_frames": True})
    runtime.sim.wait(60)
    runtime.stop()
    parent_of = tree(sink)
    assert parent_of["crate"] == "world" and parent_of["car"] == "world"


def test_static_transforms_go_out_once_and_again_when_a_sensor_comes(run):
    runtime, sink = run(SCENE)
    assert wait_for(lambda: len(sink.of("tf_static")) == 1)
    ok, message = runtime.requests.pause(True)
    assert ok, message
    ok, message = runtime.requests.pause(False)
    assert ok, message
    ok, message = runtime.requests.spawn("{name: hood_cam, type: camera, parent: car, pose: [1.5, 0, 0.4, 0, 0, 0]}")
    assert ok, message
    assert wait_for(lambda: len(sink.of("tf_static")) == 2)
    children = {t.child_frame_id: t.header.frame_id for t in sink.of("tf_static", TF)[-1][1].transforms}
    assert children["hood_cam"] == "base_link" and children["hood_cam_optical"] == "hood_cam"
    assert len(children) == 4  # roof_scan, post_imu, hood_cam and its optical frame


def compose(a, b):
    """Two geometry_msgs Transforms composed: a then b, as (xyz, xyzw) arrays."""
    from vplayground_ros.robots import compose as poses
    pose = poses(((a.translation.x, a.translation.y, a.translation.z), (a.rotation.x, a.rotation.y, a.rotation.z, a.rotation.w)),
                 ((b.translation.x, b.translation.y, b.translation.z), (b.rotation.x, b.rotation.y, b.rotation.z, b.rotation.w)))
    return np.array(pose[0]), np.array(pose[1])


def test_noise_off_odometry_is_the_truth_exactly(run):
    runtime, sink = run(SCENE, "--duration", "3.0")
    runtime.sim.call(lambda world: world.drive("car", 3.0, 0.4, timeout=100))
    runtime.sim.wait(60)
    runtime.stop()
    for (_, odom), (_, truth) in zip(sink.of("/odom", ODOMETRY), sink.of("/vplayground/car/ground_truth", ODOMETRY)):
        assert (odom.pose.pose.position.x, odom.pose.pose.position.y) == (truth.pose.pose.position.x,
                                                                           truth.pose.pose.position.y)
    transforms = {t.child_frame_id: t.transform for t in sink.of("tf", TF)[-1][1].transforms}
    world_odom = transforms["odom"]
    assert (world_odom.translation.x, world_odom.translation.y, world_odom.rotation.w) == (0.0, 0.0, 1.0)


def test_odometry_drifts_as_its_error_model_says_and_world_to_odom_carries_the_drift(run):
    """A yaw-rate bias walking in time: the odometry's heading error grows, the reported yaw
    variance grows with it (sigma^2 T^3 / 3 for a walk from zero), the error stays within a few
    sigma of it, and world -> odom -> base_footprint still lands on the true footprint."""
    drift = 0.01  # rad/s/sqrt(s)
    car = {**CAR, "odometry": {"yaw_drift": drift, "slip_across": 0.05, "seed": 7}}
    runtime, sink = run({**SCENE, "vehicles": [car]}, "--duration", "12.0")
    runtime.sim.call(lambda world: world.drive("car", 4.0, 0.0, timeout=100))
    runtime.sim.wait(120)
    runtime.stop()
    (_, odom), (_, truth) = sink.of("/odom", ODOMETRY)[-1], sink.of("/vplayground/car/ground_truth", ODOMETRY)[-1]

    def yaw(q):
        return np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    error = (yaw(odom.pose.pose.orientation) - yaw(truth.pose.pose.orientation) + np.pi) % (2 * np.pi) - np.pi
    variance = np.array(odom.pose.covariance).reshape(6, 6)[5, 5]
    assert variance == pytest.approx(drift ** 2 * 12.0 ** 3 / 3, rel=0.05)
    assert 1e-6 < abs(error) < 4 * np.sqrt(variance)
    assert np.array(odom.pose.covariance).reshape(6, 6)[1, 1] > 0.05 ** 2 * 30  # slip across, over ~40 m
    transforms = {t.child_frame_id: t.transform for t in sink.of("tf", TF)[-1][1].transforms}
    position, _ = compose(transforms["odom"], transforms["base_footprint"])
    true = truth.pose.pose.position
    assert np.allclose(position[:2], [true.x, true.y], atol=1e-9)
    odom_position = odom.pose.pose.position
    assert not np.allclose([odom_position.x, odom_position.y], [true.x, true.y], atol=1e-3)


def test_a_teleport_starts_the_odometry_again(run):
    car = {**CAR, "odometry": {"slip_along": 0.2, "seed": 3}}
    runtime, sink = run({**SCENE, "vehicles": [car]})
    runtime.sim.call(lambda world: world.drive("car", 3.0, 0.0, timeout=100))
    assert wait_for(lambda: runtime.sim.snapshot.time > 3.0, 60)
    runtime.sim.call(lambda world: world.edit_body("car", position=[30.0, 30.0, 1.2]))
    assert wait_for(lambda: sink.of("/odom") and ODOMETRY(sink.of("/odom")[-1][1]).pose.pose.position.x > 25.0, 60)
    odom = ODOMETRY(sink.of("/odom")[-1][1])
    assert np.array(odom.pose.covariance).reshape(6, 6)[0, 0] < 0.2 ** 2 * 5  # the drift started again


def test_a_bad_error_model_is_refused_naming_the_key():
    with pytest.raises(ValueError, match=r"vehicles\[0\].odometry.yaw_drift: must be >= 0, got -1"):
        load_world({"version": 1, "vehicles": [{**CAR, "odometry": {"yaw_drift": -1}}]})
    with pytest.raises(ValueError, match=r"vehicles\[0\].odometry.wobble: unknown key"):
        load_world({"version": 1, "vehicles": [{**CAR, "odometry": {"wobble": 1}}]})


def test_robot_description_reproduces_the_published_transforms(run):
    """robot_description (latched, URDF) parsed as robot_state_publisher would take it: at the
    joint_states' values its forward kinematics gives the wheels where /tf has them, and its
    sensor links where /tf_static has them."""
    import io

    import yourdfpy
    from vplayground_ros.sensors import pose_matrix
    runtime, sink = run(SCENE, "--duration", "1.5")
    runtime.sim.call(lambda world: world.drive("car", 2.0, 0.6, timeout=100))
    runtime.sim.wait(60)
    runtime.stop()
    [(_, description)] = sink.of("/robot_description", decoder("std_msgs/msg/String"))
    urdf = yourdfpy.URDF.load(io.StringIO(description.data), load_meshes=False)
    time, joints = sink.of("/joint_states", decoder("sensor_msgs/msg/JointState"))[-1]
    tf = next(message for t, message in sink.of("tf", TF) if t == time)
    urdf.update_cfg(dict(zip(joints.name, joints.position)))
    edges = {t.child_frame_id: (t.header.frame_id, t.transform) for t in tf.transforms}
    edges.update({t.child_frame_id: (t.header.frame_id, t.transform) for t in sink.of("tf_static", TF)[-1][1].transforms})

    def published(frame):  # base_link -> frame, composed along the published edges
        out = np.eye(4)
        while frame != "base_link":
            parent, t = edges[frame]
            out = pose_matrix((t.translation.x, t.translation.y, t.translation.z),
                              (t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w)) @ out
            frame = parent
        return out
    for frame in [f"wheel_{w}" for w in WHEELS] + ["roof_scan"]:
        assert np.allclose(urdf.get_transform(frame, "base_link"), published(frame), atol=1e-9), frame
    assert set(joints.name) <= set(urdf.joint_map)


def test_a_robots_sensors_publish_where_a_stack_reads_them(run):
    """Sensors on a robot default to the names Nav2, slam_toolbox and image_transport read,
    under the robot's namespace, in frames with its prefix; `topic` and `frame_id` choose."""
    other = {**CAR, "name": "car_b", "position": [0, 10, 1.6]}
    sensors = [LIDAR, {**LIDAR, "name": "rear_scan", "topic": "scan_rear", "frame_id": "rear_laser"},
               {"name": "b_scan", "type": "lidar_2d", "parent": "car_b", "rate": 10},
               {"name": "b_cam", "type": "camera", "parent": "car_b", "rate": 10, "width": 8, "height": 6},
               {"name": "b_imu", "type": "imu", "parent": "car_b", "rate": 20}, POST]
    runtime, sink = run({**SCENE, "vehicles": [CAR, other], "sensors": sensors}, "--duration", "0.5")
    runtime.sim.wait(60)
    runtime.stop()
    def last(topic, kind):  # the Broadcaster keys a sensor's topic by its name and type
        return sink.of(f"sensor:{topic}:{kind}", decoder(kind))[-1][1]
    scan = "sensor_msgs/msg/LaserScan"
    assert last("scan", scan).header.frame_id == "roof_scan"
    assert last("scan_rear", scan).header.frame_id == "rear_laser"
    assert last("car_b/scan", scan).header.frame_id == "car_b/b_scan"
    assert last("car_b/camera/image_raw", "sensor_msgs/msg/Image").header.frame_id == "car_b/b_cam_optical"
    assert last("car_b/camera/camera_info", "sensor_msgs/msg/CameraInfo").header.frame_id == "car_b/b_cam_optical"
    assert last("car_b/imu/data", "sensor_msgs/msg/Imu") and last("post_imu/data", "sensor_msgs/msg/Imu")
    parent_of = tree(sink)
    assert chain(parent_of, "car_b/b_cam_optical")[:3] == ["car_b/b_cam_optical", "car_b/b_cam", "car_b/base_link"]
    assert parent_of["rear_laser"] == "base_link"


def test_sensors_on_one_topic_or_frame_are_refused_naming_both():
    twin = {**LIDAR, "name": "twin_scan"}
    with pytest.raises(ValueError, match=r"twin_scan.topic: /scan is the sensor roof_scan's already \(give the "
                                         r"sensor a `topic`\)"):
        load_world({**SCENE, "sensors": [LIDAR, twin]})
    # One that gave its topic is asked for another (it had been told to give one).
    with pytest.raises(ValueError, match=r"/scan is the sensor roof_scan's already \(give the sensor another `topic`\)"):
        load_world({**SCENE, "sensors": [LIDAR, {**twin, "topic": "scan"}]})
    with pytest.raises(ValueError, match=r"sensors\[1\].frame_id: the frame 'crate' is"):
        load_world({**SCENE, "sensors": [LIDAR, {**twin, "topic": "scan2", "frame_id": "crate"}]})
    with pytest.raises(ValueError, match=r"sensors\[1\].frame_id: the frame 'base_link' is"):
        load_world({**SCENE, "sensors": [LIDAR, {**twin, "topic": "scan2", "frame_id": "base_link"}]})
    with pytest.raises(ValueError, match=r"sensors\[0\].topic: '/bad topic' is not a topic name"):
        load_world({**SCENE, "sensors": [{**LIDAR, "topic": "/bad topic"}]})


def test_spawned_and_edited_sensors_keep_topics_and_frames_apart(run):
    runtime, _ = run(SCENE, "--start-paused")
    requests = runtime.requests
    ok, message = requests.spawn("{name: twin_scan, type: lidar_2d, parent: car}")
    assert not ok and "/scan is the sensor roof_scan's already" in message, message
    ok, message = requests.spawn("{name: twin_scan, type: lidar_2d, parent: car, topic: scan2, frame_id: roof_scan,"
                                 " allow_renaming: true}")
    assert not ok and message.startswith("NAME_NOT_UNIQUE: spawn.frame_id:"), message
    ok, message = requests.spawn("{name: twin_scan, type: lidar_2d, parent: car, topic: scan2}")
    assert ok, message
    ok, message = requests.edit("{entity: twin_scan, topic: scan}")
    assert not ok and "/scan is the sensor roof_scan's already" in message, message
    ok, message = requests.edit("{entity: twin_scan, frame_id: crate}")
    assert not ok and message.startswith("NAME_NOT_UNIQUE: twin_scan.frame_id: 'crate'"), message
    assert requests.edit("{entity: twin_scan, frame_id: side_laser}")[0]


# ------------------------------------------------------------------ review findings (issue 39)
@pytest.mark.parametrize("topic", ["odom", "/tf", "cmd_vel", "joint_states", "robot_description", "/clock",
                                   "/vplayground/state", "clicked_point"])
def test_a_sensor_may_not_publish_on_a_topic_of_the_node_or_a_robot(run, topic):
    runtime, _ = run(SCENE, "--start-paused")
    ok, message = runtime.requests.spawn(f"{{name: odd_imu, type: imu, parent: car, topic: '{topic}'}}")
    assert not ok and "odd_imu.topic:" in message and "already" in message, message


@pytest.mark.parametrize("name, topic, owner", [
    ("bodies", "/vplayground/bodies/markers", "the node's ~/bodies/markers"),
    ("scene", "/vplayground/scene/markers", "the node's ~/scene/markers"),
    ("contacts", "/vplayground/contacts/markers", "the node's ~/contacts/markers"),
    ("car-b", "/vplayground/car_b/ground_truth", "car_b's ground_truth"),  # two names, one topic token
])
def test_a_robot_may_not_publish_on_the_nodes_topics_or_another_robots(run, name, topic, owner):
    """A car's own topics are ~/<name>/ground_truth, command and markers: a car named after one
    of the node's drawing topics had published its markers on them (two streams on one topic,
    each replacing the other's drawing), and two names with one topic token shared theirs.
    Refused on spawn (the world unchanged) and in a scene file, naming both."""
    other = {**CAR, "name": "car_b", "position": [0, 10, 1.6]}
    runtime, _ = run({**SCENE, "vehicles": [CAR, other]}, "--start-paused")
    def entities():
        return runtime.sim.call(lambda world: (list(world.body_names()), list(world.vehicle_names())))
    before = entities()
    ok, message = runtime.requests.spawn(json.dumps({**CAR, "name": name, "namespace": "third",
                                                     "position": [0, 20, 1.6]}))
    assert not ok and f"{name}.name: {topic} is {owner} already" in message, message
    assert entities() == before
    with pytest.raises(ValueError, match=f"{name}.name: {topic} is {owner} already"):
        load_world({**SCENE, "vehicles": [CAR, other, {**CAR, "name": name, "namespace": "third",
                                                         "position": [0, 20, 1.6]}]})


def test_a_sensor_frame_may_not_be_a_robots_frame_nor_a_robot_land_on_one(run):
    other = {**CAR, "name": "car_b", "position": [0, 10, 1.6]}
    runtime, _ = run({**SCENE, "vehicles": [CAR, other]}, "--start-paused")
    requests = runtime.requests
    ok, message = requests.spawn("{name: odd, type: imu, parent: world, frame_id: car_b/base_link}")
    assert not ok and "odd.frame_id: the frame 'car_b/base_link' is car_b's base_link" in message, message
    ok, message = requests.spawn("{name: odd, type: imu, parent: world, frame_id: car_c/base_footprint}")
    assert ok, message
    ok, message = requests.spawn(json.dumps({**CAR, "name": "car_c", "position": [0, 20, 1.6]}))
    assert not ok and "car_c's base_footprint" in message, message
    assert "car_c" not in runtime.sim.call(lambda world: world.body_names())


def test_robot_description_joints_are_unique_whatever_the_sensors_are_called():
    import io

    import yourdfpy
    from vplayground_ros.parameters import FRAMES, Frames
    from vplayground_ros.robot_description import robot_description
    world = load_world({**SCENE, "sensors": [{"name": "cam", "type": "camera", "parent": "car", "frame_id": "front_cam"},
                                             {"name": "cam_optical", "type": "imu", "parent": "car"}]})
    text = robot_description(world.vehicle("car"), world.sensor_specs, "car", Frames(*FRAMES.values()))
    urdf = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False)
    import xml.etree.ElementTree as ET
    names = [joint.get("name") for joint in ET.fromstring(text).iter("joint")]
    assert len(names) == len(set(names)) and len(urdf.joint_map) == len(names)


def test_odometry_starts_again_for_a_robot_spawned_again(run):
    car = {**CAR, "odometry": {"slip_across": 0.3, "seed": 5}}
    runtime, sink = run({**SCENE, "vehicles": [car], "sensors": [POST]})
    runtime.sim.call(lambda world: world.drive("car", 4.0, 0.0, timeout=100))
    assert wait_for(lambda: runtime.sim.snapshot.time > 4.0, 60)
    spec = runtime.sim.call(lambda world: world.vehicle("car"))
    assert runtime.requests.remove("{entity: car}")[0]
    assert wait_for(lambda: "car" not in runtime.sim.snapshot.vehicles)
    ok, message = runtime.requests.spawn(json.dumps(spec))
    assert ok, message
    spawned = runtime.sim.snapshot.time
    assert wait_for(lambda: any(t > spawned for t, _ in sink.of("/odom")), 60)
    odom = next(ODOMETRY(data) for t, data in sink.of("/odom") if t > spawned)
    assert across_variance(odom, spec["position"]) < 0.3 ** 2 * 0.5  # not the 16 m of drift before
    # Removed and spawned again where it stands within one batch (no round between): a new car too.
    runtime.sim.call(lambda world: world.drive("car", 4.0, 0.0, timeout=100))
    assert wait_for(lambda: runtime.sim.snapshot.time > spawned + 4.0, 60)

    def respawn(world):
        again = world.vehicle("car")
        world.remove_body("car")
        world.add_vehicle(again)
        return again["position"]
    where = runtime.sim.call(respawn)
    spawned = runtime.sim.snapshot.time
    assert wait_for(lambda: any(t > spawned for t, _ in sink.of("/odom")), 60)
    odom = next(ODOMETRY(data) for t, data in sink.of("/odom") if t > spawned)
    assert across_variance(odom, where) < 0.3 ** 2 * 0.5


def across_variance(odom, start):
    """The cross-track variance of a spawned car's odometry less what slip_across (0.3) gives the
    way driven since `start` (the first /odom after a spawn comes a round or more later, further
    on a busy machine whose publisher skips snapshots): what is left is what it carried over."""
    position = odom.pose.pose.position
    driven = float(np.hypot(position.x - start[0], position.y - start[1]))
    return np.array(odom.pose.covariance).reshape(6, 6)[1, 1] - 0.3 ** 2 * driven


@pytest.mark.parametrize("overrides", [{"localization": "none"}, {"publish_odom_tf": False}])
def test_requests_take_a_robots_frames_whoever_publishes_their_edges(run, overrides):
    runtime, _ = run(SCENE, "--start-paused", overrides=overrides)
    for frame in ("odom", "base_footprint", "base_link", "wheel_front_left", "roof_scan"):
        ok, message = runtime.requests.spawn(f"{{initial_pose: {{header: {{frame_id: {frame}}}, pose: {{position: "
                                             f"{{x: 0, y: 0, z: 3}}}}}}, allow_renaming: true, name: probe}}")
        assert ok, (frame, message)


def test_a_sensor_named_with_dots_publishes_on_a_name_ros_takes(run):
    from rclpy.validate_full_topic_name import validate_full_topic_name
    sensors = [{"name": "front.lidar", "type": "lidar_2d", "parent": "world", "rate": 20}, POST]
    runtime, sink = run({**SCENE, "sensors": sensors}, "--duration", "0.3")
    runtime.sim.wait(60)
    runtime.stop()
    assert sink.of("sensor:front_lidar/scan:sensor_msgs/msg/LaserScan")
    for key, _, _ in sink.messages:
        validate_full_topic_name(runtime.broadcaster.topics[key].name)


@pytest.mark.parametrize("localization", ["none", "ground_truth"])
def test_initialpose_is_the_localisers_when_one_runs(run, localization):
    """With localization none, initialpose is AMCL's pose estimate: no teleport."""
    runtime, _ = run(SCENE, "--start-paused", overrides={"localization": localization})
    pose = SimpleNamespace(position=SimpleNamespace(x=20.0, y=20.0, z=0.0),
                           orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0))
    runtime.inputs.handle("initial_pose", SimpleNamespace(header=SimpleNamespace(frame_id="world"),
                                                          pose=SimpleNamespace(pose=pose)))
    def teleported():
        return runtime.sim.call(lambda world: world.body("car")["position"][0]) == pytest.approx(20.0)
    if localization == "ground_truth":
        assert wait_for(teleported)
    else:
        time.sleep(0.3)  # as long as a teleport takes
        assert not teleported()
