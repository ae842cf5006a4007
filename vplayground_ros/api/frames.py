"""The frames the node publishes (broadcast.py; SPEC 6.1) as poses in the world frame: what a
`frame_id` means in a request (~/spawn's initial_pose, ~/edit's state) and in a subscribed
message (clicked_point, initialpose). The names no body or sensor may take: ../frame_names.py.

`frames` are the frame names, the parameters' (parameters.Frames). Read on the simulation
thread, from the World: the state the next step starts from.
"""
import numpy as np

from ..frame_names import mount_frame, sensor_frame
from ..physics.math3d import matrix_to_quaternion, rpy_to_quat
from ..robots import namespace_prefix, robot_transforms, world_robots
from ..sensor_messages import static_frames
from ..sensors import WORLD, pose_matrix
from ..urdf_robots import link_carriers


def frame_pose(world, frame, frames):
    """The pose (4x4) in the world frame of `frame`, a frame the node publishes, or None:
    '' is the world frame; a robot's frames are where /tf puts them (its odom is the world's
    origin: the odometry's drift is not the World's to know); a sensor's frame is its mount on
    its parent, a camera's optical frame under it; a URDF robot's link is where its body puts
    it; a body's name is its frame (/tf with publish_body_frames, or when it carries a sensor)."""
    if frame in ("", frames.world, WORLD):  # WORLD: what a sensor's parent calls the world frame
        return np.eye(4)
    robots = world_robots(world, frames)
    edges = []
    for robot in robots:
        f = robot.frames
        if frame in (f.odom, f.footprint, f.base, *f.suspension, *f.steering, *f.wheel):
            edges += robot_frames_now(world, robot, frames)
    for spec in world.robot_specs:  # a URDF robot's link: where its body puts it
        prefix = namespace_prefix(spec["namespace"])
        for link, (body, pose) in spec["model"].link_frames.items():
            if frame == prefix + link:
                state = world.body(body)
                return pose_matrix(state["position"], state["quaternion"]) @ pose
    carriers = link_carriers(world.robot_specs)
    edges += static_frames(world.sensor_specs, mount_frame(frames, robots, carriers), sensor_frame(robots, carriers))
    for parent, child, pose in edges:
        if child == frame:  # names are unique among frames, so the chain up ends at the world
            up = frame_pose(world, parent, frames)
            return None if up is None else up @ pose_matrix(pose[:3], pose[3:])
    if frame in world.body_names():
        body = world.body(frame)
        return pose_matrix(body["position"], body["quaternion"])
    return None


def robot_frames_now(world, robot, frames):
    """[(parent, child, pose)] of a robot's frames, made by the function that publishes them."""
    body = world.body(robot.name)
    truth = (body["position"], body["quaternion"])
    # Every edge, whoever publishes it (a localiser's map -> odom, an EKF's odom ->
    # base_footprint): where the frame is, not who sends it.
    whole = robot._replace(localization="ground_truth", publish_odom_tf=True)
    return robot_transforms(whole, truth, truth, world.vehicle_state(robot.name), world.vehicle(robot.name)["wheels"],
                            frames.world)


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
