"""Sensors against geometry with known answers: walls, boxes, the ground, a body at rest."""
import logging
import math
import re

import numpy as np
import pytest

from vplayground_ros.physics import World, specs
from vplayground_ros.interfaces import decoder
from vplayground_ros.scene import SceneError, load_world, world_to_scene
from vplayground_ros.sensor_messages import build
from vplayground_ros.sensors import Sensors, camera_intrinsics, lidar_2d_angles, validate_sensor

G = 9.81


def scene(*sensors, bodies=(), vehicles=(), **settings):
    return {"version": 1, "settings": settings, "bodies": list(bodies), "vehicles": list(vehicles),
            "sensors": list(sensors)}


def read_once(world, name=None):
    """Steps to the first sample and returns {sensor name: reading}."""
    sensors = Sensors()
    world.step(sensors.steps_until_due(world))
    readings = {s.name: r for s, r in sensors.sample(world)}
    return readings if name is None else readings[name]


WALL = {"name": "wall", "size": [0.2, 40.0, 4.0], "position": [5.1, 0.0, 2.0], "immovable": True}


def test_lidar_2d_reads_a_wall_at_its_distance_and_inf_past_its_range():
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
             "samples": 360, "range_max": 20.0}
    world = load_world(scene(lidar, bodies=[WALL]))
    ranges = read_once(world, "scan")["ranges"]
    angles = -math.pi + 2 * math.pi * np.arange(360) / 360
    facing = np.abs(angles) < math.atan2(20.0, 5.0) - 0.01  # beams that meet the wall's face
    expected = 5.0 / np.cos(angles[facing])
    on_wall = expected <= 20.0
    assert ranges[facing][on_wall] == pytest.approx(expected[on_wall], abs=1e-3)
    assert np.all(np.isposinf(ranges[facing][~on_wall]))  # the wall lies past range_max
    assert np.all(np.isposinf(ranges[np.abs(angles) > math.pi / 2]))  # nothing behind
    assert ranges.dtype == np.float32


def test_lidar_2d_sees_a_box_at_the_angles_and_ranges_trigonometry_gives():
    """A 1 m box centred 6 m away at 30 degrees: its near face's corners subtend known angles."""
    centre = 6.0 * np.array([math.cos(math.pi / 6), math.sin(math.pi / 6)])
    box = {"name": "b", "size": [1.0, 1.0, 2.0], "position": [*centre, 1.0], "rpy": [0, 0, math.pi / 6],
           "immovable": True}
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
             "samples": 720, "range_max": 20.0}
    world = load_world(scene(lidar, bodies=[box]))
    ranges = read_once(world, "scan")["ranges"]
    angles = -math.pi + 2 * math.pi * np.arange(720) / 720
    # The box faces the sensor squarely: its near face is 5.5 m away, 1 m wide.
    edge = math.atan2(0.5, 5.5)
    inside = np.abs(angles - math.pi / 6) < edge - 0.005
    outside = np.abs(angles - math.pi / 6) > edge + 0.005
    assert ranges[inside] == pytest.approx(5.5 / np.cos(angles[inside] - math.pi / 6), abs=1e-3)
    assert np.all(np.isposinf(ranges[outside]))


def test_lidar_2d_reads_minus_inf_nearer_than_range_min():
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [4.7, 0, 1, 0, 0, 0],
             "samples": 4, "range_min": 0.5, "range_max": 20.0}
    world = load_world(scene(lidar, bodies=[WALL]))
    ranges = read_once(world, "scan")["ranges"]
    assert ranges[2] == -math.inf  # the beam along +x meets the wall 0.3 m away
    assert np.isposinf(ranges[0])


def test_depth_camera_over_the_ground_reads_its_height_per_pixel():
    """Looking straight down from h, every pixel's depth along the optical axis is h; a tilted
    camera sees h / cos of each pixel's angle from the vertical."""
    h = 2.5
    down = {"name": "down", "type": "depth_camera", "parent": "world", "pose": [0, 0, h, 0, math.pi / 2, 0],
            "width": 32, "height": 24, "horizontal_fov": 1.2, "range_max": 50.0}
    tilted = {**down, "name": "tilted", "pose": [0, 0, h, 0, 0.9, 0]}
    world = load_world(scene(down, tilted))
    readings = read_once(world)
    depth = readings["down"]["depth"]
    assert depth.shape == (24, 32) and depth.dtype == np.float32
    assert depth == pytest.approx(np.full((24, 32), h), abs=1e-3)
    # A pixel row v (from the centre, down positive) looks along (1, -u/f, -v/f) in the sensor
    # frame, pitched down by p: it meets the ground when its z has dropped h, at depth (the
    # optical-axis component, 1) h / (sin p + cos p v / f), whatever its column.
    f, p = 0.5 * 32 / math.tan(0.6), 0.9
    v = np.arange(24) + 0.5 - 12.0
    expected = h / (math.sin(p) + math.cos(p) * v / f)
    assert readings["tilted"]["depth"] == pytest.approx(np.repeat(expected[:, None], 32, axis=1), abs=1e-3)


