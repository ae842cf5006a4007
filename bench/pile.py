"""Quick benchmark of the step on a pile of boxes falling at 128 steps/s, in this thread's CPU
time (which other processes on a shared machine do not inflate) and in wall time.

Scenes: `loose` (issue 20's: 0.5 m boxes, 500 kg/m^3, friction 0.6/0.4, elasticity 0.2, dropped
from a spread 10-layer grid with random yaw and small tilts) and `dense` (a jittered 0.8 m grid).
Prints the falling phase (first 2 s) median / p95 / max, the last second, the whole run, where a
falling step's time goes (the stage timers, from a second identical run), and the step of
`--asleep` boxes standing in columns of two, every one of them frozen.

    python bench/pile.py [--scene loose|dense] [--boxes 1000] [--seconds 10] [--asleep 5000]
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from scenes import loose_pile, pile, resting_columns  # noqa: E402
from vplayground_ros.physics import World  # noqa: E402

SCENES = {"loose": loose_pile, "dense": pile}
FALLING_SECONDS = 2


def world_of(boxes, capacity=64):
    world = World(capacity=max(capacity, len(boxes)))
    for size, position, quaternion, mass in boxes:
        world.add_body({"size": size.tolist(), "position": position.tolist(),
                        "quaternion": quaternion.tolist(), "mass": mass})
    return world


def build_pile(count, seed=1, scene="dense"):
    return world_of(SCENES[scene](count, seed))


def timed_steps(world, steps):
    """(thread CPU ms, wall ms) of each of `steps` single steps."""
    cpu, wall = np.empty(steps), np.empty(steps)
    for k in range(steps):
        wall0, cpu0 = time.perf_counter(), time.thread_time_ns()
        world.step(1)
        cpu[k] = (time.thread_time_ns() - cpu0) * 1e-6
        wall[k] = (time.perf_counter() - wall0) * 1e3
    return cpu, wall


def stage_split(scene, count, rate):
    """ms per step of each stage over the falling phase, from the stage timers."""
    world = build_pile(count, scene=scene)
    world.profiling = True
    steps = FALLING_SECONDS * rate
    world.step(steps)
    return {stage: 1e3 * s / steps for stage, s in world.stage_seconds().items()}


def asleep_step(count, steps=2000):
    """Thread CPU ms of a step with `count` boxes standing in columns of two, all frozen: a
    World.step(1) call's median and max (what a caller pays: such calls step in Python,
    World.resting_shortcut), the compiled step alone (one call of `steps` steps, the shortcut
    off), and how many were frozen."""
    world = world_of(resting_columns(count // 2))
    rate = world.settings["steps_per_second"]
    for _ in range(10):  # the columns stand still and freeze after freezing.time
        world.step(rate)
        if world.state()["frozen"].all():
            break
    cpu, _ = timed_steps(world, steps)
    world.resting_shortcut = False  # time the compiled step, not the Python one of a world at rest
    started = time.thread_time_ns()
    world.step(steps)
    batched = (time.thread_time_ns() - started) * 1e-6 / steps
    world.resting_shortcut = True
    return np.median(cpu), cpu.max(), batched, int(world.state()["frozen"].sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=sorted(SCENES), default="loose")
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--asleep", type=int, default=5000, help="boxes of the resting step (0: skip)")
    args = parser.parse_args()

    started = time.perf_counter()
    World().step(1)  # compile (or load from the cache) before timing
    compile_s = time.perf_counter() - started

    world = build_pile(args.boxes, scene=args.scene)
    rate = world.settings["steps_per_second"]
    steps = int(args.seconds * rate)
    clocks = dict(zip(("cpu", "wall"), timed_steps(world, steps)))
    frozen = int(world.state()["frozen"].sum())
    print(f"compile/load {compile_s:.1f} s | {args.scene} pile of {args.boxes} boxes, "
          f"{args.seconds:g} s at {rate} steps/s")
    for clock, step_ms in clocks.items():
        falling, resting = step_ms[: FALLING_SECONDS * rate], step_ms[-rate:]
        total_s = step_ms.sum() / 1e3
        print(f"{clock:>4}: falling (first {FALLING_SECONDS} s) median {np.median(falling):.2f} ms/step, p95 "
              f"{np.percentile(falling, 95):.2f}, max {falling.max():.2f} ms, RTF "
              f"{len(falling) / rate / (falling.sum() / 1e3):.2f} | last second median "
              f"{np.median(resting):.3f} ms/step, max {resting.max():.2f} | whole run "
              f"{steps / total_s:.0f} steps/s, RTF {args.seconds / total_s:.2f}")
    print(f"{frozen}/{args.boxes} frozen at the end, "
          f"{world.stats['points'] / steps:.0f} contact points and {world.stats['pairs'] / steps:.0f} "
          "pairs per step on average")
    split = stage_split(args.scene, args.boxes, rate)
    print(f"falling-phase stages, ms/step (total {sum(split.values()):.3f}): "
          + ", ".join(f"{stage} {ms:.3f}" for stage, ms in split.items()))
    if args.asleep:
        median, longest, batched, asleep = asleep_step(args.asleep)
        print(f"{args.asleep} boxes in columns of two, {asleep} frozen, thread CPU: compiled step "
              f"{batched:.4f} ms; a step(1) call median {median:.4f} ms, max {longest:.3f} ms")


if __name__ == "__main__":
    main()
