"""Sensor readings (sensors.py) -> the CDR bytes of their standard messages (issue 18), built
without rclpy like messages.py: LaserScan (REP 117), PointCloud2, Image 32FC1 (REP 118) and
rgb8 with their CameraInfo, Imu (REP 145). Arrays go in as one block; the small messages go
through interfaces.encode. Stamps are the simulated time of the reading.

Frames: a lidar's and an IMU's messages are in the sensor's frame (its name, x forward, z up);
a camera's in `<name>_optical` (z forward, x right, y down), a static child of the sensor frame.
"""
import math
from collections import namedtuple

import numpy as np

from . import cdr
from .interfaces import encode
from .messages import EXACT_VARIANCE
from .physics import specs
from .physics.math3d import rpy_to_quat
from .sensors import camera_intrinsics, lidar_2d_angles

# Topics of each sensor type: (suffix, message type). A topic's name is the sensor's `topic`
# (its base) with the suffix after it; the base is by default the name a stack reads on a robot
# (ROBOT_TOPICS, under the robot's namespace: Nav2's and slam_toolbox's `scan`), and
# `<name>/<first part of the suffix>` elsewhere (a body's or the world's sensor).
TOPIC_SUFFIXES = {
    "lidar_2d": [("scan", "sensor_msgs/msg/LaserScan")],
    "lidar_3d": [("points", "sensor_msgs/msg/PointCloud2")],
    "depth_camera": [("depth/image_raw", "sensor_msgs/msg/Image"), ("depth/camera_info", "sensor_msgs/msg/CameraInfo")],
    "camera": [("image_raw", "sensor_msgs/msg/Image"), ("camera_info", "sensor_msgs/msg/CameraInfo")],
    "imu": [("data", "sensor_msgs/msg/Imu")],
}
# What a topic base leaves of each suffix: a lidar's or an IMU's `topic` is its topic; a
# camera's is its namespace (image_transport's), before image_raw and camera_info.
TAILS = {"scan": "", "points": "", "data": "", "depth/image_raw": "image_raw", "depth/camera_info": "camera_info",
         "image_raw": "image_raw", "camera_info": "camera_info"}
ROBOT_TOPICS = {"lidar_2d": "scan", "lidar_3d": "points", "imu": "imu/data", "camera": "camera",
                "depth_camera": "depth"}
OTHER_TOPICS = {"lidar_2d": "scan", "lidar_3d": "points", "imu": "data", "camera": "", "depth_camera": "depth"}
SensorTopic = namedtuple("SensorTopic", "suffix name type")
# The optical frame in the sensor frame: rpy (-pi/2, 0, -pi/2) turns z forward, x right, y down.
OPTICAL_ROTATION = tuple(float(v) for v in rpy_to_quat((-0.5 * math.pi, 0.0, -0.5 * math.pi)))
FLOAT32, UINT16 = 7, 4  # sensor_msgs/PointField datatypes
# The 3D lidar's points: x y z intensity (float32) and ring (uint16), padded to 20 bytes so
# every point starts 4-byte aligned.
CLOUD_DTYPE = np.dtype({"names": ["x", "y", "z", "intensity", "ring"],
                        "formats": ["<f4", "<f4", "<f4", "<f4", "<u2"],
                        "offsets": [0, 4, 8, 12, 16], "itemsize": 20})
CLOUD_FIELDS = [(name, CLOUD_DTYPE.fields[name][1], UINT16 if name == "ring" else FLOAT32, 1)
                for name in CLOUD_DTYPE.names]


def topics(spec, robot=None):
    """[SensorTopic] of one sensor spec, names relative to the node's namespace: under `robot`'s
    namespace (robots.Robot, the one carrying it, or None) unless its `topic` is absolute."""
    kind = spec["type"]
    base = spec.get("topic") or (ROBOT_TOPICS[kind] if robot is not None
                                 else "/".join(part for part in (specs.name_token(spec["name"]), OTHER_TOPICS[kind]) if part))
    if robot is not None and not base.startswith("/"):
        base = robot.topic(base)
    return [SensorTopic(suffix, f"{base}/{TAILS[suffix]}" if TAILS[suffix] else base, message)
            for suffix, message in TOPIC_SUFFIXES[kind]]


def optical_frame(name):
    return f"{name}_optical"


def static_frames(specs, parent_frame, sensor_frame=lambda spec: spec.get("frame_id", spec["name"])):
    """[(parent, child, pose xyz + xyzw)] of every sensor: its mount in its parent's frame
    (`parent_frame(the spec's parent)`: `world` means the world frame), and a camera's optical
    frame; `sensor_frame(spec)` is its frame (frame_names.sensor_frame)."""
    out = []
    for spec in specs:
        pose, frame = spec["pose"], sensor_frame(spec)
        out.append((parent_frame(spec["parent"]), frame, [*pose[:3], *rpy_to_quat(pose[3:])]))
        if spec["type"] in ("depth_camera", "camera"):
            out.append((frame, optical_frame(frame), [0.0, 0.0, 0.0, *OPTICAL_ROTATION]))
    return out


