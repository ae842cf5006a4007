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
from .physics.vehicle_registry import VEHICLE_NUMBERS
from .robots import robot_frames
from .sensor_messages import OPTICAL_ROTATION, optical_frame
from .sensors import CAMERAS, quat_to_rpy

AXLE_RPY = (0.5 * math.pi, 0.0, 0.0)  # turns a cylinder's axis (its z) onto the axle (y)
STEER_LIMIT = 0.5 * math.pi  # the inner wheel of an Ackermann turn goes beyond max_steer
ZERO = (0.0, 0.0, 0.0)
# The description's own element for what makes it a ray-cast vehicle here, and what it keeps.
EXTENSION = "vplayground"
CHASSIS_KEYS = ("elasticity", "static_friction", "dynamic_friction", "immovable", "allow_freezing")
CHASSIS_FLAGS = ("immovable", "allow_freezing")
MOUNT_TOLERANCE = 1.0e-9  # m: a wheel's mount against its suspension joint's origin and limit
WHEEL_KEYS = ("power_gain", "steered", "spring_stiffness", "damper", "static_friction", "dynamic_friction")


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
    ray_cast_vehicle(robot, vehicle_spec, f)
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


def ray_cast_vehicle(robot, vehicle_spec, f):
    """The description's extension that makes it this simulator's vehicle again (as Gazebo's
    <gazebo> elements, other readers skip it): what the links and joints do not say. The chassis
    is the `link`'s box and inertial; each wheel's spring length is its `suspension` joint's
    upper limit (its mount that joint's origin raised by it: the `mount` attribute says it
    exactly, where the sum would round), its radius and mass its `link`'s cylinder and
    inertial."""
    chassis = vehicle_spec["chassis"]
    vehicle = ET.SubElement(ET.SubElement(robot, EXTENSION), "vehicle", **{
        key: repr(float(vehicle_spec[key])) for key in VEHICLE_NUMBERS})
    ET.SubElement(vehicle, "chassis", link=f.base, **{key: text(chassis[key]) for key in CHASSIS_KEYS if key in chassis})
    for w, (wheel_name, wheel) in enumerate(zip(WHEEL_NAMES, vehicle_spec["wheels"])):
        ET.SubElement(vehicle, "wheel", suspension=f"{wheel_name}_{WHEEL_JOINTS[0]}", link=f.wheel[w],
                      mount=numbers(wheel["mount"]), **{key: text(wheel[key]) for key in WHEEL_KEYS})


def text(value):
    return ("true" if value else "false") if isinstance(value, bool) else repr(float(value))