def test_depth_camera_reads_plus_inf_for_no_return_and_minus_inf_nearer_than_range_min():
    """REP 118 takes REP 117's special values: +inf nothing within range, -inf too close."""
    camera = {"name": "sky", "type": "depth_camera", "parent": "world", "pose": [0, 0, 1, 0, -1.2, 0],
              "width": 8, "height": 6, "horizontal_fov": 1.0}
    close = {**camera, "name": "close", "pose": [4.85, 0, 1, 0, 0, 0], "range_min": 0.5}
    readings = read_once(load_world(scene(camera, close, bodies=[WALL])))
    assert np.all(np.isposinf(readings["sky"]["depth"]))
    assert np.all(np.isneginf(readings["close"]["depth"]))  # the wall's face is 0.15 m ahead


def test_depth_camera_range_max_is_a_far_plane_along_its_axis():
    """A wall 20 m ahead fills the image of a camera reaching 25 m, corners too (their rays
    are longer than 25 m; their depth is 20)."""
    wall = {"name": "far", "size": [0.2, 200.0, 100.0], "position": [20.1, 0.0, 40.0], "immovable": True}
    camera = {"name": "cam", "type": "depth_camera", "parent": "world", "pose": [0, 0, 40, 0, 0, 0],
              "width": 16, "height": 12, "horizontal_fov": 2.0, "range_max": 25.0}
    depth = read_once(load_world(scene(camera, bodies=[wall])), "cam")["depth"]
    assert depth == pytest.approx(np.full((12, 16), 20.0), abs=1e-4)


def test_camera_info_unprojects_each_pixel_onto_what_it_saw():
    """image_geometry / depth_image_proc take pixel (u, v) at integer coordinates through
    ((u - cx) / fx, (v - cy) / fy, 1): every pixel of a tilted camera over flat ground comes
    back onto the ground, the rows next to the horizon too."""
    h, pitch = 1.0, 0.35
    spec = {"name": "cam", "type": "depth_camera", "parent": "world", "pose": [0, 0, h, 0, pitch, 0],
            "width": 160, "height": 120, "horizontal_fov": math.radians(90.0), "range_max": 500.0}
    depth = read_once(load_world(scene(spec)), "cam")["depth"].astype(float)
    fx, fy, cx, cy = camera_intrinsics(validate_sensor(spec, "cam", {}))
    v, u = np.meshgrid(np.arange(120), np.arange(160), indexing="ij")
    seen = np.isfinite(depth)
    assert seen.sum() > 5000
    optical = np.stack([(u - cx) / fx * depth, (v - cy) / fy * depth, depth], axis=-1)[seen]
    # Optical (x right, y down, z forward) -> sensor (x forward, y left, z up), pitched down.
    forward, down = optical[:, 2], optical[:, 1]
    height = h - forward * math.sin(pitch) - down * math.cos(pitch)
    assert np.all(np.abs(height) <= 1e-3 * np.maximum(forward, 1.0))  # float32 depths of up to 500 m


def test_camera_paints_what_it_sees_in_the_marker_colours():
    camera = {"name": "eye", "type": "camera", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
              "width": 40, "height": 30, "horizontal_fov": 1.0}
    box = {"name": "b", "size": [1.0, 6.0, 6.0], "position": [4.0, 0.0, 1.0], "immovable": True}
    world = load_world(scene(camera, bodies=[box]))
    rgb = read_once(world, "eye")["rgb"]
    assert rgb.shape == (30, 40, 3) and rgb.dtype == np.uint8
    # The box's face (normal -x, facing away from the light's x component) gets ambient plus
    # a little Lambert; the immovable colour (0.35, 0.35, 0.45) keeps its hue.
    centre = rgb[15, 20].astype(float)
    assert centre[2] > centre[0] == centre[1]
    camera2 = {**camera, "name": "sky", "pose": [0, 0, 1, 0, -1.3, 0]}
    sky = read_once(load_world(scene(camera2)), "sky")["rgb"]
    assert np.all(sky == sky[0, 0]) and sky[0, 0, 2] > sky[0, 0, 0]


def test_imu_at_rest_reads_gravity_up_and_no_rotation():
    box = {"name": "b", "size": [1.0, 1.0, 1.0], "position": [0.0, 0.0, 0.5]}
    imu = {"name": "imu", "type": "imu", "parent": "b", "rate": 50.0}
    world = load_world(scene(imu, bodies=[box]))
    sensors = Sensors()
    readings = []
    while world.time < 2.0:
        world.step(sensors.steps_until_due(world))
        readings += sensors.sample(world)
    last = readings[-1][1]
    assert last["linear_acceleration"] == pytest.approx([0.0, 0.0, G], abs=1e-3)
    assert last["angular_velocity"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)
    assert last["orientation"] == pytest.approx([0.0, 0.0, 0.0, 1.0], abs=1e-3)
    assert len(readings) == 100 and readings[0][1]["time"] == pytest.approx(0.02, abs=1 / 128)


