"""URDF robots as a ROS 2 stack sees them (issue 38), ROS-free: a robot entry (a scene's
`robots:` item or a ~/spawn's) checked against its description and added to the World with a
namespace; the frames, joint states and odometry the node publishes for it; and the commands it
obeys, applied on the simulation thread.

Per robot, relative to its namespace (the first robot of the world, vehicles included, stands in
the root one, each other in its name's; the entry's `namespace` chooses, unique):
    joint_states          out, publish_rate: its revolute, continuous and prismatic joints by
                          their URDF names (position, velocity, effort)
    robot_description     out, latched: the URDF as loaded
    joint_commands        in, sensor_msgs/JointState by name (topic_based_ros2_control's command
                          topic): position (with velocity: its feed-forward), else velocity, else
                          effort
    position_commands, velocity_commands, effort_commands
                          in, std_msgs/Float64MultiArray in the order of the entry's `joints`
                          (a forward_command_controller's)
    joint_trajectory      in, trajectory_msgs/JointTrajectory (a joint_trajectory_controller's
                          topic): followed on the simulation's clock
    cmd_vel, odom         with a `drive` (diff_drive_controller's keys and conventions)
Frames are `<prefix><link>`: /tf carries <world_frame> -> the root link (with a drive, REP 105's
<world_frame> -> odom -> root, as the vehicles have it) and each joint's parent link -> child
link as the bodies stand now; links lumped into one body are fixed to it (/tf_static).
"""
import logging
import math
from collections import namedtuple

import numpy as np

from .physics import specs
from .physics.math3d import matrix_to_quaternion, quaternions_to_matrices
from .robots import STACK_FRAMES, namespace_prefix, validate_robot
from .sensors import WORLD

ENTRY_KEYS = {"name", "urdf", "position", "rpy", "quaternion", "fixed_base", "self_collide",
              "joint_positions", "hold", "namespace", "joints", "drive", "localization", "publish_odom_tf"}
# A drive's keys, in the words of the ros2_controllers that do the same on a real robot:
# diff_drive_controller's and ackermann_steering_controller's.
DRIVE_KEYS = {
    "diff_drive": {"type", "left_wheel_names", "right_wheel_names", "wheel_separation", "wheel_radius",
                   "wheel_separation_multiplier"},
    "ackermann": {"type", "front_wheels_names", "rear_wheels_names", "wheelbase", "front_wheel_track",
                  "rear_wheel_track", "rear_wheels_radius"},
}
DRIVE_TYPES = tuple(DRIVE_KEYS)
# What an entry of a ray-cast vehicle's description may say (urdf_robots.vehicle_entry).
VEHICLE_ENTRY_KEYS = {"name", "urdf", "position", "rpy", "quaternion"} | specs.ROBOT_KEYS
LOCALIZATIONS = ("ground_truth", "none")
COMMAND_KINDS = ("position", "velocity", "effort")
log = logging.getLogger(__name__)
# diff_drive_controller's default pose and twist covariance diagonals (x y z roll pitch yaw):
# the wheels' odometry is not exact (they slip), and a filter fusing it must know.
WHEEL_ODOMETRY_COVARIANCE = [(0.01 if row == 5 else 0.001) if row == column else 0.0
                             for row in range(6) for column in range(6)]
# An effort command is a velocity motor whose effort bound is the effort, aiming at the joint's
# speed limit (or this, without one): it pushes with exactly that effort until the limit.
EFFORT_SPEED = 1.0e3


def is_description_text(source):
    """Whether a robot's `urdf` (or a description's source) is the description's text itself,
    not a file's name: it starts with '<'."""
    return isinstance(source, str) and source.lstrip().startswith("<")


def description_source(raw, path):
    """A robot entry's `urdf`, checked: a file's name, or the description's text itself."""
    if "urdf" not in raw:
        raise specs.SpecError(f"{path}.urdf", "missing (a robot is a name and a URDF file)")
    if not isinstance(raw["urdf"], str) or not raw["urdf"]:
        raise specs.SpecError(f"{path}.urdf", "expected a file name or the description's text")
    return raw["urdf"]


