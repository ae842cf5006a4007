"""config/foxglove_layout.json against the keys Lichtblick 1.10.8 and Foxglove read (their panel
sources and docs) and against the simulator's own topic, service and diagnostics names: a
layout that imports without complaint can still show nothing, so the names are checked here."""
import json
from pathlib import Path
from unittest.mock import MagicMock

import pytest

from vplayground_ros import sensor_messages
from vplayground_ros.broadcast import TOPICS, resolve, robot_topics
from vplayground_ros.foxglove_server import NAVIGATION_GOALS
from vplayground_ros.inputs import SUBSCRIPTIONS
from vplayground_ros.services import service_table

LAYOUT = json.loads((Path(__file__).parent.parent / "config" / "foxglove_layout.json").read_text())
PANELS = LAYOUT["configById"]
SCENE = PANELS["3D!scene"]
SERVICE_PANELS = {key: config for key, config in PANELS.items() if key.startswith("CallService!")}
# The panel area of a 1920x1080 window: less Lichtblick's app bar (44 px) and a bag's playback
# bar (60 px), measured on the viewer's screenshots.
WINDOW = (1920, 1080 - 44 - 60)
# A Service Call panel at its smallest showing its button (Lichtblick 1.10.8, horizontal
# layout: title bar, the Request and Response boxes side by side, the button row), by eye.
SERVICE_PANEL_MIN = (150, 165)


def tiles(node, x, y, width, height):
    """{panel id: (width, height)} of every leaf of the mosaic tree, in pixels."""
    if isinstance(node, str):
        return {node: (width, height)}
    share = node.get("splitPercentage", 50) / 100
    if node["direction"] == "row":
        return {**tiles(node["first"], x, y, width * share, height),
                **tiles(node["second"], x + width * share, y, width * (1 - share), height)}
    return {**tiles(node["first"], x, y, width, height * share),
            **tiles(node["second"], x, y + height * share, width, height * (1 - share))}


TILES = tiles(LAYOUT["layout"], 0, 0, *WINDOW)


def test_every_panel_is_placed_and_titled_where_the_viewers_look():
    assert set(TILES) == set(PANELS)
    for key, config in PANELS.items():
        assert "title" not in config, key  # neither viewer reads it
        assert config["foxglovePanelTitle"], key


def test_the_3d_publish_tools_send_what_the_simulator_takes():
    publish = SCENE["publish"]
    takes = {resolve(s.name): s.type for s in SUBSCRIPTIONS}
    assert takes[publish["pointTopic"]] == "geometry_msgs/msg/PointStamped"
    assert takes[publish["poseEstimateTopic"]] == "geometry_msgs/msg/PoseWithCovarianceStamped"
    # The pose tool sends a PoseStamped goal: on the estimate's topic it would be a wrong type.
    assert publish["poseTopic"] != publish["poseEstimateTopic"]
    assert publish["poseTopic"] in NAVIGATION_GOALS


def test_no_frame_links_from_the_world_to_every_body():
    """/tf carries world -> each body: the 3D panel draws a line from a visible parent frame to
    each child, so world (and odom, the car's parent) are hidden; labels are off."""
    assert SCENE["transforms"]["frame:world"]["visible"] is False
    assert SCENE["transforms"]["frame:odom"]["visible"] is False
    assert SCENE["scene"]["transforms"]["showLabel"] is False
    assert SCENE["followTf"] == "world"


def test_service_buttons_call_the_simulators_services_and_fit_their_panels():
    services = {resolve(s.name) for s in service_table(MagicMock())}
    called = {(c["serviceName"], c["requestPayload"]) for c in SERVICE_PANELS.values()}
    assert {name for name, _ in called} == {f"/vplayground/{s}" for s in ("pause", "step", "reset", "spawn", "wake_all")}
    assert ("/vplayground/pause", '{"data": true}') in called and ("/vplayground/pause", '{"data": false}') in called
    for key, config in SERVICE_PANELS.items():
        assert config["serviceName"] in services, key
        assert isinstance(json.loads(config["requestPayload"]), dict), key
        assert config["buttonText"] and config["editingMode"] is False  # Foxglove: the button alone
        assert config["layout"] == "horizontal", key  # Lichtblick always shows Request and Response
        width, height = TILES[key]
        assert width >= SERVICE_PANEL_MIN[0] and height >= SERVICE_PANEL_MIN[1], (key, width, height)


@pytest.mark.parametrize("panel", ["DiagnosticSummary!diag", "DiagnosticStatusPanel!detail"])
def test_diagnostics_panels_read_the_simulators_diagnostics(panel):
    assert PANELS[panel]["topicToRender"] == "/diagnostics"
    assert "/diagnostics" in {resolve(t.name) for t in TOPICS}


def test_the_detail_panel_shows_the_simulation_figures():
    detail = PANELS["DiagnosticStatusPanel!detail"]
    assert (detail["selectedHardwareId"], detail["selectedName"]) == ("vplayground", "simulation")


def test_plots_read_published_topics():
    published = {resolve(t.name) for t in TOPICS} | set(default_robot_topics())
    paths = [p["value"] for p in PANELS["Plot!plot"]["paths"]]
    assert paths and all(path.split(".", 1)[0] in published for path in paths), paths


def default_robots_and_sensors():
    from vplayground_ros.parameters import FRAMES, Frames
    from vplayground_ros.resources import find_shared
    from vplayground_ros.robots import robot
    from vplayground_ros.scene import load_world
    world = load_world(find_shared("config/default_scene.yaml"))
    return {name: robot(world.vehicle(name), Frames(*FRAMES.values())) for name in world.vehicle_names()}, \
        world.sensor_specs


def default_sensor_topics():
    """{topic: type} of the default scene's sensors, as the node names them."""
    robots, sensors = default_robots_and_sensors()
    return {resolve(t.name): t.type for spec in sensors for t in sensor_messages.topics(spec, robots.get(spec["parent"]))}


def default_robot_topics():
    """{topic: type} of the default scene's robot, as the node names them."""
    robots, _ = default_robots_and_sensors()
    return {t.name: t.type for r in robots.values() for t in robot_topics(r).values()}


def test_the_3d_panel_shows_the_default_cars_scan_and_cloud():
    published = {**default_sensor_topics(), **default_robot_topics()}
    published.update({resolve(t.name): t.type for t in TOPICS})
    shown = {topic: published[topic] for topic, config in SCENE["topics"].items() if config["visible"]}
    assert "sensor_msgs/msg/LaserScan" in shown.values() and "sensor_msgs/msg/PointCloud2" in shown.values()


def test_image_panels_show_the_two_cameras_with_their_calibration():
    published = default_sensor_topics()
    images = [config["imageMode"] for key, config in PANELS.items() if key.startswith("Image!")]
    assert sorted(published[mode["imageTopic"]] for mode in images) == ["sensor_msgs/msg/Image"] * 2
    assert {mode["imageTopic"].rsplit("/", 1)[0] for mode in images} == \
        {t.rsplit("/", 1)[0] for t, kind in published.items() if kind == "sensor_msgs/msg/Image"}
    for mode in images:  # each image with the CameraInfo beside it
        assert published[mode["calibrationTopic"]] == "sensor_msgs/msg/CameraInfo"
        assert mode["calibrationTopic"].rsplit("/", 1)[0] == mode["imageTopic"].rsplit("/", 1)[0]
