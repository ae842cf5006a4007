"""Sensors (scene key `sensors`): 2D and 3D lidars, depth and colour cameras and IMUs, computed
from the World by its ray casts. ROS-free: readings are numpy arrays (sensor_messages.py makes
them ROS messages). Scene files take the `sensors` key and keep it on saving.

Sampling runs on simulation time: a sensor of rate r is read after the step that first reaches
each multiple of 1/r, from the state after that step, also across a change of steps_per_second
(a Clock maps times to steps). A rate above steps_per_second is read once a step, with a
warning. The Simulation ends its batches on those steps (steps_until_due), so a run at any
real-time factor reads the same scans. Noise comes from
one generator per sensor seeded from `settings.seed` and the sensor's name: the same scene gives
bit-identical readings.

Frames: a sensor's frame is its `frame_id`, else its name (with a namespaced robot's namespace
before it), posed by `pose` (xyz + rpy) in its parent's frame (a
vehicle's base_link, a body's own frame, or the world frame for `parent: world`). Lidars and the
IMU look along +x with z up (REP 103); cameras also have `<name>_optical` (z forward, x right,
y down; pixel centres at integer coordinates, as OpenCV and image_geometry take them).

Ranges (REP 117, and REP 118 for depth images): a return nearer than range_min is -inf, none
within range_max +inf; noise is added before that test, so a noisy return never lies outside
[range_min, range_max]. Cameras measure along the optical axis: their range_max is a far plane
(a wall 20 m away fills a 25 m camera's image), the depth camera's range_min a near one under
which pixels read -inf, and the colour camera's range_min its near clipping plane (what is
nearer is not drawn).
"""
import logging
import math
import re
import zlib

import numpy as np

from .messages import CATEGORY_COLOURS, COLOURS, FROZEN, IMMOVABLE, VEHICLE, BOX
from .physics import specs
from .physics.ids import GROUND, NOTHING, PLAYGROUND
from .physics.math3d import matrix_to_quaternion, quaternions_to_matrices, rpy_to_quat

TYPES = ("lidar_2d", "lidar_3d", "depth_camera", "camera", "imu")
CAMERAS = ("depth_camera", "camera")  # the types that see through a pinhole, with an optical frame
COMMON_KEYS = {"name", "type", "parent", "pose", "rate", "topic", "frame_id"}
# A topic name (relative, or absolute with a leading '/') and a frame name, as a sensor's
# `topic` and `frame_id` keys take them.
TOPIC_PATTERN = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(?:/[A-Za-z_][A-Za-z0-9_]*)*")
FRAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*(?:/[A-Za-z_][A-Za-z0-9_.\-]*)*")
RANGE_KEYS = {"range_min", "range_max", "noise_stddev"}
TYPE_KEYS = {
    "lidar_2d": RANGE_KEYS | {"angle_min", "angle_max", "samples"},
    "lidar_3d": RANGE_KEYS | {"horizontal_samples", "channels", "vertical_min", "vertical_max"},
    "depth_camera": RANGE_KEYS | {"width", "height", "horizontal_fov"},
    "camera": {"range_min", "range_max", "width", "height", "horizontal_fov"},
    "imu": {"gyro_noise", "accel_noise", "gyro_bias", "accel_bias"},
}
DEFAULTS = {
    "pose": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "rate": 10.0,
    "range_min": 0.1, "range_max": 30.0, "noise_stddev": 0.0,
    "angle_min": -math.pi, "angle_max": math.pi, "samples": 360,
    "horizontal_samples": 1024, "channels": 16, "vertical_min": -math.radians(15.0),
    "vertical_max": math.radians(15.0),
    "width": 160, "height": 120, "horizontal_fov": math.radians(90.0),
    "gyro_noise": 0.0, "accel_noise": 0.0, "gyro_bias": [0.0, 0.0, 0.0], "accel_bias": [0.0, 0.0, 0.0],
}
MAX_RAYS = 4_000_000  # per sensor and scan: beyond this one scan would stall the simulation
MAX_RATE = 1000.0
# Lower bounds no sensor needs to go under: a reading every ~17 minutes, a field of view or a
# scan's span of 0.06 degrees, a reach of a millimetre. Tiny positive values got through a mere
# "> 0" and broke what follows: a rate of 1e-320 Hz overflowed the schedule, a field of view of
# 5e-324 rad divided by zero (the simulation thread died of both), one of 1e-310 gave CameraInfo
# K = inf; a range_max of 1e-9 m saw nothing, and 1e-300 is 0 in LaserScan's float32.
MIN_RATE = 1.0e-3  # Hz
MIN_SPAN = 1.0e-3  # rad: horizontal_fov, and a 2D scan's or a 3D lidar's span, first beam to last
MIN_RANGE_MAX = 1.0e-3  # m
MAX_FOV = math.radians(170.0)  # a camera's, horizontal and the vertical one its size implies
# +-pi written with fewer places (3.1416, 3.14159) is +-pi: a full turn when both ends are.
PI_SLACK = 1.0e-4
WORLD = "world"

