"""Our CDR encoders against rclpy's own deserialiser (compare decoded messages, not bytes)."""
import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import PoseArray  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from vplayground_ros import cdr, messages  # noqa: E402


def stamp_of(header):
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


@pytest.mark.parametrize("count", [0, 1, 7, 50])
def test_body_markers_round_trip(count):
    rng = np.random.default_rng(count)
    namespaces = rng.choice(["box", "immovable", "vehicle"], count)
    ids = np.arange(count) * 3 + 1
    poses = rng.normal(size=(count, 7))
    sizes, colours = rng.uniform(0.1, 3, (count, 3)), rng.uniform(0, 1, (count, 4)).astype(np.float32)
    types = rng.choice([Marker.CUBE, Marker.SPHERE, Marker.CYLINDER], count)
    data = cdr.BodyMarkerEncoder().encode(12.25, "world", namespaces, types, ids, poses, sizes, colours)
    msg = deserialize_message(data, MarkerArray)
    assert len(msg.markers) == count + 1
    assert msg.markers[0].action == Marker.DELETEALL
    for k, m in enumerate(msg.markers[1:]):
        assert m.header.frame_id == "world" and stamp_of(m.header) == pytest.approx(12.25)
        assert m.ns == namespaces[k] and m.id == ids[k] and m.type == types[k]
        assert [m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.x,
                m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w] == list(poses[k])
        assert [m.scale.x, m.scale.y, m.scale.z] == list(sizes[k])
        assert [m.color.r, m.color.g, m.color.b, m.color.a] == pytest.approx(list(colours[k]))
        assert m.frame_locked and list(m.points) == [] and m.text == ""