def build(spec, reading, seconds, frame):
    """[(suffix, CDR bytes)] of one reading, in the order of TOPIC_SUFFIXES; `frame` is the
    sensor's (a camera's messages are in its optical frame)."""
    kind = spec["type"]
    if kind == "lidar_2d":
        return [("scan", laser_scan(spec, reading["ranges"], seconds, frame, reading["period"]))]
    if kind == "lidar_3d":
        return [("points", lidar_cloud(frame, reading, seconds))]
    if kind == "depth_camera":
        return [("depth/image_raw", image(seconds, optical_frame(frame), reading["depth"], "32FC1")),
                ("depth/camera_info", camera_info(spec, seconds, frame))]
    if kind == "camera":
        return [("image_raw", image(seconds, optical_frame(frame), reading["rgb"], "rgb8")),
                ("camera_info", camera_info(spec, seconds, frame))]
    return [("data", imu(spec, reading, seconds, frame))]


def laser_scan(spec, ranges, seconds, frame, scan_time):
    """sensor_msgs/LaserScan: ranges as read (+inf no return, -inf nearer than range_min).
    scan_time is the time between the scans published (1 / rate, or a step when the rate is
    above steps_per_second); time_increment 0: every beam is cast from one state."""
    angles = lidar_2d_angles(spec)
    increment = float(angles[1] - angles[0]) if len(angles) > 1 else 0.0
    w = cdr.Writer()
    w.header(cdr.split_stamp(seconds), frame)
    w.f32s([angles[0], angles[-1], increment, 0.0, scan_time, spec["range_min"], spec["range_max"]])
    w.u32(len(ranges))
    w.data += np.ascontiguousarray(ranges, "<f4").tobytes()
    w.u32(0)  # intensities: none
    return cdr.ENCAPSULATION + bytes(w.data)


def lidar_cloud(frame, reading, seconds):
    """sensor_msgs/PointCloud2 of the returns (x y z intensity ring) in the sensor frame."""
    points = reading["points"]
    rows = np.zeros(len(points), CLOUD_DTYPE)
    rows["x"], rows["y"], rows["z"] = points[:, 0], points[:, 1], points[:, 2]
    rows["intensity"], rows["ring"] = reading["intensity"], reading["ring"]
    return cdr.point_cloud(seconds, frame, CLOUD_FIELDS, rows)


def image(seconds, frame, pixels, encoding):
    """sensor_msgs/Image of an (H, W) float32 or (H, W, 3) uint8 array, row by row from the top."""
    pixels = np.ascontiguousarray(pixels, "<f4" if encoding == "32FC1" else np.uint8)
    height, width = pixels.shape[:2]
    w = cdr.Writer()
    w.header(cdr.split_stamp(seconds), frame)
    w.u32(height)
    w.u32(width)
    w.string(encoding)
    w.u8(0)  # is_bigendian
    w.u32(pixels.nbytes // height)  # step
    w.u32(pixels.nbytes)
    w.data += pixels.tobytes()
    return cdr.ENCAPSULATION + bytes(w.data)


def camera_info(spec, seconds, frame):
    """sensor_msgs/CameraInfo of the pinhole camera the rays were cast through (no distortion)."""
    fx, fy, cx, cy = camera_intrinsics(spec)
    return encode("sensor_msgs/msg/CameraInfo", {
        "header": {"stamp": dict(zip(("sec", "nanosec"), cdr.split_stamp(seconds))),
                   "frame_id": optical_frame(frame)},
        "height": spec["height"], "width": spec["width"], "distortion_model": "plumb_bob",
        "d": [0.0] * 5, "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]})


def diagonal(variance):
    v = float(variance) if variance > 0.0 else EXACT_VARIANCE
    return [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v]


def imu(spec, reading, seconds, frame):
    """sensor_msgs/Imu in the sensor frame; covariances diagonal, the noises' variances."""
    return encode("sensor_msgs/msg/Imu", {
        "header": {"stamp": dict(zip(("sec", "nanosec"), cdr.split_stamp(seconds))), "frame_id": frame},
        "orientation": dict(zip("xyzw", map(float, reading["orientation"]))),
        "orientation_covariance": diagonal(0.0),
        "angular_velocity": dict(zip("xyz", map(float, reading["angular_velocity"]))),
        "angular_velocity_covariance": diagonal(spec["gyro_noise"] ** 2),
        "linear_acceleration": dict(zip("xyz", map(float, reading["linear_acceleration"]))),
        "linear_acceleration_covariance": diagonal(spec["accel_noise"] ** 2)})