def validate_entry(raw, path):
    """The keys of a robot entry that need no description, checked: name, urdf, placement,
    fixed_base, self_collide, joint_positions, hold (its joints' position motors hold
    joint_positions from the start), namespace, joints, drive, localization, publish_odom_tf.
    Returns (entry, placement fields)."""
    specs.mapping(raw, path, ENTRY_KEYS)
    if "name" not in raw:
        raise specs.SpecError(f"{path}.name", "missing (a robot is a name and a URDF file)")
    source = description_source(raw, path)
    fields = specs.validate_body_fields({key: raw[key] for key in ("name", "position", "rpy", "quaternion")
                                         if key in raw}, path)
    entry = {"name": fields["name"], "urdf": source}
    for key in ("fixed_base", "self_collide", "hold", "publish_odom_tf"):
        if raw.get(key) is not None:
            entry[key] = specs.boolean(raw[key], f"{path}.{key}")
    positions = raw.get("joint_positions") or {}
    if not isinstance(positions, dict):
        raise specs.SpecError(f"{path}.joint_positions", "expected a mapping {joint: rad or m}")
    entry["joint_positions"] = {str(joint): specs.number(value, f"{path}.joint_positions.{joint}",
                                                         -specs.MAX_COORDINATE, specs.MAX_COORDINATE)
                                for joint, value in positions.items()}
    if "namespace" in raw:
        if not isinstance(raw["namespace"], str) or not specs.NAMESPACE_PATTERN.fullmatch(raw["namespace"]):
            raise specs.SpecError(f"{path}.namespace", f"{specs.quote(raw['namespace'])} is not a relative ROS "
                                                       "namespace (letters, digits and '_' in tokens joined by '/')")
        entry["namespace"] = raw["namespace"]
    if "localization" in raw:
        if raw["localization"] not in LOCALIZATIONS:
            raise specs.SpecError(f"{path}.localization", f"{specs.quote(raw['localization'])}: expected one of "
                                                          f"{', '.join(LOCALIZATIONS)}")
        entry["localization"] = raw["localization"]
    if raw.get("joints") is not None:
        entry["joints"] = names_list(raw["joints"], f"{path}.joints")
    if raw.get("drive") is not None:
        entry["drive"] = validate_drive(raw["drive"], f"{path}.drive")
    return entry, fields


def vehicle_entry(raw, path, description, label):
    """The vehicle (a `vehicles` entry, validated) that a robot entry stands for when its
    description (the URDF text, urdf_import.read_description's) is a ray-cast vehicle's, with a
    <vplayground><vehicle> element (robot_description writes it; the built-in car's is the
    package's config/car.urdf): name, placement and the vehicle's robot keys (namespace,
    localization, publish_odom_tf, odometry) from the entry. None for any other description.
    UrdfError when the description does not hold together."""
    from .robot_description import vehicle_from_description  # (it imports frame_names, which imports this)
    vehicle = vehicle_from_description(description, label)
    if vehicle is None:
        return None
    specs.mapping(raw, path, VEHICLE_ENTRY_KEYS)  # no joints to name, hold or drive: its wheels are rays
    if "name" not in raw:
        raise specs.SpecError(f"{path}.name", "missing (a robot is a name and a URDF file)")
    return validate_robot(specs.validate_vehicle({**vehicle, **{key: value for key, value in raw.items()
                                                                if key != "urdf"}}, path), path)


def names_list(value, path):
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise specs.SpecError(path, "expected a list of joint names")
    if len(set(value)) != len(value):
        raise specs.SpecError(path, "a joint is named twice")
    return list(value)