# The camera's fixed light: from above, a little from the front-left, so faces of one box differ.
LIGHT = np.array([0.3, 0.4, 0.866]) / np.linalg.norm([0.3, 0.4, 0.866])
AMBIENT = 0.35
SKY = np.array([0.62, 0.75, 0.90])

log = logging.getLogger(__name__)


def validate_sensor(raw, path, parents, links=None):
    """A normalised sensor spec (defaults filled in); `parents` are the names that may carry it.
    A parent among `links` (lumped_links) becomes the body the link is lumped into, the pose
    composed with the link's there (a lumped link has no body of its own to ride)."""
    specs.mapping(raw, path, COMMON_KEYS | set().union(*TYPE_KEYS.values()))
    for key in ("name", "type", "parent"):
        if key not in raw:
            raise specs.SpecError(specs.child(path, key), "missing")
    name = specs.name(raw["name"], specs.child(path, "name"))
    kind = raw["type"]
    if kind not in TYPES:
        raise specs.SpecError(specs.child(path, "type"), f"unknown type {specs.quote(kind)} "
                                                         f"(one of: {', '.join(TYPES)})")
    specs.mapping(raw, path, COMMON_KEYS | TYPE_KEYS[kind])
    parent = raw["parent"]
    if not isinstance(parent, str):  # `parents` is a set or dict: a list would not even hash
        raise specs.SpecError(specs.child(path, "parent"), f"expected a string, got {type(parent).__name__}")
    link = (links or {}).get(parent) if parent not in parents else None
    if parent != WORLD and parent not in parents and link is None:
        raise specs.SpecError(specs.child(path, "parent"), f"no vehicle or body named "
                                                           f"{specs.quote(parent)} (or 'world')")
    out = {"name": name, "type": kind, "parent": parent}
    at = lambda key: specs.child(path, key)  # noqa: E731
    for key, pattern, what in (("topic", TOPIC_PATTERN, "a topic name (tokens of letters, digits and '_' "
                                "separated by '/', absolute with a leading '/')"),
                               ("frame_id", FRAME_PATTERN, "a frame name (no leading '/', no spaces)")):
        if key in raw:  # kept only when given: the defaults follow where the sensor is mounted
            if not isinstance(raw[key], str) or len(raw[key]) > 200 or not pattern.fullmatch(raw[key]):
                raise specs.SpecError(at(key), f"{specs.quote(raw[key])} is not {what}")
            out[key] = raw[key]
    value = lambda key: raw.get(key, DEFAULTS[key])  # noqa: E731
    out["pose"] = specs.vector(value("pose"), at("pose"), 6, -specs.MAX_COORDINATE, specs.MAX_COORDINATE)
    if link is not None:
        body, on_body = link
        pose = on_body @ pose_matrix(out["pose"][:3], rpy_to_quat(out["pose"][3:]))
        out["parent"], out["pose"] = body, [*map(float, pose[:3, 3]), *quat_to_rpy(matrix_to_quaternion(pose))]
    out["rate"] = specs.number(value("rate"), at("rate"), MIN_RATE, MAX_RATE)
    keys = TYPE_KEYS[kind]
    for key in sorted(keys & {"range_min", "noise_stddev", "gyro_noise", "accel_noise"}):
        out[key] = specs.number(value(key), at(key), 0.0, 1.0e4)
    if "range_max" in keys:
        out["range_max"] = specs.number(value("range_max"), at("range_max"), MIN_RANGE_MAX, 1.0e4)
    for key in sorted(keys & {"samples", "horizontal_samples", "channels", "width", "height"}):
        out[key] = specs.integer(value(key), at(key), 1, 100_000)
    for key in sorted(keys & {"angle_min", "angle_max"}):
        out[key] = angle(value(key), at(key))
    for key in sorted(keys & {"vertical_min", "vertical_max"}):
        out[key] = specs.number(value(key), at(key), -math.pi / 2, math.pi / 2)
    if "horizontal_fov" in keys:
        out["horizontal_fov"] = specs.number(value("horizontal_fov"), at("horizontal_fov"), MIN_SPAN, MAX_FOV)
    for key in sorted(keys & {"gyro_bias", "accel_bias"}):
        out[key] = specs.vector(value(key), at(key), 3, -1.0e3, 1.0e3)
    if "range_max" in out and not out["range_min"] < out["range_max"]:
        raise specs.SpecError(at("range_max"), f"must be > range_min ({out['range_min']:g}), "
                                               f"got {out['range_max']:g}")
    for low, high, count in (("angle_min", "angle_max", "samples"), ("vertical_min", "vertical_max", "channels")):
        if low not in out:
            continue
        if not out[low] <= out[high]:
            raise specs.SpecError(at(high), f"must be >= {low} ({out[low]:g}), got {out[high]:g}")
        if out[count] > 1 and out[high] - out[low] < MIN_SPAN:
            # Beams (rings) on one angle: LaserScan's angle_increment 0, or duplicate rings.
            raise specs.SpecError(at(high), f"must exceed {low} ({out[low]:g}) by at least {MIN_SPAN:g} rad "
                                            f"with {out[count]} {count} (one alone takes {count}: 1), "
                                            f"got {out[high]:g}")
    if "horizontal_fov" in out:
        check_vertical_fov(out, at("height"))
    rays = ray_count(out)
    if rays > MAX_RAYS:
        raise specs.SpecError(path, f"{rays} rays a scan, more than {MAX_RAYS}")
    return out


