"""The sensors through the node (issue 18, deliverables 3 and 4): what a ROS client receives
on each sensor topic, against the geometry of a known scene (a wall at 5 m, the ground), with
the REP conventions; the static frames; sensors spawned, edited and removed through the
services (the default car's IMU against its odometry while it turns: test_node.py)."""
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import CameraInfo, Image, Imu, LaserScan, PointCloud2  # noqa: E402
from geometry_msgs.msg import TransformStamped  # noqa: E402
from visualization_msgs.srv import GetInteractiveMarkers  # noqa: E402

from test_node import NS, Harness, wait_for  # noqa: E402
from vplayground_ros.messages import COLOURS  # noqa: E402
from vplayground_ros.sensor_messages import OPTICAL_ROTATION  # noqa: E402
from vplayground_ros.sensors import AMBIENT, SKY  # noqa: E402

WALL = 5.0  # m: the wall's near face, x = WALL, in front of sensors at the origin facing +x
HEIGHT = 1.0  # m: the sensors' height above the ground
WIDTH, ROWS, FOV = 40, 30, math.radians(90.0)
SCENE = {
    "version": 1,
    "settings": {"steps_per_second": 128},
    "ground": {"height": 0.0},
    "bodies": [{"name": "wall", "size": [0.2, 20.0, 4.0], "position": [WALL + 0.1, 0.0, 2.0], "immovable": True},
               {"name": "crate", "size": [0.5, 0.5, 0.5], "position": [-8.0, 8.0, 0.25]}],
    "sensors": [
        {"name": "front", "type": "lidar_2d", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, 0], "rate": 10,
         "angle_min": -0.6, "angle_max": 0.6, "samples": 13, "range_min": 0.1, "range_max": 30.0},
        {"name": "back", "type": "lidar_2d", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, math.pi], "rate": 10,
         "angle_min": -0.6, "angle_max": 0.6, "samples": 13, "range_min": 0.1, "range_max": 30.0},
        {"name": "near", "type": "lidar_2d", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, 0], "rate": 10,
         "angle_min": -0.1, "angle_max": 0.1, "samples": 3, "range_min": WALL + 1.0, "range_max": 30.0},
        {"name": "velodyne", "type": "lidar_3d", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, 0], "rate": 5,
         "horizontal_samples": 64, "channels": 4, "vertical_min": -0.1, "vertical_max": 0.1,
         "range_min": 0.3, "range_max": 30.0},
        {"name": "depth", "type": "depth_camera", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, 0], "rate": 10,
         "width": WIDTH, "height": ROWS, "horizontal_fov": FOV, "range_min": 0.1, "range_max": 30.0},
        {"name": "eye", "type": "camera", "parent": "world", "pose": [0, 0, HEIGHT, 0, 0, 0], "rate": 10,
         "width": WIDTH, "height": ROWS, "horizontal_fov": FOV, "range_min": 0.1, "range_max": 60.0},
        {"name": "imu", "type": "imu", "parent": "world", "rate": 50},
    ],
}
TOPICS = {"/front/scan": LaserScan, "/back/scan": LaserScan, "/near/scan": LaserScan, "/velodyne/points": PointCloud2,
          "/depth/depth/image_raw": Image, "/depth/depth/camera_info": CameraInfo,
          "/eye/image_raw": Image, "/eye/camera_info": CameraInfo, "/imu/data": Imu}


@pytest.fixture(scope="module")
def ros():
    directory = Path(tempfile.mkdtemp(prefix="vplayground_sensor_scene_"))
    scene = directory / "wall.yaml"
    scene.write_text(yaml.safe_dump(SCENE))
    harness = Harness(args=["--scene", str(scene)])
    for topic, kind in TOPICS.items():
        harness.listen(kind, topic)
    harness.frames = {}  # (parent, child) -> the latest ~/transforms message
    harness.client.create_subscription(
        TransformStamped, f"{NS}/transforms",
        lambda m: harness.frames.__setitem__((m.header.frame_id, m.child_frame_id), m), 100)
    assert wait_for(lambda: all(topic in harness.latest for topic in TOPICS), timeout=60,
                    explain=lambda: sorted(set(TOPICS) - set(harness.latest)))
    yield harness
    harness.close()


def stamp(msg):
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def test_every_sensor_topic_is_advertised_with_its_type(ros):
    advertised = dict((name, types[0]) for name, types in ros.client.get_topic_names_and_types())
    for topic, kind in TOPICS.items():
        assert advertised[topic] == f"sensor_msgs/msg/{kind.__name__}"


def test_a_lidar_facing_a_wall_reads_its_distance_and_inf_out_of_range(ros):
    scan = ros.latest["/front/scan"]
    assert scan.header.frame_id == "front"
    angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
    assert len(scan.ranges) == 13
    assert math.isclose(scan.angle_min, -0.6, abs_tol=1e-6) and math.isclose(scan.angle_max, 0.6, abs_tol=1e-6)
    assert math.isclose(angles[-1], scan.angle_max, abs_tol=1e-5)
    np.testing.assert_allclose(scan.ranges, WALL / np.cos(angles), atol=1e-3)
    assert (scan.range_min, scan.range_max) == (pytest.approx(0.1), pytest.approx(30.0))
    # Facing away: nothing within range_max, REP 117's +inf on every beam.
    assert all(r == math.inf for r in ros.latest["/back/scan"].ranges)
    # The wall nearer than range_min: -inf on every beam.
    assert list(ros.latest["/near/scan"].ranges) == [-math.inf] * 3


