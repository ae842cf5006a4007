"""Node overhead (SPEC 8): the ROS node with N boxes (default 1,000, a pile settled until every
box is frozen) in real time, recording its bag, a subscriber on every topic it publishes, for a
few seconds. The overhead is everything the node process does beyond the engine's compiled step
(snapshots, messages, bag, ROS, callbacks): the process's CPU time minus the CPU time its
simulation thread spent inside the compiled step over the same interval (/diagnostics
`engine_cpu_s`), as % of one core. Also per thread (the node runs under named_node.py, which
gives the Python threads' names to the OS) with how often each thread slept and was woken, the
time from starting the process to the first ~/bodies/poses message (warm Numba cache), and the
bag's bytes per simulated second. With --foxglove the built-in Foxglove server runs too, with a
WebSocket client subscribed to every channel (foxglove_viewer.py, in a process of its own as a
viewer is). With --awake the pile never freezes (freezing off, 2 s after the drop): the boxes
jostle in contact all along, so every pose, marker, transform and contact changes each round.

    python bench/node_overhead.py [--boxes 1000] [--seconds 20] [--foxglove] [--awake] [--scene PATH]
                                  [--param NAME:=VALUE ...]

NODE_RUNNER=script.py runs the node under another script taking named_node.py's arguments (a
profiler wrapping it, say).
"""
import argparse
import atexit
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent / "test"))
from foxglove_client import URL_IN_LOG  # noqa: E402
from pile import build_pile  # noqa: E402

from vplayground_ros.broadcast import TOPICS, resolve  # noqa: E402
from vplayground_ros.scene import save_world  # noqa: E402

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
LATCHED = {resolve(t.name) for t in TOPICS if t.qos == "latched"}


# The pile settles for at most this long (simulated s) before the measurement anyway.
MAX_SETTLING_SECONDS = 40


def cpu_seconds(stat_path):
    """utime + stime of a process or thread from its /proc stat file."""
    fields = Path(stat_path).read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def thread_counters(pid):
    """{thread name: (CPU seconds, wakes)} summed over the threads of that name, the wakes being
    the times they went to sleep and were woken (voluntary context switches): on a VM an idle
    node's cost follows these more than its work (a thread's first ~100 us after a sleep run many
    times slower than hot). Threads that end meanwhile are skipped (their CPU time stays in the
    process's)."""
    counters = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            seconds = cpu_seconds(task / "stat")
            status = (task / "status").read_text()
        except (FileNotFoundError, ProcessLookupError):
            continue
        wakes = next(int(line.split()[1]) for line in status.splitlines()
                     if line.startswith("voluntary_ctxt_switches"))
        cpu, woken = counters.get(name, (0.0, 0))
        counters[name] = (cpu + seconds, woken + wakes)
    return counters


def settled_scene(boxes, path):
    """A pile of `boxes` that has fallen and frozen (as far as MAX_SETTLING_SECONDS allow),
    saved to `path`; returns how many boxes froze."""
    world = build_pile(boxes)
    for _ in range(MAX_SETTLING_SECONDS):
        world.step(128)
        if world.state()["frozen"].all():
            break
    save_world(world, path)
    return int(world.state()["frozen"].sum())


def awake_scene(boxes, path, seconds=2):
    """A pile of `boxes` dropped `seconds` ago with freezing off, saved to `path`."""
    world = build_pile(boxes)
    world.update_settings({"freezing": {"enabled": False}})
    world.step(seconds * world.settings["steps_per_second"])
    save_world(world, path)


def diagnostic_values(message):
    return {kv.key: kv.value for s in message.status for kv in s.values}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--foxglove", action="store_true", help="also serve Foxglove, a client subscribed to all")
    parser.add_argument("--awake", action="store_true", help="a pile that never freezes, instead of a settled one")
    parser.add_argument("--scene", type=Path, help="run this scene instead of building a settled pile (--boxes unused)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a node parameter (--ros-args -p NAME:=VALUE), repeatable")
    args = parser.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 50))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    with tempfile.TemporaryDirectory(prefix="node_overhead_") as workspace:  # the bag is GBs at 10,000
        measure(args, Path(workspace))


