"""The built-in Foxglove WebSocket server (SPEC 6.5) through a real WebSocket client, with the
simulator in a process where rclpy and every ROS message package fail to import: the live
window must work without a ROS install."""
import gc
import json
import logging
import math
import random
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import foxglove
import pytest
import yaml
from mcap_ros2._dynamic import serialize_dynamic
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from foxglove_client import OLD_SUBPROTOCOL, SUBPROTOCOL, URL_IN_LOG, FoxgloveClient
from foxglove_js import needs_node, run_script
from helpers import wait_for

from vplayground_ros.cli import parse_args
from vplayground_ros.foxglove_front import MAX_VIEWERS, HandshakeError, read_head
from vplayground_ros.foxglove_server import FoxgloveServer
from vplayground_ros.runtime import Runtime
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import Simulation

NS = "/vplayground"
TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock", f"{NS}/bodies/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/bodies/resting_markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/bodies/poses": "geometry_msgs/msg/PoseArray", f"{NS}/scene/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/contacts/points": "sensor_msgs/msg/PointCloud2", f"{NS}/contacts/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/transforms": "geometry_msgs/msg/TransformStamped", "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage", "/odom": "nav_msgs/msg/Odometry",
    f"{NS}/car/ground_truth": "nav_msgs/msg/Odometry", "/joint_states": "sensor_msgs/msg/JointState",
    f"{NS}/car/command": "geometry_msgs/msg/TwistStamped", f"{NS}/car/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/state": "std_msgs/msg/UInt8", f"{NS}/real_time_factor": "std_msgs/msg/Float64",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray", "/robot_description": "std_msgs/msg/String",
    f"{NS}/robots/visuals": "visualization_msgs/msg/MarkerArray",
}
SERVICES = {"spawn", "edit", "remove", "get_entity", "save_scene", "get_entities", "pause", "set_freezing",
            "step", "reset", "wake_all", "get_simulator_features", "load_scene"}
# simulation_interfaces' (standard_services.py), relative names: at the root here.
STANDARD = {"get_simulator_features", "spawn_entity", "spawn_entities", "delete_entity", "get_entities",
            "get_entities_states", "get_entity_state", "set_entity_state", "get_entity_info", "get_entity_bounds",
            "get_simulation_state", "set_simulation_state", "reset_simulation", "step_simulation", "load_world",
            "unload_world", "get_current_world", "get_available_worlds"}
ADVERTISED = {f"{NS}/{name}" for name in SERVICES} | {f"/{name}" for name in STANDARD}
ROS_MODULES = ["rclpy", "rosidl_runtime_py", "builtin_interfaces", "rcl_interfaces", "rosgraph_msgs", "std_msgs",
               "std_srvs", "geometry_msgs", "nav_msgs", "sensor_msgs", "visualization_msgs", "diagnostic_msgs",
               "tf2_msgs"]
# The simulator with every ROS Python package made unimportable.
WITHOUT_ROS = (f"import sys; sys.modules.update(dict.fromkeys({ROS_MODULES!r})); "
               "from vplayground_ros.cli import main; sys.exit(main())")


