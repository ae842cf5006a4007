"""Message definitions and CDR without rclpy (interfaces.py): the bundled copies match the
installed interface packages, and every type the simulator offers resolves from them alone."""
from unittest.mock import MagicMock

import pytest

from vplayground_ros import interfaces
from vplayground_ros.broadcast import TOPICS
from vplayground_ros.inputs import SUBSCRIPTIONS, TWIST_STAMPED
from vplayground_ros.services import service_table

OWN = sorted(p for p in interfaces.OWN_DEFINITIONS.rglob("*") if p.suffix in (".msg", ".srv"))


def service_types():
    return {s.type for s in service_table(MagicMock())}


def installed(path):
    relative = path.relative_to(interfaces.OWN_DEFINITIONS)
    for root in interfaces.search_roots()[:-1]:
        if (root / relative).is_file():
            return root / relative
    return None


@pytest.mark.parametrize("path", OWN, ids=lambda p: str(p.relative_to(interfaces.OWN_DEFINITIONS)))
def test_bundled_definitions_equal_the_installed_ones(path):
    other = installed(path)
    if other is None:
        pytest.skip(f"{path.name} is not installed here (tf2_msgs comes only with a ROS install)")
    assert path.read_text() == other.read_text()


def test_every_type_resolves_from_the_bundled_definitions_alone(monkeypatch):
    monkeypatch.setattr(interfaces, "search_roots", lambda: [interfaces.OWN_DEFINITIONS])
    for cached in (interfaces.definition, interfaces.schema, interfaces.encoder, interfaces.decoder):
        cached.cache_clear()
    try:
        types = {t.type for t in TOPICS} | {s.type for s in SUBSCRIPTIONS} | {TWIST_STAMPED}
        types |= {f"{t}_{part}" for t in service_types() for part in ("Request", "Response")}
        for type_name in sorted(types):
            text = interfaces.schema(type_name)
            assert "/msg/" not in "".join(line for line in text.splitlines() if line.startswith("MSG: "))
            # An all-zero message encodes and decodes back.
            interfaces.decoder(type_name)(interfaces.encode(type_name, {}))
    finally:
        for cached in (interfaces.definition, interfaces.schema, interfaces.encoder, interfaces.decoder):
            cached.cache_clear()


def test_service_parts_split_at_the_separator():
    assert interfaces.schema("std_srvs/srv/SetBool_Request").strip().startswith("bool data")
    response = interfaces.schema("nav_msgs/srv/LoadMap_Response")
    assert "uint8 result" in response and "MSG: nav_msgs/OccupancyGrid" in response
    with pytest.raises(LookupError, match="neither"):
        interfaces.schema("std_srvs/srv/SetBool")


def test_encoded_bytes_match_rclpy_where_it_is_installed():
    rclpy_serialization = pytest.importorskip("rclpy.serialization")
    from nav_msgs.msg import Odometry
    message = {"header": {"stamp": {"sec": 3, "nanosec": 250}, "frame_id": "odom"}, "child_frame_id": "base_link",
               "pose": {"pose": {"position": {"x": 1.5, "y": -2.0, "z": 0.25}}}}
    decoded = rclpy_serialization.deserialize_message(interfaces.encode("nav_msgs/msg/Odometry", message), Odometry)
    assert (decoded.header.stamp.sec, decoded.header.frame_id, decoded.child_frame_id) == (3, "odom", "base_link")
    assert (decoded.pose.pose.position.x, decoded.pose.pose.orientation.w) == (1.5, 1.0)



def test_schemas_are_complete_down_to_the_time_types():
    """SPEC 7: every dependency's definition, builtin_interfaces/Time and Duration too, as
    rosbag2 writes them (a reader that does not know them as time types still decodes)."""
    header = interfaces.schema("std_msgs/msg/Header")
    assert "\nMSG: builtin_interfaces/Time\n" in header and "int32 sec" in header and "uint32 nanosec" in header
    assert "\nMSG: builtin_interfaces/Duration\n" in interfaces.schema("visualization_msgs/msg/Marker")
