"""The frames the node publishes (broadcast.py; SPEC 6.1) as poses in the world frame: what a
`frame_id` means in a request (~/spawn's initial_pose, ~/edit's state) and in a subscribed
message (clicked_point, initialpose). The names no body or sensor may take: ../frame_names.py.

`frames` are the (world, odom, base) frame names, the parameters'. Read on the simulation
thread, from the World: the state the next step starts from.
"""
from types import SimpleNamespace

import numpy as np

from ..frame_names import WHEEL_FRAMES, mount_frame
from ..messages import car_transforms
from ..sensor_messages import static_frames
from ..sensors import WORLD, matrix_to_quaternion, pose_matrix
from ..physics.math3d import rpy_to_quat


def driven_car(world):
    """The car base_link is on: the first vehicle (as broadcast.Broadcaster.car), or None."""
    vehicles = world.vehicle_names()
    return vehicles[0] if vehicles else None


def frame_pose(world, frame, frames):
    """The pose (4x4) in the world frame of `frame`, a frame the node publishes, or None:
    '' is the world frame, and odom is too (world -> odom is the identity); base_link and the
    wheel frames are the driven car's (the wheels as ~/transforms has them: steered, spun,
    down by the spring); a sensor's frame is its mount on its parent, a camera's optical frame
    under it; a body's name is its frame (/tf in the bag, ~/transforms with publish_body_frames)."""
    world_frame, odom_frame, base_frame = frames
    if frame in ("", world_frame, odom_frame, WORLD):  # WORLD: what a sensor's parent calls the world frame
        return np.eye(4)
    car = driven_car(world)
    edges = car_frames(world, car, frames) if car is not None and (frame == base_frame or frame in WHEEL_FRAMES) else []
    edges += static_frames(world.sensor_specs, mount_frame(frames, car))
    for parent, child, pose in edges:
        if child == frame:  # names are unique among frames, so the chain up ends at the world
            up = frame_pose(world, parent, frames)
            return None if up is None else up @ pose_matrix(pose[:3], pose[3:])
    if frame in world.body_names():
        body = world.body(frame)
        return pose_matrix(body["position"], body["quaternion"])
    return None


def car_frames(world, car, frames):
    """[(parent, child, pose)] of the car's frames, made by the function that publishes them."""
    body = world.body(car)
    now = SimpleNamespace(names=[car], state={"positions": [body["position"]], "quaternions": [body["quaternion"]]},
                          vehicles={car: world.vehicle_state(car)})
    return car_transforms(now, car, frames, world.vehicle(car)["wheels"])


def pose_in_world(transform, fields):
    """Body keys (position, quaternion or rpy, velocities) given in a frame at `transform`
    (4x4), in the world frame: the position moved, the orientation turned, the velocities
    turned (a twist is expressed in the frame's axes)."""
    rotation = transform[:3, :3]
    out = dict(fields)
    if "position" in fields:
        out["position"] = (transform @ [*fields["position"], 1.0])[:3].tolist()
    if "quaternion" in fields or "rpy" in fields:
        local = fields["quaternion"] if "quaternion" in fields else rpy_to_quat(out.pop("rpy"))
        out["quaternion"] = matrix_to_quaternion(rotation @ pose_matrix((0, 0, 0), local)[:3, :3]).tolist()
    for key in ("linear_velocity", "angular_velocity"):
        if key in fields:
            out[key] = (rotation @ fields[key]).tolist()
    return out