def validate_drive(raw, path):
    """A drive: `type` diff_drive (the default) with diff_drive_controller's keys
    left_wheel_names, right_wheel_names (joints), wheel_separation and wheel_radius (m,
    required, as there) and wheel_separation_multiplier (1.0: a skid-steer's wheels slip
    sideways in a turn, so it turns as if they stood that much farther apart); or ackermann
    with ackermann_steering_controller's front_wheels_names (the two steering joints, left then
    right), rear_wheels_names (the two driven wheel joints, left then right), wheelbase,
    front_wheel_track (between the steering joints), rear_wheel_track and rear_wheels_radius."""
    if not isinstance(raw, dict):
        raise specs.SpecError(path, "expected a mapping")
    kind = raw.get("type", "diff_drive")
    if kind not in DRIVE_TYPES:
        raise specs.SpecError(f"{path}.type", f"{specs.quote(kind)}: expected one of {', '.join(DRIVE_TYPES)}")
    specs.mapping(raw, path, DRIVE_KEYS[kind])
    drive = {"type": kind}
    names = (("left_wheel_names", "right_wheel_names") if kind == "diff_drive" else
             ("front_wheels_names", "rear_wheels_names"))
    lengths = (("wheel_separation", "wheel_radius") if kind == "diff_drive" else
               ("wheelbase", "front_wheel_track", "rear_wheel_track", "rear_wheels_radius"))
    for key in names:
        if key not in raw:
            raise specs.SpecError(f"{path}.{key}", "missing (the joints of that side)" if kind == "diff_drive"
                                  else "missing (two joints: left, right)")
        drive[key] = names_list(raw[key], f"{path}.{key}")
        if kind == "ackermann" and len(drive[key]) != 2:
            raise specs.SpecError(f"{path}.{key}", "expected two joints: left, right")
    for key in lengths:
        if key not in raw:
            raise specs.SpecError(f"{path}.{key}", "missing (m)")
        drive[key] = specs.number(raw[key], f"{path}.{key}", 0.0, specs.MAX_COORDINATE, low_open=True)
    if kind == "diff_drive":
        drive["wheel_separation_multiplier"] = specs.number(raw.get("wheel_separation_multiplier", 1.0),
                                                            f"{path}.wheel_separation_multiplier", 0.0, 100.0,
                                                            low_open=True)
    shared = set(drive[names[0]]) & set(drive[names[1]])
    if shared:
        raise specs.SpecError(f"{path}.{names[1]}", f"{sorted(shared)[0]!r} is in {names[0]} too")
    return drive


def check_against_model(entry, model, path):
    """The entry's joint names against the description's: `joints` name movable joints (the
    default: all of them, in the description's order); a drive's wheels continuous or revolute
    ones."""
    movable = model.joint_names
    for joint in entry.get("joints", []):
        if joint not in movable:
            raise specs.SpecError(f"{path}.joints", f"{joint!r} is no revolute, continuous or prismatic joint of "
                                                    "the description")
        if joint in model.mimics:
            raise specs.SpecError(f"{path}.joints", f"{joint!r} mimics {model.mimics[joint][0]!r}: it takes no "
                                                    "commands of its own")
    drive = entry.get("drive")
    if drive is not None:
        kinds = {spec["name"]: spec["type"] for spec in model.joints}
        for key in ("left_wheel_names", "right_wheel_names", "front_wheels_names", "rear_wheels_names"):
            for joint in drive.get(key, ()):
                if joint not in movable or kinds[movable[joint]] == "prismatic":
                    raise specs.SpecError(f"{path}.drive.{key}", f"{joint!r} is no revolute or continuous joint "
                                                                 "of the description")
                if joint in model.mimics:
                    raise specs.SpecError(f"{path}.drive.{key}", f"{joint!r} mimics {model.mimics[joint][0]!r}: "
                                                                 "it takes no commands of its own")


def reserved_frames(entry, frames):
    """The frames no link of the robot of `entry` may be: the world frame (and WORLD, what a
    sensor's parent calls it), a stack's, and with a drive the odom frame."""
    return {frames.world, WORLD, *STACK_FRAMES, *((frames.odom,) if entry.get("drive") else ())}


def robot_namespace(entry, model, taken, frames):
    """The namespace the robot of `entry` (its RobotModel `model`) stands in where `taken`
    ({namespace: whose}) are taken: the entry's, else the root one unless a robot has it or a
    link would be a reserved frame there, else its name's."""
    root_free = "" not in taken and not reserved_frames(entry, frames).intersection(model.link_frames)
    return entry.get("namespace", "" if root_free else specs.name_token(entry["name"]))


