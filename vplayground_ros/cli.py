"""Console entry point `vplayground` (SPEC 2).

One Runtime (runtime.py) serves up to three sinks at once: the ROS node when rclpy imports (not
with --no-ros), the bag (unless --no-record) and the Foxglove server (--foxglove). Either way it
prints a status line and stops cleanly (exit 0) on Ctrl-C, SIGTERM or when --duration of
simulated time has passed.
"""
import argparse
import logging
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

from .parameters import MAX_DURATION, MAX_REAL_TIME_FACTOR, MAX_SPLIT_SIZE
from .recorder import MIN_CHUNK_SIZE
from .resources import find_shared
from .scene import SceneError, load_world
from .simulation import Simulation

STATUS_PERIOD = 2.0  # s of wall time between status lines
STARTING = "starting: Numba loads the engine from its cache, or compiles it (a minute or two on a first run)"


def finite_float(text):
    """A float option's value: NaN passes every `<= 0` check and inf no step count can hold, so
    both are refused here rather than ending the physics thread later."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, not {text!r}")
    return value


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="vplayground", description="Real-time rigid-body sandbox.")
    parser.add_argument("--scene", type=Path, default=None, help="scene file (default: built-in)")
    parser.add_argument("--duration", type=finite_float, default=None,
                        help="stop after this many simulated seconds (default: run until stopped)")
    parser.add_argument("--real-time-factor", type=finite_float, default=1.0,
                        help="simulated seconds per wall-clock second; 0 = as fast as possible")
    parser.add_argument("--start-paused", action="store_true", help="start paused")
    parser.add_argument("--no-ros", action="store_true", help="no ROS node even where rclpy imports")
    foxglove = parser.add_mutually_exclusive_group()
    foxglove.add_argument("--foxglove", type=int, nargs="?", const=8765, default=None, metavar="PORT",
                          help="serve Foxglove's WebSocket protocol on PORT (8765 if not given; 0 = any free port)")
    foxglove.add_argument("--no-foxglove", action="store_const", const=None, dest="foxglove",
                          help="no Foxglove server (the default)")
    parser.add_argument("--foxglove-host", default="127.0.0.1",
                        help="address the Foxglove server listens on (default 127.0.0.1)")
    record = parser.add_mutually_exclusive_group()
    record.add_argument("--record", type=Path, default=None, metavar="PATH.mcap",
                        help="write the MCAP bag here (default: bags/<date-time>.mcap)")
    record.add_argument("--no-record", action="store_true", help="write no bag")
    parser.add_argument("--record-split-size", type=int, default=0, metavar="BYTES",
                        help="continue the bag in a new file past this size (0 = one file)")
    args = parser.parse_args(argv)
    if args.duration is not None and not 0 < args.duration <= MAX_DURATION:
        parser.error(f"--duration must be > 0 and at most {MAX_DURATION:g} s")
    # Within the parameters' ranges: past them the node refused to start, blaming an override.
    if not 0 <= args.real_time_factor <= MAX_REAL_TIME_FACTOR:
        parser.error(f"--real-time-factor must be >= 0 and at most {MAX_REAL_TIME_FACTOR:g}")
    if args.record_split_size > MAX_SPLIT_SIZE:
        parser.error(f"--record-split-size must be at most {MAX_SPLIT_SIZE} bytes")
    if args.record_split_size < 0 or 0 < args.record_split_size < MIN_CHUNK_SIZE:
        # (1 byte had written a file per chunk, thousands a second)
        parser.error(f"--record-split-size must be 0 (one file) or at least {MIN_CHUNK_SIZE} bytes (the bag's "
                     "smallest chunk)")
    if args.foxglove is not None and not 0 <= args.foxglove <= 65535:
        parser.error("--foxglove PORT must be in 0..65535")
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
    return (f"t={snap.time:8.2f} s  bodies={len(snap.names)}  frozen={frozen}  "
            f"rtf={sim.achieved_rtf:.2f}  step={sim.mean_step_ms:.3f} ms  "
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
    recorder = None
    if options.record is not None:
        from .recorder import Recorder
        recorder = Recorder(options.record, options.record_split_size)  # its `error` says if it cannot write
    sim = Simulation(world, real_time_factor=options.real_time_factor,
                     start_paused=options.start_paused, duration=options.duration)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        import rclpy  # noqa: F401
    except ImportError:
        rclpy = None
    if ros_args and (rclpy is None or options.no_ros):
        print(f"vplayground: {' '.join(ros_args)}: ignored, no ROS node runs here "
              f"({'--no-ros' if options.no_ros else 'rclpy is not installed'})", file=sys.stderr)
    return run(sim, options, recorder, ros_args if rclpy is not None and not options.no_ros else None, stop)


# Where Fast DDS looks for a profile: its variables (2.x, 3.x) and its default file in the
# working directory. Any of them set means the user chose the middleware's settings.
FASTDDS_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
FASTDDS_DEFAULT_FILES = ("DEFAULT_FASTRTPS_PROFILES.xml", "DEFAULT_FASTDDS_PROFILES.xml")
FASTDDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")


def use_middleware_profile(environ=os.environ):
    """Points Fast DDS at config/fastdds_profiles.xml (heartbeats ten times a second instead of
    one with every sample, each of which drew an ACKNACK that woke the node: ~0.8 % of a core
    at 1,000 bodies), unless the middleware is another or the user chose a profile. Before
    rclpy.init, which creates the participant that reads it. Returns the profile or None."""
    if environ.get("RMW_IMPLEMENTATION", FASTDDS_RMWS[0]) not in FASTDDS_RMWS:
        return None
    if any(environ.get(name) for name in FASTDDS_PROFILE_VARIABLES) or any(map(os.path.exists, FASTDDS_DEFAULT_FILES)):
        return None
    profile = find_shared("config/fastdds_profiles.xml")
    if profile is not None:
        environ[FASTDDS_PROFILE_VARIABLES[0]] = str(profile)
    return profile


def spin(executor, stop, fault):
    """The ROS callbacks (services, subscriptions, parameters), on their own thread: rclpy's
    executor waits for work without a timeout, where the main thread's spin_once(0.1) had
    rebuilt its wait set of ~40 entities ten times a second (~0.7 % of a core). An exception
    out of a callback (or out of rclpy sending its reply) goes to fault(where, error), which
    logs each distinct one once and counts it for /diagnostics, and the executor spins on: one
    bad request must not take every service away. Returns once the executor or the ROS context
    is shut down, and then stops the run (nothing would answer ROS any more)."""
    from rclpy.executors import ExternalShutdownException
    try:
        while True:
            try:
                executor.spin()  # returns once shut down
                return
            except ExternalShutdownException:
                return
            except Exception as error:
                fault("ROS callback", error)
    finally:
        stop.set()


class ThreadDeaths:
    """Threads ended by an exception while the run lasts (threading.excepthook, which still
    prints the traceback): a physics or publisher thread gone would leave a run that looks
    alive, or one that ends with exit 0 having simulated nothing. Each death stops the run."""

    def __init__(self, stop):
        self.stop = stop
        self.names = []

    def __enter__(self):
        self._previous = threading.excepthook
        threading.excepthook = self._died
        return self

    def _died(self, args):
        self._previous(args)
        name = args.thread.name if args.thread is not None else "a thread"
        self.names.append(f"{name} ({args.exc_type.__name__}: {args.exc_value})")
        self.stop.set()

    def __exit__(self, *_):
        threading.excepthook = self._previous


def run(sim, options, recorder, ros_args, stop):
    """The main thread: the status line, until stopped; the ROS callbacks (if any) on a thread
    of their own. Returns the exit status: 1 if a thread of the run died of an exception."""
    with ThreadDeaths(stop) as deaths:
        status = run_until_stopped(sim, options, recorder, ros_args, stop, deaths)
    return status


def run_until_stopped(sim, options, recorder, ros_args, stop, deaths):
    from .runtime import Runtime

    node = executor = spinner = server = None
    if ros_args is not None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from .node import SimulatorNode
        profile = use_middleware_profile()
        try:
            rclpy.init(args=["vplayground", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
        except RuntimeError as error:  # rcl refusing the arguments (RCLError): its reason, not a traceback
            print(f"vplayground: cannot start: {' '.join(ros_args)}: {str(error).split(', at ')[0]}", file=sys.stderr)
            if recorder is not None:
                recorder.close()
            return 2
        node = SimulatorNode()
        log = node.get_logger()
        if profile is not None:
            log.info(f"Fast DDS settings: {profile}")
        runtime = Runtime(sim, options, log, recorder, node.resolve_topic_name)
    else:
        logging.basicConfig(level=logging.INFO, stream=sys.stdout, format="[%(levelname)s] %(name)s: %(message)s")
        log = logging.getLogger("vplayground")
        runtime = Runtime(sim, options, log, recorder)
    try:
        if options.foxglove is not None:
            from .foxglove_server import FoxgloveServer
            server = FoxgloveServer(runtime, options.foxglove_host, options.foxglove)
        if node is not None:
            try:
                node.attach(runtime)
            except ValueError as error:  # a --ros-args -p override refused
                log.error(f"cannot start: {error}")
                return 2
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            spinner = threading.Thread(target=spin, args=(executor, stop, sim.fault), name="vplayground-ros",
                                       daemon=True)
        speed, duration = runtime.parameters["real_time_factor"], runtime.parameters["duration"]  # overrides too
        log.info(f"{options.scene}: {len(sim.world.body_names())} bodies; real-time factor "
                 f"{speed:g}{f', {duration:g} s' if duration > 0 else ''}; "
                 f"{'ROS node' if node else 'no ROS node'}; "
                 f"{'recording to ' + str(options.record) if recorder and recorder.error is None else 'not recording'}")
        if recorder is not None and recorder.error is not None:  # the run goes on without a bag (issue 16.1)
            log.error(f"bag: cannot record: {recorder.error}; the simulation runs on without one")
        if server is not None:
            log.info(f"Foxglove: open connection to {server.url} (Foxglove WebSocket), then load "
                     f"{find_shared('config/foxglove_layout.json') or 'config/foxglove_layout.json'}")
        runtime.start()
        if spinner is not None:
            spinner.start()
        status_due = time.monotonic() + STATUS_PERIOD
        while not stop.is_set() and not sim.wait(0):
            # Not stop.wait: the SIGINT/SIGTERM handler sets `stop` on this thread, and a signal
            # landing inside Event.wait, whose lock is not reentrant, hung the run for good.
            time.sleep(0.1)
            if time.monotonic() >= status_due:
                status_due += STATUS_PERIOD
                starting = sim.snapshot.step == 0 and not sim.paused
                log.info(STARTING if starting else status_line(sim))
    except OSError as error:  # the Foxglove port is taken, say
        log.error(f"cannot start: {error}")
        return 2
    finally:
        if spinner is not None and spinner.is_alive():
            executor.shutdown(timeout_sec=5.0)  # no callback runs past here, as none ran after the loop
            spinner.join(5.0)
        runtime.stop()  # joins the physics thread: a death in it is known past here
        if deaths.names:
            log.error(f"stopping: {', '.join(deaths.names)} ended by an exception (traceback above)")
        if server is not None:
            server.stop()
        if recorder is not None:
            recorder.close()
            log.info(f"bag: {', '.join(str(f) for f in recorder.files)} ({recorder.bytes_written} bytes of "
                     f"messages, {recorder.dropped} dropped){'; error: ' + recorder.error if recorder.error else ''}")
        log.info(f"stopped: {status_line(sim)}, {sim.world.step_count} steps")
        if node is not None:
            if executor is not None:
                executor.remove_node(node)
            node.destroy_node()
            rclpy.try_shutdown()
    return 1 if deaths.names else 0


if __name__ == "__main__":
    sys.exit(main())
