"""What the simulator publishes (SPEC 6.1), ROS-free: the topic table, when each topic goes out,
and the sinks that take it. Each message is serialised once (messages.py) and the same bytes go
to every sink: the ROS publishers (node.py), the bag (recorder.py) and the Foxglove server
(foxglove_server.py).

A sink has `publish(topic, data, seconds)`, `subscribed(topic)` and `statuses()` (its
/diagnostics entries); visual topics are built only when some sink wants them (the bag always
does).
"""
import math
import time
from collections import namedtuple

import numpy as np

from . import cdr, messages

Topic = namedtuple("Topic", "key name type qos")
# qos: "reliable_1", "reliable_10", "reliable_100", "latched" (reliable, transient local, depth 1)
TOPICS = [
    Topic("clock", "/clock", "rosgraph_msgs/msg/Clock", "reliable_1"),
    Topic("body_markers", "~/bodies/markers", "visualization_msgs/msg/MarkerArray", "reliable_1"),
    Topic("poses", "~/bodies/poses", "geometry_msgs/msg/PoseArray", "reliable_1"),
    Topic("scene_markers", "~/scene/markers", "visualization_msgs/msg/MarkerArray", "latched"),
    Topic("contact_points", "~/contacts/points", "sensor_msgs/msg/PointCloud2", "reliable_1"),
    Topic("contact_markers", "~/contacts/markers", "visualization_msgs/msg/MarkerArray", "reliable_1"),
    Topic("transforms", "~/transforms", "geometry_msgs/msg/TransformStamped", "reliable_100"),
    Topic("tf", "/tf", "tf2_msgs/msg/TFMessage", "reliable_100"),
    Topic("tf_static", "/tf_static", "tf2_msgs/msg/TFMessage", "latched"),
    Topic("odom", "odom", "nav_msgs/msg/Odometry", "reliable_10"),
    Topic("ground_truth", "~/car/ground_truth", "nav_msgs/msg/Odometry", "reliable_10"),
    Topic("joint_states", "joint_states", "sensor_msgs/msg/JointState", "reliable_10"),
    Topic("car_command", "~/car/command", "geometry_msgs/msg/TwistStamped", "reliable_10"),
    Topic("car_markers", "~/car/markers", "visualization_msgs/msg/MarkerArray", "reliable_1"),
    Topic("state", "~/state", "std_msgs/msg/UInt8", "latched"),
    Topic("rtf", "~/real_time_factor", "std_msgs/msg/Float64", "reliable_10"),
    Topic("diagnostics", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "reliable_10"),
]
NODE_NAME = "vplayground"


def resolve(name, node_name=NODE_NAME):
    """The absolute name of a relative or private (`~/`) name in the root namespace."""
    if name.startswith("~/"):
        return f"/{node_name}/{name[2:]}"
    return name if name.startswith("/") else f"/{name}"


class BagSink:
    """The recorder as a sink: it takes everything; latched topics are re-written into splits."""

    def __init__(self, recorder):
        self.recorder = recorder

    def publish(self, topic, data, seconds):
        self.recorder.write(topic.name, topic.type, data, seconds, topic.qos == "latched")

    def subscribed(self, topic):
        return True

    def statuses(self):
        r = self.recorder
        level = 2 if r.error else (1 if r.dropped else 0)
        return [("vplayground: recorder", level, r.error or str(r.files[-1]),
                 {"path": r.files[-1], "files": len(r.files), "bytes": r.bytes_written, "dropped": r.dropped})]