def add_robot_entry(world, entry, model, path, frames):
    """Adds a checked entry's robot (urdf_import.add_robot: all or none) and lists it in
    world.robot_specs with its namespace: the entry's, else the root one if no vehicle or robot
    has it (and none of its links would be a reserved frame there), else its name's. `frames`
    (parameters.Frames): no link may be the world frame, a stack's or, with a drive, the odom
    frame, nor a body's name or a sensor's frame (frame_names.check_robot_frames: FrameTaken).
    Returns the bodies added."""
    from .frame_names import check_robot_frames  # (it imports this module)
    from .urdf_import import add_robot
    taken = world.robot_namespaces()
    reserved = reserved_frames(entry, frames)
    namespace = robot_namespace(entry, model, taken, frames)
    if namespace in taken:
        raise specs.SpecError(f"{path}.namespace", f"{namespace!r} is the namespace of {taken[namespace]} already")
    prefix = namespace_prefix(namespace)
    clash = next((link for link in model.link_frames if prefix + link in reserved), None)
    if clash is not None:
        raise specs.SpecError(f"{path}.namespace", f"its link {clash!r} would be the frame {prefix + clash!r}, which "
                                                   "the node or a stack publishes: give the robot a namespace")
    check_robot_frames(world, entry["name"], model, namespace, path, frames)
    added = add_robot(world, model)
    limits = {spec["name"]: (spec["motor"]["max_effort"], spec["motor"]["max_speed"]) for spec in model.joints}
    if entry.get("hold"):  # powered on: position motors hold where the joints start (a mimic follows its own)
        start = {spec["name"]: spec["position"] for spec in model.joints}
        world.drive_joints({entity: {"mode": "position", "target": start[entity], "velocity": 0.0,
                                     "max_effort": limits[entity][0], "max_speed": limits[entity][1]}
                            for joint, entity in model.joint_names.items() if joint not in model.mimics})
    world.robot_specs = [*world.robot_specs, {
        **entry, "namespace": namespace,
        "joints": entry.get("joints", [joint for joint in model.joint_names if joint not in model.mimics]),
        "bodies": [b["name"] for b in model.bodies], "joints_held": list(model.joint_names.values()),
        "model": model, "limits": limits, "id": world.body_id(model.bodies[0]["name"])}]
    return added


def robot_spec(world, name):
    """The world.robot_specs entry of the URDF robot `name`, or None."""
    return next((robot for robot in world.robot_specs if robot["name"] == name), None)


# ---------------------------------------------------------------------- sensors on their links
class LinkCarrier(namedtuple("LinkCarrier", "name namespace link")):
    """A URDF robot's body as a sensor's parent: the sensor hangs from the body's link frame
    (prefix + link), its own frame takes the robot's prefix and its topics the robot's namespace,
    as on a vehicle."""

    @property
    def prefix(self):
        return namespace_prefix(self.namespace)

    def topic(self, name):
        return self.prefix + name

    @property
    def base(self):
        return self.prefix + self.link


def link_carriers(robot_specs):
    """{body name: LinkCarrier} of the URDF robots' bodies (World.robot_specs)."""
    return {body: LinkCarrier(body, spec["namespace"], link)
            for spec in robot_specs for body, link in spec["model"].body_links.items()}


# ---------------------------------------------------------------------- as the publisher sees it
class UrdfRobot(namedtuple("UrdfRobot", "name namespace joint_names body_rows links drive localization "
                                        "publish_odom_tf description")):
    """A URDF robot in a snapshot's layout: its joint_states names (URDF), the snapshot rows of
    its bodies, `links`: [(link, parent link or None, body index in body_rows,
    its 4x4 pose in that body's frame)], parents first; `drive` (the entry's, or None)."""

    @property
    def prefix(self):
        return namespace_prefix(self.namespace)

    def topic(self, name):
        return self.prefix + name

    def frame(self, link):
        return self.prefix + link

    @property
    def root(self):
        return self.links[0][0]


def publishing_view(spec, rows, localization="ground_truth", publish_odom_tf=True):
    """The UrdfRobot of a world.robot_specs entry; `rows`: {body name: snapshot row}."""
    model = spec["model"]
    bodies = spec["bodies"]
    index = {body: k for k, body in enumerate(bodies)}
    links = [(link, model.link_parents.get(link), index[body], pose)
             for link, (body, pose) in model.link_frames.items()]
    return UrdfRobot(spec["name"], spec["namespace"], tuple(model.joint_names),
                     np.array([rows[b] for b in bodies], np.int64), links, spec.get("drive"),
                     spec.get("localization", localization), spec.get("publish_odom_tf", publish_odom_tf),
                     model.description)


def body_matrices(state, rows):
    """4x4 poses of the bodies at snapshot `rows`."""
    out = np.tile(np.eye(4), (len(rows), 1, 1))
    out[:, :3, :3] = quaternions_to_matrices(state["quaternions"][rows])
    out[:, :3, 3] = state["positions"][rows]
    return out