def car(**overrides):
    wheel = {"radius": 0.35, "mass": 20, "spring_stiffness": 40000, "damper": 4000,
             "spring_length": 0.5, "static_friction": 1.0, "dynamic_friction": 0.8}
    mounts = [[1.3, 0.8, -0.3], [1.3, -0.8, -0.3], [-1.3, 0.8, -0.3], [-1.3, -0.8, -0.3]]
    return {"name": "car", "position": [0.0, 0.0, 1.0], "chassis": {"size": [4.0, 1.8, 0.6], "mass": 1200},
            "engine_power": 6000, "brake_power": 9000, "max_steer": 0.6,
            "wheels": [{**wheel, "mount": m, "steered": k < 2, "power_gain": 0.0 if k < 2 else 0.5}
                       for k, m in enumerate(mounts)], **overrides}


def test_imu_on_the_turning_car_reads_its_yaw_rate():
    imu = {"name": "imu", "type": "imu", "parent": "car", "pose": [0.5, 0, 0.3, 0, 0, 0], "rate": 20.0}
    world = load_world(scene(imu, vehicles=[car()]))
    sensors = Sensors()
    while world.time < 6.0:
        world.drive("car", 3.0, 0.5)
        world.step(sensors.steps_until_due(world))
        readings = sensors.sample(world)
    body = world.body("car")
    x, y, z, w = body["quaternion"]
    up = np.array([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])
    yaw_rate = float(np.dot(body["angular_velocity"], up))
    assert abs(yaw_rate) > 0.2  # it does turn
    assert readings[0][1]["angular_velocity"][2] == pytest.approx(yaw_rate, abs=1e-6)


def test_lidar_3d_points_lie_only_on_surfaces():
    boxes = [{"name": "a", "size": [1.0, 2.0, 1.5], "position": [4.0, 1.0, 0.75], "immovable": True},
             {"name": "b", "size": [2.0, 1.0, 3.0], "position": [-3.0, -4.0, 1.5], "rpy": [0, 0, 0.7],
              "immovable": True}]
    lidar = {"name": "velo", "type": "lidar_3d", "parent": "world", "pose": [0, 0, 1.2, 0, 0, 0.3],
             "horizontal_samples": 256, "channels": 16, "range_max": 30.0}
    world = load_world(scene(lidar, bodies=boxes))
    reading = read_once(world, "velo")
    yaw = 0.3
    r = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    points = reading["points"].astype(float) @ r.T + [0, 0, 1.2]
    assert len(points) > 1000
    distance = np.abs(points[:, 2])  # to the ground plane
    for b in boxes:
        c, s = math.cos(b.get("rpy", [0, 0, 0])[2]), math.sin(b.get("rpy", [0, 0, 0])[2])
        local = (points - b["position"]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        half = np.array(b["size"]) / 2
        outside = np.maximum(np.abs(local) - half, 0)
        inside = np.min(half - np.abs(local), axis=1)
        to_surface = np.where(np.all(outside == 0, axis=1), inside, np.linalg.norm(outside, axis=1))
        distance = np.minimum(distance, to_surface)
    assert np.max(distance) < 1e-4  # float32 points of up to 30 m
    assert set(np.unique(reading["ring"])) <= set(range(16))


def noisy_scene(seed, **settings):
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
             "noise_stddev": 0.02}
    imu = {"name": "imu", "type": "imu", "parent": "world", "gyro_noise": 0.01, "accel_noise": 0.05}
    return scene(lidar, imu, bodies=[WALL], seed=seed, **settings)


def test_noisy_runs_of_one_scene_are_bit_identical_and_seeds_differ():
    def run(seed):
        world = load_world(noisy_scene(seed))
        sensors = Sensors()
        out = []
        while world.time < 0.5:
            world.step(sensors.steps_until_due(world))
            out += [(s.name, r["time"], r.get("ranges", r.get("linear_acceleration")).tobytes())
                    for s, r in sensors.sample(world)]
        return out

    first, second = run(7), run(7)
    assert len(first) == 10 and first == second
    assert run(8) != first