class Broadcaster:
    def __init__(self, sim, parameters, log, resolve_name=resolve):
        self.sim = sim
        self.parameters = parameters
        self.log = log
        self.topics = {t.key: t._replace(name=resolve_name(t.name)) for t in TOPICS}
        self.sinks = []
        self.frames = tuple(parameters[p] for p in ("world_frame", "odom_frame", "base_frame"))
        self.marker_ids = {}
        self._next_marker_id = 0
        self._ids_of = ([], np.zeros(0, np.int32))  # the last names and their marker ids
        self.marker_encoder = cdr.BodyMarkerEncoder()
        self.tf_encoder = cdr.TransformEncoder()
        self._last_clock = -math.inf
        self._last_static = -math.inf
        self._last_state = None
        self._removed_reported = 0
        self._jobs = {}  # name -> [period (wall s), next due, fn]
        self._add_jobs()
        parameters.listen(self._on_parameters)
        sim.add_listener(self._after_batch)

    def add_sink(self, sink):
        self.sinks.append(sink)
        self.scene_changed()  # the newcomer gets the scenery at once

    def send(self, key, data, seconds):
        topic = self.topics[key]
        for sink in self.sinks:
            sink.publish(topic, data, seconds)

    def wanted(self, key):
        topic = self.topics[key]
        return any(sink.subscribed(topic) for sink in self.sinks)

    # ------------------------------------------------------------------ schedule
    def _add_jobs(self):
        self._jobs = {
            "state": [1.0 / self.parameters["publish_rate"], 0.0, self.publish_state],
            "markers": [1.0 / self.parameters["marker_rate"], 0.0, self.publish_markers],
            "static": [0.1, 0.0, self.publish_static],
            "rtf": [0.5, 0.0, self.publish_rtf],
            "diagnostics": [1.0, 0.0, self.publish_diagnostics],
        }

    def _on_parameters(self, changed):
        if "publish_rate" in changed:
            self._jobs["state"][0] = 1.0 / changed["publish_rate"]
        if "marker_rate" in changed:
            self._jobs["markers"][0] = 1.0 / changed["marker_rate"]

    def tick(self, now=None):
        """Runs the jobs that are due (wall clock); returns the seconds until the next one."""
        now = time.monotonic() if now is None else now
        for job in self._jobs.values():
            period, due, fn = job
            if now >= due:
                job[1] = max(due + period, now)  # keep the rate; never burst to catch up
                fn()
        return max(0.0, min(job[1] for job in self._jobs.values()) - time.monotonic())

    def resend_latched(self):
        """The latched topics (scenery, state, /tf_static) go out again at the next tick."""
        self._last_static = -math.inf
        self._last_state = None

    def scene_changed(self):
        """A new scene (or a new sink): latched topics at once, marker ids restart."""
        self.resend_latched()
        self.marker_ids.clear()
        self._ids_of = ([], np.zeros(0, np.int32))

    # ------------------------------------------------------------------ topics
    def car(self, snapshot):
        """The driven car: the first vehicle of the world, or None."""
        return next(iter(snapshot.vehicles), None)

    def car_wheels(self, car):
        """The car's wheel specs (they change only through ~/edit), or None once it is gone."""
        try:
            return self.sim.world.vehicle(car)["wheels"]
        except KeyError:
            return None

    def _after_batch(self, snapshot):
        """On the simulation thread after each batch: warnings for bodies the world removed,
        and /clock, capped by clock_rate."""
        while self._removed_reported < len(self.sim.removed):
            name = self.sim.removed[self._removed_reported]
            self._removed_reported += 1
            self.log.warning(f"removed {name}: its state went non-finite or it left the world")
        rate = self.parameters["clock_rate"]
        if rate > 0.0 and snapshot.time - self._last_clock < 1.0 / rate - 1e-9:
            return
        self._last_clock = snapshot.time
        self.send("clock", messages.clock(snapshot.time), snapshot.time)

    def publish_state(self):
        snap = self.sim.snapshot
        world_frame, odom_frame, base_frame = self.frames
        self.send("poses", messages.pose_array(snap, world_frame), snap.time)
        state = self.sim.state
        if state != self._last_state:
            self._last_state = state
            self.send("state", messages.uint8(state), snap.time)
            self.send("tf_static", self.tf_encoder.encode(snap.time, [world_frame], [odom_frame],
                                                          [messages.IDENTITY]), snap.time)
        car = self.car(snap)
        wheels = self.car_wheels(car) if car is not None else None
        car_frames = []
        if car is not None:
            self.send("odom", messages.car_odometry(snap, car, odom_frame, base_frame), snap.time)
            self.send("ground_truth", messages.car_odometry(snap, car, world_frame, base_frame), snap.time)
            self.send("joint_states", messages.joint_states(snap, car), snap.time)
            self.send("car_command", messages.car_command(snap, car, base_frame), snap.time)
            if wheels is not None:
                car_frames = messages.car_transforms(snap, car, self.frames, wheels)
                for parent, child, pose in [(world_frame, odom_frame, messages.IDENTITY), *car_frames]:
                    self.send("transforms", cdr.transform_stamped(snap.time, parent, child, pose), snap.time)
        s = snap.state
        if self.parameters["publish_body_frames"]:
            for row, name in enumerate(snap.names):
                self.send("transforms", cdr.transform_stamped(
                    snap.time, world_frame, name, [*s["positions"][row], *s["quaternions"][row]]), snap.time)
        if self.wanted("tf"):
            # world -> every body (child = its name), odom -> base_link, base_link -> wheels.
            parents = [world_frame] * len(snap.names) + [p for p, _, _ in car_frames]
            children = list(snap.names) + [c for _, c, _ in car_frames]
            poses = np.concatenate([np.concatenate([s["positions"], s["quaternions"]], axis=1).reshape(-1, 7),
                                    np.asarray([p for _, _, p in car_frames], float).reshape(-1, 7)])
            self.send("tf", self.tf_encoder.encode(snap.time, parents, children, poses), snap.time)

    def marker_id(self, name):
        """A body's marker id, stable while it exists."""
        if name not in self.marker_ids:
            self.marker_ids[name] = self._next_marker_id
            self._next_marker_id += 1
        return self.marker_ids[name]

    def marker_ids_of(self, names):
        """The marker ids of `names`, an array; looked up again only when the names changed."""
        if names != self._ids_of[0]:
            self.forget_removed(names)
            self._ids_of = (list(names), np.array([self.marker_id(name) for name in names], np.int32))
        return self._ids_of[1]

    def forget_removed(self, names):
        """Drops the ids of bodies that are gone, so spawning and removing for hours never
        grows the table."""
        if len(self.marker_ids) > 2 * len(names) + 64:
            present = set(names)
            self.marker_ids = {n: i for n, i in self.marker_ids.items() if n in present}

    def publish_markers(self):
        snap = self.sim.snapshot
        world_frame = self.frames[0]
        if self.wanted("body_markers"):
            self.send("body_markers", messages.body_markers(snap, world_frame, self.marker_ids_of(snap.names),
                                                            self.marker_encoder), snap.time)
        car = self.car(snap)
        if car is not None and self.wanted("car_markers"):
            wheels = self.car_wheels(car)
            if wheels is not None:
                self.send("car_markers", messages.car_markers(snap, car, world_frame, wheels), snap.time)
        if self.parameters["contacts.publish"] and snap.contacts is not None:
            limit = self.parameters["contacts.max_points"]
            if self.wanted("contact_points"):
                self.send("contact_points", messages.contact_cloud(snap, world_frame, limit), snap.time)
            if self.wanted("contact_markers"):
                self.send("contact_markers", messages.contact_markers(snap, world_frame, limit), snap.time)

    def publish_static(self):
        """The scenery, latched: at start, after a scene load, every static_republish_period
        (so a bag seeks into a full scene), and at marker_rate while the octree is shown."""
        snap = self.sim.snapshot
        period = self.parameters["static_republish_period"]
        show_octree = self.parameters["show_octree"]
        if show_octree:
            period = min(period, 1.0 / self.parameters["marker_rate"])
        if 0 <= snap.time - self._last_static < period:
            return
        self._last_static = snap.time
        cells = self.sim.call(lambda world: world.octree_cells()) if show_octree else ()
        world = self.sim.world
        self.send("scene_markers", messages.scene_markers(snap.time, self.frames[0], world.ground,
                                                          world.playground_triangles, cells), snap.time)

    def publish_rtf(self):
        self.send("rtf", messages.float64(self.sim.achieved_rtf), self.sim.snapshot.time)

    def publish_diagnostics(self):
        snap, sim = self.sim.snapshot, self.sim
        steps = max(snap.step, 1)
        frozen = int(np.count_nonzero(snap.state["frozen"]))
        statuses = [
            ("vplayground: simulation", 0, ["stopped", "playing", "paused"][sim.state],
             {"target_real_time_factor": sim.real_time_factor, "achieved_real_time_factor": round(sim.achieved_rtf, 3),
              "step_ms": round(1e3 * sim.step_seconds / steps, 4), "late_ticks": sim.late_ticks,
              "simulation_thread_cpu_s": round(sim.thread_cpu_seconds, 3),
              "engine_cpu_s": round(sim.engine_cpu_seconds, 3),
              "time": round(snap.time, 4)}),
            ("vplayground: bodies", 1 if sim.removed else 0, f"{len(snap.names)} bodies",
             {"active": len(snap.names) - frozen, "frozen": frozen, "removed": len(sim.removed),
              "last_removed": sim.removed[-1] if sim.removed else ""}),
        ]
        for sink in self.sinks:
            statuses.extend(sink.statuses())
        car = self.car(snap)
        if car is not None:
            age = snap.vehicles[car]["command_age"]
            statuses.append(("vplayground: car", 0, car, {"command_age": round(age, 3)}))
        self.send("diagnostics", messages.diagnostics(snap.time, statuses), snap.time)
