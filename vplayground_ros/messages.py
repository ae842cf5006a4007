"""Snapshots -> the CDR bytes of the SPEC 6.1 messages, built without rclpy: markers, poses,
clouds and transforms straight from numpy (cdr.py), the small messages as dicts through
interfaces.encode. Every stamp is simulation time; frames follow REP 105 (robots.py: each
robot's odom -> base_footprint -> base_link, its wheels under base_link), bodies under `world`.
"""
import math
from collections import namedtuple

import numpy as np

from . import cdr
from .interfaces import encode
from .physics import shapes
from .physics.math3d import quaternions_to_matrices

WHEEL_NAMES = ("front_left", "front_right", "rear_left", "rear_right")
# Each wheel's joints, from the chassis out (robots.py, robot_description.py): <wheel>_suspension
# (prismatic, the spring's compression), <wheel>_steer (revolute), <wheel>_spin (continuous).
WHEEL_JOINTS = ("suspension", "steer", "spin")
WHEEL_WIDTH = 0.25  # m: as the markers and robot_description draw a wheel


def joint_names():
    """The wheels' joints in the order joint_states sends them: each wheel's WHEEL_JOINTS."""
    return [f"{wheel}_{joint}" for wheel in WHEEL_NAMES for joint in WHEEL_JOINTS]
COLOURS = {  # category -> RGBA
    "box": (0.85, 0.55, 0.20, 1.0),
    "immovable": (0.35, 0.35, 0.45, 1.0),
    "vehicle": (0.15, 0.45, 0.85, 1.0),
    "wheel": (0.1, 0.1, 0.1, 1.0),
    "frozen": (0.6, 0.6, 0.6, 1.0),
    "ground": (0.30, 0.42, 0.30, 1.0),
    "playground": (0.55, 0.60, 0.65, 1.0),
    "contact": (1.0, 0.1, 0.1, 1.0),
}
# visualization_msgs/Marker types and actions (a capsule's own entry is its middle part).
CUBE, SPHERE, CYLINDER, LINE_LIST, CUBE_LIST, SPHERE_LIST, TRIANGLE_LIST = 1, 2, 3, 5, 6, 7, 11
ADD, DELETEALL = 0, 3
CAPSULE_MARKER = CYLINDER
IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # pose: xyz + xyzw
FLOAT32, INT32 = 7, 5  # sensor_msgs/PointField datatypes


def stamp(seconds):
    sec, nanosec = cdr.split_stamp(seconds)
    return {"sec": sec, "nanosec": nanosec}


def header(seconds, frame):
    return {"stamp": stamp(seconds), "frame_id": frame}


def xyz(values):
    return dict(zip("xyz", (float(v) for v in values)))


def xyzw(values):
    return dict(zip("xyzw", (float(v) for v in values)))


def clock(seconds):
    return cdr.clock(seconds)


def uint8(value):
    return encode("std_msgs/msg/UInt8", {"data": int(value)})


def string(value):
    return encode("std_msgs/msg/String", {"data": str(value)})


def float64(value):
    return encode("std_msgs/msg/Float64", {"data": float(value)})


def marker(ns, marker_id, kind, pose=IDENTITY, scale=(1.0, 1.0, 1.0), rgba=(0.0, 0.0, 0.0, 0.0),
           points=None, action=ADD):
    return dict(ns=ns, marker_id=marker_id, kind=kind, action=action, pose=[float(v) for v in pose],
                scale=[float(v) for v in scale], rgba=[float(v) for v in rgba], frame_locked=False,
                points=points)


DELETE_ALL = marker("", 0, 0, action=DELETEALL)


# Body categories (marker namespaces), and their colours with frozen grey last.
CATEGORIES = np.array(["box", "immovable", "vehicle"])
BOX, IMMOVABLE, VEHICLE, FROZEN = range(4)
CATEGORY_COLOURS = np.array([COLOURS[c] for c in CATEGORIES] + [COLOURS["frozen"]], np.float32)


