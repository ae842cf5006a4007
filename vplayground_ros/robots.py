"""The robots (issue 39): each vehicle of the world as a ROS 2 stack sees a robot, ROS-free: its
namespace, its frames and which transforms the simulator owns (REP 105).

Per robot, prefixed `<ns>/` when it has a namespace:

    <world_frame> -> odom            localization `ground_truth` only (`none`: a SLAM or AMCL node
                                     publishes map -> odom, and odom must have no other parent)
    odom -> base_footprint           publish_odom_tf only (false: an EKF or a LiDAR odometry owns it)
    base_footprint -> base_link      always: roll, pitch and the ride height
    base_link -> suspension_<wheel> -> steering_<wheel> -> wheel_<wheel>
                                     always: the joints <wheel>_suspension (prismatic along z, the
                                     spring's compression), <wheel>_steer (about z), <wheel>_spin
                                     (about y), as robot_description has them
    base_link -> a mounted sensor    static

base_footprint is base_link turned by its heading only and lowered by the car's ride height at
rest, so a tilted car's footprint stays level (Nav2 and slam_toolbox plan in its plane). The
odometry (odometry.py) gives odom -> base_footprint; `<world_frame> -> odom` is what makes the
true pose out of it, so the drift shows there, as a fake localisation would correct it.
"""
import math
from collections import namedtuple

import numpy as np

from . import odometry
from .messages import IDENTITY, WHEEL_NAMES, quaternion_multiply
from .physics.math3d import quaternions_to_matrices

# The names a stack gives frames of its own (REP 105's map and earth): no entity may take them.
STACK_FRAMES = ("map", "earth")
# The ride height that places base_footprint is the car's at rest under standard gravity: a fixed
# offset, so that base_footprint -> base_link does not follow a gravity parameter.
STANDARD_GRAVITY = 9.80665

RobotFrames = namedtuple("RobotFrames", "odom footprint base suspension steering wheel")


def namespace_prefix(namespace):
    """What a robot's frames (and relative topics) start with: `<namespace>/`, or nothing in the
    root namespace."""
    return f"{namespace}/" if namespace else ""


def validate_robot(vehicle, path):
    """A vehicle spec (specs.validate_vehicle's) with its `odometry` error model checked key by
    key (odometry.validate), which the engine keeps without knowing it."""
    if "odometry" in vehicle:
        vehicle = {**vehicle, "odometry": odometry.validate(vehicle["odometry"], f"{path}.odometry")}
    return vehicle


def robot_frames(frames, prefix):
    """A robot's frames (`frames`: parameters.Frames): odom, base_footprint and base_link with `prefix`, and the wheels' chains
    (tuples in WHEEL_NAMES order)."""
    return RobotFrames(prefix + frames.odom, prefix + frames.footprint, prefix + frames.base,
                       *(tuple(f"{prefix}{link}_{wheel}" for wheel in WHEEL_NAMES)
                         for link in ("suspension", "steering", "wheel")))


class Robot(namedtuple("Robot", "name namespace localization publish_odom_tf frames ride_height")):
    """A vehicle as a robot: its (vehicle and chassis body) name, namespace ('' for none),
    localization, publish_odom_tf, RobotFrames, and the height (m) of base_link above
    base_footprint."""

    @property
    def prefix(self):
        return namespace_prefix(self.namespace)

    def topic(self, name):
        """A topic of the robot, relative: `name` under its namespace."""
        return self.prefix + name


def ride_height(vehicle):
    """How high base_link stands over level ground at rest (m): the wheels' mounts, springs
    compressed by the car's weight shared out evenly, and radii, averaged over the wheels."""
    wheels = vehicle["wheels"]
    mass = vehicle["chassis"]["mass"] + sum(w["mass"] for w in wheels)
    heights = []
    for w in wheels:
        compression = min(mass * STANDARD_GRAVITY / len(wheels) / w["spring_stiffness"], w["spring_length"])
        heights.append(w["spring_length"] - compression + w["radius"] - w["mount"][2])
    return float(np.mean(heights))


def robot(vehicle, frames, localization="ground_truth", publish_odom_tf=True):
    """The Robot of a vehicle spec (World.vehicle): its own `namespace`, `localization` and
    `publish_odom_tf` keys win over the node's parameters."""
    namespace = vehicle.get("namespace", "")
    return Robot(vehicle["name"], namespace, vehicle.get("localization", localization),
                 vehicle.get("publish_odom_tf", publish_odom_tf),
                 robot_frames(frames, namespace_prefix(namespace)), ride_height(vehicle))