def test_sensor_messages_are_stamped_on_their_rate_grid(ros):
    """A sample of rate r is read after the first step at or after each multiple of 1/r."""
    for topic, rate in (("/front/scan", 10), ("/imu/data", 50), ("/velodyne/points", 5)):
        assert wait_for(lambda: stamp(ros.latest[topic]) > 0.5)
        seconds = stamp(ros.latest[topic])
        step = round(seconds * 128)
        assert math.isclose(step, seconds * 128, abs_tol=1e-6)
        n = math.floor(step * rate / 128 + 1e-9)
        assert step == math.ceil(n * 128 / rate - 1e-9), (topic, seconds)


def test_the_3d_cloud_has_its_fields_and_its_points_on_the_wall_and_ground(ros):
    cloud = ros.latest["/velodyne/points"]
    assert cloud.header.frame_id == "velodyne"
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
        ("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4)]
    dtype = np.dtype({"names": ["x", "y", "z", "intensity", "ring"], "formats": ["<f4"] * 4 + ["<u2"],
                      "offsets": [0, 4, 8, 12, 16], "itemsize": cloud.point_step})
    points = np.frombuffer(bytes(cloud.data), dtype)
    assert cloud.width == len(points) > 0 and cloud.height == 1
    on_wall = np.abs(points["x"] - WALL) < 1e-3
    on_ground = np.abs(points["z"] + HEIGHT) < 1e-3  # the sensor frame is HEIGHT above the ground
    assert np.all(on_wall | on_ground)
    assert set(points["ring"]) <= {0, 1, 2, 3} and np.all((points["intensity"] >= 0) & (points["intensity"] <= 1))


def test_the_depth_image_is_32fc1_metres_with_nan_for_no_return(ros):
    image, info = ros.latest["/depth/depth/image_raw"], ros.latest["/depth/depth/camera_info"]
    assert (image.encoding, image.width, image.height, image.step) == ("32FC1", WIDTH, ROWS, 4 * WIDTH)
    assert image.header.frame_id == info.header.frame_id == "depth_optical"
    depth = np.frombuffer(bytes(image.data), "<f4").reshape(ROWS, WIDTH)
    f = 0.5 * WIDTH / math.tan(0.5 * FOV)
    down = (np.arange(ROWS) + 0.5 - 0.5 * ROWS) / f  # a row's slope below the optical axis
    for row, slope in enumerate(down):
        if slope * WALL > HEIGHT:  # the ground before the wall, at depth HEIGHT / slope
            expected = HEIGHT / slope
        elif -slope * WALL > 4.0 - HEIGHT:  # above the wall's top: nothing within range (REP 117's +inf)
            expected = math.inf
        else:
            expected = WALL
        np.testing.assert_allclose(depth[row], expected, atol=1e-3, err_msg=f"row {row}")
    assert np.isposinf(depth[0]).all()


def test_camera_info_k_and_p_follow_the_field_of_view(ros):
    """Pixel centres at integer coordinates (image_geometry): the principal point is the
    image's centre, ((W - 1) / 2, (H - 1) / 2)."""
    f = 0.5 * WIDTH / math.tan(0.5 * FOV)
    cx, cy = (WIDTH - 1) / 2, (ROWS - 1) / 2
    for topic in ("/depth/depth/camera_info", "/eye/camera_info"):
        info = ros.latest[topic]
        assert (info.width, info.height) == (WIDTH, ROWS)
        np.testing.assert_allclose(info.k, [f, 0, cx, 0, f, cy, 0, 0, 1])
        np.testing.assert_allclose(info.p, [f, 0, cx, 0, 0, f, cy, 0, 0, 0, 1, 0])


def test_the_colour_image_is_rgb8_sky_above_and_the_shaded_wall_ahead(ros):
    image = ros.latest["/eye/image_raw"]
    assert (image.encoding, image.width, image.height, image.step) == ("rgb8", WIDTH, ROWS, 3 * WIDTH)
    assert image.header.frame_id == "eye_optical"
    rgb = np.frombuffer(bytes(image.data), np.uint8).reshape(ROWS, WIDTH, 3)
    assert (rgb[0] == np.round(SKY * 255)).all()
    # The wall's face looks along -x, away from the light: ambient only.
    wall = np.round(AMBIENT * np.array(COLOURS["immovable"][:3]) * 255)
    assert (rgb[ROWS // 2, WIDTH // 2] == wall).all()


def test_an_imu_at_rest_reads_plus_g_up_and_no_rate(ros):
    imu = ros.latest["/imu/data"]
    assert imu.header.frame_id == "imu"
    a, w = imu.linear_acceleration, imu.angular_velocity
    np.testing.assert_allclose([a.x, a.y, a.z], [0.0, 0.0, 9.81], atol=1e-3)
    np.testing.assert_allclose([w.x, w.y, w.z], 0.0, atol=1e-9)
    q = imu.orientation
    np.testing.assert_allclose([q.x, q.y, q.z, q.w], [0, 0, 0, 1], atol=1e-9)
    assert imu.angular_velocity_covariance[0] > 0 and imu.linear_acceleration_covariance[8] > 0


def static_frames(ros):
    """The frames ~/transforms carries now (the last 0.2 s): {(parent, child): transform}.
    (/tf_static goes to the bag and Foxglove too, where tf2_msgs is missing: test_bag.py.)"""
    frames = dict(ros.frames)
    latest = max(stamp(m) for m in frames.values())
    return {key: m.transform for key, m in frames.items() if stamp(m) > latest - 0.2}


def test_static_frames_mount_each_sensor_and_the_cameras_optical_frames(ros):
    frames = static_frames(ros)
    back = frames[("world", "back")]
    assert (back.translation.x, back.translation.y, back.translation.z) == (0.0, 0.0, HEIGHT)
    np.testing.assert_allclose([back.rotation.z, back.rotation.w], [1.0, 0.0], atol=1e-9)
    for camera in ("depth", "eye"):
        optical = frames[(camera, f"{camera}_optical")].rotation
        np.testing.assert_allclose([optical.x, optical.y, optical.z, optical.w], OPTICAL_ROTATION)
    # The optical rotation takes the optical z (forward) onto the sensor's x, optical x onto -y.
    x, y, z, w = OPTICAL_ROTATION
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(rotation @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(rotation @ [1, 0, 0], [0, -1, 0], atol=1e-12)


def test_a_sensor_spawned_on_a_body_publishes_and_goes_with_its_parent(ros):
    ok, message = ros.text("spawn", yaml.safe_dump({
        "name": "crate_laser", "type": "lidar_2d", "parent": "crate", "pose": [0, 0, 0.5, 0, 0, 0], "rate": 20,
        "angle_min": -0.1, "angle_max": 0.1, "samples": 3, "range_max": 20.0}))
    assert ok, message
    ros.listen(LaserScan, "/crate_laser/scan")
    assert wait_for(lambda: "/crate_laser/scan" in ros.latest, timeout=20)
    assert ros.latest["/crate_laser/scan"].header.frame_id == "crate_laser"
    assert wait_for(lambda: ("crate", "crate_laser") in static_frames(ros))
    names = lambda: [m.name for m in ros.call(GetInteractiveMarkers, f"{NS}/get_entities",  # noqa: E731
                                               GetInteractiveMarkers.Request()).markers]
    assert "crate_laser" in names()
    ok, description = ros.text("get_entity", "{entity: crate_laser}")
    assert ok and yaml.safe_load(description)["category"] == "sensor"
    # A second sensor of that name is refused; a bad spec names the key.
    ok, message = ros.text("spawn", "{name: crate_laser, type: imu, parent: crate}")
    assert not ok and message.startswith("NAME_NOT_UNIQUE")
    ok, message = ros.text("spawn", "{name: bad, type: lidar_2d, parent: crate, samples: -3}")
    assert not ok and "spawn.samples" in message
    ok, message = ros.text("spawn", "{name: lost, type: imu, parent: nobody}")
    assert not ok and "spawn.parent" in message
    ok, message = ros.text("edit", "{entity: crate_laser, rate: 5.0}")
    assert ok, message
    ok, message = ros.text("edit", "{entity: crate_laser, range_max: -1}")
    assert not ok and "crate_laser.range_max" in message
    saved = ros.scene_directory / "with_sensor.yaml"
    assert ros.text("save_scene", str(saved))[0]
    entry = next(s for s in yaml.safe_load(saved.read_text())["sensors"] if s["name"] == "crate_laser")
    assert (entry["parent"], entry["rate"], entry["samples"]) == ("crate", 5.0, 3)
    ok, message = ros.text("remove", "{entity: crate}")
    assert ok and "crate_laser" in message
    assert wait_for(lambda: ("crate", "crate_laser") not in static_frames(ros))
    assert "crate_laser" not in names() and "front" in names()


def test_a_sensor_removed_by_name_stops_publishing(ros):
    ok, message = ros.text("spawn", "{name: spare_imu, type: imu, parent: world, rate: 20}")
    assert ok, message
    ros.listen(Imu, "/spare_imu/data")
    assert wait_for(lambda: "/spare_imu/data" in ros.latest, timeout=20)
    ok, message = ros.text("remove", "{entity: spare_imu}")
    assert ok, message
    last = stamp(ros.latest["/spare_imu/data"])
    assert wait_for(lambda: stamp(ros.latest["/imu/data"]) > last + 0.5)
    # At most one in flight: the next sample, at the first step at or after the next multiple
    # of 1/rate (so up to one step, 1/128 s, more than 1/rate later).
    assert stamp(ros.latest["/spare_imu/data"]) <= last + 0.05 + 1.0 / 128
