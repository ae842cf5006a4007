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
import math
import re
from collections import namedtuple

import numpy as np

from .physics import specs
from .physics.math3d import quaternions_to_matrices

ENTRY_KEYS = {"name", "urdf", "position", "rpy", "quaternion", "fixed_base", "self_collide",
              "joint_positions", "namespace", "joints", "drive", "localization", "publish_odom_tf"}
DRIVE_KEYS = {"type", "left_wheel_names", "right_wheel_names", "wheel_separation", "wheel_radius",
              "wheel_separation_multiplier"}
DRIVE_TYPES = ("diff_drive",)
LOCALIZATIONS = ("ground_truth", "none")
COMMAND_KINDS = ("position", "velocity", "effort")
# diff_drive_controller's default pose and twist covariance diagonals (x y z roll pitch yaw):
# the wheels' odometry is not exact (they slip), and a filter fusing it must know.
WHEEL_ODOMETRY_COVARIANCE = [(0.01 if row == 5 else 0.001) if row == column else 0.0
                             for row in range(6) for column in range(6)]
# An effort command is a velocity motor whose effort bound is the effort, aiming at the joint's
# speed limit (or this, without one): it pushes with exactly that effort until the limit.
EFFORT_SPEED = 1.0e3


def validate_entry(raw, path):
    """The keys of a robot entry that need no description, checked: name, urdf, placement,
    fixed_base, self_collide, joint_positions, namespace, joints, drive, localization,
    publish_odom_tf. Returns (entry, placement fields)."""
    specs.mapping(raw, path, ENTRY_KEYS)
    for key in ("name", "urdf"):
        if key not in raw:
            raise specs.SpecError(f"{path}.{key}", "missing (a robot is a name and a URDF file)")
    fields = specs.validate_body_fields({key: raw[key] for key in ("name", "position", "rpy", "quaternion")
                                         if key in raw}, path)
    if not isinstance(raw["urdf"], str) or not raw["urdf"]:
        raise specs.SpecError(f"{path}.urdf", "expected a file name")
    entry = {"name": fields["name"], "urdf": raw["urdf"]}
    for key in ("fixed_base", "self_collide", "publish_odom_tf"):
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


def names_list(value, path):
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise specs.SpecError(path, "expected a list of joint names")
    if len(set(value)) != len(value):
        raise specs.SpecError(path, "a joint is named twice")
    return list(value)


def validate_drive(raw, path):
    """A differential drive, in diff_drive_controller's words: left_wheel_names,
    right_wheel_names (joints), wheel_separation and wheel_radius (m, required, as there), and
    wheel_separation_multiplier (1.0): a skid-steer's wheels slip sideways in a turn, so it
    turns as if its wheels stood that much farther apart."""
    specs.mapping(raw, path, DRIVE_KEYS)
    kind = raw.get("type", "diff_drive")
    if kind not in DRIVE_TYPES:
        raise specs.SpecError(f"{path}.type", f"{specs.quote(kind)}: expected one of {', '.join(DRIVE_TYPES)}")
    drive = {"type": kind}
    for key in ("left_wheel_names", "right_wheel_names"):
        if key not in raw:
            raise specs.SpecError(f"{path}.{key}", "missing (the wheel joints of that side)")
        drive[key] = names_list(raw[key], f"{path}.{key}")
    for key in ("wheel_separation", "wheel_radius"):
        if key not in raw:
            raise specs.SpecError(f"{path}.{key}", "missing (m)")
        drive[key] = specs.number(raw[key], f"{path}.{key}", 0.0, specs.MAX_COORDINATE, low_open=True)
    drive["wheel_separation_multiplier"] = specs.number(raw.get("wheel_separation_multiplier", 1.0),
                                                        f"{path}.wheel_separation_multiplier", 0.0, 100.0, low_open=True)
    shared = set(drive["left_wheel_names"]) & set(drive["right_wheel_names"])
    if shared:
        raise specs.SpecError(f"{path}.right_wheel_names", f"{sorted(shared)[0]!r} is a left wheel too")
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
    drive = entry.get("drive")
    if drive is not None:
        kinds = {spec["name"]: spec["type"] for spec in model.joints}
        for key in ("left_wheel_names", "right_wheel_names"):
            for joint in drive[key]:
                if joint not in movable or kinds[movable[joint]] == "prismatic":
                    raise specs.SpecError(f"{path}.drive.{key}", f"{joint!r} is no revolute or continuous joint "
                                                                 "of the description")