def link_edges(robot, state):
    """[(parent frame, child frame, xyz + xyzw)] of the joints between links of different bodies,
    from the bodies' poses in `state`."""
    bodies = body_matrices(state, robot.body_rows)
    poses = {link: bodies[body] @ pose for link, _, body, pose in robot.links}
    body_of = {link: body for link, _, body, _ in robot.links}
    return [(robot.frame(parent), robot.frame(link), matrix_pose(np.linalg.solve(poses[parent], poses[link])))
            for link, parent, body, _ in robot.links[1:] if body_of[parent] != body]


def fixed_edges(robot):
    """The same for the links lumped into one body: fixed, from the description."""
    frames = {link: (body, pose) for link, _, body, pose in robot.links}
    return [(robot.frame(parent), robot.frame(link), matrix_pose(np.linalg.solve(frames[parent][1], pose)))
            for link, parent, body, pose in robot.links[1:] if frames[parent][0] == body]


def root_pose(robot, state):
    """The root link's pose in the world (its body's frame is the root link's)."""
    row = robot.body_rows[0]
    return [*map(float, state["positions"][row]), *map(float, state["quaternions"][row])]


def matrix_pose(matrix):
    return [*map(float, matrix[:3, 3]), *map(float, matrix_to_quaternion(matrix[:3, :3]))]


# ---------------------------------------------------------------------- odometry from the wheels
class WheelOdometry:
    """A drive's odometry, as its ros2_controller integrates it: each interval the base moves
    along its heading by the driven wheels' mean travel (angle change x radius) and turns by
    it over the turning radius (a differential drive: the sides' difference over the effective
    separation; an Ackermann drive: the curvature its steering joints stand at), an exact arc."""

    def __init__(self, drive, pose, joints, seconds):
        """`joints`: the positions of drive_joints(drive) now."""
        self.drive = drive
        self.reset(pose, joints, seconds)

    def reset(self, pose, joints, seconds):
        """Starts at `pose` (x, y, yaw) with the drive's joints at `joints`."""
        self.x, self.y, self.yaw = pose
        self.angles = np.array(joints, float)
        self.time = seconds
        self.linear = self.angular = 0.0

    def update(self, joints, seconds):
        d = self.drive
        joints = np.array(joints, float)
        if d["type"] == "diff_drive":
            travel = (joints - self.angles) * d["wheel_radius"]
            left_count = len(d["left_wheel_names"])
            left, right = float(np.mean(travel[:left_count])), float(np.mean(travel[left_count:]))
            distance = 0.5 * (left + right)
            turn = (right - left) / (d["wheel_separation"] * d["wheel_separation_multiplier"])
        else:  # the steering joints (where they stand), then the driven wheels (how far they turned)
            distance = float(np.mean(joints[2:] - self.angles[2:])) * d["rear_wheels_radius"]
            turn = distance * steering_curvature(d, joints[0], joints[1])
        self.angles = joints
        if abs(turn) < 1e-9:
            heading = self.yaw + 0.5 * turn
            self.x += distance * math.cos(heading)
            self.y += distance * math.sin(heading)
        else:
            radius = distance / turn
            self.x += radius * (math.sin(self.yaw + turn) - math.sin(self.yaw))
            self.y -= radius * (math.cos(self.yaw + turn) - math.cos(self.yaw))
        self.yaw += turn
        dt = seconds - self.time
        if dt > 0.0:
            self.linear, self.angular = distance / dt, turn / dt
        self.time = seconds

    def pose(self):
        """xyz + xyzw in odom (on the ground plane: z 0)."""
        return [self.x, self.y, 0.0, 0.0, 0.0, math.sin(0.5 * self.yaw), math.cos(0.5 * self.yaw)]


def drive_joints(drive):
    """The joints a drive's odometry reads: the wheels (diff_drive), or the two steering joints
    and then the two driven wheels (ackermann)."""
    if drive["type"] == "diff_drive":
        return [*drive["left_wheel_names"], *drive["right_wheel_names"]]
    return [*drive["front_wheels_names"], *drive["rear_wheels_names"]]


