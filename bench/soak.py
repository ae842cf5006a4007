"""Soak test (issue 9): the real node for a long time under steady traffic, and its figures.

Starts the `vplayground` console script (the default scene, real time, recording a bag to a
temporary directory) as a subprocess on a private ROS domain and drives it with rclpy:
- a Twist on cmd_vel at 10 Hz (the car drives changing circles in the yard);
- continuous ~/spawn of boxes and ~/remove of the oldest (SPAWN_RATE each, KEEP alive at once),
  and now and then a malformed request, which must be refused.
It samples the simulator's RSS (/proc/<pid>/status), simulated time (/clock) and its
/diagnostics (late ticks, bodies, recorder), and reports per minute: achieved RTF, RSS, late
ticks, bodies and requests; at the end RSS after warm-up vs at the end (growth in %), RTF, late
ticks, requests done and refused, and the bag (finished, message count). With --foxglove the
node serves Foxglove too and a WebSocket client stays subscribed to every channel all along.

    python bench/soak.py --duration 1200 [--foxglove] [--output bench/results/soak.txt]

Not part of `make test`: `make soak DURATION=<seconds>`.
"""
import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SPAWN_RATE = 5.0   # spawns per second, and as many removals once KEEP boxes are alive
KEEP = 40          # spawned boxes alive at once: the world stays ~the default scene plus KEEP
BAD_EVERY = 50     # one malformed spawn per this many requests: it must be refused
SAMPLE_PERIOD = 5.0  # s between RSS samples


def rss_bytes(pid):
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmRSS")


def diagnostic_values(msg):
    """{status name: {key: value}} of a DiagnosticArray."""
    return {status.name: {kv.key: kv.value for kv in status.values} for status in msg.status}