def categories(snapshot):
    """Each body's category (an index into CATEGORIES), without a Python loop over the bodies:
    this runs at marker_rate over thousands of them."""
    kinds = np.where(snapshot.state["immovable"], IMMOVABLE, BOX)
    if snapshot.vehicles:
        kinds[np.isin(np.asarray(snapshot.names, object), list(snapshot.vehicles))] = VEHICLE
    return kinds


# The marker that draws each shape; a capsule is its cylinder plus a SPHERE on each end, whose
# ids are the body's with CAPSULE_END_ID_BITS set (body ids stay far below them).
# A convex body is its hull's triangles (a TRIANGLE_LIST in its frame, scale 1). A compound body
# is its parts, each drawn as its shape at its pose in the body's frame, with the part's index
# from PART_ID_SHIFT up in its id (below the capsule ends' bits).
SHAPE_MARKER_TYPES = np.array([CUBE, SPHERE, CAPSULE_MARKER, CYLINDER, TRIANGLE_LIST], np.int32)
CAPSULE_END_ID_BITS = (1 << 29, 1 << 30)
PART_ID_SHIFT = 23

# What drawing bodies' shapes takes beyond their poses (it changes only with the layout): the
# body row of each marker, its type, id and scale, the markers drawn off their body's pose (a
# capsule's ends, a compound's parts) with those poses in the body's frame, and each marker's
# TRIANGLE_LIST points (None for the other markers; None when no marker has any).
ShapeMarkerLayout = namedtuple("ShapeMarkerLayout", "rows types ids scales offset_markers offset_poses points")
IDENTITY_POSE = np.array(IDENTITY)


def shape_marker_layout(shape_codes, dimensions, ids, hull_triangles=None, parts=None):
    """Vectorised over the bodies that are one shape (no Python loop per body: the node draws
    thousands at marker_rate); a compound's parts are taken one by one. hull_triangles: each
    row's convex hull (T, 3, 3) or None; parts: each row's shapes.compound.FrameParts or None
    (both needed when such shapes are drawn)."""
    ids = np.asarray(ids, np.int32).reshape(-1)
    rows = np.arange(len(shape_codes))
    compounds = np.nonzero(shape_codes == shapes.COMPOUND)[0]
    local, hulls = np.zeros((0, 7)), list(hull_triangles) if hull_triangles is not None else [None] * len(rows)
    if len(compounds):  # each compound's row gives way to its parts'
        whole = np.nonzero(shape_codes != shapes.COMPOUND)[0]
        frames = [parts[row] for row in compounds.tolist()]
        owner = np.repeat(compounds, [len(f.codes) for f in frames])
        index = np.concatenate([np.arange(len(f.codes)) for f in frames])
        hulls = [hulls[row] for row in whole.tolist()] + [t for f in frames for t in f.hull_triangles]
        rows = np.concatenate([whole, owner])
        ids = np.concatenate([ids[whole], ids[owner] | (index << PART_ID_SHIFT).astype(np.int32)])
        shape_codes = np.concatenate([shape_codes[whole], *[f.codes for f in frames]])
        dimensions = np.concatenate([dimensions[whole], *[f.dimensions for f in frames]])
        local = np.concatenate([f.poses for f in frames])
    offset = np.arange(len(rows) - len(local), len(rows))
    r, half = dimensions[:, 0], dimensions[:, 1]
    scales = np.where((shape_codes == shapes.BOX)[:, None], 2.0 * dimensions,
                      np.stack([2.0 * r, 2.0 * r, np.where(shape_codes == shapes.SPHERE, 2.0 * r, 2.0 * half)], 1))
    scales[shape_codes == shapes.CONVEX] = 1.0
    types = SHAPE_MARKER_TYPES[shape_codes]
    capsules = np.nonzero(shape_codes == shapes.CAPSULE)[0]
    diameter = np.repeat(2.0 * r[capsules, None], 3, axis=1)
    # Where each capsule (or capsule part) is in its body's frame, and its ends beside it.
    centre = np.tile(IDENTITY_POSE, (len(rows), 1))
    centre[offset] = local
    ends = []
    for sign in (1.0, -1.0):
        along = np.zeros((len(capsules), 7))
        along[:, 2], along[:, 6] = sign * half[capsules], 1.0
        ends.append(compose_poses(centre[capsules], along))
    points = None
    if any(h is not None for h in hulls):
        points = tuple(h.reshape(-1, 3) if h is not None else None for h in hulls) + (None,) * (2 * len(capsules))
    return ShapeMarkerLayout(
        np.concatenate([rows, rows[capsules], rows[capsules]]),
        np.concatenate([types, np.full(2 * len(capsules), SPHERE, np.int32)]),
        np.concatenate([ids, ids[capsules] | CAPSULE_END_ID_BITS[0], ids[capsules] | CAPSULE_END_ID_BITS[1]]),
        np.concatenate([scales, diameter, diameter]),
        np.concatenate([offset, len(rows) + np.arange(2 * len(capsules))]).astype(np.int64),
        np.concatenate([local, *ends]), points)


