"""What the simulator subscribes to (SPEC 6.2), ROS-free: one handler per topic, fed by the ROS
subscriptions (rclpy messages) and by the Foxglove server's client channels (messages decoded
from CDR, or JSON as nested namespaces). Handlers only read attributes, so all three work, and
they hand their work to the simulation thread.
"""
import json
import math
from collections import namedtuple
from types import SimpleNamespace

import numpy as np
import yaml

from .api.descriptions import describe_robot
from .api.entities import move_robot
from .api.frames import frame_pose
from .interfaces import decoder
from .parameters import frames as frame_names
from .physics.math3d import rpy_to_quat
from .physics.specs import MAX_COORDINATE
from .sensors import pose_matrix
from .throttle import ThrottledLog
from .urdf_robots import robot_spec

Subscription = namedtuple("Subscription", "key name type")
TWIST, TWIST_STAMPED = "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"
SUBSCRIPTIONS = [
    Subscription("cmd_vel", "cmd_vel", TWIST),
    Subscription("clicked_point", "clicked_point", "geometry_msgs/msg/PointStamped"),
    Subscription("initial_pose", "initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    Subscription("push", "~/push", "geometry_msgs/msg/WrenchStamped"),
]


MAX_TRAJECTORY_POINTS = 100_000  # a trajectory's points: 20 minutes at 100 Hz

# What a URDF robot takes under its namespace (urdf_robots), keyed as Inputs.handle knows them;
# cmd_vel only with a drive.
JOINT_STATE, FLOAT64_ARRAY = "sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray"
URDF_ROBOT_INPUTS = [
    Subscription("joint_commands", "joint_commands", JOINT_STATE),
    Subscription("position_commands", "position_commands", FLOAT64_ARRAY),
    Subscription("velocity_commands", "velocity_commands", FLOAT64_ARRAY),
    Subscription("effort_commands", "effort_commands", FLOAT64_ARRAY),
    Subscription("joint_trajectory", "joint_trajectory", "trajectory_msgs/msg/JointTrajectory"),
]


def subscriptions(cmd_vel_stamped):
    """The subscription table; cmd_vel is TwistStamped when the parameter says so."""
    return [s._replace(type=TWIST_STAMPED) if s.key == "cmd_vel" and cmd_vel_stamped else s
            for s in SUBSCRIPTIONS]


def from_json(data):
    """A JSON message as nested namespaces (attribute access, like the other two)."""
    def convert(value):
        if isinstance(value, dict):
            return SimpleNamespace(**{k: convert(v) for k, v in value.items()})
        if isinstance(value, list):
            return [convert(v) for v in value]
        return value
    return convert(json.loads(data))


def from_cdr(type_name, data):
    return decoder(type_name)(bytes(data))


class Inputs:
    """`robots` and `urdf_robots` (snapshot -> [robots.Robot], [urdf_robots.UrdfRobot]) and
    `resolve` (relative name -> absolute, remaps applied) are the Broadcaster's: each robot's
    cmd_vel is its namespace's. `control` (urdf_robots.RobotControl) applies the URDF robots'
    commands on the simulation thread."""

    def __init__(self, sim, requests, parameters, log, robots, resolve, urdf_robots=lambda snapshot: [],
                 control=None):
        self.sim = sim
        self.requests = requests
        self.parameters = parameters
        self.log = ThrottledLog(log)  # anyone on the domain (or a Foxglove client) sends inputs
        self.robots = robots
        self.urdf_robots = urdf_robots
        self.control = control
        self.resolve = resolve
        self.handlers = {"cmd_vel": self.cmd_vel, "clicked_point": self.clicked_point,
                         "initial_pose": self.initial_pose, "push": self.push}

    def command_topics(self):
        """{absolute cmd_vel topic: robot name} of every robot now, vehicles and URDF robots
        with a drive (the root namespace's is cmd_vel's own subscription; the transports
        subscribe to the others as robots come)."""
        snapshot = self.sim.snapshot
        topics = {self.resolve(robot.topic("cmd_vel")): robot.name for robot in self.robots(snapshot)}
        topics.update({self.resolve(robot.topic("cmd_vel")): robot.name for robot in self.urdf_robots(snapshot)
                       if robot.drive is not None})
        return topics

    def robot_inputs(self):
        """{absolute topic: (Subscription, robot name)} of the URDF robots' command topics now."""
        return {self.resolve(robot.topic(sub.name)): (sub, robot.name)
                for robot in self.urdf_robots(self.sim.snapshot) for sub in URDF_ROBOT_INPUTS}

    def handle(self, key, msg, topic=None):
        """Runs the handler of subscription `key` (cmd_vel: `topic` says which, absolute; the
        root namespace's when None); a message missing a field is logged, not raised, and a bug
        is logged once and counted (Simulation.fault), whichever transport delivered it."""
        try:
            if key == "cmd_vel":
                self.cmd_vel(msg, topic or self.resolve("cmd_vel"))
            elif key in self.handlers:
                self.handlers[key](msg)
            else:
                self.robot_command(key, msg, topic)
        except (AttributeError, TypeError, ValueError, OverflowError) as error:  # (an integer past a float's range)
            self.log.warning(f"{key}: malformed message ignored ({error})")
        except TimeoutError as error:
            self.log.warning(f"{key} ignored: {error}")
        except Exception as error:
            self.sim.fault(f"input {key}", error)

    def submit(self, key, fn):
        """sim.submit(fn) with what goes wrong there logged: nobody waits for an input's Future,
        so an exception left in it would be lost (a teleport out of the world, say)."""
        def report(future):
            error = None if future.cancelled() else future.exception()
            if error is not None:
                reason = error.args[0] if isinstance(error, KeyError) and error.args else error
                self.log.warning(f"{key} ignored: {reason}")
        self.sim.submit(fn).add_done_callback(report)

    def cmd_vel(self, msg, topic):
        """Twist or TwistStamped on a robot's cmd_vel `topic` (absolute): drives that robot."""
        twist = msg.twist if hasattr(msg, "twist") else msg
        speed, yaw_rate = float(twist.linear.x), float(twist.angular.z)
        timeout = self.parameters["cmd_vel_timeout"]
        if not (math.isfinite(speed) and math.isfinite(yaw_rate)):
            self.log.warning(f"{topic} with non-finite values ignored")
            return
        car = self.command_topics().get(topic)
        if car is None:
            return
        if any(robot.name == car for robot in self.urdf_robots(self.sim.snapshot)):
            self.submit(topic, lambda world: self.control.drive(world, car, speed, yaw_rate, timeout))
        else:
            self.submit(topic, lambda world: world.drive(car, speed, yaw_rate, timeout))

    def robot_command(self, key, msg, topic):
        """A URDF robot's command (URDF_ROBOT_INPUTS) on `topic` (absolute), checked here and
        applied on the simulation thread; one that names no joint of the robot is logged."""
        entry = self.robot_inputs().get(topic)
        if entry is None or entry[0].key != key:
            return
        robot = entry[1]
        control = self.control
        if key == "joint_commands":
            names = [str(n) for n in msg.name]
            kind, values, velocities = joint_state_command(msg, len(names))
            self.submit(topic, lambda world: control.command(world, robot, kind, names, values, velocities))
        elif key == "joint_trajectory":
            names, start, times, positions, velocities = trajectory_command(msg)
            self.submit(topic, lambda world: control.follow(world, robot, names, start, times, positions, velocities))
        else:
            values = [float(v) for v in msg.data]
            kind = key[:-len("_commands")]

            def command(world):
                order = control.robot(world, robot)["joints"]
                if len(values) != len(order):
                    raise ValueError(f"{len(values)} values for the {len(order)} joints {', '.join(order)}")
                control.command(world, robot, kind, order, values)
            self.submit(topic, command)

    def frames(self):
        return frame_names(self.parameters)

    def to_world(self, frame, point):
        """A point in any frame the simulator publishes, in the world frame (None if unknown)."""
        frames = self.frames()
        transform = self.sim.call(lambda world: frame_pose(world, frame, frames))
        return None if transform is None else (transform @ [*point, 1.0])[:3]

    def clicked_point(self, msg):
        frame = str(msg.header.frame_id)
        p = self.to_world(frame, (float(msg.point.x), float(msg.point.y), float(msg.point.z)))
        if p is None or not np.all(np.isfinite(p)):
            self.log.warning(f"clicked_point in unknown frame {frame!r:.80} or not finite: ignored")
            return
        size = self.parameters["click_spawn_size"]
        height = self.parameters["click_spawn_height"]
        spec = yaml.safe_dump({"size": [size] * 3, "position": [float(p[0]), float(p[1]), float(p[2] + height + size / 2)]})
        ok, message = self.requests.spawn(spec)
        # One call per severity: rclpy refuses a call site whose severity changes (and the
        # handler then logged "malformed message ignored" instead of what happened).
        if ok:
            self.log.info(f"clicked_point: {message}")
        else:
            self.log.warning(f"clicked_point: {message}")

    def initial_pose(self, msg):
        """Teleports the robot in the root namespace (the car, or a URDF robot), unless a
        localiser owns its pose (localization none): in a Nav2 graph initialpose is AMCL's, a
        pose estimate. The robot stands upright on the pose's height, facing its heading, and
        stops."""
        snapshot = self.sim.snapshot
        urdf = next((r for r in self.urdf_robots(snapshot) if not r.namespace), None)
        robot = next((r for r in self.robots(snapshot) if not r.namespace), urdf)
        frame = str(msg.header.frame_id)
        pose = msg.pose.pose
        p = [float(getattr(pose.position, k)) for k in "xyz"]
        q = [float(getattr(pose.orientation, k)) for k in "xyzw"]
        if robot is None:
            self.log.warning("initialpose ignored: no robot in the root namespace")
            return
        if robot.localization == "none":
            self.log.info(f"initialpose left to the localiser ({robot.name}'s localization is none): not a teleport")
            return
        name = robot.name
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            self.log.warning(f"initialpose ignored: the pose is not finite ({p}, {q})")
            return
        largest = max(abs(v) for v in q)  # scaled first: the norm of (0, 0, 0, 1e308) overflows
        norm = float(np.linalg.norm([v / largest for v in q])) * largest if largest > 0.0 else 0.0
        q = [v / norm for v in q] if norm > 0.0 else [0.0, 0.0, 0.0, 1.0]  # no orientation: the frame's
        frames = self.frames()
        timeout = self.parameters["cmd_vel_timeout"]

        def teleport(world):
            transform = frame_pose(world, frame, frames)
            if transform is None:
                raise ValueError(f"header.frame_id {frame!r:.80} is not a frame the node publishes")
            target = transform @ pose_matrix(p, q)
            yaw = math.atan2(target[1, 0], target[0, 0])  # upright: only the heading is kept
            heading = list(rpy_to_quat((0.0, 0.0, yaw)))
            if robot is urdf:
                spec = robot_spec(world, name)
                # Its lowest point on the pose's height: the box around its links, in the root's
                # frame, which the move leaves upright.
                lift = -describe_robot(world, spec)["bounds"]["low"][2]
                position = [float(target[0, 3]), float(target[1, 3]), float(target[2, 3]) + lift]
                move_robot(world, spec, {"position": position, "quaternion": heading,
                                         "linear_velocity": [0.0] * 3, "angular_velocity": [0.0] * 3}, "pose")
                if spec.get("drive") is not None:
                    self.control.drive(world, name, 0.0, 0.0, timeout)
                return
            wheels = world.vehicle(name)["wheels"]
            lift = max(w["spring_length"] + w["radius"] - w["mount"][2] for w in wheels)
            position = [float(target[0, 3]), float(target[1, 3]), float(target[2, 3]) + lift]
            world.check_inside(position, "pose.position")
            world.edit_body(name, position=position, quaternion=heading,
                            linear_velocity=[0, 0, 0], angular_velocity=[0, 0, 0])
            world.drive(name, 0.0, 0.0)
        self.submit("initialpose", teleport)

    def push(self, msg):
        name = str(msg.header.frame_id)
        force = [float(getattr(msg.wrench.force, k)) for k in "xyz"]
        torque = [float(getattr(msg.wrench.torque, k)) for k in "xyz"]

        def push(world):
            dt = 1.0 / world.settings["steps_per_second"]
            world.apply_impulse(name, [f * dt for f in force], [t * dt for t in torque])
        self.submit("~/push", push)


def joint_state_command(msg, count):
    """(kind, values, feed-forward velocities or None) of a JointState command: its positions
    (with its velocities, if as many), else its velocities, else its efforts."""
    # A JSON message (a Foxglove client's) may leave out the arrays it does not use.
    positions, velocities, efforts = ([float(v) for v in getattr(msg, key, ())] for key in ("position", "velocity", "effort"))
    if count == 0:
        raise ValueError("no joint named")
    for kind, values in (("position", positions), ("velocity", velocities), ("effort", efforts)):
        if values and len(values) != count:
            raise ValueError(f"{len(values)} {kind} values for {count} names")
    if positions:
        return "position", positions, velocities or None
    if velocities:
        return "velocity", velocities, None
    if efforts:
        return "effort", efforts, None
    raise ValueError("no position, velocity or effort given")


def trajectory_command(msg):
    """(joint names, start time in s or None for now, [time_from_start], positions (P, J),
    velocities (P, J) or None) of a JointTrajectory, checked: every point with a position per
    joint, times increasing."""
    names = [str(n) for n in msg.joint_names]
    if not names or len(set(names)) != len(names):
        raise ValueError("joint_names: none, or a joint named twice")
    points = list(msg.points)
    if not 0 < len(points) <= MAX_TRAJECTORY_POINTS:
        raise ValueError(f"{len(points)} points: expected 1 to {MAX_TRAJECTORY_POINTS}")
    times, positions, velocities = [], [], []
    for k, point in enumerate(points):
        t = seconds(point.time_from_start)
        if not (math.isfinite(t) and t >= 0.0) or times and t <= times[-1]:
            raise ValueError(f"points[{k}].time_from_start {t:g} s: times must increase")
        p, v = [float(x) for x in point.positions], [float(x) for x in getattr(point, "velocities", ())]
        if len(p) != len(names) or (v and len(v) != len(names)):
            raise ValueError(f"points[{k}]: {len(p)} positions, {len(v)} velocities for {len(names)} joints")
        if not all(abs(x) <= MAX_COORDINATE for x in p + v):  # NaN fails too
            raise ValueError(f"points[{k}]: a position or velocity not finite or beyond {MAX_COORDINATE:g}")
        times.append(t)
        positions.append(p)
        velocities.append(v)
    header = getattr(msg, "header", None)
    stamp = 0.0 if header is None else seconds(header.stamp)
    if not math.isfinite(stamp):
        raise ValueError("header.stamp not finite")
    given = all(velocities)
    return (names, stamp if stamp > 0.0 else None, times, np.array(positions),
            np.array(velocities) if given else None)


def seconds(time):
    """A builtin_interfaces Time or Duration in seconds."""
    return float(time.sec) + 1e-9 * float(time.nanosec)