def drive_commands(drive, speed, yaw_rate):
    """[(kind, joints, values)] that drive the base at `speed` (m/s) and `yaw_rate` (rad/s):
    wheel rates (rad/s) of a differential drive; an Ackermann drive's steering angles (each
    front wheel on its own circle about the turn's one centre, the inner one turned more) and
    rear wheel rates (each its own circle's speed). With no speed the steering stays."""
    if drive["type"] == "diff_drive":
        half = 0.5 * drive["wheel_separation"] * drive["wheel_separation_multiplier"]
        left, right = (speed - yaw_rate * half) / drive["wheel_radius"], (speed + yaw_rate * half) / drive["wheel_radius"]
        return [("velocity", drive_joints(drive),
                 [left] * len(drive["left_wheel_names"]) + [right] * len(drive["right_wheel_names"]))]
    half_rear, radius = 0.5 * drive["rear_wheel_track"], drive["rear_wheels_radius"]
    wheels = ("velocity", drive["rear_wheels_names"],
              [(speed - yaw_rate * half_rear) / radius, (speed + yaw_rate * half_rear) / radius])
    if speed == 0.0:
        return [wheels]
    curvature, base, half = yaw_rate / speed, drive["wheelbase"], 0.5 * drive["front_wheel_track"]
    steer = [math.atan2(base * curvature, 1.0 - curvature * half), math.atan2(base * curvature, 1.0 + curvature * half)]
    return [("position", drive["front_wheels_names"], steer), wheels]


def steering_curvature(drive, left, right):
    """The curvature (1/m) of the turn an Ackermann drive's steering joints at `left` and
    `right` (rad) steer: drive_commands' steering undone, the two averaged."""
    base, half = drive["wheelbase"], 0.5 * drive["front_wheel_track"]
    tl, tr = math.tan(left), math.tan(right)
    return 0.5 * (tl / (base + tl * half) + tr / (base - tr * half))


# ---------------------------------------------------------------------- commands
class Trajectory:
    """A JointTrajectory on the simulation's clock: from the joints' positions when it starts
    to each point at start + time_from_start; cubic where both ends give velocities, else
    linear; then held at the last point."""

    def __init__(self, joints, start, current, times, positions, velocities):
        self.joints = list(joints)
        self.times = np.concatenate([[start], start + np.asarray(times, float)])
        self.positions = np.vstack([current, positions])
        self.velocities = None if velocities is None else np.vstack([np.zeros(len(joints)), velocities])

    @property
    def end(self):
        return float(self.times[-1])

    def sample(self, seconds):
        """(positions, velocities) at `seconds`."""
        times, positions = self.times, self.positions
        if seconds >= times[-1]:
            return positions[-1], np.zeros(len(self.joints))
        if seconds <= times[0]:
            return positions[0], np.zeros(len(self.joints))
        k = int(np.searchsorted(times, seconds, side="right")) - 1
        span = times[k + 1] - times[k]
        if span <= 0.0:
            return positions[k + 1], np.zeros(len(self.joints))
        s = (seconds - times[k]) / span
        p0, p1 = positions[k], positions[k + 1]
        if self.velocities is None or k == 0:
            return p0 + s * (p1 - p0), (p1 - p0) / span
        v0, v1 = self.velocities[k] * span, self.velocities[k + 1] * span  # Hermite tangents
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
        return (h00 * p0 + h10 * v0 + h01 * p1 + h11 * v1,
                (d00 * p0 + d10 * v0 + d01 * p1 + d11 * v1) / span)


