"""Snapshots -> ROS messages (SPEC 6.1). Every stamp is simulation time; frames follow REP-105:
`world` -> `odom` -> `base_link` (the car), wheels under base_link, bodies under `world`.

The odom frame is where the car started: odometry here is perfect (a simulator knows), so
world -> odom is fixed at the car's pose when the scene was loaded.
"""
import math

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, TransformStamped, TwistStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from . import cdr
from .physics.world import quaternions_to_matrices

WHEEL_NAMES = ("front_left", "front_right", "rear_left", "rear_right")
COLOURS = {  # category -> RGBA
    "box": (0.85, 0.55, 0.20, 1.0),
    "immovable": (0.35, 0.35, 0.45, 1.0),
    "vehicle": (0.15, 0.45, 0.85, 1.0),
    "frozen": (0.6, 0.6, 0.6, 1.0),
    "ground": (0.30, 0.42, 0.30, 1.0),
    "playground": (0.55, 0.60, 0.65, 1.0),
    "contact": (1.0, 0.1, 0.1, 1.0),
}


def stamp(seconds):
    sec = int(math.floor(seconds))
    return Time(sec=sec, nanosec=int(round((seconds - sec) * 1e9)) % 1_000_000_000)


def header(seconds, frame):
    return Header(stamp=stamp(seconds), frame_id=frame)


def clock(seconds):
    return Clock(clock=stamp(seconds))


def pose(position, quaternion):
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in position)
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(v) for v in quaternion)
    return p


def colour(rgba):
    return ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def pose_array(snapshot, frame):
    """~/bodies/poses as CDR bytes, in the order of ~/get_entities."""
    return cdr.pose_array(snapshot.time, frame, snapshot.state["positions"], snapshot.state["quaternions"])


def category(snapshot, row):
    name = snapshot.names[row]
    if name in snapshot.vehicles:
        return "vehicle"
    return "immovable" if snapshot.state["immovable"][row] else "box"


def body_markers(snapshot, frame, marker_ids, encoder):
    """~/bodies/markers as CDR bytes: DELETEALL, then one CUBE per body (ns = category, id
    stable per name, frozen grey)."""
    s = snapshot.state
    namespaces = [category(snapshot, row) for row in range(len(snapshot.names))]
    colours = np.array([COLOURS["frozen" if frozen else kind] for kind, frozen in zip(namespaces, s["frozen"])],
                       dtype=np.float32).reshape(-1, 4)
    ids = [marker_ids(name) for name in snapshot.names]
    poses = np.concatenate([s["positions"], s["quaternions"]], axis=1)
    return encoder.encode(snapshot.time, frame, namespaces, ids, poses, s["sizes"], colours)


def scene_markers(seconds, frame, ground, triangles, octree_cells=()):
    """The static scenery: the ground plane, the playground as a TRIANGLE_LIST, and (when
    asked) the occupied octree cells as one translucent CUBE_LIST per level."""
    stamp_header = header(seconds, frame)
    markers = [Marker(header=stamp_header, action=Marker.DELETEALL)]
    if ground is not None:
        m = Marker(header=stamp_header, ns="ground", id=0, type=Marker.CUBE, action=Marker.ADD)
        m.pose.position.z = float(ground["height"]) - 0.005
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = 200.0
        m.scale.z = 0.01
        m.color = colour(COLOURS["ground"])
        markers.append(m)
    if len(triangles):
        m = Marker(header=stamp_header, ns="playground", id=0, type=Marker.TRIANGLE_LIST,
                   action=Marker.ADD)
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.color = colour(COLOURS["playground"])
        m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in triangles.reshape(-1, 3)]
        markers.append(m)
    for level, centres, edge in octree_cells:
        m = Marker(header=stamp_header, ns="octree", id=level, type=Marker.CUBE_LIST, action=Marker.ADD)
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = float(edge)
        m.color = colour((0.2, 0.6, 1.0, 0.12))
        m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in centres]
        markers.append(m)
    return MarkerArray(markers=markers)


CONTACT_FIELDS = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                  for k, n in enumerate(("x", "y", "z", "nx", "ny", "nz", "depth", "impulse"))] + [
                  PointField(name="body_a", offset=32, datatype=PointField.INT32, count=1),
                  PointField(name="body_b", offset=36, datatype=PointField.INT32, count=1)]