def angle(raw, path):
    """A 2D scan's end, in [-pi, pi]; within PI_SLACK of +-pi it is +-pi."""
    value = specs.number(raw, path)
    if abs(abs(value) - math.pi) <= PI_SLACK:
        return math.copysign(math.pi, value)
    if abs(value) > math.pi:
        raise specs.SpecError(path, f"must be within [-pi, pi] (rad; values within {PI_SLACK:g} of +-pi "
                                    f"count as +-pi), got {value:g}")
    return value


def check_vertical_fov(spec, path):
    """A camera's vertical field of view, which its size and horizontal_fov imply (square
    pixels), must be within MAX_FOV as its horizontal one is: a 1 x 20,000 image at 90 degrees
    across saw 179.99 degrees up and down."""
    ratio = spec["height"] / spec["width"]
    vertical = 2.0 * math.atan(ratio * math.tan(0.5 * spec["horizontal_fov"]))
    if vertical > MAX_FOV:
        rows = math.floor(spec["width"] * math.tan(0.5 * MAX_FOV) / math.tan(0.5 * spec["horizontal_fov"]))
        raise specs.SpecError(path, f"{spec['height']} rows at width {spec['width']} give a vertical field of view "
                                    f"of {math.degrees(vertical):.2f} deg (square pixels), more than "
                                    f"{math.degrees(MAX_FOV):g} (at most {rows} rows at this width and horizontal_fov)")