class RobotControl:
    """The URDF robots' commands, applied on the simulation thread (every method takes the
    World): joint motors set by name, trajectories followed before each batch of steps, and
    drives turned into wheel speeds (stopped after `cmd_vel_timeout` without a command)."""

    def __init__(self):
        self.world = None          # the World the commands below were given in
        self.time = 0.0            # its time when last seen
        self.trajectories = {}     # (robot, joint) -> the Trajectory that moves it
        self.drive_deadlines = {}  # robot -> simulated s its last cmd_vel lapses at
        self.mimic_targets = {}    # robot -> (targets, velocities) its <mimic> joints were last given
        self.commanded = {}        # robot -> the id of the robot of that name these were given to
        self._robot_specs = None   # the world.robot_specs last checked against `commanded`

    def _attend(self, world):
        """Commands given in another World (a scene loaded, a reset) are forgotten, and so are a
        robot's once it is gone, even if another of its name came since (its `id` differs);
        when the world's time went back (a reset of the time) they carry on on the new clock: a
        drive's deadline and a trajectory's times move back with it."""
        if world is not self.world:
            self.world, self.trajectories, self.drive_deadlines, self.mimic_targets, self.commanded = \
                world, {}, {}, {}, {}
        elif world.time < self.time:
            shift = world.time - self.time
            self.drive_deadlines = {name: deadline + shift for name, deadline in self.drive_deadlines.items()}
            for trajectory in {id(t): t for t in self.trajectories.values()}.values():
                trajectory.times = trajectory.times + shift
        self.time = world.time
        if world.robot_specs is not self._robot_specs:
            self._robot_specs = world.robot_specs
            present = {robot["name"]: robot["id"] for robot in world.robot_specs}
            gone = {name for name, robot_id in self.commanded.items() if present.get(name) != robot_id}
            if gone:
                self.commanded = {name: robot_id for name, robot_id in self.commanded.items() if name not in gone}
                self.drive_deadlines = {name: t for name, t in self.drive_deadlines.items() if name not in gone}
                self.mimic_targets = {name: t for name, t in self.mimic_targets.items() if name not in gone}
                self.trajectories = {key: t for key, t in self.trajectories.items() if key[0] not in gone}

    @staticmethod
    def robot(world, name):
        spec = robot_spec(world, name)
        if spec is None:
            raise KeyError(f"no robot named {name!r}")
        return spec

    def command(self, world, name, kind, joints, values, velocities=None, mimicking=False):
        """Motors of `joints` (URDF names) to `values`: position targets (with `velocities` as
        their feed-forward), velocities or efforts. A command for a joint ends the trajectory
        that moved it; a joint that mimics another takes none (`mimicking`: before_batch's). A
        command refused (any of its joints) changes nothing: trajectories go on."""
        self._attend(world)
        spec = self.robot(world, name)
        entities, mimics = spec["model"].joint_names, spec["model"].mimics
        motors = {}
        for k, joint in enumerate(joints):
            entity = entities.get(joint)
            if entity is None:
                raise ValueError(f"{name} has no revolute, continuous or prismatic joint {joint!r}")
            if joint in mimics and not mimicking:
                raise ValueError(f"{name}'s joint {joint!r} mimics {mimics[joint][0]!r}: command that one")
            value = float(values[k])
            if not math.isfinite(value):
                raise ValueError(f"{joint}: {value} is not finite")
            max_effort, max_speed = spec["limits"][entity]
            if kind == "position":
                # A feed-forward beyond the joint's speed limit is the limit (a trajectory's fast segment).
                limit = min(max_speed, specs.MAX_SPEED)
                feed_forward = 0.0 if velocities is None else min(max(float(velocities[k]), -limit), limit)
                motors[entity] = {"mode": "position", "target": value, "velocity": feed_forward,
                                  "max_effort": max_effort, "max_speed": max_speed}
            elif kind == "velocity":
                motors[entity] = {"mode": "velocity", "target": value, "velocity": 0.0,
                                  "max_effort": max_effort, "max_speed": max_speed}
            else:
                effort = min(abs(value), max_effort)
                speed = max_speed if math.isfinite(max_speed) else EFFORT_SPEED
                motors[entity] = {"mode": "velocity" if effort > 0.0 else "none",
                                  "target": math.copysign(speed, value), "velocity": 0.0,
                                  "max_effort": effort if effort > 0.0 else max_effort, "max_speed": max_speed}
        world.drive_joints(motors)
        self.commanded[name] = spec["id"]
        for joint in joints:
            self.trajectories.pop((name, joint), None)

    def hold(self, world, name, joints):
        """Ends the trajectories of `joints` with their motors holding where the joints are (a
        target left moving at a trajectory's velocity would move on for ever)."""
        for joint in joints:
            self.trajectories.pop((name, joint), None)
        entities = self.robot(world, name)["model"].joint_names
        present = [joint for joint in joints if joint in entities]
        if present:
            positions = world.joint_states([entities[joint] for joint in present])[0]
            try:
                self.command(world, name, "position", present, positions, np.zeros(len(present)))
            except ValueError as error:  # a joint's state gone non-finite
                log.warning("%s: %s not held: %s", name, ", ".join(present), error)

    def follow(self, world, name, joints, start, times, positions, velocities):
        """Follows a trajectory of `joints` from `start` (simulated s; None: now)."""
        self._attend(world)
        spec = self.robot(world, name)
        entities, mimics = spec["model"].joint_names, spec["model"].mimics
        missing = [joint for joint in joints if joint not in entities]
        if missing:
            raise ValueError(f"{name} has no revolute, continuous or prismatic joint {missing[0]!r}")
        following = [joint for joint in joints if joint in mimics]
        if following:
            raise ValueError(f"{name}'s joint {following[0]!r} mimics {mimics[following[0]][0]!r}: command that one")
        if start is not None and len(times) and start + times[-1] < world.time:
            # As joint_trajectory_controller: a trajectory over before it came is refused (run
            # at once, it had sent the joints to its last point at their velocity limits).
            raise ValueError(f"the trajectory for {name} ended at {start + times[-1]:.3f} s, before now "
                             f"({world.time:.3f} s of simulated time): stamp it 0 to start on receipt")
        current = world.joint_states([entities[joint] for joint in joints])[0]
        trajectory = Trajectory(joints, world.time if start is None else start, current, times, positions, velocities)
        for joint in joints:
            self.trajectories[(name, joint)] = trajectory
        self.before_batch(world)

    def mimic(self, world):
        """Each <mimic> joint's position motor aimed at multiplier x its leader + offset, moving
        at multiplier x the leader's rate through the batch (a servo, as Gazebo's mimic plugins
        do; bounded by its own effort and velocity limits). True if it moved a target."""
        moved = False
        for spec in world.robot_specs:
            mimics = spec["model"].mimics
            if not mimics:
                continue
            entities = spec["model"].joint_names
            leaders = [entities[leader] for leader, _, _ in mimics.values()]
            positions, velocities, _ = world.joint_states(leaders)
            scale = np.array([multiplier for _, multiplier, _ in mimics.values()])
            offset = np.array([offset for _, _, offset in mimics.values()])
            targets = (scale * positions + offset, scale * velocities)
            last = self.mimic_targets.get(spec["name"])
            if last is not None and not np.any(targets[1]) and np.array_equal(targets[0], last[0]):
                continue  # at rest where it was: a command would wake the robot every batch
            self.mimic_targets[spec["name"]] = targets
            try:
                self.command(world, spec["name"], "position", list(mimics), *targets, mimicking=True)
            except ValueError as error:  # a leader so far out that its follower's target cannot be
                log.warning("%s: mimic joints not moved: %s", spec["name"], error)
                continue
            moved = True
        return moved

    def drive(self, world, name, speed, yaw_rate, timeout):
        """A drive's cmd_vel: its wheels' velocity motors, until `timeout` s without another."""
        spec = self.robot(world, name)
        drive = spec.get("drive")
        if drive is None:
            raise ValueError(f"{name} has no drive")
        for kind, joints, values in drive_commands(drive, speed, yaw_rate):
            self.command(world, name, kind, joints, values)
        self.drive_deadlines[name] = world.time + timeout if timeout > 0.0 else math.inf

    def before_batch(self, world):
        """Trajectories sampled at the batch's start (their motors' targets move on at the
        sampled velocity through it); lapsed drives stopped; robots gone forgotten."""
        self._attend(world)
        mimicked = self.mimic(world)
        if not (self.drive_deadlines or self.trajectories):
            return mimicked
        now = world.time
        stopped = False
        for name, deadline in list(self.drive_deadlines.items()):
            if now >= deadline:
                del self.drive_deadlines[name]
                for kind, joints, values in drive_commands(self.robot(world, name)["drive"], 0.0, 0.0):
                    self.command(world, name, kind, joints, values)
                stopped = True
        if not self.trajectories:
            return stopped or mimicked
        by_trajectory = {}
        for (name, joint), trajectory in list(self.trajectories.items()):
            by_trajectory.setdefault(id(trajectory), (name, trajectory, []))[2].append(joint)
        for name, trajectory, joints in by_trajectory.values():
            positions, velocities = trajectory.sample(now)
            columns = [trajectory.joints.index(joint) for joint in joints]
            done = now >= trajectory.end
            try:
                self.command(world, name, "position", joints, positions[columns], velocities[columns])
            except ValueError as error:  # a point the joint's motor cannot take: the trajectory ends
                log.warning("%s: trajectory of %s abandoned: %s", name, ", ".join(joints), error)
                self.hold(world, name, joints)
                done = True
            if not done:
                for joint in joints:
                    self.trajectories[(name, joint)] = trajectory
        return True