def world_robots(world, frames):
    """The Robots of the world's vehicles, in the World's order, owning every transform (where
    a frame is, not who publishes it)."""
    return [robot(world.vehicle(name), frames) for name in world.vehicle_names()]


def footprint_pose(position, quaternion, height):
    """base_footprint of a base_link pose (xyz, xyzw): `height` below it, turned by its yaw
    only. Returns (xyz, xyzw)."""
    r = quaternions_to_matrices(np.asarray(quaternion, float)[None])[0]
    yaw = math.atan2(r[1, 0], r[0, 0])
    return ((float(position[0]), float(position[1]), float(position[2]) - height),
            (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)))


def compose(a, b):
    """The pose b expressed in a's parent, a and b (xyz, xyzw) with b in a's frame: a b."""
    rotated = quaternion_multiply(quaternion_multiply(a[1], (*b[0], 0.0)), conjugate(a[1]))[:3]
    return tuple(np.add(a[0], rotated)), quaternion_multiply(a[1], b[1])


def inverse(a):
    q = conjugate(a[1])
    return tuple(-v for v in quaternion_multiply(quaternion_multiply(q, (*a[0], 0.0)), a[1])[:3]), q


def conjugate(q):
    return (-q[0], -q[1], -q[2], q[3])


def as_pose(pose):
    """(xyz, xyzw) as one list xyz + xyzw."""
    return [*map(float, pose[0]), *map(float, pose[1])]


def robot_transforms(robot, truth, odometry, vehicle_state, wheels, world_frame):
    """[(parent, child, pose xyz + xyzw)] of the robot's moving frames, as /tf carries them:
    `truth` and `odometry` are base_link's (xyz, xyzw) in the world and in odom (the same pose
    when the odometry has no error), `vehicle_state` the vehicle's (World.vehicle_state),
    `wheels` its wheel specs."""
    f = robot.frames
    true_footprint = footprint_pose(*truth, robot.ride_height)
    exact = odometry is truth
    measured = true_footprint if exact else footprint_pose(*odometry, robot.ride_height)
    out = []
    if robot.localization == "ground_truth":
        # world -> odom: the true footprint after the measured one undone (the identity while
        # they agree, exactly: composing would leave rounding).
        out.append((world_frame, f.odom, IDENTITY if exact else as_pose(compose(true_footprint, inverse(measured)))))
    if robot.publish_odom_tf:
        out.append((f.odom, f.footprint, as_pose(measured)))
    out.append((f.footprint, f.base, as_pose(compose(inverse(true_footprint), truth))))
    out.extend(wheel_transforms(robot, vehicle_state, wheels))
    return out


def wheel_transforms(robot, vehicle_state, wheels):
    """[(parent, child, pose)] of the wheels' joint chains (robot_description's): the spring
    lowers the mount by spring_length less its compression, the steering turns about z, the
    wheel spins about y."""
    f, v = robot.frames, vehicle_state
    out = []
    for w, wheel in enumerate(wheels):
        mount = wheel["mount"]
        drop = wheel["spring_length"] - float(v["compression"][w])
        steer, spin = 0.5 * float(v["steer_angle"][w]), 0.5 * float(v["spin_angle"][w])
        out += [(f.base, f.suspension[w], [mount[0], mount[1], mount[2] - drop, 0.0, 0.0, 0.0, 1.0]),
                (f.suspension[w], f.steering[w], [0.0, 0.0, 0.0, 0.0, 0.0, math.sin(steer), math.cos(steer)]),
                (f.steering[w], f.wheel[w], [0.0, 0.0, 0.0, 0.0, math.sin(spin), 0.0, math.cos(spin)])]
    return out


def frames_of(robots):
    """{frame: what it is} of every robot's frames (names no entity may take)."""
    out = {}
    for r in robots:
        out.update({r.frames.odom: f"{r.name}'s odom frame", r.frames.footprint: f"{r.name}'s base_footprint",
                    r.frames.base: f"{r.name}'s base_link"})
        for links in (r.frames.suspension, r.frames.steering, r.frames.wheel):
            out.update({link: f"a wheel link of {r.name}" for link in links})
    return out