@pytest.mark.parametrize("steps_per_second", [128, 100])
def test_samples_do_not_depend_on_how_the_steps_are_batched(steps_per_second):
    """The same scans, at the same times, whether the world steps one step at a time or in
    batches that end on the sensors' due steps (real time vs --real-time-factor 0), also at a
    step whose length binary fractions do not hold (1/100 s): the world's time had been summed
    batch by batch, and its rounding (and an IMU's on it) followed the batches."""
    falling = noisy_scene(3, steps_per_second=steps_per_second)
    falling["bodies"].append({"name": "falling", "size": [1, 1, 1], "position": [3.0, 0.0, 5.0]})
    falling["sensors"].append({"name": "falling_imu", "type": "imu", "parent": "falling", "accel_noise": 0.05})

    def run(batch):
        world = load_world(falling)
        sensors = Sensors()
        out = []
        while world.time < 1.0:
            world.step(min(batch, sensors.steps_until_due(world)))
            out += [(s.name, r["time"], r.get("ranges", r.get("linear_acceleration")).tobytes())
                    for s, r in sensors.sample(world)]
        return out

    assert run(1) == run(16) == run(1000)


def run_sensors(world, sensors, until, out):
    """Steps `world` to each sample until `until` s, appending (name, reading) to `out`."""
    while world.time < until - 1e-9:
        world.step(sensors.steps_until_due(world))
        out += [(s.name, r) for s, r in sensors.sample(world)]
    return out


@pytest.mark.parametrize("before, after", [(100, 400), (400, 100), (128, 1000), (1000, 128)])
def test_sensors_keep_their_rates_when_steps_per_second_changes(before, after):
    """Sample n is read at the first step at or after n / rate of simulated time, whatever the
    step rate was on the way there. Scheduled at step n x steps_per_second / rate, the steps
    taken at the old rate counted as if at the new one: after 1 s at 100 steps/s, 400 steps/s
    silenced every sensor for 0.75 s. No gap, no burst, whichever way the rate changes."""
    imu = {"name": "imu", "type": "imu", "parent": "world", "rate": 50.0}
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "samples": 8, "rate": 10.0}
    world = load_world(scene(imu, lidar, steps_per_second=before))
    sensors, readings = Sensors(), []
    run_sensors(world, sensors, 1.0, readings)
    world.update_settings({"steps_per_second": after})
    run_sensors(world, sensors, 3.0, readings)
    late = 1.0 / min(before, after) + 1e-9  # a sample is read at the first step at or after its time
    for name, rate in (("imu", 50.0), ("scan", 10.0)):
        times = np.array([r["time"] for n, r in readings if n == name])
        due = np.arange(1, len(times) + 1) / rate
        assert len(times) == pytest.approx(3.0 * rate, abs=1)
        assert np.all(times >= due - 1e-9) and np.all(times - due < late), (name, times)
        assert np.all(np.abs(np.diff(times) - 1.0 / rate) < late), (name, np.diff(times))


def test_a_sensor_spawned_after_the_step_rate_went_and_came_back_keeps_its_times():
    """The sensors' clock followed the step rate only while a sensor was there: 100 -> 50 -> 100
    steps/s with none, then an IMU spawned, read between the multiples of 1 / rate (a review)."""
    imu = {"name": "imu", "type": "imu", "parent": "world", "rate": 10.0}
    world = load_world(scene(imu, steps_per_second=100))
    sensors, readings = Sensors(), []
    run_sensors(world, sensors, 0.2, readings)
    spec, world.sensor_specs = world.sensor_specs[0], []  # removed: nothing follows the world now
    world.update_settings({"steps_per_second": 50})
    world.step(27)
    world.update_settings({"steps_per_second": 100})
    world.step(3)
    world.sensor_specs = [dict(spec)]  # spawned again
    readings.clear()
    run_sensors(world, sensors, 1.2, readings)
    assert world.time == pytest.approx(1.2)  # 0.2 + 27 / 50 + 3 / 100 = 0.77 s when it came back
    assert [r["time"] for _, r in readings] == pytest.approx([0.8, 0.9, 1.0, 1.1, 1.2])


def test_a_rate_above_steps_per_second_reads_once_a_step_and_says_so(caplog):
    """A stepped simulator has one state a step: a 1,000 Hz lidar in a 100 steps/s world is read
    every step. Its LaserScan's scan_time says the 0.01 s between the scans published (it said
    1 / rate), and the log warns when such a sensor starts and whenever steps_per_second drops
    under a sensor's rate (not while the step rate keeps up)."""
    fast = {"name": "fast", "type": "lidar_2d", "parent": "world", "samples": 8, "rate": 1000.0}
    slow = {"name": "slow", "type": "lidar_2d", "parent": "world", "samples": 8, "rate": 20.0}
    world = load_world(scene(fast, slow, steps_per_second=100))
    sensors, readings = Sensors(), []
    with caplog.at_level(logging.WARNING, logger="vplayground_ros.sensors"):
        run_sensors(world, sensors, 0.1, readings)
    assert [round(r["time"], 9) for n, r in readings if n == "fast"] == [round(0.01 * k, 9) for k in range(1, 11)]
    warnings = [record.getMessage() for record in caplog.records]
    assert len(warnings) == 1 and warnings[0].startswith("sensor fast: rate 1000 Hz is above steps_per_second "
                                                         "(100): it is read once a step, at 100 Hz"), warnings
    decode = decoder("sensor_msgs/msg/LaserScan")
    scans = {n: decode(build(world.sensor_specs[k], r, r["time"], n)[0][1])
             for n, r in readings[-2:] for k in [[s["name"] for s in world.sensor_specs].index(n)]}
    assert scans["fast"].scan_time == pytest.approx(0.01) and scans["slow"].scan_time == pytest.approx(0.05)
    assert scans["fast"].time_increment == 0.0  # every beam of a scan is cast at one instant
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="vplayground_ros.sensors"):
        world.update_settings({"steps_per_second": 2000})
        run_sensors(world, sensors, 0.2, readings)
        assert caplog.records == []
        world.update_settings({"steps_per_second": 500})
        run_sensors(world, sensors, 0.3, readings)
    assert [record.getMessage()[:60] for record in caplog.records] == [
        "sensor fast: rate 1000 Hz is above steps_per_second (500): i"]