def start_simulator(*options):
    """The simulator without ROS serving Foxglove (`--foxglove 0`, any free port): (process, the
    URL it logged or None, its output so far)."""
    process = subprocess.Popen([sys.executable, "-c", WITHOUT_ROS, "--foxglove", "0", "--no-record", *options],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output, url = [], None
    deadline = time.monotonic() + 120
    while url is None and time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        output.append(line)
        found = URL_IN_LOG.search(line)
        url = found.group(1) if found else None
    return process, url, output


@pytest.fixture(scope="module")
def server():
    process, url, output = start_simulator()
    assert url, "".join(output)
    threading.Thread(target=lambda: output.extend(process.stdout), daemon=True).start()  # keep the pipe drained
    yield url, output
    process.terminate()
    assert process.wait(30) == 0, "".join(output)
    assert "Traceback" not in "".join(output), "".join(output)


@pytest.fixture
def client(server):
    c = FoxgloveClient(server[0])
    assert c.wait(lambda: len(c.channels) >= len(TOPICS) and len(c.services) >= len(ADVERTISED))
    yield c
    c.close()


def test_runs_without_ros_and_advertises_every_topic_and_service(client, server):
    assert "no ROS node" in "".join(server[1])
    assert {t: c["schemaName"] for t, c in client.channels.items()} == TOPICS
    assert all(c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg" for c in client.channels.values())
    assert set(client.services) == ADVERTISED
    for service in client.services.values():
        assert service["request"]["encoding"] == service["response"]["encoding"] == "cdr"
        assert service["request"]["schemaName"] == service["type"] + "_Request"
    assert {"clientPublish", "parameters", "parametersSubscribe", "services", "time"} <= set(
        client.server_info["capabilities"])


@pytest.mark.parametrize("subprotocol", [SUBPROTOCOL, OLD_SUBPROTOCOL])
def test_viewers_of_either_protocol_generation_connect_to_a_ros_source(server, subprotocol):
    """Lichtblick <= 1.10.8 and older Foxglove ask for foxglove.websocket.v1, newer viewers for
    foxglove.sdk.v1; both are served on the one URL. The server names its ROS distribution:
    viewers offer the 3D panel's publish tools only to a ROS source."""
    client = FoxgloveClient(server[0], subprotocol=subprotocol)
    try:
        assert client.ws.subprotocol == subprotocol
        assert client.wait(lambda: client.server_info is not None and len(client.channels) >= len(TOPICS))
        assert client.server_info["metadata"]["ROS_DISTRO"] == "jazzy"
        assert client.server_info["name"] == "vplayground"
        client.subscribe("/clock")
        assert client.wait(lambda: len(client.frames["/clock"]) >= 1)
        assert client.call(f"{NS}/get_simulator_features", {}).success
    finally:
        client.close()


def test_a_viewer_asking_for_another_protocol_is_refused(server):
    with pytest.raises(InvalidStatus) as refused:
        connect(server[0], subprotocols=["foxglove.websocket.v2"], open_timeout=10)
    assert refused.value.response.status_code == 400


def test_an_oversized_request_gets_its_answer_not_a_reset(server):
    """An HTTP head past the relay's 64 KiB limit is answered 400; the bytes still unread made
    the close a reset, and the client lost the answer."""
    host, port = server[0].removeprefix("ws://").rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nX-Filler: " + b"a" * 100_000 + b"\r\n\r\n")
        answer = b""
        while True:
            chunk = sock.recv(65536)
            if not chunk:
                break
            answer += chunk
    assert answer.startswith(b"HTTP/1.1 400") and b"HTTP head too large" in answer


def test_viewers_past_the_cap_are_refused_and_served_again_once_slots_free(server):
    """Connections that never finish their handshake (a slow or hostile client) hold their slot
    up to the handshake timeout; past MAX_VIEWERS the relay answers 503 instead of starting
    threads without end."""
    host, port = server[0].removeprefix("ws://").rsplit(":", 1)
    idle = [socket.create_connection((host, int(port)), timeout=30) for _ in range(MAX_VIEWERS)]
    try:
        extra = socket.create_connection((host, int(port)), timeout=30)
        with extra:
            assert extra.recv(4096).startswith(b"HTTP/1.1 503 Service Unavailable")
    finally:
        for sock in idle:
            sock.close()

    def a_viewer_is_served():
        try:
            FoxgloveClient(server[0]).close()
            return True
        except InvalidStatus:
            return False
    assert wait_for(a_viewer_is_served)
    assert f"foxglove: {MAX_VIEWERS} viewers connected, refusing more" in "".join(server[1])


def test_a_taken_port_is_a_clear_error(server):
    port = server[0].rsplit(":", 1)[1]
    result = subprocess.run([sys.executable, "-m", "vplayground_ros.cli", "--no-ros", "--no-record", "--foxglove", port],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert f"cannot listen on 127.0.0.1:{port}" in result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr


def test_subscribed_frames_decode_to_their_types_stamped_with_sim_time(client):
    client.subscribe(f"{NS}/bodies/poses", "/odom", f"{NS}/bodies/markers", f"{NS}/bodies/resting_markers",
                     "/diagnostics", "/clock", "/tf", f"{NS}/scene/markers")
    assert client.wait(lambda: any(stamp > 0 for stamp, _ in client.frames[f"{NS}/bodies/poses"]))
    log_time, poses = client.latest(f"{NS}/bodies/poses")
    assert len(poses.poses) == 44 and poses.header.frame_id == "world"
    stamp = poses.header.stamp.sec * 10**9 + poses.header.stamp.nanosec
    assert stamp == log_time and 0 < stamp < 3600 * 10**9  # simulated, not wall-clock, time
    _, odom = client.latest("/odom")
    assert odom.child_frame_id == "base_footprint" and math.isfinite(odom.pose.pose.position.x)
    # A cube per body but the car, on one topic or the other (the resting one latched: re-sent to
    # a new subscriber; the moving one goes out while something moves); the two of one round agree.
    def drawn(topic):
        frames = client.frames[topic]
        return len(client.decoder(topic)(frames[-1][1]).markers) - 1 if frames else 0
    assert client.wait(lambda: drawn(f"{NS}/bodies/markers") + drawn(f"{NS}/bodies/resting_markers") == 43)
    assert client.latest(f"{NS}/bodies/resting_markers")[1].markers[0].action == 3  # DELETEALL first
    _, scene = client.latest(f"{NS}/scene/markers")  # latched: re-sent to a new subscriber
    assert any(m.ns == "playground" and len(m.points) > 0 for m in scene.markers)
    _, tf = client.latest("/tf")
    assert {"odom", "base_link", "wheel_front_left"} <= {t.child_frame_id for t in tf.transforms}
    _, diagnostics = client.latest("/diagnostics")
    assert any(s.name == "foxglove" for s in diagnostics.status)
    # The time capability follows the simulation.
    assert client.wait(lambda: len(client.times) >= 2)
    assert 0 < client.times[-1] < 3600 * 10**9 and client.times[-1] >= client.times[0]


def test_every_clock_message_arrives_in_order_and_the_server_time_follows(client):
    # /clock (every step) is handed to the sdk in bursts before the next round of data, and the
    # server time goes out once a burst or a round, not once a step: nothing may be lost or
    # reordered, and the timeline must still follow the simulation.
    client.subscribe("/clock", f"{NS}/bodies/poses", "/tf")
    assert client.wait(lambda: len(client.frames["/clock"]) >= 130)
    clocks = list(client.frames["/clock"])
    stamps = [stamp for stamp, _ in clocks]
    decode = client.decoder("/clock")
    assert all(stamp == decode(payload).clock.sec * 10**9 + decode(payload).clock.nanosec for stamp, payload in clocks)
    steps = [(b - a) * 128 / 1e9 for a, b in zip(stamps, stamps[1:])]
    # A step each, or a few when a late batch ran several (one /clock a batch): never back, never repeated.
    assert all(step > 0.5 and abs(step - round(step)) < 1e-3 for step in steps) and steps.count(1) > len(steps) / 2
    times = [stamp for topic, stamp in list(client.arrivals) if topic == "time"]
    assert times == sorted(times)
    # Each a simulated time that went out: a /clock's or a round's (times come from the connection
    # on, /clock from the subscription on).
    sent = set(stamps) | {stamp for stamp, _ in client.frames[f"{NS}/bodies/poses"]}
    assert {t for t in times if stamps[0] <= t <= stamps[-1]} <= sent
    assert len(stamps) / 8 <= len(times) < len(stamps)  # at least one a burst, not one a step
    assert client.wait(lambda: client.times[-1] >= stamps[-1])  # and it catches up
    # Paused, each ~/step runs one step and sends one /clock: all 20 arrive, one step apart,
    # though fewer than a burst is held at a time and no round of data follows each.
    assert client.call(f"{NS}/pause", {"data": True}).success
    try:
        time.sleep(0.3)
        count = len(client.frames["/clock"])
        for _ in range(20):
            assert client.call(f"{NS}/step", {}).success
        assert client.wait(lambda: len(client.frames["/clock"]) >= count + 20)
        stepped = [stamp for stamp, _ in list(client.frames["/clock"])[count - 1:]]
        assert [round((b - a) * 128 / 1e9, 6) for a, b in zip(stepped, stepped[1:])] == [1.0] * 20
    finally:
        assert client.call(f"{NS}/pause", {"data": False}).success


def test_service_call_spawns_a_body_that_get_entities_then_lists(client):
    response = client.call(f"{NS}/spawn", {"load_namespace": "{name: socket_crate, size: [0.4, 0.4, 0.4], "
                                                             "position: [3, -6, 2]}"})
    assert response.success and response.message == "RESULT_OK: socket_crate"
    entities = client.call(f"{NS}/get_entities", {})
    assert "socket_crate" in [m.name for m in entities.markers]
    again = client.call(f"{NS}/spawn", {"load_namespace": "{name: socket_crate}"})
    assert not again.success and again.message.startswith("NAME_NOT_UNIQUE:")
    paused = client.call(f"{NS}/pause", {"data": True})
    assert paused.success
    assert client.call(f"{NS}/pause", {"data": False}).success
    missing = client.call(f"{NS}/load_scene", {"map_url": "/nonexistent/scene.yaml"})
    assert missing.result == 1  # MAP_DOES_NOT_EXIST, the old world stays
    assert "socket_crate" in [m.name for m in client.call(f"{NS}/get_entities", {}).markers]


def test_the_standard_services_are_offered_with_their_types(client):
    """simulation_interfaces over the Foxglove WebSocket too (a viewer's Call Service panel), with
    the same handlers: its definitions from the vendored package where it is not installed."""
    assert client.services["/spawn_entity"]["type"] == "simulation_interfaces/srv/SpawnEntity"
    features = client.call("/get_simulator_features", {}).features
    assert 0 in features.features and list(features.spawn_formats) == ["yaml", "urdf"]
    spawned = client.call("/spawn_entity", {"name": "si_crate", "resource_string": "{shape: box, size: [0.4, 0.4, 0.4]}",
                                            "initial_pose": {"pose": {"position": {"x": 3.0, "y": 6.0, "z": 2.0},
                                                                      "orientation": {"w": 1.0}}}})
    assert spawned.result.result == 1 and spawned.entity_name == "si_crate", spawned.result.error_message
    state = client.call("/get_entity_state", {"entity": "si_crate"})
    assert state.result.result == 1 and abs(state.state.pose.position.y - 6.0) < 0.1
    assert client.call("/get_entity_state", {"entity": "nobody"}).result.result == 2  # RESULT_NOT_FOUND
    assert "si_crate" in client.call("/get_entities", {}).entities
    assert client.call("/delete_entity", {"entity": "si_crate"}).result.result == 1
    # A call in JSON is refused by the server (the services' schemas are CDR), before any handler.
    service, call = client.services["/get_entities"], 4242
    client.ws.send(struct.pack("<BIII", 2, service["id"], call, 4) + b"json" + b"{}")
    assert client.wait(lambda: call in client.responses)
    assert client.responses.pop(call) == ("failure", "Unsupported encoding")


def test_malformed_service_request_fails_cleanly(client):
    service = client.services[f"{NS}/spawn"]
    call = 99999
    client.ws.send(struct.pack("<BIII", 2, service["id"], call, 3) + b"cdr" + b"\x00\x01\x00\x00\xff\xff")
    assert client.wait(lambda: call in client.responses)
    assert client.responses.pop(call)[0] == "failure"
    assert client.call(f"{NS}/get_simulator_features", {}).success  # still serving


def test_parameters_are_validated_like_the_ros_ones(client):
    before = client.get_parameters("publish_rate", "gravity", "scene")
    assert before["publish_rate"] == 30.0 and before["gravity"] == [0.0, 0.0, -9.81]
    for bad in ({"publish_rate": -5.0}, {"publish_rate": "fast"}, {"gravity": [0.0, 1.0]}, {"scene": "x.yaml"},
                {"no_such_parameter": 1}):
        client.set_parameters(bad)
    assert client.get_parameters("publish_rate", "gravity", "scene") == before  # nothing changed
    reasons = [s["message"] for s in client.statuses]
    assert any("publish_rate" in r and "outside" in r for r in reasons), reasons
    assert any("read-only" in r for r in reasons), reasons
    after = client.set_parameters({"click_spawn_height": 3.5})
    assert after == {"click_spawn_height": 3.5}
    assert client.get_parameters("click_spawn_height") == {"click_spawn_height": 3.5}


def test_parameter_updates_reach_the_clients_subscribed_to_them(server, client):
    """The Parameters panel follows a change without polling, whether another client made it or
    the simulator (a service changing the world's settings), once per change; a client that
    unsubscribed, or never subscribed, gets no update; none of it logs an error."""
    def updates(watcher, name):
        return [p["value"] for p in watcher.parameter_updates if p["name"] == name]
    other = FoxgloveClient(server[0])
    try:
        client.subscribe_parameter_updates("click_spawn_size", "freezing.enabled")
        other.subscribe_parameter_updates("freezing.enabled")
        for watcher in (client, other):  # a round trip: the server has taken the subscription
            watcher.get_parameters("click_spawn_size")
        other.set_parameters({"click_spawn_size": 0.75})
        assert client.wait(lambda: updates(client, "click_spawn_size") == [0.75]), client.parameter_updates
        client.unsubscribe_parameter_updates("click_spawn_size")
        client.get_parameters("click_spawn_size")
        other.set_parameters({"click_spawn_size": 0.5})
        assert client.call(f"{NS}/set_freezing", {"data": False}).success
        for watcher in (client, other):
            assert watcher.wait(lambda w=watcher: updates(w, "freezing.enabled") == [False]), watcher.parameter_updates
        assert client.call(f"{NS}/set_freezing", {"data": True}).success
        assert client.wait(lambda: updates(client, "freezing.enabled") == [False, True])
        assert updates(client, "click_spawn_size") == [0.75]  # unsubscribed before the second set
        assert updates(other, "click_spawn_size") == []
        port = other.ws.socket.getsockname()[1]
    finally:
        other.close()
    deadline = time.monotonic() + 10  # the server has seen the client leave: it says so
    while f"viewer 127.0.0.1:{port} left" not in "".join(server[1]) and time.monotonic() < deadline:
        time.sleep(0.05)
    log = "".join(server[1])
    assert f"viewer 127.0.0.1:{port} left" in log and "ERROR" not in log and "AttributeError" not in log, log


def twist_publisher(client, encoding):
    if encoding == "json":
        channel = client.advertise("/cmd_vel", "json", "geometry_msgs/msg/Twist")
        return lambda speed, yaw: client.publish(channel, json.dumps(
            {"linear": {"x": speed, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": yaw}}).encode())
    schema = "Vector3 linear\nVector3 angular\n" + "=" * 80 + "\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
    channel = client.advertise("/cmd_vel", "cdr", "geometry_msgs/msg/Twist", schema)
    encode = serialize_dynamic("geometry_msgs/msg/Twist", schema)["geometry_msgs/msg/Twist"]
    return lambda speed, yaw: client.publish(channel, encode(
        {"linear": {"x": speed, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": yaw}}))


def stamped_twist_publisher(client, topic):
    schema = ("std_msgs/Header header\nTwist twist\n" + "=" * 80 + "\nMSG: std_msgs/Header\n"
              "builtin_interfaces/Time stamp\nstring frame_id\n" + "=" * 80 + "\nMSG: builtin_interfaces/Time\n"
              "int32 sec\nuint32 nanosec\n" + "=" * 80 + "\nMSG: geometry_msgs/Twist\nVector3 linear\n"
              "Vector3 angular\n" + "=" * 80 + "\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n")
    channel = client.advertise(topic, "cdr", "geometry_msgs/msg/TwistStamped", schema)
    encode = serialize_dynamic("geometry_msgs/msg/TwistStamped", schema)["geometry_msgs/msg/TwistStamped"]
    return lambda speed: client.publish(channel, encode(
        {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
         "twist": {"linear": {"x": speed, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}}))


def test_a_stamped_twist_and_a_namespaced_robots_cmd_vel_drive_over_foxglove(client):
    """Issue 39: cmd_vel takes TwistStamped as well as Twist from a client, and a namespaced
    robot's cmd_vel is taken as it comes."""
    car = {"name": "rover", "position": [-20.0, 20.0, 1.2], "chassis": {"size": [2.0, 1.2, 0.4], "mass": 300},
           "wheels": [{"mount": [x, y, -0.2], "radius": 0.3, "power_gain": 0.5} for x in (0.8, -0.8) for y in (0.6, -0.6)]}
    response = client.call(f"{NS}/spawn", {"load_namespace": json.dumps(car)})
    assert response.success, response.message
    try:
        assert client.wait(lambda: f"{NS}/rover/command" in client.channels)  # advertised as it first goes out
        client.subscribe(f"{NS}/car/command", f"{NS}/rover/command")
        drive_car, drive_rover = stamped_twist_publisher(client, "/cmd_vel"), stamped_twist_publisher(client, "/rover/cmd_vel")
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            drive_car(1.25)
            drive_rover(-0.75)
            time.sleep(0.1)
        assert client.latest(f"{NS}/car/command")[1].twist.linear.x == 1.25
        assert client.latest(f"{NS}/rover/command")[1].twist.linear.x == -0.75
        drive_car(0.0)
    finally:
        client.call(f"{NS}/remove", {"load_namespace": "{entity: rover}"})


@pytest.mark.parametrize("encoding", ["cdr", "json"])
def test_twist_published_by_the_client_drives_the_car(client, encoding):
    client.subscribe(f"{NS}/car/command", "/odom")
    drive = twist_publisher(client, encoding)
    speed = 1.5 if encoding == "cdr" else -1.0
    end = time.monotonic() + 4.0
    while time.monotonic() < end:
        drive(speed, 0.0)
        time.sleep(0.1)
    _, command = client.latest(f"{NS}/car/command")
    assert command.twist.linear.x == speed
    _, odom = client.latest("/odom")
    assert odom.twist.twist.linear.x == pytest.approx(speed, abs=0.4)
    drive(0.0, 0.0)


def test_clicked_point_from_the_3d_panel_drops_a_box(client):
    before = {m.name for m in client.call(f"{NS}/get_entities", {}).markers}
    channel = client.advertise("/clicked_point", "json", "geometry_msgs/msg/PointStamped")
    client.publish(channel, json.dumps({"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "world"},
                                        "point": {"x": -4.0, "y": 6.0, "z": 0.0}}).encode())

    def dropped():
        return {m.name for m in client.call(f"{NS}/get_entities", {}).markers} - before
    deadline = time.monotonic() + 5
    while not dropped() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(dropped()) == 1
    # A topic the simulator does not take is refused with a status, not an exception; the
    # navigation goals of the 3D panel's pose tool are taken quietly (statuses come in order).
    client.advertise("/goal_pose", "cdr", "geometry_msgs/msg/PoseStamped")
    client.advertise("/move_base_simple/goal", "cdr", "geometry_msgs/PoseStamped")
    client.advertise("/not_a_simulator_topic", "json", "std_msgs/msg/String")
    assert client.wait(lambda: any("not_a_simulator_topic" in s["message"] for s in client.statuses))
    assert not any("goal" in s["message"] for s in client.statuses), client.statuses


ROSMSG_PARSER = r"""
const { parse } = require("@foxglove/rosmsg");
const schemas = JSON.parse(require("fs").readFileSync(process.argv[2], "utf8"));
const parsed = {};
for (const [name, text] of Object.entries(schemas)) {
  parsed[name] = parse(text, { ros2: true }).length;
}
console.log(JSON.stringify(parsed));
"""


@needs_node
def test_foxglove_parser_accepts_every_advertised_schema(client, tmp_path):
    schemas = {c["schemaName"]: c["schema"] for c in client.channels.values()}
    for service in client.services.values():
        for part in ("request", "response"):
            schemas[service[part]["schemaName"]] = service[part]["schema"]
    path = tmp_path / "schemas.json"
    path.write_text(json.dumps(schemas))
    parsed = json.loads(run_script("parse_schemas.js", ROSMSG_PARSER, path))
    assert set(parsed) == set(schemas) and all(count >= 1 for count in parsed.values())


def test_hostile_client_changes_nothing_and_the_server_keeps_serving(client):
    """Random bytes and malformed JSON on every input channel, garbage service payloads in
    both encodings, and parameter sets of every parameter with values of the wrong kind: no
    crash, no body added or removed, the simulation still running."""
    rng = random.Random(7)
    client.call(f"{NS}/pause", {"data": True})
    before = sorted(m.name for m in client.call(f"{NS}/get_entities", {}).markers)
    parameters = client.get_parameters()
    tried = 0
    for topic in ("/cmd_vel", "/clicked_point", "/initialpose", f"{NS}/push"):
        for encoding in ("cdr", "json"):
            channel = client.advertise(topic, encoding, "geometry_msgs/msg/Twist")
            for _ in range(25):
                junk = rng.choice([bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 64))),
                                   b"[" * 5000, b'{"linear": "fast"}', b"\x00\x01\x00\x00", b"null",
                                   json.dumps({"header": {"frame_id": "x" * 10000}}).encode()])
                client.publish(channel, junk)
                tried += 1
    for name, service in client.services.items():
        if name.endswith(("/pause", "/step", "/reset", "/wake_all", "/set_freezing", "/load_scene",
                          "/set_simulation_state", "/reset_simulation", "/step_simulation", "/load_world",
                          "/unload_world")):
            continue  # well-formed calls of these change state by design; their bad input is tested above
        for _ in range(10):
            encoding = rng.choice([b"cdr", b"json", b"protobuf"])
            junk = bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 48)))
            call = 10**6 + tried
            client.ws.send(struct.pack("<BIII", 2, service["id"], call, len(encoding)) + encoding + junk)
            assert client.wait(lambda: call in client.responses)
            client.responses.pop(call)
            tried += 1
    wrong = ["text", ["a", "b"], {"nested": {"deep": [1]}}, 1e308, -1, True, [0.0] * 100]
    for name, current in parameters.items():
        for value in wrong:
            if isinstance(value, bool) and isinstance(current, bool):
                continue  # a right kind for a switch (the others are wrong or out of range for all)
            client.set_parameters({name: value})
            tried += 1
    # A null value or a mixed array is refused by the protocol layer itself, with an error status.
    for value in (None, [1, "a"]):
        errors = sum(s["level"] == 2 for s in client.statuses)
        client.ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "gravity", "value": value}]}))
        assert client.wait(lambda: sum(s["level"] == 2 for s in client.statuses) > errors)
    assert tried > 400
    assert client.get_parameters() == parameters
    assert sorted(m.name for m in client.call(f"{NS}/get_entities", {}).markers) == before
    assert client.call(f"{NS}/pause", {"data": False}).success
    assert client.wait(lambda: client.times)  # /clock goes out as time advances: none while paused
    stamp = client.times[-1]
    assert client.wait(lambda: client.times[-1] > stamp)  # still stepping


def test_a_viewer_joining_a_paused_simulation_gets_the_world_and_its_time(server, client):
    """While paused nothing new goes out, so a viewer that connected then (a page reload, a
    second viewer) got the scenery and nothing on it, and no time (its timeline at 0)."""
    assert client.call(f"{NS}/pause", {"data": True}).success
    try:
        time.sleep(0.5)  # what was on its way is out
        late = FoxgloveClient(server[0])
        try:
            assert late.wait(lambda: len(late.channels) >= len(TOPICS))
            late.subscribe(f"{NS}/bodies/poses", f"{NS}/bodies/markers", f"{NS}/bodies/resting_markers", "/tf", "/odom")
            _, poses = late.latest(f"{NS}/bodies/poses")
            _, moving = late.latest(f"{NS}/bodies/markers")
            _, resting = late.latest(f"{NS}/bodies/resting_markers")
            assert len(poses.poses) > 40 and len(moving.markers) + len(resting.markers) == 2 + len(poses.poses) - 1
            assert late.latest("/tf") and late.latest("/odom")
            assert late.wait(lambda: len(late.times) >= 1) and late.times[-1] > 0
        finally:
            late.close()
    finally:
        assert client.call(f"{NS}/pause", {"data": False}).success


def test_a_subscription_to_a_latched_topic_resends_that_topic_alone(server, client):
    """Each subscription to a latched topic re-sent all three latched topics, to every client."""
    client.subscribe("/tf_static")
    client.latest("/tf_static")
    time.sleep(0.5)
    before = len(client.frames["/tf_static"])
    other = FoxgloveClient(server[0])
    try:
        assert other.wait(lambda: len(other.channels) >= len(TOPICS))
        other.subscribe(f"{NS}/state")
        other.latest(f"{NS}/state")
        time.sleep(0.5)
        assert len(client.frames["/tf_static"]) == before
    finally:
        other.close()


def test_what_a_client_does_wrong_is_not_an_error_in_the_log(caplog):
    """The sdk logs a dropped connection or a garbage frame as ERROR, a line each: anyone on the
    network could fill the log. Such lines are debug; the sdk's own failures stay errors."""
    import logging

    import vplayground_ros.foxglove_server  # noqa: F401 (installs the filters)
    with caplog.at_level(logging.WARNING):
        logging.getLogger("foxglove.websocket.connected_client").error("Invalid message from 127.0.0.1:1: Buffer too short")
        logging.getLogger("foxglove.websocket.server").error("Dropping client 127.0.0.1:2: handshake failed")
        logging.getLogger("foxglove.websocket.server").error("the listener failed")
    assert [record.getMessage() for record in caplog.records] == ["the listener failed"]


def ipv6_loopback():
    try:
        with socket.create_server(("::1", 0), family=socket.AF_INET6):
            return True
    except OSError:
        return False


@pytest.mark.skipif(not ipv6_loopback(), reason="no IPv6 loopback here")
def test_the_server_listens_on_an_ipv6_address():
    """--foxglove-host ::1 failed: 'Address family for hostname not supported'."""
    process, url, output = start_simulator("--foxglove-host", "::1")
    try:
        assert url and url.startswith("ws://[::1]:"), "".join(output)
        viewer = FoxgloveClient(url)
        try:
            assert viewer.wait(lambda: viewer.server_info is not None and len(viewer.channels) >= len(TOPICS))
        finally:
            viewer.close()
    finally:
        process.terminate()
        process.wait(30)


def test_a_urdf_robot_spawned_over_the_socket_takes_joint_commands_from_a_client(client):
    """A robot spawned from URDF text over the socket: its joint_states channel comes, and a
    client's JSON JointState on its joint_commands (name and position only) moves its joints."""
    text = (Path(__file__).parent.parent / "config" / "arm.urdf").read_text()  # the package's own three-joint arm
    response = client.call(f"{NS}/spawn", {"load_namespace": json.dumps({"name": "sock_arm", "urdf": text,
                                                                          "position": [-12.0, -12.0, 0.0]})})
    assert response.success, response.message
    try:
        assert client.wait(lambda: "/sock_arm/joint_states" in client.channels)
        client.subscribe("/sock_arm/joint_states")
        channel = client.advertise("/sock_arm/joint_commands", "json", "sensor_msgs/msg/JointState")
        target = [0.2, 0.4, 0.7]
        names = ["yaw", "shoulder", "elbow"]

        end, error = time.monotonic() + 30.0, math.inf
        while time.monotonic() < end and error > 2e-3:
            client.publish(channel, json.dumps({"name": names, "position": target}).encode())
            time.sleep(0.2)
            error = max(abs(a - b) for a, b in zip(client.latest("/sock_arm/joint_states")[1].position, target))
        assert error < 2e-3
    finally:
        assert client.call(f"{NS}/remove", {"load_namespace": "{entity: sock_arm}"}).success


def live_channels():
    """The foxglove-sdk channels alive in this process."""
    gc.collect()
    return sum(type(o) is foxglove.Channel for o in gc.get_objects())


def test_the_channels_of_entities_gone_are_unadvertised_and_freed():
    """Robots and sensors spawned and removed under new names (a run of days) left every channel
    they ever had advertised to the viewers and held in the process (the sdk keeps ~4 kB of each
    until it is dropped): a channel whose topic is withdrawn is closed, a viewer subscribed to it
    sees it go, and it is advertised again when its entity comes back. (In this process: the
    sdk's channels are counted.)"""
    options = parse_args(["--no-record"])
    runtime = Runtime(Simulation(load_world(options.scene)), options, logging.getLogger("test_foxglove"))
    server = FoxgloveServer(runtime, port=0)
    runtime.start()
    client = FoxgloveClient(server.url)

    def spawn(tag):
        return runtime.requests.spawn(yaml.safe_dump([
            {"name": f"{tag}_car", "urdf": "car.urdf", "position": [-12.0, 12.0, 1.0]},
            {"name": f"{tag}_scan", "type": "lidar_2d", "parent": f"{tag}_car", "pose": [0, 0, 1, 0, 0, 0], "samples": 8},
            {"name": f"{tag}_arm", "urdf": "arm.urdf", "position": [12.0, -12.0, 0.0]},
            {"name": f"{tag}_box", "size": [0.5, 0.5, 0.5], "position": [12.0, 12.0, 0.5]},
            {"name": f"{tag}_imu", "type": "imu", "parent": f"{tag}_box", "pose": [0, 0, 0, 0, 0, 0]}]))

    def channels_of(tag):
        return sorted(topic for topic in client.channels if f"/{tag}_" in topic)
    try:
        assert client.wait(lambda: len(client.channels) >= len(TOPICS))
        time.sleep(1.0)  # the default scene's sensors and robots are advertised on first use
        before = (dict(client.channels), len(server.channels), live_channels())
        for k in range(4):
            tag = f"fx{k}"
            ok, message = spawn(tag)[:2]
            assert ok, message
            assert client.wait(lambda: {f"/{tag}_car/odom", f"/{tag}_arm/joint_states", f"/{tag}_imu/data"}
                               <= set(channels_of(tag))), channels_of(tag)
            client.subscribe(*channels_of(tag))  # a viewer subscribed to them as they go
            client.latest(f"/{tag}_arm/joint_states")
            for name in ("car", "arm", "box"):
                ok, message = runtime.requests.remove(yaml.safe_dump({"entity": f"{tag}_{name}"}))[:2]
                assert ok, message
            assert client.wait(lambda: not channels_of(tag)), f"still advertised: {channels_of(tag)}"
        assert client.wait(lambda: client.channels == before[0]), set(client.channels) ^ set(before[0])
        assert (len(server.channels), live_channels()) == before[1:]
        # An entity that comes back gets its channels again, and a viewer its messages.
        assert spawn("fx0")[0]
        assert client.wait(lambda: "/fx0_arm/joint_states" in client.channels)
        client.subscribe("/fx0_arm/joint_states")
        assert client.latest("/fx0_arm/joint_states", count=len(client.frames["/fx0_arm/joint_states"]) + 1)
    finally:
        client.close()
        runtime.stop()
        server.stop()


def test_a_handshake_trickled_a_byte_at_a_time_ends_at_its_deadline():
    """The handshake's time is for the whole HTTP head: a peer sending a byte every 0.2 s (each
    read well within the timeout) had held its viewer's place for as long as it went on."""
    ours, theirs = socket.socketpair()
    stop = threading.Event()

    def trickle():
        while not stop.wait(0.2):
            try:
                theirs.send(b"G")
            except OSError:
                return
    threading.Thread(target=trickle, daemon=True).start()
    try:
        ours.settimeout(30.0)
        started = time.monotonic()
        with pytest.raises(HandshakeError, match="no whole HTTP head within 1 s"):
            read_head(ours, 1.0)
        assert time.monotonic() - started < 5.0  # (not a measure of speed: it ended, where it had not)
        assert ours.gettimeout() == 30.0
    finally:
        stop.set()
        ours.close()
        theirs.close()


def test_a_client_flooding_garbage_leaves_the_others_connected_and_the_log_short(server, client):
    """Each undecodable message had been a status to every client and a log line: 5,000 of them
    from one client filled a bystander's queue until the sdk dropped the bystander, and the
    log with 5,000 lines. Now a few of each kind in a while, then how many were held back."""
    url, output = server
    bystander = FoxgloveClient(url)
    try:
        assert bystander.wait(lambda: "/clock" in bystander.channels)
        bystander.subscribe("/clock")
        channel = client.advertise("/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
        logged_before = sum("undecodable message ignored" in line for line in output)
        for _ in range(3000):
            client.publish(channel, b"\x00\x01")
        count = len(bystander.frames["/clock"])
        assert bystander.wait(lambda: len(bystander.frames["/clock"]) > count + 10)  # still served
        assert bystander.connected
        garbage = [s for s in bystander.statuses if "undecodable message ignored" in s["message"]]
        assert 1 <= len(garbage) <= 5 * 2  # a window or two of the burst
        logged = sum("undecodable message ignored" in line for line in output) - logged_before
        assert 1 <= logged <= 5 * 2
    finally:
        bystander.close()
