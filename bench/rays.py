"""Rays per second of World.cast_rays (issue 18 target: >= 5 million rays/s on one core) in the
default scene plus a pile of 1,000 boxes: the default sensor set's rays from the car, and rays
from random points of the yard in every direction, 30 m long; then the CPU share of reading the
whole sensor set at its rates (scans and images at 10 Hz, the IMU at 100 Hz). CPU time of this
thread (the machine may be shared)."""
import argparse
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from vplayground_ros.resources import find_shared
from vplayground_ros.scene import load_world
from vplayground_ros.sensors import Sensors

sys.path.insert(0, str(Path(__file__).parent))
from scenes import pile  # noqa: E402


def default_world(boxes, settle_seconds):
    scene = yaml.safe_load(find_shared("config/default_scene.yaml").read_text())
    world = load_world(scene)  # its car carries the sensor set
    for size, position, quaternion, mass in pile(boxes):
        world.add_body({"size": size.tolist(), "position": (position + (-10.0, 8.0, 0.0)).tolist(),
                        "quaternion": quaternion.tolist(), "mass": mass})
    world.step(int(settle_seconds * world.settings["steps_per_second"]))
    return world


def sensor_rays(world):
    """The rays of the default scene's sensors from the car (every lidar beam and pixel)."""
    return Sensors().all_rays(world)


def sensor_cpu(world, seconds):
    """CPU seconds of reading the default sensor set (rays, noise, shading) per simulated second."""
    sensors = Sensors()
    sensors.follow(world)
    start_time, cpu = world.time, 0.0
    while world.time - start_time < seconds:
        world.step(sensors.steps_until_due(world))
        started = time.thread_time()
        sensors.sample(world)
        cpu += time.thread_time() - started
    return cpu / seconds


def random_rays(count, rng):
    origins = rng.uniform((-24.0, -24.0, 0.3), (24.0, 24.0, 3.0), (count, 3))
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1)[:, None], np.full(count, 30.0)


def rate(world, origins, directions, ranges, repeats):
    world.cast_rays(origins[:10], directions[:10], ranges[:10])  # compiled and warm
    start = time.thread_time()
    for _ in range(repeats):
        hits = world.cast_rays(origins, directions, ranges)
    seconds = (time.thread_time() - start) / repeats
    return len(origins) / seconds, seconds, float(np.mean(np.isfinite(hits.distance)))


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--settle", type=float, default=2.0, help="seconds simulated first")
    args = parser.parse_args()
    world = default_world(args.boxes, args.settle)
    print(f"{len(world.body_names())} bodies, {len(world.playground_triangles)} triangles; CPU time of this thread")
    batches = [("default sensor set", sensor_rays(world)),
               ("random rays, 30 m", random_rays(args.rays, np.random.default_rng(1)))]
    for label, (origins, directions, ranges) in batches:
        per_second, seconds, hit_fraction = rate(world, origins, directions, ranges, args.repeats)
        print(f"{label:20s} {len(origins):8d} rays  {seconds * 1e3:8.2f} ms a batch  "
              f"{per_second / 1e6:6.2f} M rays/s  ({hit_fraction:.0%} hit)")
    share = sensor_cpu(world, 2.0)
    print(f"default sensor set read at its rates: {share:.1%} of a core at real time")


if __name__ == "__main__":
    main()