def test_a_fast_sensors_warning_is_said_once_not_at_every_rebuild(caplog):
    """Every ~/reset rebuilds the sensors (another World of the scene; or the time gone back
    and the specs copied, a partial one): the warning that a rate is above steps_per_second came
    again with each, a line per sensor per episode for a harness that resets between them. It
    is said once per sensor and setting; a new rate or step rate is another setting."""
    fast = {"name": "fast", "type": "lidar_2d", "parent": "world", "samples": 8, "rate": 1000.0}
    world, sensors = load_world(scene(fast, steps_per_second=100)), Sensors()
    with caplog.at_level(logging.WARNING, logger="vplayground_ros.sensors"):
        for _ in range(3):
            run_sensors(world, sensors, 0.05, [])
            world.time, world.step_count = 0.0, 0
            world.sensor_specs = [dict(spec) for spec in world.sensor_specs]
            run_sensors(world, sensors, 0.05, [])
            world = load_world(scene(fast, steps_per_second=100))
        assert [record.getMessage()[:40] for record in caplog.records] == ["sensor fast: rate 1000 Hz is above steps"]
        world.sensor_specs = [{**world.sensor_specs[0], "rate": 500.0}]
        run_sensors(world, sensors, 0.1, [])
    assert [record.getMessage()[:40] for record in caplog.records][1:] == ["sensor fast: rate 500 Hz is above steps_"]


def test_sensors_are_saved_with_the_scene_and_go_with_a_removed_parent(caplog):
    imu = {"name": "imu", "type": "imu", "parent": "b"}
    world = load_world(scene(imu, bodies=[{"name": "b", "position": [0, 0, 0.5]}]))
    saved = world_to_scene(world)
    assert saved["sensors"][0]["name"] == "imu" and saved["sensors"][0]["rate"] == 10.0
    assert load_world(saved).sensor_specs == world.sensor_specs
    world.remove_body("b")
    sensors = Sensors()
    world.step(sensors.steps_until_due(world))
    assert sensors.sample(world) == []
    assert world.sensor_specs == [] and "parent b is gone" in caplog.text
    assert "sensors" not in world_to_scene(world)


def test_a_sensor_goes_with_its_parent_even_when_another_body_takes_its_name(caplog):
    """Removed and replaced by a body of the same name between two samples: the sensor was on
    the body that went, so it goes (it does not jump onto the newcomer)."""
    imu = {"name": "imu", "type": "imu", "parent": "b", "rate": 50}
    world = load_world(scene(imu, bodies=[{"name": "b", "position": [0, 0, 0.5]}]))
    sensors = Sensors()
    world.step(sensors.steps_until_due(world))
    assert [s.name for s, _ in sensors.sample(world)] == ["imu"]
    world.remove_body("b")
    world.add_body({"name": "b", "position": [5, 0, 3]})
    world.step(sensors.steps_until_due(world))
    assert sensors.sample(world) == [] and world.sensor_specs == [] and "parent b is gone" in caplog.text


