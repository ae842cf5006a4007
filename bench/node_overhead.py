"""Node overhead (SPEC 8): the ROS node with N boxes (default 1,000, a settled pile) in real
time, recording its bag, a subscriber on every topic it publishes, for a few seconds. Reports the
node process's CPU use beyond its simulation thread (messages, bag, ROS, callbacks) as % of one
core, the time from starting the process to the first ~/bodies/poses message (warm Numba
cache), and the bag's bytes per simulated second. With --foxglove the built-in Foxglove server
runs too, with a WebSocket client subscribed to every channel.

    python bench/node_overhead.py [--boxes 1000] [--seconds 20] [--foxglove]
"""
import argparse
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
from foxglove_client import URL_IN_LOG, watching_everything  # noqa: E402
from pile import build_pile  # noqa: E402

from vplayground_ros.broadcast import TOPICS  # noqa: E402
from vplayground_ros.scene import save_world  # noqa: E402

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def process_cpu_seconds(pid):
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS  # utime + stime


def latest_time(latest):
    values = {kv.key: kv.value for s in latest["diag"].status for kv in s.values}
    return values["time"]


def settled_scene(boxes, path):
    world = build_pile(boxes)
    world.step(6 * 128)  # fall and freeze: the overhead is measured on a live, settled scene
    save_world(world, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--boxes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--foxglove", action="store_true", help="also serve Foxglove, a client subscribed to all")
    args = parser.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 50))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    scene = Path(tempfile.mkdtemp()) / "pile.yaml"
    settled_scene(args.boxes, scene)

    rclpy.init()
    client = rclpy.create_node("overhead_bench")
    latest = {}
    started = time.perf_counter()
    bag = scene.with_name("overhead.mcap")
    node = subprocess.Popen([sys.executable, "-m", "vplayground_ros.cli", "--scene", str(scene), "--record", str(bag),
                             *(["--foxglove", "0"] if args.foxglove else [])],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    urls = []

    def drain():  # the node's log, read so its pipe never fills; the Foxglove URL noted
        for line in node.stdout:
            urls.extend(URL_IN_LOG.findall(line))
    threading.Thread(target=drain, daemon=True).start()
    first_pose = []
    client.create_subscription(PoseArray, "/vplayground/bodies/poses",
                               lambda m: first_pose or first_pose.append(time.perf_counter() - started), 1)
    client.create_subscription(DiagnosticArray, "/diagnostics", lambda m: latest.__setitem__("diag", m), 10)
    deadline = time.perf_counter() + 60
    while not first_pose and time.perf_counter() < deadline:
        rclpy.spin_once(client, timeout_sec=0.05)
    # Subscribe to everything the node publishes, so every message is built and sent.
    for name, types in client.get_topic_names_and_types():
        if name.startswith("/vplayground") or name in ("/clock", "/odom", "/joint_states", "/diagnostics"):
            module, _, kind = types[0].replace("/msg/", "/").partition("/")
            message = getattr(__import__(f"{module}.msg", fromlist=[kind]), kind)
            durable = name.endswith("scene/markers") or name.endswith("/state")
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if durable else DurabilityPolicy.VOLATILE)
            client.create_subscription(message, name, lambda m: None, qos)
    foxglove = None
    if args.foxglove:
        foxglove = watching_everything(urls[0], len(TOPICS))
    end = time.perf_counter() + 3.0
    while time.perf_counter() < end:  # let discovery settle
        rclpy.spin_once(client, timeout_sec=0.05)

    def sample():
        rclpy.spin_once(client, timeout_sec=0.05)
        values = {kv.key: kv.value for s in latest["diag"].status for kv in s.values}
        return time.perf_counter(), process_cpu_seconds(node.pid), float(values["simulation_thread_cpu_s"]), float(values["achieved_real_time_factor"])
    wall0, cpu0, sim0, _ = sample()
    end = time.perf_counter() + args.seconds
    while time.perf_counter() < end:
        rclpy.spin_once(client, timeout_sec=0.05)
    time.sleep(1.1)  # one more diagnostics message
    for _ in range(30):
        rclpy.spin_once(client, timeout_sec=0.05)
    wall1, cpu1, sim1, rtf = sample()
    foxglove_frames = foxglove.received if foxglove else None
    if foxglove:
        foxglove.close()
    node.terminate()
    node.wait(30)
    wall = wall1 - wall0
    total, physics = (cpu1 - cpu0) / wall, (sim1 - sim0) / wall
    result = {"boxes": args.boxes, "seconds": round(wall, 1), "process_cpu_percent": round(100 * total, 1),
              "simulation_thread_percent": round(100 * physics, 1),
              "overhead_percent": round(100 * (total - physics), 1), "achieved_rtf": rtf,
              "start_to_first_pose_s": round(first_pose[0], 2) if first_pose else None,
              "bag_bytes_per_sim_second": round(bag.stat().st_size / max(float(latest_time(latest)), 1e-9)),
              "foxglove_frames_received": foxglove_frames, "exit_code": node.returncode}
    print(json.dumps(result))
    client.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
