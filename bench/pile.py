"""Quick benchmark: a pile of boxes (default 1,000; 0.5 m, 500 kg/m^3, jittered grid, fixed
seed) falling for a few simulated seconds at 128 steps/s. Prints compile time, steps/s and the
real-time factor of the falling phase, of the last second (settled) and of the whole run, in
this thread's CPU time (which other processes on a shared machine do not inflate) and in wall time.

    python bench/pile.py [--boxes 1000] [--seconds 10]
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from scenes import pile  # noqa: E402
from vplayground_ros.physics import World  # noqa: E402


def world_of(boxes, capacity=64):
    world = World(capacity=max(capacity, len(boxes)))
    for size, position, quaternion, mass in boxes:
        world.add_body({"size": size.tolist(), "position": position.tolist(),
                        "quaternion": quaternion.tolist(), "mass": mass})
    return world


def build_pile(count, seed=1):
    return world_of(pile(count, seed))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()

    started = time.perf_counter()
    World().step(1)  # compile (or load from the cache) before timing
    compile_s = time.perf_counter() - started

    world = build_pile(args.boxes)
    rate = world.settings["steps_per_second"]
    steps = int(args.seconds * rate)
    clocks = {"cpu": np.empty(steps), "wall": np.empty(steps)}
    for k in range(steps):
        wall0, cpu0 = time.perf_counter(), time.thread_time_ns()
        world.step(1)
        clocks["cpu"][k] = (time.thread_time_ns() - cpu0) * 1e-6
        clocks["wall"][k] = (time.perf_counter() - wall0) * 1e3
    frozen = int(world.state()["frozen"].sum())
    print(f"compile/load {compile_s:.1f} s | {args.boxes} boxes, {args.seconds:g} s at {rate} steps/s")
    for clock, step_ms in clocks.items():
        falling, resting = step_ms[: 2 * rate], step_ms[-rate:]
        total_s = step_ms.sum() / 1e3
        print(f"{clock:>4}: falling (first 2 s) median {np.median(falling):.2f} ms/step, p95 "
              f"{np.percentile(falling, 95):.2f}, max {falling.max():.1f} ms, RTF "
              f"{len(falling) / rate / (falling.sum() / 1e3):.2f} | last second median "
              f"{np.median(resting):.3f} ms/step, max {resting.max():.2f} | whole run "
              f"{steps / total_s:.0f} steps/s, RTF {args.seconds / total_s:.2f}")
    print(f"{frozen}/{args.boxes} frozen at the end, "
          f"{world.stats['points'] / steps:.0f} contact points and {world.stats['pairs'] / steps:.0f} "
          "pairs per step on average")


if __name__ == "__main__":
    main()