def validate_sensors(raw, parents, path="sensors", links=None):
    """The scene's `sensors` list, validated; names are unique among the sensors and the bodies
    (a sensor's name is its frame, beside the bodies' frames). `parents` maps every body's and
    vehicle's name to what has it (e.g. "bodies[0]'s name"), for the messages; `links` as
    validate_sensor's."""
    raw = [] if raw is None else raw
    if not isinstance(raw, list):
        raise specs.SpecError(path, f"expected a list, got {type(raw).__name__}")
    out, owners = [], {**parents, WORLD: "the world frame"}
    for k, entry in enumerate(raw):
        at = specs.child(path, k)
        sensor = validate_sensor(entry, at, parents, links)
        if sensor["name"] in owners:
            raise specs.SpecError(specs.child(at, "name"),
                                  f"duplicate name {specs.quote(sensor['name'])}: already "
                                  f"{owners[sensor['name']]} (sensor names are frames, unique "
                                  "among bodies, vehicles and sensors)")
        owners[sensor["name"]] = f"{at}'s name"
        out.append(sensor)
    return out


def ray_count(spec):
    kind = spec["type"]
    if kind == "lidar_2d":
        return spec["samples"]
    if kind == "lidar_3d":
        return spec["horizontal_samples"] * spec["channels"]
    if kind in ("depth_camera", "camera"):
        return spec["width"] * spec["height"]
    return 0


def spread(low, high, count, closed):
    """count angles from low to high: including high when closed, else a full turn's spacing."""
    if count == 1:
        return np.array([0.5 * (low + high)])
    return low + (high - low) * np.arange(count) / (count - 1 if closed else count)


# A scan at least this close to a full turn is one (its last beam would repeat its first): the
# default scene's -3.14159265..3.14159265, pi to eight places, falls 7e-9 short of 2 pi.
FULL_TURN_TOLERANCE = 1e-6


def lidar_2d_angles(spec):
    """The beam angles; a full turn does not repeat its first beam at its end."""
    full = spec["angle_max"] - spec["angle_min"] >= 2.0 * math.pi - FULL_TURN_TOLERANCE
    return spread(spec["angle_min"], spec["angle_max"], spec["samples"], not full)


def camera_intrinsics(spec):
    """fx = fy, cx, cy of a pinhole camera with the given horizontal field of view, pixel
    centres at integer coordinates (OpenCV, image_geometry, depth_image_proc): the image's
    centre is ((width - 1) / 2, (height - 1) / 2), its edges half a pixel beyond the first
    and the last centres."""
    width, height = spec["width"], spec["height"]
    f = 0.5 * width / math.tan(0.5 * spec["horizontal_fov"])
    return f, f, 0.5 * (width - 1), 0.5 * (height - 1)


def local_directions(spec):
    """Unit ray directions in the sensor frame (x forward, y left, z up), scan order: a 2D scan
    counter-clockwise; a 3D scan ring by ring (lowest first), each counter-clockwise from
    behind; a camera image row by row from the top left, through pixel centres (at integer
    pixel coordinates, camera_intrinsics)."""
    kind = spec["type"]
    if kind == "lidar_2d":
        a = lidar_2d_angles(spec)
        return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    if kind == "lidar_3d":
        azimuth = spread(-math.pi, math.pi, spec["horizontal_samples"], False)
        elevation = spread(spec["vertical_min"], spec["vertical_max"], spec["channels"], True)
        e, a = np.meshgrid(elevation, azimuth, indexing="ij")
        return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1).reshape(-1, 3)
    fx, fy, cx, cy = camera_intrinsics(spec)
    v, u = np.meshgrid(np.arange(spec["height"]), np.arange(spec["width"]), indexing="ij")
    # Optical (x right, y down, z forward) -> sensor frame (x forward, y left, z up).
    right, down = (u - cx) / fx, (v - cy) / fy
    d = np.stack([np.ones_like(right), -right, -down], axis=-1).reshape(-1, 3)
    return d / np.linalg.norm(d, axis=1)[:, None]


def quat_to_rpy(q):
    """(x, y, z, w) -> roll, pitch, yaw (fixed axes X, Y, Z: URDF's and math3d.rpy_to_quat's)."""
    x, y, z, w = q
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))  # rounding may pass 1
    return (math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)), pitch,
            math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def lumped_links(models):
    """{'<robot>.<link>': (its body, its pose in that body's frame, 4x4)} of the URDF links that
    fixed joints lump into another link's body (the Husky's base_link into base_footprint's):
    `models` are (robot name, urdf_import.RobotModel)."""
    out = {}
    for robot, model in models:
        for link, (body, pose) in model.link_frames.items():
            if body != f"{robot}.{link}":
                out[f"{robot}.{link}"] = (body, pose)
    return out