def compose_poses(outer, inner):
    """Poses (K, 7) xyz + xyzw of frames at `inner` in frames at `outer`, both (K, 7)."""
    turns = quaternions_to_matrices(outer[:, 3:])
    (ax, ay, az, aw), (bx, by, bz, bw) = outer[:, 3:].T, inner[:, 3:].T
    turned = np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                       aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], 1)
    return np.concatenate([outer[:, :3] + np.einsum("kij,kj->ki", turns, inner[:, :3]), turned], axis=1)


def shape_marker_poses(layout, poses):
    """The markers' poses (M, 7) from the bodies' (N, 7): a capsule's ends beside it, a
    compound's parts where they are on it."""
    if len(layout.offset_markers) == 0:
        return poses  # one marker a body, at its pose
    placed = poses[layout.rows]
    moved = layout.offset_markers
    placed[moved] = compose_poses(placed[moved], layout.offset_poses)
    return placed


# What one body-marker topic draws, kept while the layout and the bodies at rest stay: `key` the
# layout's arrays (by identity), `at_rest` the flags it was made for and `frozen` the array they
# came from (a settled world's snapshots share it), `rows` the bodies drawn.
MarkerLayout = namedtuple("MarkerLayout", "key at_rest frozen rows namespaces markers colours points")


class BodyMarkers:
    """One of the two topics that draw the bodies: DELETEALL, then each body's shape
    (shape_marker_layout; ns = category, ids stable per name, frozen grey). `resting` draws the bodies
    at rest (frozen or immovable: ~/bodies/resting_markers, latched), else the others
    (~/bodies/markers, every round), so what does not move is not re-sent every round. Neither
    draws the vehicles: ~/<name>/markers draws each with its wheels, and two markers at one
    place would show whichever colour the viewer draws last.

    Names, categories, ids, shapes, sizes and which bodies are at rest change only with the
    layout (spawn, remove, edit) or when a body freezes or wakes: what is made of them is kept,
    read-only, until they do. A settled world's snapshots share their arrays (Simulation), so
    then only the stamps are written (cdr.TemplateEncoder)."""

    def __init__(self, resting):
        self.resting = resting
        self.encoder = cdr.BodyMarkerEncoder()
        self._layout = None  # MarkerLayout
        self._drawn = None   # (layout, the pose block, the poses of the rows drawn) last encoded

    def layout(self, snapshot, ids):
        s = snapshot.state
        key = (snapshot.names, s["immovable"], s["shapes"], s["dimensions"], s["hull_triangles"], s["parts"], ids,
               snapshot.robot_specs, tuple(snapshot.vehicles))
        cached = self._layout
        if cached is not None and all(a is b for a, b in zip(key[:8], cached.key[:8])) and key[8:] == cached.key[8:]:
            if s["frozen"] is cached.frozen or np.array_equal(s["frozen"] | s["immovable"], cached.at_rest):
                return cached
        at_rest = s["frozen"] | s["immovable"]
        drawn = at_rest.copy() if self.resting else ~at_rest
        drawn[[snapshot.names.index(name) for name in snapshot.vehicles]] = False
        # A URDF robot with visual elements is drawn by them (~/<name>/visuals), not its bodies.
        drawn[[snapshot.names.index(body) for robot in snapshot.robot_specs if robot["model"].visuals
               for body in robot["bodies"]]] = False
        rows = np.nonzero(drawn)[0]
        kinds = categories(snapshot)[rows]
        picked = rows.tolist()
        markers = shape_marker_layout(s["shapes"][rows], s["dimensions"][rows], np.asarray(ids)[rows],
                                      [s["hull_triangles"][row] for row in picked], [s["parts"][row] for row in picked])
        namespaces = CATEGORIES[kinds[markers.rows]]
        colours = CATEGORY_COLOURS[np.where(s["frozen"][rows], FROZEN, kinds)][markers.rows]
        for array in (at_rest, rows, namespaces, colours, *markers[:-1]):
            array.flags.writeable = False
        points = None if markers.points is None else tuple(
            b"" if p is None else np.ascontiguousarray(p, "<f8").tobytes() for p in markers.points)
        self._layout = MarkerLayout(key, at_rest, s["frozen"], rows, namespaces, markers, colours, points)
        return self._layout

    def draws_nothing(self, snapshot, ids):
        return len(self.layout(snapshot, ids).rows) == 0

    def draws_the_same(self, snapshot, ids, poses):
        """Whether encode would draw what it drew last: the same bodies, shapes and colours at
        the same poses (the stamp aside)."""
        last = self._drawn
        if last is None or self.layout(snapshot, ids) is not last[0]:
            return False
        return poses is last[1] or np.array_equal(poses[last[0].rows], last[2])

    def encode(self, snapshot, frame, ids, poses):
        """ids (N,) the bodies' marker ids, poses (N, 7) xyz + xyzw of every body."""
        layout = self.layout(snapshot, ids)
        drawn = poses[layout.rows]
        self._drawn = (layout, poses, drawn)
        markers = layout.markers
        return self.encoder.encode(snapshot.time, frame, layout.namespaces, markers.types, markers.ids,
                                   shape_marker_poses(markers, drawn), markers.scales, layout.colours, layout.points)


