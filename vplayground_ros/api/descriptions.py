"""Entities as plain data (~/get_entity, ~/get_entities): category, pose, twist, properties
and bounds of a body, a vehicle or a sensor.
"""
import numpy as np

from ..physics.math3d import matrix_to_quaternion, rpy_to_quat
from ..physics.shapes import SHAPES, half_extents, solid
from ..sensors import mount_motion, pose_matrix

SENSOR_SIZE = 0.1  # m: the cube ~/get_entities draws a sensor as


def describe(world, name, vehicles=None):
    """An entity as plain data: category, pose and twist in `world`, properties, bounds.
    `vehicles`: the set of vehicle names, when describing many."""
    is_vehicle = name in (world.vehicle_names() if vehicles is None else vehicles)
    props = world.vehicle(name) if is_vehicle else world.body(name)
    body = world.body(name)
    shape = solid(body["shape"], body)
    half = np.asarray(half_extents(SHAPES[body["shape"]].code, shape.dimensions))
    if shape.compound is not None:  # about its frame, where its pose is, not its centre of mass
        half = half + np.abs(shape.compound.centre)
    if is_vehicle:
        half = with_wheels(props, half)
    size = 2.0 * half
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
        "bounds": {"size": size.tolist()},
    }


def with_wheels(vehicle, half):
    """A chassis's half extents about its frame grown to take in its wheels over their
    suspension's whole travel: they are rays, no body's volume, but they stand where nothing
    should be spawned (the bounds had been the chassis alone, 0.8 m above the car's contact
    points). Each wheel's box is its radius every way about its centre (the engine's wheels
    have no width)."""
    for wheel in vehicle["wheels"]:
        mount, radius = np.asarray(wheel["mount"], float), float(wheel["radius"])
        low = mount - [radius, radius, wheel["spring_length"] + radius]
        high = mount + radius
        half = np.maximum(half, np.maximum(np.abs(low), np.abs(high)))
    return half


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
        "bounds": {"size": [SENSOR_SIZE] * 3},
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
        half = 0.5 * np.asarray(link["bounds"]["size"])
        for signs in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T:
            corners.append(frame[:3, :3] @ (signs * half) + frame[:3, 3])
    corners = np.array(corners)
    half = np.maximum(np.abs(corners.min(axis=0)), np.abs(corners.max(axis=0)))  # about the root's frame
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
        "bounds": {"size": (2.0 * half).tolist()},
    }