def pose_matrix(xyz, quaternion):
    m = np.eye(4)
    m[:3, :3] = quaternions_to_matrices(np.asarray(quaternion, float)[None])[0]
    m[:3, 3] = xyz
    return m


def mount_motion(world, parent, mount):
    """(the pose in the world (4 x 4) of a frame at `mount` (4 x 4) on `parent`, a body's name
    or WORLD; the parent's angular velocity; the world velocity of that frame's origin, the
    parent's at that point), all in the world frame: where a sensor is and how it moves."""
    if parent == WORLD:
        return mount, np.zeros(3), np.zeros(3)
    body = world.body(parent)
    pose = pose_matrix(body["position"], body["quaternion"]) @ mount
    angular = np.asarray(body["angular_velocity"], float)
    arm = pose[:3, 3] - np.asarray(body["position"], float)
    return pose, angular, np.asarray(body["linear_velocity"], float) + np.cross(angular, arm)


class Clock:
    """Simulated time against the world's step count: the steps from `step` on, taken at
    `steps_per_second`, each last 1 / steps_per_second after `time`. A change of the step rate
    starts another from then (so the steps taken before at the old rate are not counted as
    if at the new one); while the rate stays, a step's time is its count over the rate."""

    # A time reached within this fraction of a step counts as reached (float rounding).
    SLACK = 1e-6

    def __init__(self, step, time, steps_per_second):
        self.step, self.time, self.steps_per_second = step, time, steps_per_second

    def time_of(self, step):
        return self.time + (step - self.step) / self.steps_per_second

    def step_at(self, time):
        """The first step at or after simulated `time` (for a time before this clock's start,
        as if the steps had been this long: one already passed, so skipped, not read late)."""
        return self.step + math.ceil((time - self.time) * self.steps_per_second - self.SLACK)


class Sensor:
    """One sensor: its spec, its rays in its own frame and its noise generator."""

    def __init__(self, spec, seed):
        self.spec = spec
        self.name, self.kind, self.parent = spec["name"], spec["type"], spec["parent"]
        self.mount = pose_matrix(spec["pose"][:3], rpy_to_quat(spec["pose"][3:]))
        self.directions = local_directions(spec) if self.kind != "imu" else np.zeros((0, 3))
        # How far along each ray it reaches (range_max; a camera's far plane) and where it
        # starts (the colour camera's near clipping plane).
        self.reach, self.clip = spec.get("range_max", 0.0), 0.0
        if self.kind in CAMERAS:
            self.reach = spec["range_max"] / self.directions[:, 0]
        if self.kind == "camera":
            self.clip = spec["range_min"] / self.directions[:, 0]
        self.rng = np.random.Generator(np.random.PCG64([seed, zlib.crc32(self.name.encode())]))
        self.hits = None  # the RayHits each scan is cast into (allocated once: a scan's size is fixed)
        self.samples_taken = 0  # n of the next sample time n / rate
        self.last_velocity = None  # an IMU's mount point's world velocity at its last sample, or
        self.last_time = None      # when it was made (None: its parent was not there then)
        self.parent_id = None      # World.body_id of the body it was put on (None: the world's)

    def due_step(self, clock):
        """The step count at which the next sample is read: the first step at or after n / rate."""
        return clock.step_at(self.samples_taken / self.spec["rate"])


class SensorError(RuntimeError):
    """A sensor could not be made or scheduled (Sensors.follow: the others go on)."""