@pytest.mark.parametrize("sensor, message", [
    ({"name": "s", "type": "sonar", "parent": "world"}, "sensors[0].type: unknown type 'sonar'"),
    ({"name": "s", "type": "imu", "parent": "nobody"}, "sensors[0].parent: no vehicle or body named 'nobody'"),
    ({"name": "s", "type": "imu"}, "sensors[0].parent: missing"),
    ({"name": "s", "type": "lidar_2d", "parent": "world", "samples": 0}, "sensors[0].samples: must be between 1"),
    ({"name": "s", "type": "lidar_2d", "parent": "world", "range_min": 5, "range_max": 2},
     "sensors[0].range_max: must be > range_min"),
    ({"name": "s", "type": "camera", "parent": "world", "channels": 4}, "sensors[0].channels: unknown key"),
    ({"name": "s", "type": "imu", "parent": "world", "rate": 0}, "sensors[0].rate: must be >= 0.001"),
    # Tiny positive values: a rate of 1e-320 Hz overflowed the schedule, a field of view of
    # 5e-324 rad divided by zero (both killed the node's simulation thread), 1e-310 gave K = inf.
    ({"name": "s", "type": "imu", "parent": "world", "rate": 1.0e-320}, "sensors[0].rate: must be >= 0.001"),
    ({"name": "s", "type": "imu", "parent": "world", "rate": 1.0e-300}, "sensors[0].rate: must be >= 0.001"),
    ({"name": "s", "type": "camera", "parent": "world", "horizontal_fov": 5.0e-324},
     "sensors[0].horizontal_fov: must be >= 0.001"),
    ({"name": "s", "type": "depth_camera", "parent": "world", "horizontal_fov": 1.0e-310},
     "sensors[0].horizontal_fov: must be >= 0.001"),
    # A reach of a nanometre saw nothing (1e-300 is 0 in LaserScan's float32: range_max = range_min).
    ({"name": "s", "type": "lidar_2d", "parent": "world", "range_min": 0, "range_max": 1.0e-9},
     "sensors[0].range_max: must be >= 0.001"),
    ({"name": "s", "type": "depth_camera", "parent": "world", "range_min": 0, "range_max": 1.0e-300},
     "sensors[0].range_max: must be >= 0.001"),
    # Degenerate scans: beams on one angle, rings on one elevation, an image taller than 170 deg.
    ({"name": "s", "type": "lidar_2d", "parent": "world", "angle_min": 0.5, "angle_max": 0.5, "samples": 10},
     "sensors[0].angle_max: must exceed angle_min (0.5) by at least 0.001 rad with 10 samples"),
    ({"name": "s", "type": "lidar_3d", "parent": "world", "vertical_min": 0.1, "vertical_max": 0.1, "channels": 4},
     "sensors[0].vertical_max: must exceed vertical_min (0.1) by at least 0.001 rad with 4 channels"),
    ({"name": "s", "type": "depth_camera", "parent": "world", "width": 1, "height": 20000},
     "sensors[0].height: 20000 rows at width 1 give a vertical field of view of 179.99 deg (square pixels), "
     "more than 170 (at most 11 rows"),
    ({"name": "s", "type": "lidar_2d", "parent": "world", "angle_max": 3.2},
     "sensors[0].angle_max: must be within [-pi, pi]"),
    ({"name": "b", "type": "imu", "parent": "world"}, "sensors[0].name: duplicate name 'b'"),
    ({"name": "s", "type": "imu", "parent": [1]}, "sensors[0].parent: expected a string, got list"),
    ({"name": "s", "type": "imu", "parent": {"a": 1}}, "sensors[0].parent: expected a string, got dict"),
    ({"name": "s", "type": "depth_camera", "parent": "world", "pose": [0, 0, 1]},
     "sensors[0].pose: expected 6 numbers"),
])
def test_bad_sensor_specs_are_refused_naming_the_key(sensor, message):
    with pytest.raises(SceneError, match=re.escape(f"<scene>: {message}")):
        load_world(scene(sensor, bodies=[{"name": "b"}]))


def test_seed_is_validated():
    with pytest.raises(SceneError, match=r"settings\.seed: must be between 0"):
        load_world(scene(seed=-1))
    assert World({"seed": 5}).settings["seed"] == 5


UNNAMED_CAR = {k: v for k, v in car().items() if k != "name"}


@pytest.mark.parametrize("sensor, bodies, vehicles, message", [
    ("box_1", [{}], [], "sensors[0].name: duplicate name 'box_1': already the name generated for bodies[0]"),
    ("box_1", [{"name": "box_1"}], [], "sensors[0].name: duplicate name 'box_1': already bodies[0]'s name"),
    ("car_1", [], [UNNAMED_CAR], "sensors[0].name: duplicate name 'car_1': already the name generated for vehicles[0]"),
    ("car", [], [car()], "sensors[0].name: duplicate name 'car': already vehicles[0]'s name"),
])
def test_a_sensor_may_not_take_a_body_or_vehicle_name_given_or_generated(sensor, bodies, vehicles, message):
    """Sensor names are frames, as bodies' names are: two frames of one name would be ambiguous."""
    imu = {"name": sensor, "type": "imu", "parent": "world"}
    with pytest.raises(SceneError, match=re.escape(f"<scene>: {message}")):
        load_world(scene(imu, bodies=bodies, vehicles=vehicles))


def test_a_sensor_may_ride_a_body_by_its_generated_name():
    world = load_world(scene({"name": "imu", "type": "imu", "parent": "box_1"}, bodies=[{}]))
    assert world.sensor_specs[0]["parent"] == "box_1" and world.body_names() == ["box_1"]