class Soak:
    def __init__(self, args, node, pid):
        from diagnostic_msgs.msg import DiagnosticArray
        from diagnostic_msgs.srv import AddDiagnostics
        from geometry_msgs.msg import Twist
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        self.args, self.node, self.pid = args, node, pid
        self.spawn = node.create_client(AddDiagnostics, "/vplayground/spawn")
        self.remove = node.create_client(AddDiagnostics, "/vplayground/remove")
        self.request_type = AddDiagnostics.Request
        self.twist = node.create_publisher(Twist, "cmd_vel", 10)
        self.Twist = Twist
        self.sim_time = None
        self.diagnostics = {}
        node.create_subscription(Clock, "/clock", self._on_clock,
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.alive, self.serial = [], 0
        self.done = {"spawn": 0, "remove": 0, "refused_bad": 0, "failed": 0, "timeouts": 0}
        self.pending = []  # (kind, future, sent at, expect_ok)
        self.latencies = []

    def _on_clock(self, msg):
        self.sim_time = msg.clock.sec + 1e-9 * msg.clock.nanosec

    def _on_diagnostics(self, msg):
        self.diagnostics = diagnostic_values(msg)

    def wait_ready(self, timeout=120.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            import rclpy
            rclpy.spin_once(self.node, timeout_sec=0.1)
            if self.spawn.service_is_ready() and self.remove.service_is_ready() and self.sim_time is not None:
                return
        raise RuntimeError("the node did not come up")

    def drive(self, t):
        msg = self.Twist()
        msg.linear.x = 3.0 + 2.0 * math.sin(t / 17.0)  # m/s
        msg.angular.z = 0.4 * math.sin(t / 29.0)       # rad/s
        self.twist.publish(msg)

    def send(self, kind, text, expect_ok=True):
        client = self.spawn if kind == "spawn" else self.remove
        future = client.call_async(self.request_type(load_namespace=text))
        self.pending.append((kind, future, time.monotonic(), expect_ok))

    def traffic(self):
        """One spawn (every BAD_EVERY-th malformed) and, past KEEP, one removal of the oldest."""
        self.serial += 1
        if self.serial % BAD_EVERY == 0:
            self.send("spawn", "{name: soak_bad, size: [1, -1, 1], mass: .nan}", expect_ok=False)
            return
        # Unique names (every box a new one, as clicked_point drops make) or a pool of 2 x KEEP
        # reused ones: the difference is what per-name caches cost.
        name = f"soak_{self.serial if self.args.names == 'unique' else self.serial % (2 * KEEP)}"
        x, y = random.uniform(-15, 15), random.uniform(-15, 15)
        self.send("spawn", json.dumps({"name": name, "size": [0.5, 0.5, 0.5], "position": [x, y, 3.0],
                                       "rpy": [random.uniform(-1, 1) for _ in range(3)]}))
        self.alive.append(name)
        if len(self.alive) > KEEP:
            self.send("remove", json.dumps({"entity": self.alive.pop(0)}))

    def collect(self):
        now = time.monotonic()
        still = []
        for kind, future, sent, expect_ok in self.pending:
            if future.done():
                response = future.result()
                self.latencies.append(now - sent)
                if expect_ok and response.success:
                    self.done[kind] += 1
                elif not expect_ok and not response.success and response.message.startswith("RESULT_OPERATION_FAILED:"):
                    self.done["refused_bad"] += 1
                elif "RESULT_NOT_FOUND" in response.message and kind == "remove":
                    self.done[kind] += 1  # the box left the world (removed by the simulator) first
                else:
                    self.done["failed"] += 1
                    print(f"unexpected reply to {kind}: {response.success} {response.message[:200]}", flush=True)
            elif now - sent > 30.0:
                self.done["timeouts"] += 1
            else:
                still.append((kind, future, sent, expect_ok))
        self.pending = still


def watch_in_foxglove(log_path, timeout=30.0):
    """A Foxglove client on the node's server (its URL read from the node's log), subscribed to
    every channel, keeping only its last few frames."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))
    from foxglove_client import URL_IN_LOG, watching_everything

    from vplayground_ros.broadcast import TOPICS
    deadline = time.monotonic() + timeout
    while not (urls := URL_IN_LOG.findall(Path(log_path).read_text())):
        if time.monotonic() > deadline:
            raise RuntimeError("the node did not print its Foxglove URL")
        time.sleep(0.2)
    return watching_everything(urls[0], len(TOPICS), timeout=timeout)


STOP = []  # set by SIGINT/SIGTERM: the soak ends early and still reports what it measured


def interrupted(started):
    if STOP:
        print(f"soak: interrupted after {time.monotonic() - started:.0f} s; reporting so far", flush=True)
    return bool(STOP)


def run(args):
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.append(True))
    import rclpy

    bag_dir = Path(tempfile.mkdtemp(prefix="vplayground_soak_"))
    bag = bag_dir / "soak.mcap"
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(120, 200)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.update(ROS_DOMAIN_ID=env["ROS_DOMAIN_ID"], ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    command = [args.vplayground, "--real-time-factor", "1", "--record", str(bag),
               *(["--foxglove", "0"] if args.foxglove else ["--no-foxglove"])]
    log_path = Path(args.output).with_suffix(".node.log") if args.output else bag_dir / "node.log"
    node_log = open(log_path, "w")
    process = subprocess.Popen(command, stdout=node_log, stderr=subprocess.STDOUT, env=env)
    print(f"soak: {' '.join(command)} (pid {process.pid}), {args.duration:g} s, warm-up {args.warmup:g} s, "
          f"node log {log_path}", flush=True)
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C ends the loop, not rclpy
    node = rclpy.create_node("vplayground_soak")
    soak = Soak(args, node, process.pid)
    minutes = []
    foxglove = foxglove_report = None
    try:
        soak.wait_ready()
        if args.foxglove:
            foxglove = watch_in_foxglove(log_path)
        started = time.monotonic()
        next_drive = next_traffic = next_sample = started
        rss_start, late_start = None, 0
        samples = []  # (wall s since start, sim s, rss bytes)
        sim_start = soak.sim_time
        minute_start = (started, soak.sim_time, 0, 0)
        while time.monotonic() - started < args.duration and not interrupted(started):
            if process.poll() is not None:
                raise RuntimeError(f"the node exited with {process.returncode}")
            rclpy.spin_once(node, timeout_sec=0.01)
            now = time.monotonic()
            if now >= next_drive:
                soak.drive(now - started)
                next_drive += 0.1
            if now >= next_traffic:
                soak.traffic()
                next_traffic += 1.0 / SPAWN_RATE
            soak.collect()
            if now >= next_sample:
                next_sample += SAMPLE_PERIOD
                rss = rss_bytes(process.pid)
                samples.append((now - started, soak.sim_time, rss))
                if rss_start is None and now - started >= args.warmup:
                    rss_start = (now - started, rss)
                    late_start = int(soak.diagnostics.get("simulation", {}).get("late_ticks", 0))
            if now - minute_start[0] >= 60.0:
                wall = now - minute_start[0]
                rtf = (soak.sim_time - minute_start[1]) / wall
                sim = soak.diagnostics.get("simulation", {})
                bodies = soak.diagnostics.get("bodies", {})
                requests = soak.done["spawn"] + soak.done["remove"] + soak.done["refused_bad"]
                row = {"minute": len(minutes) + 1, "rtf": round(rtf, 4), "rss_mb": round(rss_bytes(process.pid) / 2**20, 1),
                       "late_ticks": int(sim.get("late_ticks", -1)), "step_ms": float(sim.get("step_ms", "nan")),
                       "bodies": int(bodies.get("active", 0)) + int(bodies.get("frozen", 0)),
                       "removed_by_simulator": int(bodies.get("removed", 0)),
                       "requests": requests - minute_start[2]}
                if foxglove is not None:
                    row["foxglove_frames"] = foxglove.received - minute_start[3]
                minutes.append(row)
                print("soak: " + "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
                minute_start = (now, soak.sim_time, requests, foxglove.received if foxglove else 0)
        end = time.monotonic() - started
        rss_end = rss_bytes(process.pid)
        diagnostics = soak.diagnostics
        sim_end = soak.sim_time
        foxglove_report = None if foxglove is None else {
            "frames_received": foxglove.received, "still_connected": foxglove.connected}
    finally:
        if foxglove is not None:
            foxglove.close()
        process.send_signal(signal.SIGINT)  # Ctrl-C: a clean stop that finishes the bag
        try:
            process.wait(120)
        except subprocess.TimeoutExpired:
            process.kill()
        node.destroy_node()
        rclpy.try_shutdown()
        node_log.close()

    from vplayground_ros.recorder import summary
    try:
        counts = summary(bag)
        bag_report = {"finished": True, "messages": sum(counts.values()), "topics": len(counts),
                      "bytes": bag.stat().st_size}
    except Exception as error:  # an unfinished bag is a finding, not a crash of the report
        bag_report = {"finished": False, "error": f"{type(error).__name__}: {error}"}
    rtf_values = [m["rtf"] for m in minutes]
    sim = diagnostics.get("simulation", {})
    recorder = {k: v for k, v in diagnostics.items() if "recorder" in k}
    report = {
        "duration_s": round(end, 1), "warmup_s": args.warmup, "exit_code": process.returncode,
        "rss_start_mb": round(rss_start[1] / 2**20, 2) if rss_start else None,
        "rss_end_mb": round(rss_end / 2**20, 2),
        "rss_growth_percent": round(100.0 * (rss_end - rss_start[1]) / rss_start[1], 2) if rss_start else None,
        "rtf_overall": round((sim_end - sim_start) / end, 4) if end else None,
        "rtf_per_minute_min": min(rtf_values) if rtf_values else None,
        "rtf_per_minute_max": max(rtf_values) if rtf_values else None,
        "late_ticks": int(sim.get("late_ticks", -1)),
        "late_ticks_after_warmup": int(sim.get("late_ticks", -1)) - late_start,
        "step_ms_mean": float(sim.get("step_ms", "nan")),
        "requests": dict(soak.done),
        "request_latency_ms_p50": round(1e3 * sorted(soak.latencies)[len(soak.latencies) // 2], 2) if soak.latencies else None,
        "request_latency_ms_max": round(1e3 * max(soak.latencies), 2) if soak.latencies else None,
        "bodies_removed_by_simulator": int(diagnostics.get("bodies", {}).get("removed", 0)),
        "recorder": recorder, "bag": bag_report, "rss_samples": len(samples),
    }
    if foxglove_report is not None:
        report["foxglove"] = foxglove_report
    print("soak result: " + json.dumps(report, indent=1), flush=True)
    if args.output:
        Path(args.output).with_suffix(".json").write_text(json.dumps({"report": report, "minutes": minutes,
                                                                      "rss_samples": samples}, indent=1))
    ok = (process.returncode == 0 and report["requests"]["failed"] == 0 and report["requests"]["timeouts"] == 0
          and bag_report.get("finished"))
    if not args.keep_bag:
        for path in bag_dir.glob("*"):
            path.unlink()
        bag_dir.rmdir()
    return 0 if ok else 1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=1200.0, help="seconds of wall time (default 1200)")
    parser.add_argument("--warmup", type=float, default=None,
                        help="seconds before the start RSS is taken (default: a tenth of the run, 30-120 s)")
    parser.add_argument("--output", default=None, help="also write <output>.json and <output>.node.log")
    parser.add_argument("--keep-bag", action="store_true")
    parser.add_argument("--foxglove", action="store_true",
                        help="serve Foxglove too, with a WebSocket client subscribed to every channel")
    parser.add_argument("--names", choices=("unique", "pool"), default="unique",
                        help="spawn a new name each time (default) or reuse a pool of 2 x KEEP names")
    parser.add_argument("--vplayground", default=str(Path(sys.executable).parent / "vplayground"),
                        help="the console script to run")
    args = parser.parse_args(argv)
    if args.warmup is None:
        args.warmup = min(120.0, max(30.0, args.duration / 10.0))
    if args.output:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
