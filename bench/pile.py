"""Quick benchmark of the step on a pile of boxes falling at 128 steps/s, in this thread's CPU
time (which other processes on a shared machine do not inflate) and in wall time.

Scenes: `loose` (issue 20's: 0.5 m boxes, 500 kg/m^3, friction 0.6/0.4, elasticity 0.2, dropped
from a spread 10-layer grid with random yaw and small tilts) and `dense` (a jittered 0.8 m grid).
Prints the falling phase (first 2 s) median / p95 / max, the last second, the whole run, where a
falling step's time goes (the stage timers, from a second identical run), and the step of
`--asleep` boxes standing in columns of two, every one of them frozen. With `--runs N` the falling
phase runs N times: each run's longest step, and each step's fastest over the runs.

`--compare-threads` instead runs the falling phase with the contact solve on one thread and on
two (World.solver_threads), interleaved `--rounds` times, and prints per step the wall time, the
stepping thread's CPU and the CPU of the whole process (both solver threads), with the speed-up
and the load average; the two settings' final states are compared too.

    python bench/pile.py [--scene loose|dense] [--boxes 1000] [--seconds 10] [--asleep 5000]
                         [--solver-threads 1|2] [--runs 1]
    python bench/pile.py --compare-threads [--scene loose|dense] [--boxes 1000] [--rounds 3]
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from machine import core_round_trip_ns, round_trip_text  # noqa: E402
from scenes import loose_pile, pile, resting_columns, tower  # noqa: E402
from vplayground_ros.physics import World  # noqa: E402

SCENES = {"loose": loose_pile, "dense": pile}
FALLING_SECONDS = 2


def world_of(boxes, capacity=64, solver_threads=None, measure_threads=False):
    """A world of `boxes` whose every step runs on `solver_threads` (the World's default when
    None), or with measure_threads on the second only while it pays (World.measure_threads)."""
    world = World(capacity=max(capacity, len(boxes)), solver_threads=solver_threads)
    world.measure_threads = measure_threads
    for size, position, quaternion, mass in boxes:
        world.add_body({"size": size.tolist(), "position": position.tolist(),
                        "quaternion": quaternion.tolist(), "mass": mass})
    return world


def warm_up():
    """Compiles (or loads from Numba's cache) every kernel a step of boxes calls, before any
    timing: an empty world's step skips the bounds of the octree's first fit, whose cache load
    (~4 ms) was then the first timed step, often the run's longest."""
    world_of(tower(2)).step(1)


def build_pile(count, seed=1, scene="dense", solver_threads=None):
    return world_of(SCENES[scene](count, seed), solver_threads=solver_threads)


def timed_steps(world, steps, process=None):
    """(thread CPU ms, wall ms) of each of `steps` single steps; the process's CPU ms of each
    (every thread's) into `process` when given."""
    cpu, wall = np.empty(steps), np.empty(steps)
    for k in range(steps):
        wall0, cpu0, process0 = time.perf_counter(), time.thread_time_ns(), time.process_time_ns()
        world.step(1)
        cpu[k] = (time.thread_time_ns() - cpu0) * 1e-6
        wall[k] = (time.perf_counter() - wall0) * 1e3
        if process is not None:
            process[k] = (time.process_time_ns() - process0) * 1e-6
    return cpu, wall


def machine_cpu_seconds():
    """(busy, total) CPU seconds of the whole machine so far, summed over its cores, from
    /proc/stat (Linux); None elsewhere."""
    try:
        with open("/proc/stat") as stat:
            ticks = [int(v) for v in stat.readline().split()[1:]]
    except OSError:
        return None
    hz = os.sysconf("SC_CLK_TCK")
    idle = ticks[3] + ticks[4]
    return (sum(ticks) - idle) / hz, sum(ticks) / hz


def compare_threads(scene, count, rounds):
    """The falling phase with the contact solve on 1 and on 2 threads, interleaved `rounds`
    times: per setting, the steps of every round pooled."""
    rate = World().settings["steps_per_second"]
    steps = FALLING_SECONDS * rate
    clocks = {threads: {"wall": [], "thread CPU": [], "process CPU": []} for threads in (1, 2)}
    loads, finals, others = [], {}, []
    for _ in range(rounds):
        for threads in (1, 2):
            world = build_pile(count, scene=scene, solver_threads=threads)
            process = np.empty(steps)
            loads.append(os.getloadavg()[0])
            machine0, process0 = machine_cpu_seconds(), time.process_time()
            cpu, wall = timed_steps(world, steps, process)
            machine1, process1 = machine_cpu_seconds(), time.process_time()
            if machine0 is not None and machine1[1] > machine0[1]:
                # Cores busy with other processes meanwhile (the machine's busy time not ours,
                # over the round's wall time): a second solver thread only helps with a free core.
                cores = os.cpu_count() or 1
                others.append(cores * ((machine1[0] - machine0[0]) - (process1 - process0))
                              / (machine1[1] - machine0[1]))
            for clock, values in (("wall", wall), ("thread CPU", cpu), ("process CPU", process)):
                clocks[threads][clock].append(values)
            finals[threads] = world.state()
            busy = f", other processes busy {others[-1]:.2f} cores" if others else ""
            print(f"  round {len(loads) // 2 + len(loads) % 2}, {threads} thread{'s' if threads > 1 else ''}: "
                  f"wall {wall.sum():.0f} ms (median {np.median(wall):.3f}, p95 {np.percentile(wall, 95):.3f}, "
                  f"max {wall.max():.3f}), process CPU {process.sum():.0f} ms, load {loads[-1]:.2f}{busy}")
    print(f"{scene} pile of {count} boxes, falling phase (first {FALLING_SECONDS} s), {rounds} rounds "
          f"of 1 and 2 solver threads interleaved, load average (1 min) {min(loads):.2f}-{max(loads):.2f}"
          + (f", other processes busy {min(others):.2f}-{max(others):.2f} cores" if others else "")
          + f", a cache line's round trip between two threads {round_trip_text(core_round_trip_ns())}")
    summary = {}
    for threads in (1, 2):
        for clock, rounds_of in clocks[threads].items():
            ms = np.concatenate(rounds_of)
            summary[threads, clock] = ms
            print(f"  {threads} thread{'s' if threads > 1 else ' '} {clock:>11}: median {np.median(ms):.3f} "
                  f"p95 {np.percentile(ms, 95):.3f} max {ms.max():.3f} ms/step, total {ms.sum() / rounds:.0f} ms")
    for clock in ("wall", "process CPU"):
        one, two = summary[1, clock], summary[2, clock]
        print(f"  {clock}: 1 thread / 2 threads = median {np.median(one) / np.median(two):.2f}, "
              f"p95 {np.percentile(one, 95) / np.percentile(two, 95):.2f}, "
              f"max {one.max() / two.max():.2f}, total {one.sum() / two.sum():.2f}")
    same = all(np.array_equal(finals[1][key], finals[2][key]) for key in finals[1])
    print(f"  final states of 1 and 2 threads {'bit-identical' if same else 'DIFFER'}")


def stage_split(scene, count, rate, solver_threads=1):
    """ms per step of each stage over the falling phase, from the stage timers (the stepping
    thread's CPU time)."""
    world = build_pile(count, scene=scene, solver_threads=solver_threads)
    world.profiling = True
    steps = FALLING_SECONDS * rate
    world.step(steps)
    return {stage: 1e3 * s / steps for stage, s in world.stage_seconds().items()}


def asleep_step(count, steps=2000, solver_threads=1):
    """Thread CPU ms of a step with `count` boxes standing in columns of two, all frozen: a
    World.step(1) call's median and max (what a caller pays: such calls step in Python,
    World.resting_shortcut), the compiled step alone (one call of `steps` steps, the shortcut
    off), and how many were frozen."""
    world = world_of(resting_columns(count // 2), solver_threads=solver_threads)
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


def fastest_steps(scene, count, solver_threads, first_run, runs_in_all):
    """The falling phase `runs_in_all` times (the same steps: the engine is deterministic):
    each run's longest step, and each step's fastest time over the runs, whose median / p95 /
    max say what the steps cost the engine when nothing else on the machine took its share (on
    a shared VM one step's time varies by tens of per cent from run to run)."""
    runs = [first_run]
    for _ in range(runs_in_all - 1):
        world = build_pile(count, scene=scene, solver_threads=solver_threads)
        runs.append(timed_steps(world, len(first_run))[0])
    fastest = np.min(runs, axis=0)
    print(f"falling phase, {runs_in_all} runs: longest step of each run "
          + ", ".join(f"{run.max():.2f}" for run in runs) + f" ms (step {', '.join(str(int(run.argmax())) for run in runs)}); "
          f"each step's fastest: median {np.median(fastest):.2f}, p95 {np.percentile(fastest, 95):.2f}, "
          f"max {fastest.max():.2f} ms (step {int(fastest.argmax())})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=sorted(SCENES), default="loose")
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--asleep", type=int, default=5000, help="boxes of the resting step (0: skip)")
    parser.add_argument("--solver-threads", type=int, default=1, choices=(1, 2),
                        help="World.solver_threads of the runs (1: one core, as issue 20 measures)")
    parser.add_argument("--compare-threads", action="store_true",
                        help="falling phase with 1 and 2 solver threads, and the speed-up")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --compare-threads")
    parser.add_argument("--runs", type=int, default=1,
                        help="falling phases timed in all: with more than 1, also each step's fastest")
    args = parser.parse_args()
    if args.compare_threads:
        warm_up()
        compare_threads(args.scene, args.boxes, args.rounds)
        return

    started = time.perf_counter()
    warm_up()
    compile_s = time.perf_counter() - started

    world = build_pile(args.boxes, scene=args.scene, solver_threads=args.solver_threads)
    rate = world.settings["steps_per_second"]
    steps = int(args.seconds * rate)
    clocks = dict(zip(("cpu", "wall"), timed_steps(world, steps)))
    frozen = int(world.state()["frozen"].sum())
    print(f"compile/load {compile_s:.1f} s | {args.scene} pile of {args.boxes} boxes, "
          f"{args.seconds:g} s at {rate} steps/s, {world.solver_threads} solver thread(s)")
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
    if args.runs > 1:
        fastest_steps(args.scene, args.boxes, args.solver_threads, clocks["cpu"][: FALLING_SECONDS * rate], args.runs)
    split = stage_split(args.scene, args.boxes, rate, args.solver_threads)
    print(f"falling-phase stages, ms/step (total {sum(split.values()):.3f}): "
          + ", ".join(f"{stage} {ms:.3f}" for stage, ms in split.items()))
    if args.asleep:
        median, longest, batched, asleep = asleep_step(args.asleep, solver_threads=args.solver_threads)
        print(f"{args.asleep} boxes in columns of two, {asleep} frozen, thread CPU: compiled step "
              f"{batched:.4f} ms; a step(1) call median {median:.4f} ms, max {longest:.3f} ms")


if __name__ == "__main__":
    main()