def add_robot_entry(world, entry, model, path="robot"):
    """Adds a checked entry's robot (urdf_import.add_robot: all or none) and lists it in
    world.robot_specs with its namespace: the entry's, else the root one if no vehicle or robot
    has it, else its name's. Returns the bodies added."""
    from .urdf_import import add_robot
    taken = world.robot_namespaces()
    namespace = entry.get("namespace", re.sub(r"[^A-Za-z0-9_]", "_", entry["name"]) if "" in taken else "")
    if namespace in taken:
        raise specs.SpecError(f"{path}.namespace", f"{namespace!r} is the namespace of {taken[namespace]} already")
    added = add_robot(world, model)
    limits = {spec["name"]: (spec["motor"]["max_effort"], spec["motor"]["max_speed"]) for spec in model.joints}
    world.robot_specs = [*world.robot_specs, {
        **entry, "namespace": namespace, "joints": entry.get("joints", list(model.joint_names)),
        "bodies": [b["name"] for b in model.bodies], "model": model, "limits": limits}]
    return added


# ---------------------------------------------------------------------- as the publisher sees it
class UrdfRobot(namedtuple("UrdfRobot", "name namespace joint_names entities body_rows links drive localization "
                                        "publish_odom_tf description")):
    """A URDF robot in a snapshot's layout: its joint_states names (URDF) and World joints, the
    snapshot rows of its bodies, `links`: [(link, parent link or None, body index in body_rows,
    its 4x4 pose in that body's frame)], parents first; `drive` (the entry's, or None)."""

    @property
    def prefix(self):
        return f"{self.namespace}/" if self.namespace else ""

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
    return UrdfRobot(spec["name"], spec["namespace"], tuple(model.joint_names), tuple(model.joint_names.values()),
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
    from .physics.math3d import matrix_to_quaternion
    return [*map(float, matrix[:3, 3]), *map(float, matrix_to_quaternion(matrix[:3, :3]))]


# ---------------------------------------------------------------------- odometry from the wheels
class WheelOdometry:
    """diff_drive_controller's odometry: each interval the wheels' travel (angle change x
    radius, averaged per side) moves the base along its heading by the mean and turns it by the
    difference over the effective separation (exact arc)."""

    def __init__(self, drive, pose, wheel_angles, seconds):
        self.drive = drive
        self.reset(pose, wheel_angles, seconds)

    def reset(self, pose, wheel_angles, seconds):
        """Starts at `pose` (x, y, yaw) with the wheels at `wheel_angles` (left..., right...)."""
        self.x, self.y, self.yaw = pose
        self.angles = np.array(wheel_angles, float)
        self.time = seconds
        self.linear = self.angular = 0.0

    def update(self, wheel_angles, seconds):
        d = self.drive
        wheel_angles = np.array(wheel_angles, float)
        travel = (wheel_angles - self.angles) * d["wheel_radius"]
        self.angles = wheel_angles
        left_count = len(d["left_wheel_names"])
        left, right = float(np.mean(travel[:left_count])), float(np.mean(travel[left_count:]))
        distance = 0.5 * (left + right)
        turn = (right - left) / (d["wheel_separation"] * d["wheel_separation_multiplier"])
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


def wheel_speeds(drive, speed, yaw_rate):
    """Left and right wheel rates (rad/s) for a base speed (m/s) and yaw rate (rad/s)."""
    half = 0.5 * drive["wheel_separation"] * drive["wheel_separation_multiplier"]
    radius = drive["wheel_radius"]
    return (speed - yaw_rate * half) / radius, (speed + yaw_rate * half) / radius


def wheel_joints(drive):
    return [*drive["left_wheel_names"], *drive["right_wheel_names"]]


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
        self.trajectories = {}     # (robot, joint) -> the Trajectory that moves it
        self.drive_deadlines = {}  # robot -> simulated s its last cmd_vel lapses at

    def _attend(self, world):
        """Commands given in another World (a scene loaded, a reset) are forgotten."""
        if world is not self.world:
            self.world, self.trajectories, self.drive_deadlines = world, {}, {}

    @staticmethod
    def robot(world, name):
        spec = next((r for r in world.robot_specs if r["name"] == name), None)
        if spec is None:
            raise KeyError(f"no robot named {name!r}")
        return spec

    def command(self, world, name, kind, joints, values, velocities=None):
        """Motors of `joints` (URDF names) to `values`: position targets (with `velocities` as
        their feed-forward), velocities or efforts. A command for a joint ends the trajectory
        that moved it."""
        self._attend(world)
        spec = self.robot(world, name)
        entities = spec["model"].joint_names
        motors = {}
        for k, joint in enumerate(joints):
            entity = entities.get(joint)
            if entity is None:
                raise ValueError(f"{name} has no revolute, continuous or prismatic joint {joint!r}")
            value = float(values[k])
            if not math.isfinite(value):
                raise ValueError(f"{joint}: {value} is not finite")
            max_effort, max_speed = spec["limits"][entity]
            if kind == "position":
                feed_forward = 0.0 if velocities is None else float(velocities[k])
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
            self.trajectories.pop((name, joint), None)
        world.drive_joints(motors)

    def follow(self, world, name, joints, start, times, positions, velocities):
        """Follows a trajectory of `joints` from `start` (simulated s; None: now)."""
        self._attend(world)
        spec = self.robot(world, name)
        entities = spec["model"].joint_names
        missing = [joint for joint in joints if joint not in entities]
        if missing:
            raise ValueError(f"{name} has no revolute, continuous or prismatic joint {missing[0]!r}")
        current = world.joint_states([entities[joint] for joint in joints])[0]
        trajectory = Trajectory(joints, world.time if start is None else start, current, times, positions, velocities)
        for joint in joints:
            self.trajectories[(name, joint)] = trajectory
        self.before_batch(world)

    def drive(self, world, name, speed, yaw_rate, timeout):
        """A drive's cmd_vel: its wheels' velocity motors, until `timeout` s without another."""
        spec = self.robot(world, name)
        drive = spec.get("drive")
        if drive is None:
            raise ValueError(f"{name} has no drive")
        left, right = wheel_speeds(drive, speed, yaw_rate)
        rates = [left] * len(drive["left_wheel_names"]) + [right] * len(drive["right_wheel_names"])
        self.command(world, name, "velocity", wheel_joints(drive), rates)
        self.drive_deadlines[name] = world.time + timeout if timeout > 0.0 else math.inf

    def before_batch(self, world):
        """Trajectories sampled at the batch's start (their motors' targets move on at the
        sampled velocity through it); lapsed drives stopped; robots gone forgotten."""
        self._attend(world)
        if not (self.drive_deadlines or self.trajectories):
            return False
        present = {r["name"] for r in world.robot_specs}
        now = world.time
        stopped = False
        for name, deadline in list(self.drive_deadlines.items()):
            if name not in present:
                del self.drive_deadlines[name]
            elif now >= deadline:
                del self.drive_deadlines[name]
                wheels = wheel_joints(self.robot(world, name)["drive"])
                self.command(world, name, "velocity", wheels, [0.0] * len(wheels))
                stopped = True
        if not self.trajectories:
            return stopped
        by_trajectory = {}
        for (name, joint), trajectory in list(self.trajectories.items()):
            if name not in present:
                del self.trajectories[(name, joint)]
                continue
            by_trajectory.setdefault(id(trajectory), (name, trajectory, []))[2].append(joint)
        for name, trajectory, joints in by_trajectory.values():
            positions, velocities = trajectory.sample(now)
            columns = [trajectory.joints.index(joint) for joint in joints]
            done = now >= trajectory.end
            self.command(world, name, "position", joints, positions[columns], velocities[columns])
            if not done:
                for joint in joints:
                    self.trajectories[(name, joint)] = trajectory
        return True