VISUAL_KINDS = {"box": CUBE, "sphere": SPHERE, "cylinder": CYLINDER, "mesh": TRIANGLE_LIST}


def robot_visuals(seconds, robots):
    """The URDF robots' visual elements (urdf_import.Visual; `robots`: [(frame prefix, its
    Visuals)]) as markers locked to their link frames: sent once, they follow the links as /tf
    moves them. ns: the link's frame."""
    markers = [DELETE_ALL]
    for prefix, visuals in robots:
        for k, v in enumerate(visuals):
            m = marker(prefix + v.link, k, VISUAL_KINDS[v.kind], v.pose, v.size, v.rgba,
                       points=None if v.triangles is None else v.triangles.reshape(-1, 3))
            markers.append({**m, "frame_locked": True, "frame": prefix + v.link})
    return marker_array(seconds, "", markers)


def marker_array(seconds, frame, markers):
    """The MarkerArray of `markers` less the list markers without points (Foxglove warns "has
    no points" for each); the DELETEALL they follow clears what such a marker drew before."""
    return cdr.marker_array(seconds, frame, [m for m in markers if m["points"] is None or len(m["points"])])


def scene_markers(seconds, frame, ground, triangles, octree_cells=()):
    """The static scenery: the ground plane, the playground as a TRIANGLE_LIST, and (when
    asked) the occupied octree cells as one translucent CUBE_LIST per level."""
    markers = [DELETE_ALL]
    if ground is not None:
        markers.append(marker("ground", 0, CUBE, (0.0, 0.0, float(ground["height"]) - 0.005, 0.0, 0.0, 0.0, 1.0),
                              (200.0, 200.0, 0.01), COLOURS["ground"]))
    if len(triangles):
        markers.append(marker("playground", 0, TRIANGLE_LIST, rgba=COLOURS["playground"],
                              points=np.asarray(triangles).reshape(-1, 3)))
    for level, centres, edge in octree_cells:
        markers.append(marker("octree", int(level), CUBE_LIST, scale=(edge, edge, edge),
                              rgba=(0.2, 0.6, 1.0, 0.12), points=np.asarray(centres).reshape(-1, 3)))
    return marker_array(seconds, frame, markers)