def test_pose_array_round_trip():
    positions, quaternions = np.random.default_rng(1).normal(size=(5, 3)), np.random.default_rng(2).normal(size=(5, 4))
    msg = deserialize_message(cdr.pose_array(3.5, "world", positions, quaternions), PoseArray)
    assert msg.header.frame_id == "world" and stamp_of(msg.header) == 3.5
    assert [[p.position.x, p.position.y, p.position.z] for p in msg.poses] == positions.tolist()
    assert [[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in msg.poses] == quaternions.tolist()


def test_contact_cloud_round_trip():
    rows = np.zeros(3, messages.CONTACT_DTYPE)
    rows["x"], rows["body_b"] = [1.0, 2.0, 3.0], [-1, 4, -2]
    msg = deserialize_message(cdr.point_cloud(1.0, "world", messages.CONTACT_FIELD_LAYOUT, rows), PointCloud2)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == messages.CONTACT_FIELD_LAYOUT
    assert [f.name for f in msg.fields] == list(messages.CONTACT_DTYPE.names)
    assert msg.width == 3 and msg.point_step == 40 and msg.is_dense
    decoded = np.frombuffer(bytes(msg.data), messages.CONTACT_DTYPE)
    assert decoded["x"].tolist() == [1.0, 2.0, 3.0] and decoded["body_b"].tolist() == [-1, 4, -2]


@pytest.mark.parametrize("seconds", [0.0, 2.5, 1e6 + 0.0078125])
def test_a_world_without_contacts_gets_the_bytes_a_full_build_gives(seconds):
    """no_contacts restamps one message per frame: byte for byte what the general path builds."""
    for frame in ("world", "another_frame"):
        assert messages.no_contacts("cloud", frame, seconds) == cdr.point_cloud(
            seconds, frame, messages.CONTACT_FIELD_LAYOUT, np.zeros(0, messages.CONTACT_DTYPE))
        assert messages.no_contacts("markers", frame, seconds) == messages.marker_array(
            seconds, frame, [messages.DELETE_ALL])
        msg = deserialize_message(messages.no_contacts("cloud", frame, seconds), PointCloud2)
        assert msg.header.frame_id == frame and stamp_of(msg.header) == pytest.approx(seconds, abs=1e-9)


def test_tf_message_round_trip_without_tf2_msgs():
    from mcap_ros2._dynamic import generate_dynamic

    from vplayground_ros.interfaces import schema
    decode = generate_dynamic("tf2_msgs/msg/TFMessage", schema("tf2_msgs/msg/TFMessage"))["tf2_msgs/msg/TFMessage"]
    poses = np.random.default_rng(3).normal(size=(4, 7))
    data = cdr.TransformEncoder().encode(7.125, ["world", "world", "odom", "base_link"],
                                         ["crate", "a_longer_name", "base_link", "wheel_front_left"], poses)
    msg = decode(data)
    assert [t.child_frame_id for t in msg.transforms] == ["crate", "a_longer_name", "base_link", "wheel_front_left"]
    assert [t.header.frame_id for t in msg.transforms] == ["world", "world", "odom", "base_link"]
    for t, p in zip(msg.transforms, poses):
        assert t.header.stamp.sec == 7 and t.header.stamp.nanosec == 125_000_000
        tr, rot = t.transform.translation, t.transform.rotation
        assert [tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w] == list(p)


def test_templates_of_removed_names_are_not_kept():
    """Hours of spawning and removing bodies with new names must not grow the encoders."""
    encoder = cdr.TransformEncoder()
    for k in range(300):
        names = [f"crate_{k}_{j}" for j in range(5)]
        encoder.encode(float(k), ["world"] * 5, names, np.zeros((5, 7)))
    assert len(encoder._elements._templates) <= 2 * 5  # this layout's names, at most two alignments each


@pytest.mark.parametrize("seconds", [0.0, 7.125, 0.9999999999, 86400.5])
def test_clock_round_trip(seconds):
    from rosgraph_msgs.msg import Clock
    msg = deserialize_message(cdr.clock(seconds), Clock)
    assert (msg.clock.sec, msg.clock.nanosec) == cdr.split_stamp(seconds)


def test_a_stamp_just_under_a_second_rounds_up_not_back():
    assert cdr.split_stamp(0.9999999999) == (1, 0)
    assert cdr.split_stamp(2.5) == (2, 500_000_000)
    assert cdr.split_stamp(3.0) == (3, 0)


def test_a_marker_encoder_reused_follows_changed_namespaces():
    # The encoder keeps its last layout: a change of categories in a same-length list (a body
    # made immovable, say) must not reuse it.
    encoder = cdr.BodyMarkerEncoder()
    poses, sizes, colours = np.zeros((3, 7)), np.ones((3, 3)), np.ones((3, 4), np.float32)
    for namespaces in (["box", "box", "vehicle"], ["box", "immovable", "vehicle"], ["box", "box", "vehicle"]):
        msg = deserialize_message(encoder.encode(1.0, "world", namespaces, [1] * 3, [1, 2, 3], poses, sizes, colours),
                                  MarkerArray)
        assert [m.ns for m in msg.markers[1:]] == namespaces
    for types in ([1, 1, 1], [1, 2, 1], [3, 2, 1]):  # a body of another shape in its place
        msg = deserialize_message(encoder.encode(1.0, "world", namespaces, types, [1, 2, 3], poses, sizes, colours),
                                  MarkerArray)
        assert [m.type for m in msg.markers[1:]] == types


def test_a_reused_encoder_writes_what_a_fresh_one_does():
    # A reused encoder rewrites only the fields whose bits changed: every message must still be
    # byte for byte what an encoder seeing it first writes (a sign of zero included).
    markers, transforms = cdr.BodyMarkerEncoder(), cdr.TransformEncoder()
    rng = np.random.default_rng(3)
    poses, sizes, colours = rng.normal(size=(4, 7)), np.ones((4, 3)), np.ones((4, 4), np.float32)
    namespaces, ids = ["box"] * 4, [5, 6, 7, 8]
    moved = poses.copy()
    moved[2, :3] += 0.25
    signed = moved.copy()
    signed[0, 0] = -0.0
    greyed = colours.copy()
    greyed[1] = 0.6
    for seconds, p, c, ns in [(1.0, poses, colours, namespaces), (1.5, poses, colours, namespaces),
                              (2.0, moved, colours, namespaces), (2.5, signed, greyed, namespaces),
                              (3.0, signed, greyed, ["box", "immovable", "box", "box"]), (3.5, poses, colours, namespaces)]:
        assert markers.encode(seconds, "world", ns, [1] * 4, ids, p, sizes, c) == \
            cdr.BodyMarkerEncoder().encode(seconds, "world", ns, [1] * 4, ids, p, sizes, c)
        children = [f"{n}_{k}" for k, n in enumerate(ns)]
        assert transforms.encode(seconds, ["world"] * 4, children, p) == \
            cdr.TransformEncoder().encode(seconds, ["world"] * 4, children, p)
    msg = deserialize_message(markers.encode(4.0, "world", namespaces, [1] * 4, ids, moved, sizes, greyed), MarkerArray)
    assert msg.markers[0].header.stamp.sec == 4 and msg.markers[3].pose.position.x == moved[2, 0]
    assert msg.markers[2].color.r == pytest.approx(0.6)


def test_read_only_arrays_given_again_or_anew_encode_as_a_fresh_encoder_does():
    # A settled world hands the encoders the same read-only arrays round after round (taken as
    # unchanged without comparing); a new array, equal or not, is compared: either way every
    # message is what a fresh encoder writes.
    rng = np.random.default_rng(4)

    def frozen(array):
        array.flags.writeable = False
        return array
    poses, sizes = frozen(rng.normal(size=(6, 7))), frozen(np.ones((6, 3)))
    colours, ids = frozen(np.ones((6, 4), np.float32)), frozen(np.arange(6, dtype="<i4").reshape(-1, 1))
    namespaces = frozen(np.array(["box"] * 5 + ["immovable"]))
    types = frozen(np.array([1, 1, 2, 3, 1, 1], np.int32))
    moved = poses.copy()
    moved[4, 2] += 1.0
    markers, transforms = cdr.BodyMarkerEncoder(), cdr.TransformEncoder()
    parents, children = ("world",) * 6, tuple(f"b{k}" for k in range(6))
    for seconds, p in [(1.0, poses), (1.5, poses), (2.0, frozen(poses.copy())), (2.5, frozen(moved)), (3.0, poses)]:
        assert markers.encode(seconds, "world", namespaces, types, ids, p, sizes, colours) == \
            cdr.BodyMarkerEncoder().encode(seconds, "world", list(namespaces), list(types), ids.ravel(), p.copy(),
                                           sizes, colours)
        assert transforms.encode(seconds, parents, children, p) == \
            cdr.TransformEncoder().encode(seconds, list(parents), list(children), p.copy())