@pytest.mark.parametrize("rate", [64.0, 100.0, 30.0, 1000.0])
def test_imu_in_free_fall_reads_no_specific_force_at_any_rate(rate):
    """Samples fall on whole steps (at 100 Hz one or two steps apart at 128 steps/s, at 1,000 Hz
    every step): the acceleration is over the time between them, from the first sample on."""
    box = {"name": "b", "size": [1.0, 1.0, 1.0], "position": [0.0, 0.0, 50.0]}
    imu = {"name": "imu", "type": "imu", "parent": "b", "rate": rate}
    world = load_world(scene(imu, bodies=[box]))
    sensors = Sensors()
    readings = []
    while world.time < 0.5:
        world.step(sensors.steps_until_due(world))
        readings += [r["linear_acceleration"] for _, r in sensors.sample(world)]
    assert len(readings) >= 10
    assert np.array(readings) == pytest.approx(np.zeros((len(readings), 3)), abs=1e-6)


def test_imu_on_a_spinning_body_reads_its_centripetal_acceleration():
    """A body spinning at w about z, no gravity, an IMU r from the axis: -w^2 r towards the
    axis (in the sensor's frame, which turns with the body), w about z, at 100 Hz."""
    w, r = 2.0, 1.0
    box = {"name": "b", "size": [0.5, 0.5, 0.5], "position": [0.0, 0.0, 5.0], "angular_velocity": [0, 0, w]}
    imu = {"name": "imu", "type": "imu", "parent": "b", "pose": [r, 0, 0, 0, 0, 0], "rate": 100.0}
    world = load_world(scene(imu, bodies=[box], gravity=[0.0, 0.0, 0.0]))
    sensors = Sensors()
    readings = []
    while world.time < 1.0:
        world.step(sensors.steps_until_due(world))
        readings += [r for _, r in sensors.sample(world)]
    # The mean acceleration over a sample's interval T is the chord's: (2 sin(wT/2) / T) w r,
    # pointing to the axis from the interval's middle, so w^2 r within (wT)^2 / 24 and a
    # sideways part of wT / 2 turned away: the x reading is within 0.05 % of -w^2 r.
    for reading in readings[1:]:
        assert reading["linear_acceleration"][0] == pytest.approx(-w * w * r, rel=2e-3)
        assert reading["angular_velocity"] == pytest.approx([0.0, 0.0, w], abs=1e-9)


def test_a_full_turn_scan_given_as_plus_minus_pi_to_eight_places_does_not_repeat_a_beam():
    """The default scene writes +-3.14159265: 360 beams one degree apart, not 1.0028."""
    spec = {"type": "lidar_2d", "angle_min": -3.14159265, "angle_max": 3.14159265, "samples": 360}
    angles = lidar_2d_angles(spec)
    assert np.diff(angles) == pytest.approx(np.full(359, math.radians(1.0)), abs=1e-10)


def test_degenerate_scans_of_one_beam_ring_or_row_are_still_accepted():
    """One beam, one ring, a one-row camera, a camera at the vertical cap: nothing repeats."""
    beam = validate_sensor({"name": "s", "type": "lidar_2d", "parent": "world", "angle_min": 0.3,
                            "angle_max": 0.3, "samples": 1}, "s", {})
    assert lidar_2d_angles(beam) == pytest.approx([0.3])
    ring = {"name": "s", "type": "lidar_3d", "parent": "world", "vertical_min": 0.0, "vertical_max": 0.0, "channels": 1}
    assert validate_sensor(ring, "s", {})["channels"] == 1
    line = {"name": "s", "type": "camera", "parent": "world", "width": 20000, "height": 1}
    assert validate_sensor(line, "s", {})["height"] == 1
    # tan(85 deg) / tan(45 deg) = 11.43: 11 rows a column at 90 deg across, not 12.
    tall = {"name": "s", "type": "camera", "parent": "world", "width": 1, "height": 11}
    assert validate_sensor(tall, "s", {})["height"] == 11
    with pytest.raises(specs.SpecError, match=re.escape("s.height: 12 rows at width 1 give a vertical field of view of 170.47")):
        validate_sensor({**tall, "height": 12}, "s", {})


@pytest.mark.parametrize("low, high", [(-3.14159, 3.14159), (-3.1416, 3.1416), (-3.1415, 3.14163)])
def test_plus_minus_pi_to_four_places_is_a_full_turn(low, high):
    """+-pi written with fewer decimals (within 1e-4) is +-pi: 360 beams one degree apart
    (+-3.14159 was a partial scan whose last beam nearly repeated its first; 3.1416 was
    refused as more than pi)."""
    spec = validate_sensor({"name": "s", "type": "lidar_2d", "parent": "world", "angle_min": low,
                            "angle_max": high, "samples": 360}, "s", {})
    assert (spec["angle_min"], spec["angle_max"]) == (-math.pi, math.pi)
    assert np.diff(lidar_2d_angles(spec)) == pytest.approx(np.full(359, math.radians(1.0)), abs=1e-10)
    half = validate_sensor({"name": "s", "type": "lidar_2d", "parent": "world", "angle_min": 0.0,
                            "angle_max": high, "samples": 181}, "s", {})
    assert half["angle_max"] == math.pi and lidar_2d_angles(half)[-1] == math.pi