CONTACT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                          ("nz", "<f4"), ("depth", "<f4"), ("impulse", "<f4"), ("body_a", "<i4"),
                          ("body_b", "<i4")])
CONTACT_FIELD_LAYOUT = [(name, CONTACT_DTYPE.fields[name][1], INT32 if name.startswith("body") else FLOAT32, 1)
                        for name in CONTACT_DTYPE.names]


def contact_cloud(snapshot, frame, max_points):
    """~/contacts/points."""
    c = snapshot.contacts
    n = min(len(c["depths"]), max_points)
    if n == 0:
        return no_contacts("cloud", frame, snapshot.time)
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
    if n == 0:
        return no_contacts("markers", frame, snapshot.time)
    points = c["points"][:n]
    tips = points - 0.3 * c["normals"][:n]  # normals point from A into B: draw them out of B
    segments = np.stack([points, tips], axis=1).reshape(-1, 3)
    return marker_array(snapshot.time, frame, [
        DELETE_ALL,
        marker("contact_points", 0, SPHERE_LIST, scale=(0.05, 0.05, 0.05), rgba=COLOURS["contact"], points=points),
        marker("contact_normals", 1, LINE_LIST, scale=(0.01, 0.01, 0.01), rgba=COLOURS["contact"], points=segments)])


# A world at rest touches nothing (frozen bodies keep no contacts): its contact topics differ
# round to round only in their stamp, so each is built once per frame and restamped.
_NO_CONTACTS = {}  # (topic, frame) -> (message stamped 0, the stamp's byte offset)


def no_contacts(topic, frame, seconds):
    """~/contacts/points ("cloud") or ~/contacts/markers ("markers") with no contact."""
    if (topic, frame) not in _NO_CONTACTS:
        if topic == "cloud":  # the Header starts the message
            built = cdr.point_cloud(0.0, frame, CONTACT_FIELD_LAYOUT, np.zeros(0, CONTACT_DTYPE)), 4
        else:  # the array's count, then the DELETEALL's Header
            built = marker_array(0.0, frame, [DELETE_ALL]), 8
        _NO_CONTACTS[(topic, frame)] = built
    message, offset = _NO_CONTACTS[(topic, frame)]
    return cdr.restamped(message, seconds, offset)


# What the simulator knows exactly gets this small diagonal (as the IMU's exact parts), not
# zeros, which robot_localization and others take for "unknown".
EXACT_VARIANCE = 1e-12
EXACT_COVARIANCE = [EXACT_VARIANCE if row == column else 0.0 for row in range(6) for column in range(6)]


def odometry(seconds, frame, child, pose, child_orientation, linear, angular, pose_covariance=EXACT_COVARIANCE,
             twist_covariance=EXACT_COVARIANCE):
    """nav_msgs/Odometry: `pose` (xyz, xyzw) of `child` in `frame`; the twist (world linear and
    angular velocity) in the child's axes, which `child_orientation` (xyzw) turns into the world's."""
    to_child = quaternions_to_matrices(np.asarray(child_orientation, float)[None])[0].T
    return encode("nav_msgs/msg/Odometry", {
        "header": header(seconds, frame), "child_frame_id": child,
        "pose": {"pose": {"position": xyz(pose[0]), "orientation": xyzw(pose[1])}, "covariance": list(pose_covariance)},
        "twist": {"twist": {"linear": xyz(to_child @ linear), "angular": xyz(to_child @ angular)},
                  "covariance": list(twist_covariance)}})


