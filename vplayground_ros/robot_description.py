"""A vehicle's `robot_description` (issue 39): the URDF that robot_state_publisher, RViz and
Foxglove's URDF layer read, so that with the node's joint_states they reproduce its own
transforms (robots.wheel_transforms, sensor_messages.static_frames) exactly.

The tree, link names as robots.robot_frames has them, unprefixed (a namespaced robot takes
robot_state_publisher's `frame_prefix`): base_link (the chassis; the node publishes odom ->
base_footprint -> base_link itself), and per wheel in WHEEL_NAMES three joints in a chain, whose
positions joint_states carries (messages.joint_names):
  <wheel>_suspension  prismatic along z  base_link -> suspension_<wheel>  spring compression (m)
  <wheel>_steer       revolute about z   -> steering_<wheel>              steer angle (rad)
  <wheel>_spin        continuous about y -> wheel_<wheel>                 spin angle (rad)
The suspension joint sits where the wheel's centre is with the spring at full length, so
compression c raises it to the mount less (spring_length - c), as the engine places it. Each
sensor on the vehicle hangs from base_link by a fixed joint at its pose; a camera's optical
frame hangs from it by OPTICAL_ROTATION.

The intermediate links carry no inertial: no reader of this description needs one
(robot_state_publisher's KDL, RViz, Foxglove and yourdfpy take a massless link as a frame);
only a physics engine importing the URDF would, and the simulator is the physics here.
The root's inertial makes KDL (robot_state_publisher) warn once that it ignores a root link's
inertia; harmless, as it only publishes transforms.
"""
import math
import xml.etree.ElementTree as ET

from .frame_names import DEFAULT_FRAMES
from .messages import COLOURS, WHEEL_JOINTS, WHEEL_NAMES, WHEEL_WIDTH
from .physics.shapes import box, cylinder
from .robots import robot_frames
from .sensor_messages import OPTICAL_ROTATION, optical_frame
from .sensors import CAMERAS

AXLE_RPY = (0.5 * math.pi, 0.0, 0.0)  # turns a cylinder's axis (its z) onto the axle (y)
STEER_LIMIT = 0.5 * math.pi  # the inner wheel of an Ackermann turn goes beyond max_steer
ZERO = (0.0, 0.0, 0.0)


def quat_to_rpy(q):
    """(x, y, z, w) -> roll, pitch, yaw (fixed axes X, Y, Z: URDF's and math3d.rpy_to_quat's)."""
    x, y, z, w = q
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))  # rounding may pass 1
    return (math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)), pitch,
            math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


OPTICAL_RPY = quat_to_rpy(OPTICAL_ROTATION)


