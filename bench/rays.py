"""Rays per second of World.cast_rays (issue 18 target: >= 5 million rays/s on one core) and the
CPU share of reading the default car's sensor set at its rates (scans and images at 10 Hz, the
IMU at 100 Hz; target: < 15 % of one core at real time), in two scenes: the default scene plus a settled pile of 1,000 boxes, and the same boxes
as a loose pile tumbling down through the air (spread out and higher, read while they fall).
Batches: the default sensor set's rays from the car, and rays from random points of the yard in
every direction, 30 m long.

Figures are CPU time of the whole process (the ray kernel's threads included), with one Numba
thread (one core) and with two; with two, the wall time a batch takes too. Median and worst over
the repeats. The machine may be shared: its load average is printed."""
import argparse
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np
import yaml

from vplayground_ros.resources import find_shared
from vplayground_ros.scene import load_world
from vplayground_ros.sensors import Sensors

sys.path.insert(0, str(Path(__file__).parent))
from scenes import pile  # noqa: E402


PILE_AT = np.array((-10.0, 8.0, 0.0))  # beside the car, in the view of its lidars and cameras


def default_world(boxes, settle_seconds, spread=1.0, lift=0.0):
    """The default scene with the sensor set and a pile of boxes (its spacing times `spread`,
    raised by `lift` m), stepped settle_seconds."""
    scene = yaml.safe_load(find_shared("config/default_scene.yaml").read_text())
    world = load_world(scene)  # its car carries the sensor set
    for size, position, quaternion, mass in pile(boxes):
        at = PILE_AT + position * (spread, spread, spread) + (0.0, 0.0, lift)
        world.add_body({"size": size.tolist(), "position": at.tolist(), "quaternion": quaternion.tolist(),
                        "mass": mass})
    world.step(int(settle_seconds * world.settings["steps_per_second"]))
    return world


def random_rays(count, rng):
    origins = rng.uniform((-24.0, -24.0, 0.3), (24.0, 24.0, 3.0), (count, 3))
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1)[:, None], np.full(count, 30.0)


def batch_times(world, origins, directions, ranges, repeats):
    """(CPU seconds, wall seconds) of each of `repeats` casts of the batch, and its hit fraction."""
    world.cast_rays(origins[:10], directions[:10], ranges[:10])  # compiled and warm
    cpu, wall = [], []
    for _ in range(repeats):
        started_cpu, started_wall = time.process_time(), time.perf_counter()
        hits = world.cast_rays(origins, directions, ranges)
        cpu.append(time.process_time() - started_cpu)
        wall.append(time.perf_counter() - started_wall)
    return np.array(cpu), np.array(wall), float(np.mean(np.isfinite(hits.distance)))


def sensor_cpu(world, seconds):
    """CPU seconds of each sampling instant of the default sensor set (the grid, rays, noise,
    shading) over `seconds` of simulated time, stepping the world between them."""
    sensors = Sensors()
    sensors.follow(world)
    start_time, per_instant = world.time, []
    while world.time - start_time < seconds:
        world.step(sensors.steps_until_due(world))
        started = time.process_time()
        sensors.sample(world)
        per_instant.append(time.process_time() - started)
    return np.array(per_instant)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--settle", type=float, default=2.0,
                        help="seconds the settled pile is simulated first")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated seconds of sensor readings")
    args = parser.parse_args()
    scenes = [("settled pile", dict(settle_seconds=args.settle)),
              ("tumbling pile", dict(settle_seconds=0.3, spread=2.5, lift=4.0))]
    threads = [1, 2] if numba.config.NUMBA_NUM_THREADS >= 2 else [1]
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; CPU time of the process, "
          "median / worst of the repeats")
    for scene_name, scene in scenes:
        world = default_world(args.boxes, **scene)
        print(f"\n{scene_name}: {len(world.body_names())} bodies, {len(world.playground_triangles)} triangles")
        batches = [("default sensor set", Sensors().all_rays(world)),
                   ("random rays, 30 m", random_rays(args.rays, np.random.default_rng(1)))]
        for count in threads:
            numba.set_num_threads(count)
            for label, (origins, directions, ranges) in batches:
                cpu, wall, hit_fraction = batch_times(world, origins, directions, ranges, args.repeats)
                line = (f"  {count} thread{'s' if count > 1 else ' '} {label:19s} {len(origins):7d} rays "
                        f"({hit_fraction:.0%} hit): {len(origins) / np.median(cpu) / 1e6:5.2f} / "
                        f"{len(origins) / cpu.max() / 1e6:5.2f} M rays/s of CPU")
                if count > 1:
                    line += (f", {len(origins) / np.median(wall) / 1e6:5.2f} / "
                             f"{len(origins) / wall.max() / 1e6:5.2f} M rays/s of wall time")
                print(line)
        for count in threads:
            numba.set_num_threads(count)
            per_instant = sensor_cpu(world, args.seconds)
            share = per_instant.sum() / args.seconds
            print(f"  {count} thread{'s' if count > 1 else ' '} default sensor set at its rates: "
                  f"{share:.1%} of a core ({np.median(per_instant) * 1e3:.1f} / "
                  f"{per_instant.max() * 1e3:.1f} ms CPU an instant, {len(per_instant)} instants)")
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


if __name__ == "__main__":
    main()