CONTACT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                          ("nz", "<f4"), ("depth", "<f4"), ("impulse", "<f4"), ("body_a", "<i4"),
                          ("body_b", "<i4")])


CONTACT_FIELD_LAYOUT = [(f.name, f.offset, f.datatype, f.count) for f in CONTACT_FIELDS]


def contact_cloud(snapshot, frame, max_points):
    """~/contacts/points as CDR bytes."""
    c = snapshot.contacts
    n = min(len(c["depths"]), max_points)
    rows = np.zeros(n, CONTACT_DTYPE)
    for k, key in enumerate(("x", "y", "z")):
        rows[key] = c["points"][:n, k]
        rows["n" + key] = c["normals"][:n, k]
    rows["depth"], rows["impulse"] = c["depths"][:n], c["impulses"][:n]
    rows["body_a"], rows["body_b"] = c["body_a"][:n], c["body_b"][:n]
    return cdr.point_cloud(snapshot.time, frame, CONTACT_FIELD_LAYOUT, rows)


def contact_markers(snapshot, frame, max_points):
    """The 2008 "show collisions": contact points and their normals (0.3 m long)."""
    c = snapshot.contacts
    n = min(len(c["depths"]), max_points)
    stamp_header = header(snapshot.time, frame)
    points = Marker(header=stamp_header, ns="contact_points", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    points.pose.orientation.w = 1.0
    points.scale.x = points.scale.y = points.scale.z = 0.05
    points.color = colour(COLOURS["contact"])
    points.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in c["points"][:n]]
    normals = Marker(header=stamp_header, ns="contact_normals", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
    normals.pose.orientation.w = 1.0
    normals.scale.x = 0.01
    normals.color = colour(COLOURS["contact"])
    tips = c["points"][:n] - 0.3 * c["normals"][:n]  # normals point from A into B: draw them out of B
    normals.points = [Point(x=float(v[0]), y=float(v[1]), z=float(v[2]))
                      for pair in zip(c["points"][:n], tips) for v in pair]
    return MarkerArray(markers=[Marker(header=stamp_header, action=Marker.DELETEALL), points, normals])


def car_odometry(snapshot, name, frame, child):
    """Odometry of the car: pose in `frame` (world and odom coincide), twist in base_link."""
    row = snapshot.names.index(name)
    s = snapshot.state
    q = s["quaternions"][row]
    msg = Odometry(header=header(snapshot.time, frame), child_frame_id=child)
    msg.pose.pose = pose(s["positions"][row], q)
    to_body = quaternions_to_matrices(q[None])[0].T
    lin, ang = to_body @ s["linear_velocities"][row], to_body @ s["angular_velocities"][row]
    msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.linear.z = (float(v) for v in lin)
    msg.twist.twist.angular.x, msg.twist.twist.angular.y, msg.twist.twist.angular.z = (float(v) for v in ang)
    return msg


def joint_states(snapshot, name):
    """Per wheel: <wheel>_steer (angle), <wheel>_spin (angle, rate), <wheel>_suspension
    (compression, m)."""
    v = snapshot.vehicles[name]
    names, position, velocity = [], [], []
    for w, wheel in enumerate(WHEEL_NAMES):
        names += [f"{wheel}_steer", f"{wheel}_spin", f"{wheel}_suspension"]
        position += [float(v["steer_angle"][w]), float(v["spin_angle"][w]), float(v["compression"][w])]
        velocity += [0.0, float(v["spin_rate"][w]), 0.0]
    return JointState(header=header(snapshot.time, ""), name=names, position=position, velocity=velocity)


def car_command(snapshot, name, frame):
    v = snapshot.vehicles[name]
    msg = TwistStamped(header=header(snapshot.time, frame))
    msg.twist.linear.x = v["command_speed"]
    msg.twist.angular.z = v["command_yaw_rate"]
    return msg


def transform(seconds, parent, child, position, quaternion):
    t = TransformStamped(header=header(seconds, parent), child_frame_id=child)
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = (float(v) for v in position)
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = (float(v) for v in quaternion)
    return t


def car_transforms(snapshot, name, frames, wheels):
    """world -> odom (identity), odom -> base_link, base_link -> wheel_<position> at the wheel's
    centre (the mount, down by the spring's current length), steered and spun."""
    world_frame, odom_frame, base_frame = frames
    row = snapshot.names.index(name)
    s, v = snapshot.state, snapshot.vehicles[name]
    out = [transform(snapshot.time, world_frame, odom_frame, (0, 0, 0), (0, 0, 0, 1)),
           transform(snapshot.time, odom_frame, base_frame, s["positions"][row], s["quaternions"][row])]
    for w, wheel in enumerate(WHEEL_NAMES):
        centre = list(wheels[w]["mount"])
        centre[2] -= wheels[w]["spring_length"] - v["compression"][w]
        steer, spin = 0.5 * v["steer_angle"][w], 0.5 * v["spin_angle"][w]
        rotation = quaternion_multiply((0.0, 0.0, math.sin(steer), math.cos(steer)),
                                       (0.0, math.sin(spin), 0.0, math.cos(spin)))
        out.append(transform(snapshot.time, base_frame, f"wheel_{wheel}", centre, rotation))
    return out


def car_markers(snapshot, name, frame, wheels):
    """The car as Foxglove draws it: chassis, wheels (cylinders, steered and spun), springs
    (mount to wheel centre) and the wheels' ray hits."""
    row = snapshot.names.index(name)
    s, v = snapshot.state, snapshot.vehicles[name]
    q = s["quaternions"][row]
    rotation = quaternions_to_matrices(q[None])[0]
    position = s["positions"][row]
    stamp_header = header(snapshot.time, frame)
    chassis = Marker(header=stamp_header, ns="chassis", id=0, type=Marker.CUBE, action=Marker.ADD,
                     pose=pose(position, q))
    chassis.scale.x, chassis.scale.y, chassis.scale.z = (float(x) for x in s["sizes"][row])
    chassis.color = colour(COLOURS["vehicle"])
    springs = Marker(header=stamp_header, ns="springs", id=0, type=Marker.LINE_LIST, action=Marker.ADD)
    springs.pose.orientation.w = 1.0
    springs.scale.x = 0.04
    springs.color = colour((0.9, 0.9, 0.2, 1.0))
    hits = Marker(header=stamp_header, ns="ray_hits", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    hits.pose.orientation.w = 1.0
    hits.scale.x = hits.scale.y = hits.scale.z = 0.08
    hits.color = colour(COLOURS["contact"])
    markers = [Marker(header=stamp_header, action=Marker.DELETEALL), chassis]
    for w, wheel in enumerate(wheels):
        mount = np.asarray(wheel["mount"], dtype=float)
        centre_local = mount - [0.0, 0.0, wheel["spring_length"] - v["compression"][w]]
        mount_world, centre_world = position + rotation @ mount, position + rotation @ centre_local
        half = 0.5 * v["steer_angle"][w]
        # A cylinder's axis is its z: turn it onto the wheel's axle (y), then steer about z.
        axle = quaternion_multiply(quaternion_multiply(tuple(q), (0.0, 0.0, math.sin(half), math.cos(half))),
                                   (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)))
        m = Marker(header=stamp_header, ns="wheels", id=w, type=Marker.CYLINDER, action=Marker.ADD,
                   pose=pose(centre_world, axle))
        m.scale.x = m.scale.y = 2.0 * wheel["radius"]
        m.scale.z = 0.25
        m.color = colour((0.1, 0.1, 0.1, 1.0))
        markers.append(m)
        springs.points += [Point(x=float(a), y=float(b), z=float(c)) for a, b, c in (mount_world, centre_world)]
        if v["in_contact"][w]:
            x, y, z = v["contact_point"][w]
            hits.points.append(Point(x=float(x), y=float(y), z=float(z)))
    return MarkerArray(markers=markers + [springs, hits])


def quaternion_multiply(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def diagnostics(seconds, statuses):
    """statuses: [(name, level, message, {key: value})]."""
    msg = DiagnosticArray(header=header(seconds, ""))
    for name, level, message, values in statuses:
        msg.status.append(DiagnosticStatus(
            level=bytes([level]), name=name, message=message, hardware_id="vplayground",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
    return msg