class Sensors:
    """The sensors of whatever World it is handed: when they are due, and their readings. It
    follows the world's `sensor_specs` (rebuilt when the world, its sensors or its time go
    back), and hands each reading to `on_reading(sensor, reading)`."""

    def __init__(self, on_reading=None):
        self.on_reading = on_reading
        self.sensors = []
        self.clock = None  # the world's Clock since it came or last changed its step rate
        self._world, self._specs, self._step = None, None, -1
        self._said_too_fast = set()  # (name, rate, steps_per_second) warned of: once each, not per rebuild

    def follow(self, world):
        """New sensors for a new world, or when its time went back; when only its sensor specs
        changed, new ones for the specs replaced (another dict: an edit, a reset restoring the
        bodies they hang on) while the others go on (their noise, schedule and IMU history:
        spawning a sensor does not reset the rest). A new step rate starts a new Clock: the
        sensors' next samples stay at their times, now reached in steps of the new length.

        A sensor that cannot be made or scheduled (a spec no validation let through) is left
        out, the others are made, and then a SensorError names it: the Simulation counts that
        as a fault and goes on, and the spec is tried again when the specs change."""
        fresh = world is not self._world or world.step_count < self._step
        rate = world.settings["steps_per_second"]
        # Also when the clock no longer tells the world's time (the step rate changed and came
        # back while no sensor followed it: sensors spawned then read at the wrong times).
        if fresh or self.clock is None or rate != self.clock.steps_per_second or \
                abs(self.clock.time_of(world.step_count) - world.time) > 0.5 / rate:
            self.clock = Clock(world.step_count, world.time, rate)
            if not fresh:
                for sensor in self.sensors:
                    self.warn_if_too_fast(sensor.spec, rate)
        failed = []
        if fresh or world.sensor_specs is not self._specs:
            kept = {} if fresh else {id(sensor.spec): sensor for sensor in self.sensors}
            self._world, self._specs = world, world.sensor_specs
            # What was said of sensors and rates there no longer (bounded under spawn and remove).
            present = {(spec.get("name"), spec.get("rate")) for spec in world.sensor_specs}
            self._said_too_fast = {said for said in self._said_too_fast if said[:2] in present}
            self.sensors = []
            for spec in world.sensor_specs:
                sensor = kept.get(id(spec))
                if sensor is None:
                    try:
                        sensor = Sensor(spec, world.settings["seed"])
                        self.start(sensor, world)
                    except Exception as error:
                        failed.append((spec.get("name"), error))
                        continue
                    self.warn_if_too_fast(spec, rate)
                self.sensors.append(sensor)
        self._step = world.step_count
        if failed:
            raise SensorError("; ".join(f"sensor {name} left out: {type(error).__name__}: {error}"
                                        for name, error in failed)) from failed[0][1]

    def warn_if_too_fast(self, spec, steps_per_second):
        """At most one reading a step (one state a step to read): a faster rate is said, once
        for each sensor, rate and step rate (a reset makes the sensors again, with nothing new
        to say)."""
        setting = (spec["name"], spec["rate"], steps_per_second)
        if spec["rate"] > steps_per_second and setting not in self._said_too_fast:
            self._said_too_fast.add(setting)
            log.warning("sensor %s: rate %g Hz is above steps_per_second (%d): it is read once a step, "
                        "at %d Hz", spec["name"], spec["rate"], steps_per_second, steps_per_second)

    def start(self, sensor, world):
        """A new sensor's first sample is the next one after now; an IMU measures its
        acceleration from now on."""
        now = self.clock.time_of(world.step_count)
        sensor.samples_taken = math.floor(now * sensor.spec["rate"]) + 1
        while sensor.due_step(self.clock) <= world.step_count:
            sensor.samples_taken += 1
        if sensor.parent != WORLD:
            try:
                sensor.parent_id = world.body_id(sensor.parent)
            except KeyError:  # gone already: the sensor goes at its first sample
                return
        if sensor.kind == "imu":
            sensor.last_velocity, sensor.last_time = mount_motion(world, sensor.parent, sensor.mount)[2], world.time

    def steps_until_due(self, world):
        """Steps the world may take before the next sample (at least 1): a batch ends there."""
        self.follow(world)
        if not self.sensors:
            return math.inf
        return max(1, min(s.due_step(self.clock) for s in self.sensors) - world.step_count)

    def sample(self, world):
        """Reads the sensors due at the world's current step and returns [(sensor, reading)]
        (see read()), after handing each to on_reading. Samples whose step was passed without a
        reading (the world stepped past it) are skipped, not read late. A sensor whose parent
        is gone goes with it, with a warning (also when another body took its name since)."""
        self.follow(world)
        clock, now = self.clock, world.step_count
        due = []
        for sensor in list(self.sensors):
            while sensor.due_step(clock) < now:
                sensor.samples_taken += 1
            if sensor.due_step(clock) != now:
                continue
            sensor.samples_taken += 1
            if sensor.parent != WORLD:
                if sensor.parent_id is None or world.body_name(sensor.parent_id) != sensor.parent:
                    log.warning("sensor %s removed: its parent %s is gone", sensor.name, sensor.parent)
                    self.sensors.remove(sensor)
                    world.sensor_specs = self._specs = [s for s in world.sensor_specs if s is not sensor.spec]
                    continue
            due.append(sensor)
        if not due:
            return []
        scene = world.ray_scene() if any(s.kind != "imu" for s in due) else None
        readings = [(sensor, self.read(sensor, world, scene)) for sensor in due]
        if self.on_reading is not None:
            for sensor, reading in readings:
                self.on_reading(sensor, reading)
        return readings

    def all_rays(self, world):
        """Every sensor's rays now, concatenated (origins, directions, ranges): for bench/."""
        self.follow(world)
        origins, directions, ranges = [], [], []
        for sensor in self.sensors:
            if sensor.kind != "imu":
                origin, sensor_directions, reach = self.rays(sensor, world)
                origins.append(np.broadcast_to(origin, sensor_directions.shape))
                directions.append(sensor_directions)
                ranges.append(np.broadcast_to(reach, len(sensor_directions)))
        return np.concatenate(origins), np.concatenate(directions), np.concatenate(ranges)

    # ------------------------------------------------------------------ readings
    def rays(self, sensor, world):
        """The sensor's rays now, in the world frame: (their origins (3,) or (R, 3), the
        directions (R, 3), how far each reaches from its origin: a number or (R,))."""
        pose = mount_motion(world, sensor.parent, sensor.mount)[0]
        directions = sensor.directions @ pose[:3, :3].T
        origin = pose[:3, 3]
        if sensor.kind == "camera":  # from the near clipping plane
            return origin + directions * sensor.clip[:, None], directions, sensor.reach - sensor.clip
        return origin, directions, sensor.reach

    def read(self, sensor, world, scene):
        """A dict of the reading, by type:
        lidar_2d: ranges (N,) float32 (REP 117: +inf no return, -inf nearer than range_min);
        lidar_3d: points (N, 3) float32 in the sensor frame of the returns, intensity, ring;
        depth_camera: depth (H, W) float32 along the optical axis (REP 118, with REP 117's
        -inf nearer than range_min and +inf no return);
        camera: rgb (H, W, 3) uint8; imu: orientation (xyzw), angular_velocity,
        linear_acceleration (specific force, sensor frame). Each has its `time`; a 2D scan its
        `period` too (LaserScan's scan_time): 1 / rate, or a step when that is longer."""
        time = world.time
        if sensor.kind == "imu":
            return {"time": time, **self.read_imu(sensor, world)}
        origin, directions, reach = self.rays(sensor, world)
        exclude = () if sensor.parent == WORLD else (sensor.parent,)
        hits = sensor.hits = scene.cast(origin, directions, reach, exclude, out=sensor.hits)
        spec = sensor.spec
        if sensor.kind == "camera":
            return {"time": time, "rgb": self.shade(hits, directions, world).reshape(spec["height"], spec["width"], 3)}
        distance = hits.distance.copy()
        if spec["noise_stddev"] > 0.0:
            finite = np.isfinite(distance)
            distance[finite] += sensor.rng.normal(0.0, spec["noise_stddev"], int(finite.sum()))
        if sensor.kind == "depth_camera":
            distance *= sensor.directions[:, 0]  # depth is along the optical axis, not the ray
        far = ~(distance <= spec["range_max"])  # no return (inf), or noise took it beyond
        near = distance < spec["range_min"]
        if sensor.kind == "lidar_3d":
            keep = ~(far | near)
            local = sensor.directions[keep] * distance[keep, None]
            ring = np.repeat(np.arange(spec["channels"], dtype=np.uint16), spec["horizontal_samples"])[keep]
            return {"time": time, "points": local.astype(np.float32), "ring": ring,
                    "intensity": self.intensity(hits, directions)[keep].astype(np.float32)}
        ranges = distance.astype(np.float32)
        ranges[far] = np.inf
        ranges[near] = -np.inf
        if sensor.kind == "lidar_2d":
            # The time between this sensor's readings: 1 / rate, or a step when that is longer.
            period = max(1.0 / sensor.spec["rate"], 1.0 / world.settings["steps_per_second"])
            return {"time": time, "ranges": ranges, "period": period}
        return {"time": time, "depth": ranges.reshape(spec["height"], spec["width"])}

    @staticmethod
    def intensity(hits, directions):
        """A lidar return's strength: the cosine between the beam and the surface, 0..1."""
        with np.errstate(invalid="ignore"):
            return np.clip(-np.einsum("ij,ij->i", hits.normal, directions), 0.0, 1.0)

    def shade(self, hits, directions, world):
        """Each pixel the colour of what it sees (the markers' colours) lit by a fixed light:
        ambient plus Lambert; the sky where nothing is hit."""
        state = world.state()
        vehicles = set(world.vehicle_names())
        kinds = np.where(state["immovable"], IMMOVABLE, BOX)
        kinds[[k for k, n in enumerate(world.body_names()) if n in vehicles]] = VEHICLE
        kinds = np.where(state["frozen"], FROZEN, kinds)
        # One palette row per body, then NOTHING, PLAYGROUND, GROUND: what a pixel hit (a row, or
        # one of those negative codes) modulo the palette's length is its row.
        palette = np.empty((len(kinds) + 3, 3))
        palette[:len(kinds)] = CATEGORY_COLOURS[kinds, :3]
        for what, colour in ((NOTHING, SKY), (PLAYGROUND, COLOURS["playground"][:3]),
                             (GROUND, COLOURS["ground"][:3])):
            palette[what] = colour
        light = AMBIENT + (1.0 - AMBIENT) * np.clip(hits.normal @ LIGHT, 0.0, 1.0)
        light[hits.body == NOTHING] = 1.0  # the sky is not lit
        colour = palette[hits.body % len(palette)] * light[:, None]
        return np.rint(colour * 255.0).astype(np.uint8)

    def read_imu(self, sensor, world):
        """REP 145 readings of the parent body at the sensor: orientation (sensor frame in the
        world), angular velocity (sensor frame) and specific force: a - g, where a is the mean
        acceleration of the mount point since the last sample (the change of its velocity over
        the simulated time between them: samples fall on whole steps, so that interval is 1 /
        rate only on average), so at rest it reads +9.81 m/s^2 up and in free fall 0. The first
        sample measures from when the sensor was made (spawned, loaded, time reset)."""
        pose, angular, linear = mount_motion(world, sensor.parent, sensor.mount)
        rotation = pose[:3, :3]
        gravity = np.asarray(world.settings["gravity"], float)
        acceleration = np.zeros(3)
        if sensor.last_time is not None and world.time > sensor.last_time:
            acceleration = (linear - sensor.last_velocity) / (world.time - sensor.last_time)
        sensor.last_velocity, sensor.last_time = linear, world.time
        spec = sensor.spec
        gyro = rotation.T @ angular + spec["gyro_bias"]
        accel = rotation.T @ (acceleration - gravity) + spec["accel_bias"]
        if spec["gyro_noise"] > 0.0:
            gyro = gyro + sensor.rng.normal(0.0, spec["gyro_noise"], 3)
        if spec["accel_noise"] > 0.0:
            accel = accel + sensor.rng.normal(0.0, spec["accel_noise"], 3)
        return {"orientation": matrix_to_quaternion(rotation), "angular_velocity": gyro,
                "linear_acceleration": accel}