def test_noisy_returns_stay_within_the_ranges():
    """Noise added to a return near range_max or range_min would put it outside the range
    LaserScan and the cloud claim: such returns are +inf / -inf (dropped from the cloud)."""
    wall = {**WALL, "position": [29.95, 0.0, 2.0]}
    scan = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
            "samples": 200, "angle_min": -0.05, "angle_max": 0.05, "range_max": 30.0, "noise_stddev": 0.2}
    cloud = {"name": "cloud", "type": "lidar_3d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
             "horizontal_samples": 4096, "channels": 2, "vertical_min": -0.01, "vertical_max": 0.01,
             "range_max": 30.0, "noise_stddev": 0.2}
    readings = read_once(load_world(scene(scan, cloud, bodies=[wall])))
    ranges = readings["scan"]["ranges"]
    finite = ranges[np.isfinite(ranges)]
    assert 20 < len(finite) < 200 and np.all(finite <= 30.0) and np.sum(np.isposinf(ranges)) > 20
    assert np.all(np.linalg.norm(readings["cloud"]["points"], axis=1) <= 30.0 + 1e-4)


def test_the_colour_camera_does_not_draw_what_is_nearer_than_range_min():
    """range_min is its near clipping plane: a box 1 m ahead vanishes at range_min 3, and the
    image is the one without the box."""
    box = {"name": "near", "size": [0.5, 4.0, 4.0], "position": [1.25, 0.0, 1.0], "immovable": True}
    camera = {"name": "cam", "type": "camera", "parent": "world", "pose": [0, 0, 1, 0, 0.2, 0],
              "width": 32, "height": 24, "range_min": 3.0}
    clipped = read_once(load_world(scene(camera, bodies=[box])), "cam")["rgb"]
    empty = read_once(load_world(scene(camera)), "cam")["rgb"]
    seen = read_once(load_world(scene({**camera, "range_min": 0.1}, bodies=[box])), "cam")["rgb"]
    assert np.array_equal(clipped, empty) and not np.array_equal(seen, empty)


def test_a_new_sensor_leaves_the_others_running():
    """Spawning a sensor changes the world's sensor list; the sensors already there keep their
    noise streams and IMU histories (the next scan is not the first one again; a falling IMU
    does not read a fresh start's +9.81)."""
    falling = {"name": "b", "size": [1.0, 1.0, 1.0], "position": [0.0, 0.0, 50.0]}
    lidar = {"name": "scan", "type": "lidar_2d", "parent": "world", "pose": [0, 0, 1, 0, 0, 0],
             "noise_stddev": 0.05}
    imu = {"name": "imu", "type": "imu", "parent": "b", "rate": 10.0}
    world = load_world(scene(lidar, imu, bodies=[WALL, falling]))
    sensors = Sensors()
    world.step(sensors.steps_until_due(world))
    first = {s.name: r for s, r in sensors.sample(world)}
    world.sensor_specs = [*world.sensor_specs, {**world.sensor_specs[1], "name": "imu_2"}]
    world.step(sensors.steps_until_due(world))
    second = {s.name: r for s, r in sensors.sample(world)}
    assert not np.array_equal(second["scan"]["ranges"], first["scan"]["ranges"])
    assert second["imu"]["linear_acceleration"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


CAMERA = {"name": "cam", "type": "camera", "parent": "world"}


@pytest.mark.parametrize("sensors, bodies, message", [
    ([{"name": "odom", "type": "imu", "parent": "world"}], [], "sensors[0].name: 'odom' is the odom_frame"),
    ([{"name": "wheel_front_left", "type": "imu", "parent": "world"}], [],
     "sensors[0].name: 'wheel_front_left' is a wheel link of the robot in the root namespace"),
    ([], [{"name": "base_link"}], "bodies[0].name: 'base_link' is the base_frame (the robot in the root namespace)"),
    ([CAMERA], [{"name": "cam_optical"}], "bodies[0].name: 'cam_optical' is the optical frame of cam"),
    ([CAMERA, {"name": "cam_optical", "type": "imu", "parent": "world"}], [],
     "sensors[1].name: 'cam_optical' is the optical frame of cam"),
])
def test_a_scene_may_not_name_an_entity_like_a_frame_of_the_node(sensors, bodies, message):
    """As ~/spawn refuses them: such a name gives /tf a frame with two parents, or a loop."""
    with pytest.raises(SceneError, match=re.escape(f"<scene>: {message}")):
        load_world(scene(*sensors, bodies=bodies))
