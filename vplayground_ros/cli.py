"""Console entry point `vplayground`.

Until the ROS node lands, this runs a scene headless in real time (or as fast as possible) and
reports progress: the engine's main job without ROS.
"""
import argparse
import sys
import time
from pathlib import Path

from .resources import find_shared
from .scene import SceneError, load_world


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="vplayground", description="Real-time rigid-body sandbox.")
    parser.add_argument("--scene", type=Path, default=None, help="scene file (default: built-in)")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds to run")
    parser.add_argument("--real-time-factor", type=float, default=1.0,
                        help="simulated seconds per wall-clock second; 0 = as fast as possible")
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error("--duration must be > 0")
    if args.real_time_factor < 0:
        parser.error("--real-time-factor must be >= 0")
    return args


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    scene = args.scene or find_shared("config/default_scene.yaml")
    if scene is None:
        print("vplayground: the default scene config/default_scene.yaml is not installed",
              file=sys.stderr)
        return 2
    try:
        world = load_world(scene)
    except SceneError as error:
        print(f"vplayground: {error}", file=sys.stderr)
        return 2
    rate = world.settings["steps_per_second"]
    batch = max(1, rate // 16)  # steps per compiled call: 16 progress ticks per second
    total = int(round(args.duration * rate))
    started = time.perf_counter()
    stepping = 0.0
    print(f"vplayground: {scene} ({len(world.body_names())} bodies), {args.duration:g} s at "
          f"{rate} steps/s, real-time factor {args.real_time_factor:g}", flush=True)
    done = 0
    while done < total:
        n = min(batch, total - done)
        t0 = time.perf_counter()
        world.step(n)
        stepping += time.perf_counter() - t0
        done += n
        if args.real_time_factor > 0:
            wait = started + world.time / args.real_time_factor - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        if done % rate == 0 or done == total:
            frozen = int(world.state()["frozen"].sum())
            print(f"  t={world.time:6.2f} s  bodies={len(world.body_names())}  frozen={frozen}  "
                  f"physics {done / max(stepping, 1e-9):.0f} steps/s", flush=True)
    wall = time.perf_counter() - started
    frozen = int(world.state()["frozen"].sum())
    print(f"summary: {len(world.body_names())} bodies, {frozen} frozen, {done} steps in "
          f"{wall:.2f} s wall ({done / max(stepping, 1e-9):.0f} steps/s of physics, achieved "
          f"real-time factor {world.time / wall:.2f}); per step {world.stats['pairs'] / done:.0f} "
          f"body pairs and {world.stats['triangles'] / done:.1f} of "
          f"{len(world.playground_triangles)} playground triangles tested")
    return 0


if __name__ == "__main__":
    sys.exit(main())
