"""Entities as plain data (~/get_entity, ~/get_entities): category, pose, twist, properties
and bounds of a body, a vehicle or a sensor.
"""
import numpy as np

from ..physics.math3d import matrix_to_quaternion, rpy_to_quat
from ..physics.shapes import SHAPES, half_extents, solid
from ..physics.shapes.compound import part_rotation
from ..sensors import mount_motion, pose_matrix

SENSOR_SIZE = 0.1  # m: the cube ~/get_entities draws a sensor as


def describe(world, name, vehicles=None):
    """An entity as plain data: category, pose and twist in `world`, properties, bounds.
    `vehicles`: the set of vehicle names, when describing many."""
    is_vehicle = name in (world.vehicle_names() if vehicles is None else vehicles)
    props = world.vehicle(name) if is_vehicle else world.body(name)
    body = world.body(name)
    low, high = frame_box(body["shape"], solid(body["shape"], body))
    if is_vehicle:
        low, high = with_wheels(props, low, high)
    return {
        "name": name,
        "category": "vehicle" if is_vehicle else ("immovable" if body["immovable"] else "box"),
        "frame": "world",
        "pose": {"position": body["position"], "orientation": body["quaternion"]},
        "twist": {"linear": body["linear_velocity"], "angular": body["angular_velocity"]},
        "mass": body["mass"],
        "frozen": body["frozen"],
        "properties": props,
        "shape": body["shape"],
        "bounds": bounds(low, high),
    }


def bounds(low, high):
    """An entity's `bounds`: the corners of the box around it in its frame (`low`, `high`: what
    GetEntityBounds answers and ~/get_entities draws a box as), and `size`, the box centred on
    its pose that holds it."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    return {"size": (2.0 * np.maximum(-low, high)).tolist(), "low": low.tolist(), "high": high.tolist()}


def frame_box(shape_name, shape):
    """(low, high) corners of the box around a shape (shapes.Solid) in its body's frame. Not
    always about the frame: a hull's frame is its centre of mass, a compound's parts stand
    anywhere in theirs."""
    if shape.hull is not None:
        return shape.hull.points.min(axis=0), shape.hull.points.max(axis=0)
    if shape.compound is not None:
        lows, highs = zip(*map(part_box, shape.compound.parts))
        return np.min(lows, axis=0), np.max(highs, axis=0)
    half = np.asarray(half_extents(SHAPES[shape_name].code, shape.dimensions))
    return -half, half


def part_box(part):
    """(low, high) of a compound's part in the body's frame: a hull's turned vertices, else its
    shape's box turned about the part's centre."""
    turn = part_rotation(part)
    if part.solid.hull is not None:
        points = part.centre + part.solid.hull.points @ turn.T
        return points.min(axis=0), points.max(axis=0)
    reach = np.abs(turn) @ np.asarray(half_extents(part.code, part.solid.dimensions))
    return part.centre - reach, part.centre + reach


def with_wheels(vehicle, low, high):
    """A chassis's box in its frame (low, high) grown to take in its wheels over their
    suspension's whole travel: they are rays, no body's volume, but they stand where nothing
    should be spawned (the bounds had been the chassis alone, 0.8 m above the car's contact
    points). Each wheel's box is its radius every way about its centre (the engine's wheels
    have no width)."""
    for wheel in vehicle["wheels"]:
        mount, radius = np.asarray(wheel["mount"], float), float(wheel["radius"])
        low = np.minimum(low, mount - [radius, radius, wheel["spring_length"] + radius])
        high = np.maximum(high, mount + radius)
    return low, high


def describe_sensor(world, spec):
    """A sensor as plain data, like describe(): its frame's pose and twist in `world` now (its
    parent's velocity at the mount point), its spec as properties and a 0.1 m cube as its
    bounds (for ~/get_entities' marker)."""
    mount = pose_matrix(spec["pose"][:3], rpy_to_quat(spec["pose"][3:]))
    pose, angular, linear = mount_motion(world, spec["parent"], mount)
    return {
        "name": spec["name"],
        "category": "sensor",
        "frame": "world",
        "pose": {"position": pose[:3, 3].tolist(), "orientation": matrix_to_quaternion(pose[:3, :3]).tolist()},
        "twist": {"linear": linear.tolist(), "angular": angular.tolist()},
        "properties": dict(spec),
        "shape": "box",
        "bounds": bounds([-0.5 * SENSOR_SIZE] * 3, [0.5 * SENSOR_SIZE] * 3),
    }


def describe_robot(world, spec):
    """A URDF robot as plain data, like describe(): its root link's pose and twist, the mass of
    all its links, frozen when all are, its entry as properties (without the loaded model) and
    the box around its links' boxes in the root's frame."""
    root = world.body(spec["bodies"][0])
    to_root = np.linalg.inv(pose_matrix(root["position"], root["quaternion"]))
    corners, mass, frozen = [], 0.0, True
    for name in spec["bodies"]:
        link = describe(world, name)
        mass += link["mass"]
        frozen = frozen and link["frozen"]
        frame = to_root @ pose_matrix(link["pose"]["position"], link["pose"]["orientation"])
        box = np.array([link["bounds"]["low"], link["bounds"]["high"]])
        for pick in np.array(np.meshgrid([0, 1], [0, 1], [0, 1])).reshape(3, -1).T:  # low or high on each axis
            corners.append(frame[:3, :3] @ box[pick, [0, 1, 2]] + frame[:3, 3])
    corners = np.array(corners)
    return {
        "name": spec["name"],
        "category": "robot",
        "frame": "world",
        "pose": {"position": root["position"], "orientation": root["quaternion"]},
        "twist": {"linear": root["linear_velocity"], "angular": root["angular_velocity"]},
        "mass": mass,
        "frozen": frozen,
        "properties": {key: value for key, value in spec.items() if key not in ("model", "limits", "joints_held")},
        "shape": "urdf",
        "bounds": bounds(corners.min(axis=0), corners.max(axis=0)),
    }