def robot_description(vehicle_spec, sensor_specs, name, frames=DEFAULT_FRAMES):
    """The URDF (XML text) of vehicle `name`: `vehicle_spec` as physics.specs.validate_vehicle
    (or World.vehicle) gives it, and those of `sensor_specs` (as sensors.validate_sensor gives
    them) whose parent is `name`. Links are named as robots.robot_frames names the frames, for
    `frames` (parameters.Frames: the base frame is the root), unprefixed. A sensor's frame is its
    `frame_id` when the spec has one, else its name."""
    f = robot_frames(frames, "")
    robot = ET.Element("robot", name=name)
    for material, rgba in (("chassis", COLOURS["vehicle"]), ("wheel", COLOURS["wheel"])):
        ET.SubElement(ET.SubElement(robot, "material", name=material), "color", rgba=numbers(rgba))
    chassis = vehicle_spec["chassis"]
    shape = ("box", {"size": numbers(chassis["size"])})
    link(robot, f.base, shape, "chassis", chassis["mass"], box.unit_inertia(box.dimensions(chassis)))
    for w, (wheel_name, wheel) in enumerate(zip(WHEEL_NAMES, vehicle_spec["wheels"])):
        suspension, steer, spin = (f"{wheel_name}_{joint}" for joint in WHEEL_JOINTS)  # from the chassis out
        mount = wheel["mount"]
        joint(robot, suspension, "prismatic", f.base, f.suspension[w],
              (mount[0], mount[1], mount[2] - wheel["spring_length"]), axis=(0.0, 0.0, 1.0),
              limits=(0.0, wheel["spring_length"]))
        link(robot, f.suspension[w])
        joint(robot, steer, "revolute", f.suspension[w], f.steering[w], axis=(0.0, 0.0, 1.0),
              limits=(-STEER_LIMIT, STEER_LIMIT))
        link(robot, f.steering[w])
        joint(robot, spin, "continuous", f.steering[w], f.wheel[w], axis=(0.0, 1.0, 0.0))
        dims = cylinder.dimensions({"radius": wheel["radius"], "length": WHEEL_WIDTH})
        across, _, along = cylinder.unit_inertia(dims)  # about the cylinder's axis: along
        shape = ("cylinder", {"radius": repr(float(wheel["radius"])), "length": repr(float(WHEEL_WIDTH))})
        link(robot, f.wheel[w], shape, "wheel", wheel["mass"], (across, along, across), AXLE_RPY)
    for spec in sensor_specs:
        if spec["parent"] != name:
            continue
        frame, pose = spec.get("frame_id", spec["name"]), spec["pose"]
        joint(robot, f"{frame}_joint", "fixed", f.base, frame, pose[:3], pose[3:])  # links are unique, so joints are
        link(robot, frame)
        if spec["type"] in CAMERAS:
            joint(robot, f"{optical_frame(frame)}_joint", "fixed", frame, optical_frame(frame), rpy=OPTICAL_RPY)
            link(robot, optical_frame(frame))
    ET.indent(robot)
    return ET.tostring(robot, encoding="unicode")


def numbers(values):
    """repr: the shortest text that reads back as the same double, so poses round-trip."""
    return " ".join(repr(float(v)) for v in values)


def origin(parent, xyz=ZERO, rpy=ZERO):
    ET.SubElement(parent, "origin", xyz=numbers(xyz), rpy=numbers(rpy))


def link(robot, name, shape=None, material=None, mass=None, unit_inertia=None, shape_rpy=ZERO):
    """A link; with `shape` (geometry tag, its attributes) drawn and colliding as that shape
    turned by shape_rpy, and with `mass` an inertial of mass x unit_inertia (principal, in the
    link's axes) at its origin."""
    element = ET.SubElement(robot, "link", name=name)
    if shape is not None:
        for kind in ("visual", "collision"):
            part = ET.SubElement(element, kind)
            origin(part, rpy=shape_rpy)
            ET.SubElement(ET.SubElement(part, "geometry"), shape[0], shape[1])
            if kind == "visual":
                ET.SubElement(part, "material", name=material)
    if mass is not None:
        inertial = ET.SubElement(element, "inertial")
        origin(inertial)
        ET.SubElement(inertial, "mass", value=repr(float(mass)))
        ixx, iyy, izz = (repr(float(mass) * i) for i in unit_inertia)
        ET.SubElement(inertial, "inertia", ixx=ixx, ixy="0.0", ixz="0.0", iyy=iyy, iyz="0.0", izz=izz)


def joint(robot, name, kind, parent, child, xyz=ZERO, rpy=ZERO, axis=None, limits=None):
    element = ET.SubElement(robot, "joint", name=name, type=kind)
    origin(element, xyz, rpy)
    ET.SubElement(element, "parent", link=parent)
    ET.SubElement(element, "child", link=child)
    if axis is not None:
        ET.SubElement(element, "axis", xyz=numbers(axis))
    if limits is not None:
        # urdfdom refuses a limit without effort and velocity; nothing bounds either (the engine
        # sets these joints' positions itself), so both are left 0.
        ET.SubElement(element, "limit", lower=repr(float(limits[0])), upper=repr(float(limits[1])),
                      effort="0.0", velocity="0.0")