def vehicle_from_description(description, label):
    """The vehicle spec (chassis, wheels, engine_power, brake_power, max_steer, max_steer_rate; as a scene's
    `vehicles` entry has them) of a description with a <vplayground><vehicle> element, as
    ray_cast_vehicle writes it; None for a description without one. UrdfError naming the
    element for one that does not hold together."""
    from .urdf_import import UnreadableUrdf, UrdfError
    try:
        robot = ET.fromstring(description)
    except ET.ParseError as error:
        raise UnreadableUrdf(f"{label}: not XML: {error}") from None
    vehicle = robot.find(f"{EXTENSION}/vehicle")
    if vehicle is None:
        return None
    links = {element.get("name"): element for element in robot.findall("link")}
    joints = {element.get("name"): element for element in robot.findall("joint")}

    def number(element, key, where):
        try:
            return float(element.get(key))
        except (TypeError, ValueError):
            raise UrdfError(f"{label}: {where}: {key} {element.get(key)!r} is not a number") from None

    def numbers_of(element, key, where, count=3):
        values = (element.get(key) or "").split()
        try:
            if len(values) == count:
                return [float(v) for v in values]
        except ValueError:
            pass
        raise UrdfError(f"{label}: {where}: {key} {element.get(key)!r}: expected {count} numbers")

    def link_part(kind, name, where):
        """(geometry element of the link's collision, its mass) of the link `name`."""
        link = links.get(name)
        if link is None:
            raise UrdfError(f"{label}: {where}: no link {name!r}")
        geometry = link.find(f"collision/geometry/{kind}")
        mass = link.find("inertial/mass")
        if geometry is None or mass is None:
            raise UrdfError(f"{label}: {where}: link {name!r} needs a {kind} collision and an inertial mass")
        return geometry, number(mass, "value", f"link {name!r} mass")

    def flag(element, key, where):
        value = element.get(key)
        if value not in ("true", "false"):
            raise UrdfError(f"{label}: {where}: {key} {value!r}: expected true or false")
        return value == "true"

    where = f"<{EXTENSION}><vehicle>"
    spec = {key: number(vehicle, key, where) for key in VEHICLE_NUMBERS if vehicle.get(key) is not None}
    chassis = vehicle.find("chassis")
    if chassis is None:
        raise UrdfError(f"{label}: {where}: no <chassis link=...> (the chassis' link)")
    box_element, mass = link_part("box", chassis.get("link"), f"{where}<chassis>")
    place = links[chassis.get("link")].find("collision/origin")
    if place is not None and any(any(numbers_of(place, key, f"link {chassis.get('link')!r} collision"))
                                 for key in ("xyz", "rpy") if place.get(key) is not None):
        raise UrdfError(f"{label}: {where}<chassis>: link {chassis.get('link')!r}: its box must stand at the "
                        "link's origin (xyz and rpy 0): the chassis body is centred there")
    spec["chassis"] = {"size": numbers_of(box_element, "size", f"link {chassis.get('link')!r} box"), "mass": mass}
    for key in CHASSIS_KEYS:
        if chassis.get(key) is not None:
            spec["chassis"][key] = (flag(chassis, key, f"{where}<chassis>") if key in CHASSIS_FLAGS
                                    else number(chassis, key, f"{where}<chassis>"))
    spec["wheels"] = []
    for k, wheel in enumerate(vehicle.findall("wheel")):
        at = f"{where}<wheel> {k + 1}"
        suspension = joints.get(wheel.get("suspension"))
        if suspension is None or suspension.get("type") != "prismatic":
            raise UrdfError(f"{label}: {at}: suspension {wheel.get('suspension')!r} is no prismatic joint")
        parent = suspension.find("parent")
        if parent is None or parent.get("link") != chassis.get("link"):
            raise UrdfError(f"{label}: {at}: its suspension joint must hang from the chassis link "
                            f"{chassis.get('link')!r}")
        axis, place, limit = suspension.find("axis"), suspension.find("origin"), suspension.find("limit")
        if axis is None or numbers_of(axis, "xyz", f"joint {suspension.get('name')!r} axis") != [0.0, 0.0, 1.0]:
            raise UrdfError(f"{label}: {at}: its suspension joint's axis must be 0 0 1 (the chassis' z)")
        if place is not None and place.get("rpy") is not None and any(numbers_of(place, "rpy", at)):
            raise UrdfError(f"{label}: {at}: its suspension joint may not turn (rpy 0 0 0)")
        if limit is None:
            raise UrdfError(f"{label}: {at}: its suspension joint's upper limit is the spring length: none given")
        spring = number(limit, "upper", f"joint {suspension.get('name')!r} limit")
        xyz = [0.0, 0.0, 0.0] if place is None or place.get("xyz") is None else numbers_of(place, "xyz", at)
        cylinder_element, wheel_mass = link_part("cylinder", wheel.get("link"), at)
        mount = [xyz[0], xyz[1], xyz[2] + spring]
        if wheel.get("mount") is not None:
            given = numbers_of(wheel, "mount", at)
            if not all(abs(a - b) <= MOUNT_TOLERANCE for a, b in zip(given, mount)):  # (NaN too)
                raise UrdfError(f"{label}: {at}: mount {wheel.get('mount')!r} is not where its suspension joint "
                                f"puts it ({numbers(mount)}: the joint's origin, raised by its upper limit)")
            mount = given
        fields = {"mount": mount, "spring_length": spring, "mass": wheel_mass,
                  "radius": number(cylinder_element, "radius", f"link {wheel.get('link')!r} cylinder")}
        for key in WHEEL_KEYS:
            if wheel.get(key) is not None:
                fields[key] = flag(wheel, key, at) if key == "steered" else number(wheel, key, at)
        spec["wheels"].append(fields)
    return spec


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