def joint_states(snapshot, name):
    """Per wheel (joint_names()): <wheel>_suspension (compression m, its rate m/s),
    <wheel>_steer (angle, rad/s over the last step), <wheel>_spin (angle, rate)."""
    v = snapshot.vehicles[name]
    position, velocity = [], []
    for w in range(len(WHEEL_NAMES)):
        position += [float(v["compression"][w]), float(v["steer_angle"][w]), float(v["spin_angle"][w])]
        velocity += [float(v["compression_rate"][w]), float(v["steer_rate"][w]), float(v["spin_rate"][w])]
    return encode("sensor_msgs/msg/JointState", {"header": header(snapshot.time, ""), "name": joint_names(),
                                                 "position": position, "velocity": velocity})


def joint_state(seconds, names, positions, velocities=(), efforts=()):
    """sensor_msgs/JointState of named joints (a URDF robot's)."""
    return encode("sensor_msgs/msg/JointState", {
        "header": header(seconds, ""), "name": list(names), "position": [float(v) for v in positions],
        "velocity": [float(v) for v in velocities], "effort": [float(v) for v in efforts]})


def car_command(snapshot, name, frame):
    v = snapshot.vehicles[name]
    return encode("geometry_msgs/msg/TwistStamped", {
        "header": header(snapshot.time, frame),
        "twist": {"linear": xyz((v["command_speed"], 0, 0)), "angular": xyz((0, 0, v["command_yaw_rate"]))}})


def car_markers(snapshot, name, frame, wheels):
    """The car as Foxglove draws it: chassis, wheels (cylinders, steered and spun), springs
    (mount to wheel centre) and the wheels' ray hits."""
    row = snapshot.names.index(name)
    s, v = snapshot.state, snapshot.vehicles[name]
    q = s["quaternions"][row]
    rotation = quaternions_to_matrices(q[None])[0]
    position = s["positions"][row]
    markers = [DELETE_ALL, marker("chassis", 0, CUBE, [*position, *q], s["sizes"][row], COLOURS["vehicle"])]
    springs, hits = [], []
    for w, wheel in enumerate(wheels):
        mount = np.asarray(wheel["mount"], dtype=float)
        centre_local = mount - [0.0, 0.0, wheel["spring_length"] - v["compression"][w]]
        mount_world, centre_world = position + rotation @ mount, position + rotation @ centre_local
        half = 0.5 * v["steer_angle"][w]
        # A cylinder's axis is its z: turn it onto the wheel's axle (y), then steer about z.
        axle = quaternion_multiply(quaternion_multiply(tuple(q), (0.0, 0.0, math.sin(half), math.cos(half))),
                                   (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)))
        diameter = 2.0 * wheel["radius"]
        markers.append(marker("wheels", w, CYLINDER, [*centre_world, *axle], (diameter, diameter, WHEEL_WIDTH),
                              COLOURS["wheel"]))
        springs += [mount_world, centre_world]
        if v["in_contact"][w]:
            hits.append(v["contact_point"][w])
    markers.append(marker("springs", 0, LINE_LIST, scale=(0.04, 0.04, 0.04), rgba=(0.9, 0.9, 0.2, 1.0),
                          points=np.array(springs).reshape(-1, 3)))
    markers.append(marker("ray_hits", 0, SPHERE_LIST, scale=(0.08, 0.08, 0.08), rgba=COLOURS["contact"],
                          points=np.array(hits).reshape(-1, 3)))
    return marker_array(snapshot.time, frame, markers)


def quaternion_multiply(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def diagnostics(seconds, statuses):
    """statuses: [(name, level, message, {key: value})]."""
    return encode("diagnostic_msgs/msg/DiagnosticArray", {
        "header": header(seconds, ""),
        "status": [{"level": level, "name": name, "message": message, "hardware_id": "vplayground",
                    "values": [{"key": k, "value": str(v)} for k, v in values.items()]}
                   for name, level, message, values in statuses]})
