"""Console entry point `vplayground` (SPEC 2).

With rclpy importable it runs the ROS node; without it (or with --no-ros) the same simulation
runs headless. Either way it prints a status line and stops cleanly (exit 0) on Ctrl-C, SIGTERM
or when --duration of simulated time has passed.
"""
import argparse
import signal
import sys
import threading
import time
from pathlib import Path

from .resources import find_shared
from .scene import SceneError, load_world
from .simulation import Simulation

STATUS_PERIOD = 2.0  # s of wall time between status lines


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="vplayground", description="Real-time rigid-body sandbox.")
    parser.add_argument("--scene", type=Path, default=None, help="scene file (default: built-in)")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many simulated seconds (default: run until stopped)")
    parser.add_argument("--real-time-factor", type=float, default=1.0,
                        help="simulated seconds per wall-clock second; 0 = as fast as possible")
    parser.add_argument("--start-paused", action="store_true", help="start paused")
    parser.add_argument("--no-ros", action="store_true", help="run headless even where rclpy imports")
    record = parser.add_mutually_exclusive_group()
    record.add_argument("--record", type=Path, default=None, metavar="PATH.mcap",
                        help="write the MCAP bag here (default: bags/<date-time>.mcap)")
    record.add_argument("--no-record", action="store_true", help="write no bag")
    parser.add_argument("--record-split-size", type=int, default=0, metavar="BYTES",
                        help="continue the bag in a new file past this size (0 = one file)")
    args = parser.parse_args(argv)
    if args.duration is not None and args.duration <= 0:
        parser.error("--duration must be > 0")
    if args.real_time_factor < 0:
        parser.error("--real-time-factor must be >= 0")
    if args.record_split_size < 0:
        parser.error("--record-split-size must be >= 0")
    if args.no_record:
        args.record = None
    elif args.record is None:
        args.record = Path("bags") / f"{time.strftime('%Y-%m-%d_%H-%M-%S')}.mcap"
    if args.scene is None:
        args.scene = find_shared("config/default_scene.yaml")
        if args.scene is None:
            parser.error("the default scene config/default_scene.yaml is not installed")
    return args


def split_ros_args(argv):
    """Our options, and everything from --ros-args on (for rclpy)."""
    if "--ros-args" in argv:
        k = argv.index("--ros-args")
        return argv[:k], argv[k:]
    return argv, []


def status_line(sim):
    snap = sim.snapshot
    frozen = int(snap.state["frozen"].sum())
    steps = max(snap.step, 1)
    return (f"t={snap.time:8.2f} s  bodies={len(snap.names)}  frozen={frozen}  "
            f"rtf={sim.achieved_rtf:.2f}  step={1e3 * sim.step_seconds / steps:.3f} ms  "
            f"late={sim.late_ticks}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    own, ros_args = split_ros_args(argv)
    options = parse_args(own)
    try:
        world = load_world(options.scene)
    except SceneError as error:
        print(f"vplayground: {error}", file=sys.stderr)
        return 2
    sim = Simulation(world, real_time_factor=options.real_time_factor,
                     start_paused=options.start_paused, duration=options.duration)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        import rclpy  # noqa: F401
    except ImportError:
        rclpy = None
    if rclpy is None or options.no_ros:
        return run_headless(sim, options, stop)
    return run_node(sim, options, ros_args, stop)


def run_headless(sim, options, stop):
    print(f"vplayground: {options.scene} ({len(sim.world.body_names())} bodies), headless", flush=True)
    sim.start()
    last = time.perf_counter()
    while not stop.is_set() and not sim.wait(0.1):
        if time.perf_counter() - last >= STATUS_PERIOD:
            last = time.perf_counter()
            print(status_line(sim), flush=True)
    sim.stop()
    print(f"summary: {status_line(sim)}, {sim.world.step_count} steps", flush=True)
    return 0


def run_node(sim, options, ros_args, stop):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from .node import SimulatorNode

    from .recorder import Recorder

    recorder = None
    if options.record is not None:
        try:
            recorder = Recorder(options.record, options.record_split_size)
        except OSError as error:
            print(f"vplayground: cannot record to {options.record}: {error.strerror or error}", file=sys.stderr)
            return 2
    rclpy.init(args=["vplayground", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = SimulatorNode(sim, options, recorder)
    log = node.get_logger()
    node.create_timer(STATUS_PERIOD, lambda: log.info(status_line(sim)))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    log.info(f"{options.scene}: {len(sim.world.body_names())} bodies; real-time factor "
             f"{options.real_time_factor:g}{'' if options.duration is None else f', {options.duration:g} s'}; "
             f"{'recording to ' + str(options.record) if recorder else 'not recording'}")
    sim.start()
    try:
        while not stop.is_set() and not sim.wait(0):
            executor.spin_once(timeout_sec=0.05)
    finally:
        sim.stop()
        executor.spin_once(timeout_sec=0.05)  # the last state and /clock go out
        if recorder is not None:
            recorder.close()
            log.info(f"bag: {', '.join(str(f) for f in recorder.files)} ({recorder.bytes_written} bytes of "
                     f"messages, {recorder.dropped} dropped){'; error: ' + recorder.error if recorder.error else ''}")
        log.info(f"stopped: {status_line(sim)}")
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