def measure(args, workspace):
    """One run in `workspace` (the scene and the bag); prints the figures as JSON."""
    if args.scene is None and args.awake:
        scene, frozen_at_start = workspace / "awake.yaml", 0
        awake_scene(args.boxes, scene)
    elif args.scene is None:
        scene = workspace / "pile.yaml"
        frozen_at_start = settled_scene(args.boxes, scene)
    else:
        scene, frozen_at_start = args.scene, None

    rclpy.init()
    client = rclpy.create_node("overhead_bench")
    latest = {}
    started = time.perf_counter()
    bag = workspace / "overhead.mcap"
    node = subprocess.Popen([sys.executable, os.environ.get("NODE_RUNNER", str(Path(__file__).with_name("named_node.py"))),
                             "--scene", str(scene), "--record", str(bag),
                             *(["--foxglove", "0"] if args.foxglove else []),
                             *(["--ros-args", *(a for p in args.param for a in ("-p", p))] if args.param else [])],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    # A run that fails (no /diagnostics, say) must not leave the node running: one left over from
    # such a run once loaded every later measurement on the machine with ~15 % of a core.
    atexit.register(lambda: node.poll() is None and node.kill())
    urls = []

    def drain():  # the node's log, read so its pipe never fills; the Foxglove URL noted
        for line in node.stdout:
            urls.extend(URL_IN_LOG.findall(line))
    threading.Thread(target=drain, daemon=True).start()
    first_pose = []
    client.create_subscription(PoseArray, "/vplayground/bodies/poses",
                               lambda m: first_pose or first_pose.append(time.perf_counter() - started), 1)

    def on_diagnostics(message):  # only our node's: another one may share the ROS domain
        if diagnostic_values(message).get("path") == str(bag):
            latest["diag"] = message
    client.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    deadline = time.perf_counter() + 60
    while not first_pose and time.perf_counter() < deadline:
        rclpy.spin_once(client, timeout_sec=0.05)
    # Subscribe to everything the node publishes, so every message is built and sent.
    for name, types in client.get_topic_names_and_types():
        if name.startswith("/vplayground") or name in ("/clock", "/odom", "/joint_states", "/diagnostics"):
            module, _, kind = types[0].replace("/msg/", "/").partition("/")
            message = getattr(__import__(f"{module}.msg", fromlist=[kind]), kind)
            durable = name in LATCHED or name == "/robot_description"
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if durable else DurabilityPolicy.VOLATILE)
            client.create_subscription(message, name, lambda m: None, qos)
    foxglove = None
    if args.foxglove:
        foxglove = subprocess.Popen([sys.executable, str(Path(__file__).with_name("foxglove_viewer.py")), urls[0],
                                     str(len(TOPICS))], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        atexit.register(lambda: foxglove.poll() is None and foxglove.kill())
        if foxglove.stdout.readline().strip() != "subscribed":
            raise RuntimeError("the Foxglove viewer did not subscribe")
    end = time.perf_counter() + 3.0
    while time.perf_counter() < end:  # let discovery settle
        rclpy.spin_once(client, timeout_sec=0.05)

    def sample():
        """At the arrival of a fresh /diagnostics: wall time, the process's CPU seconds, its
        threads' CPU seconds and wakes, and the node's own figures (read as it sent them, so both
        cover one interval)."""
        previous, deadline = latest.get("diag"), time.perf_counter() + 10
        while latest.get("diag") is previous:
            if time.perf_counter() > deadline:
                raise RuntimeError(f"no /diagnostics from the node for 10 s (exit code {node.poll()})")
            rclpy.spin_once(client, timeout_sec=0.05)
        values = diagnostic_values(latest["diag"])
        return (time.perf_counter(), cpu_seconds(f"/proc/{node.pid}/stat"), thread_counters(node.pid),
                {key: float(values[key]) for key in ("simulation_thread_cpu_s", "engine_cpu_s", "time")},
                float(values["achieved_real_time_factor"]), values)
    wall0, cpu0, threads0, node0, _, _ = sample()
    end = time.perf_counter() + args.seconds
    while time.perf_counter() < end:
        rclpy.spin_once(client, timeout_sec=0.05)
    wall1, cpu1, threads1, node1, rtf, values = sample()
    foxglove_frames = None
    if foxglove:
        foxglove.stdin.close()
        foxglove_frames = int(foxglove.stdout.readline())
    node.terminate()
    node.wait(30)
    wall = wall1 - wall0

    def percent(seconds):
        return round(100 * seconds / wall, 1)
    process = cpu1 - cpu0
    engine = node1["engine_cpu_s"] - node0["engine_cpu_s"]
    simulation_thread = node1["simulation_thread_cpu_s"] - node0["simulation_thread_cpu_s"]
    threads = {name: percent(seconds - threads0.get(name, (0.0, 0))[0]) for name, (seconds, _) in threads1.items()}
    threads = {name: share for name, share in threads.items() if share > 0}  # idle middleware threads left out
    wakes = {name: round((count - threads0.get(name, (0.0, 0))[1]) / wall) for name, (_, count) in threads1.items()}
    wakes = {name: rate for name, rate in wakes.items() if rate > 0}
    result = {"boxes": int(values["frozen"]) + int(values["active"]), "frozen_at_start": frozen_at_start,
              "frozen_at_end": int(values["frozen"]), "foxglove": args.foxglove, "seconds": round(wall, 1),
              "process_cpu_percent": percent(process), "engine_cpu_percent": percent(engine),
              "overhead_percent": percent(process - engine),
              "simulation_thread_percent": percent(simulation_thread),
              "simulation_thread_beyond_engine_percent": percent(simulation_thread - engine),
              "threads_percent": dict(sorted(threads.items(), key=lambda item: -item[1])),
              "wakes_per_second": sum(wakes.values()),
              "threads_wakes_per_second": dict(sorted(wakes.items(), key=lambda item: -item[1])),
              "achieved_rtf": rtf, "simulated_seconds": round(node1["time"] - node0["time"], 2),
              "start_to_first_pose_s": round(first_pose[0], 2) if first_pose else None,
              "bag_bytes_per_sim_second": round(bag.stat().st_size / max(node1["time"], 1e-9)),
              "foxglove_frames_received": foxglove_frames, "exit_code": node.returncode}
    print(json.dumps(result))
    client.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
