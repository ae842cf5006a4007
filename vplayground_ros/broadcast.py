"""What the simulator publishes (SPEC 6.1), ROS-free: the topic table, when each topic goes out,
and the sinks that take it. Each message is serialised once (messages.py) and the same bytes go
to every sink: the ROS publishers (node.py), the bag (recorder.py) and the Foxglove server
(foxglove_server.py).

A sink has `publish(topic, data, seconds)`, `subscribed(topic)` and `statuses()` (its
/diagnostics entries); visual topics are built only when some sink wants them (the bag always
does).
"""
import math
import threading
import time
import traceback
from collections import deque, namedtuple

import numpy as np

from . import cdr, messages, sensor_messages
from .frame_names import check_sensor_frames, mount_frame, sensor_frame
from .parameters import frames as frame_names
from .odometry import OdometryTracker
from .physics import specs
from .physics.math3d import quaternions_to_matrices
from .robot_description import robot_description
from .robots import (as_pose, compose, footprint_pose, inverse, namespace_prefix, robot, robot_transforms,
                     world_robots)
from .simulation import STATE_NAMES
from .urdf_robots import (WHEEL_ODOMETRY_COVARIANCE, WheelOdometry, drive_joints, fixed_edges, link_carriers,
                          link_edges, publishing_view, root_pose)

Topic = namedtuple("Topic", "key name type qos")
# qos: "reliable_1", "reliable_10", "reliable_100", "latched" (reliable, transient local, depth 1)
TOPICS = [
    Topic("clock", "/clock", "rosgraph_msgs/msg/Clock", "reliable_1"),
    Topic("body_markers", "~/bodies/markers", "visualization_msgs/msg/MarkerArray", "reliable_1"),
    Topic("resting_markers", "~/bodies/resting_markers", "visualization_msgs/msg/MarkerArray", "latched"),
    Topic("poses", "~/bodies/poses", "geometry_msgs/msg/PoseArray", "reliable_1"),
    Topic("scene_markers", "~/scene/markers", "visualization_msgs/msg/MarkerArray", "latched"),
    Topic("robot_visuals", "~/robots/visuals", "visualization_msgs/msg/MarkerArray", "latched"),
    Topic("contact_points", "~/contacts/points", "sensor_msgs/msg/PointCloud2", "reliable_1"),
    Topic("contact_markers", "~/contacts/markers", "visualization_msgs/msg/MarkerArray", "reliable_1"),
    Topic("transforms", "~/transforms", "geometry_msgs/msg/TransformStamped", "reliable_100"),
    Topic("tf", "/tf", "tf2_msgs/msg/TFMessage", "reliable_100"),
    Topic("tf_static", "/tf_static", "tf2_msgs/msg/TFMessage", "latched"),
    Topic("state", "~/state", "std_msgs/msg/UInt8", "latched"),
    Topic("rtf", "~/real_time_factor", "std_msgs/msg/Float64", "reliable_10"),
    Topic("diagnostics", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "reliable_10"),
]
NODE_NAME = "vplayground"
OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
RTF_PERIOD = 0.5           # simulated s between ~/real_time_factor messages
DIAGNOSTICS_PERIOD = 1.0   # simulated s between /diagnostics messages
TIME_TOLERANCE = 1e-9      # s: a snapshot this close before a due time is at it
# Snapshots handed to the publisher thread and not yet published; beyond it the simulation
# waits (as fast as possible, at most HAND_OVER_TIMEOUT s) or the oldest is skipped (real time).
PENDING_LIMIT = 8
HAND_OVER_TIMEOUT = 1.0
# A batch of more steps than this (a late one catching up) sends only its last step's /clock.
MAX_CLOCK_FILL = 16
PAUSED_JOBS = ("state", "markers", "diagnostics")  # what goes out while paused, by the wall clock
PAUSED_ON_CHANGE = ("state", "markers")            # ... and only when the snapshot changed
ROUND_LATCHED = ("resting_markers", "scene_markers")  # latched topics the publisher thread's rounds send
WELCOME_GATHER = 0.05  # s: a new client's subscriptions gather this long before it gets the world
SENSOR_QOS = "reliable_10"  # a reliable publisher serves best-effort (sensor data) subscribers too
# A robot whose base moved farther between two rounds than its speed, this acceleration (m/s^2)
# and this slack (m) allow was put there (a teleport): its odometry starts again where it stands.
MAX_ACCELERATION = 100.0
TELEPORT_SLACK = 0.5
# Each robot's topics (robots.py): under its namespace, what a stack reads; under ~/<its name>,
# what only the simulator knows. (suffix, type, qos, private)
ROBOT_TOPICS = {
    "odom": ("odom", "nav_msgs/msg/Odometry", "reliable_10", False),
    "joint_states": ("joint_states", "sensor_msgs/msg/JointState", "reliable_10", False),
    "ground_truth": ("ground_truth", "nav_msgs/msg/Odometry", "reliable_10", True),
    "command": ("command", "geometry_msgs/msg/TwistStamped", "reliable_10", True),
    "markers": ("markers", "visualization_msgs/msg/MarkerArray", "reliable_1", True),
    "robot_description": ("robot_description", "std_msgs/msg/String", "latched", False),
}


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
        self.recorder.write(topic.name, topic.type, data, seconds, topic.qos)

    def new_timeline(self):
        self.recorder.new_timeline()

    def round_begins(self, seconds):
        self.recorder.round_begins(seconds)

    def retract(self, topic):
        self.recorder.retract(topic.name)

    def subscribed(self, topic):
        return True

    def statuses(self):
        r = self.recorder
        path = r.files[-1] if r.files else r.path  # no file when the path could not be opened
        values = {"path": path, "files": len(r.files), "bytes": r.bytes_written, "dropped": r.dropped}
        if r.error:
            return [("recorder", ERROR, f"not recording: {r.error}", values)]
        message = f"recording {path}, {r.bytes_written / 1e6:.1f} MB"
        if r.dropped:
            return [("recorder", WARN, f"{message}, {r.dropped} messages dropped", values)]
        return [("recorder", OK, message, values)]


class Job:
    """A group of topics published every `period` simulated seconds: on the snapshot of the
    first step at or after each multiple of the period, so a bag carries the same times at any
    real-time factor."""

    def __init__(self, name, period, publish):
        self.name, self.period, self.publish = name, period, publish
        self.due = 0.0           # simulated s
        self.wall_due = 0.0      # time.monotonic() s, while paused
        self.published = None    # the snapshot it last went out with
        self.errors = 0
        self.last_error = ""

    def is_due(self, seconds):
        return seconds >= self.due - TIME_TOLERANCE

    def advance(self, seconds):
        """The next multiple of the period after `seconds`."""
        self.due = (math.floor(seconds / self.period + 1e-9) + 1) * self.period


class Broadcaster:
    """Publishing is scheduled on simulated time. After each batch the simulation thread's
    listener (_after_batch) sends /clock, picks the jobs due at the snapshot's time and hands
    them to the publisher thread (publish_next), which builds and sends the messages; the
    simulation ends its batches at the next due time (Simulation.next_publish_time), so a
    30 Hz topic lands on the step at or after every 1/30 s whatever the speed. Running as
    fast as possible the simulation waits for the publisher (every due time is published);
    in real time it never waits, and a publisher that falls behind skips the oldest snapshots
    (counted on /diagnostics).

    While paused, simulated time stands still: state and markers go out on the wall clock at
    their rates when the snapshot changed (an edit, a ~/step), diagnostics once a second of
    wall time; so a live view answers edits and a paused stretch of a bag holds no copies.
    The scenery goes out on change (a new scene, show_octree) and every
    static_republish_period simulated seconds; a new sink, or a client subscribing, gets the
    latched topics as last sent."""

    def __init__(self, sim, parameters, log, resolve_name=resolve):
        self.sim = sim
        self.parameters = parameters
        self.log = log
        self.resolve_name = resolve_name
        self.topics = {t.key: t._replace(name=resolve_name(t.name)) for t in TOPICS}
        self.sinks = []
        self.frames = frame_names(parameters)
        self.marker_ids = {}
        self._next_marker_id = 0
        self._ids_of = ([], np.zeros(0, np.int32))  # the last names and their marker ids
        self.body_markers = messages.BodyMarkers(resting=False)
        self.resting_markers = messages.BodyMarkers(resting=True)
        self._resting_sent = None  # simulated s when ~/bodies/resting_markers last went out
        self._sent_empty = set()   # keys of the per-round topics whose last message drew or carried nothing
        self.tf_encoder = cdr.TransformEncoder()         # /tf, on the publisher thread
        self.tf_static_encoder = cdr.TransformEncoder()  # /tf_static, on the simulation thread
        self._pose_block = None  # (positions, quaternions, their (N, 7) rows) last made
        self._tf_frames = None   # (key, rows of the bodies on /tf, parents, children) last made
        self._robots = None      # (key, [robots.Robot]) last made
        self._urdf_robots = None  # (key, [urdf_robots.UrdfRobot]) last made
        self._wheel_odometry = {}  # URDF robot name -> (its WheelOdometry, the root position it last saw)
        self._odometry = {}      # robot name -> (OdometryTracker, its error model, the car's body id)
        self._last_clock = -math.inf
        self._last_clock_step = None  # (world, step) of the last batch's /clock
        self._last_state = None
        self._latched = {}  # key -> (data, seconds) last sent
        self._removed_reported = 0
        self._sensor_frames = []        # [(parent, child, pose)] of the sensors' static frames
        self._static_key = None         # (world, its sensor specs, the robots) they were made for
        self._robot_topics = {}         # (robot name, namespace, ROBOT_TOPICS key) -> topic key
        self._carriers = frozenset()    # names of the bodies that carry sensors
        self._descriptions = {}         # robot_description topic key -> the URDF last sent
        self._visuals_sent = ([], [])   # the URDF robots' frame prefixes and Visual lists last drawn
        self._sensor_topics = {}        # (sensor name, type, suffix) -> topic key
        self._present = None            # (vehicle specs, robot specs, sensor specs) _withdraw_gone last saw
        self._sensor_job = Job("sensors", math.inf, self.publish_readings)  # errors counted like a job's
        self._withdrawals = Job("withdrawals", math.inf, self._withdraw_gone)  # the same
        self._jobs = {
            "state": Job("state", 1.0 / parameters["publish_rate"], self.publish_state),
            "markers": Job("markers", 1.0 / parameters["marker_rate"], self.publish_markers),
            "rtf": Job("rtf", RTF_PERIOD, self.publish_rtf),
            "diagnostics": Job("diagnostics", DIAGNOSTICS_PERIOD, self.publish_diagnostics),
        }
        self._scenery = Job("scenery", self._scenery_period(), self.publish_scenery)
        self._scenery_pending = False  # handed over and not yet taken: a new request adds nothing
        self._schedule_time = -math.inf  # the time of the last snapshot the listener saw
        self._scheduled_world = None     # and its world
        self._pending = deque()  # (snapshot, due jobs, octree cells or None for no scenery)
        self._in_round = 0       # rounds taken from _pending and not yet published
        self._newcomers = {}     # sink -> latched keys to re-send: sinks with new subscribers (welcome)
        self._welcome_due = 0.0  # time.monotonic() after which they get it (a client's subscriptions come in a burst)
        self._draining = False   # the simulation thread publishes the pending rounds (_end_timeline)
        self._only = threading.local()  # .sink: a sink the publisher thread sends to alone
        self._ready = threading.Condition()
        self._retracting = threading.Lock()  # a robot's description retracted, not resent meanwhile
        self.skipped = 0  # snapshots the publisher fell too far behind to publish
        parameters.listen(self._on_parameters)
        sim.add_listener(self._after_batch)

    def add_sink(self, sink):
        self.sinks.append(sink)
        self.resend_latched(sink)

    def send(self, key, data, seconds):
        topic = self.topics[key]
        only = getattr(self._only, "sink", None)
        if only is not None:
            only.publish(topic, data, seconds)
            return
        if topic.qos == "latched":
            self._latched[key] = (data, seconds)
        for sink in self.sinks:
            sink.publish(topic, data, seconds)

    def resend_latched(self, sink, key=None):
        """The latched topics (scenery, state, /tf_static) as last sent, or the one of `key`,
        to a newcomer (a new sink, a client subscribing) only: the others, the bag above all,
        have them."""
        for latched_key in list(self._latched):
            if key is not None and key != latched_key:
                continue
            # Under _retracting: a robot gone meanwhile (the simulation thread retracts its
            # description) is either sent before its retraction, which withdraws it from the
            # sink, or not at all; sent after it, its channel came back with nothing to remove it.
            with self._retracting:
                latched, topic = self._latched.get(latched_key), self.topics.get(latched_key)
                if latched is not None and topic is not None:
                    sink.publish(topic, *latched)

    def welcome(self, sink, key=None):
        """A client of `sink` subscribed (to the topic `key`): a latched topic's last message is
        sent again, and while paused, when nothing new goes out until something changes, the
        world as it stands (poses, markers, transforms, the car), to that sink alone (a viewer
        joining a paused simulation saw the ground and nothing on it). On the publisher thread,
        WELCOME_GATHER after the first of a burst of subscriptions, once for all of them: a
        client subscribing again and again flooded every other with the scenery."""
        with self._ready:
            if not self._newcomers:
                self._welcome_due = time.monotonic() + WELCOME_GATHER
            keys = self._newcomers.setdefault(sink, set())
            topic = self.topics.get(key)  # None: withdrawn (a robot gone) while a viewer keeps its channel
            if topic is not None and topic.qos == "latched":
                keys.add(key)
            self._ready.notify_all()

    def sensor_topic(self, spec, suffix, robot):
        """The key of a sensor's topic (sensor_messages.topics; `robot` carries it, or None),
        added to the table on first use: the sinks make their publishers and channels for it as
        it comes."""
        ident = (spec["name"], spec["type"], suffix, spec.get("topic"), robot and robot.namespace)
        key = self._sensor_topics.get(ident)
        if key is None:
            topic = next(t for t in sensor_messages.topics(spec, robot) if t.suffix == suffix)
            key = sensor_key(topic)
            self.topics[key] = Topic(key, self.resolve_name(topic.name), topic.type, SENSOR_QOS)
            self._sensor_topics[ident] = key
        return key

    def robot_topic(self, robot, which):
        """The key of one of a robot's topics (ROBOT_TOPICS), its absolute name, added to the
        table on first use: the sinks make their publishers and channels for it as it comes."""
        ident = (robot.name, robot.namespace, which)
        key = self._robot_topics.get(ident)
        if key is None:
            topic = robot_topics(robot, self.resolve_name)[which]
            self.topics[topic.key] = topic
            self._robot_topics[ident] = key = topic.key
        return key

    def _withdraw_gone(self, snapshot):
        """The topics of the robots and sensors that are gone (removed, another scene) no longer
        advertised: each sink that advertises (the ROS publishers: `withdraw`) drops them, so
        spawning and removing under new names does not grow the node's publishers for ever.
        A topic an entity of the snapshot publishes on stays (the root namespace's /odom, taken
        over by another robot), and a robot or sensor spawned again gets its topics again on
        first use. The latched ones (robot_description) are retracted, and leave the table,
        where they are sent (_describe_robots); the bag keeps its channels. On the thread that
        publishes these topics (the publisher's, or the simulation's while it drains), when the
        snapshot's entities changed."""
        present = (snapshot.vehicle_specs, snapshot.robot_specs, snapshot.sensor_specs)
        if self._present is not None and all(a is b for a, b in zip(present, self._present)):
            return
        self._present = present
        robots = self.robots(snapshot)
        live = {topic.key for r in (*robots, *self.urdf_robots(snapshot))
                for topic in robot_topics(r, self.resolve_name).values()}
        carriers = {**link_carriers(snapshot.robot_specs), **{r.name: r for r in robots}}
        live.update(sensor_key(topic) for spec in snapshot.sensor_specs
                    for topic in sensor_messages.topics(spec, carriers.get(spec["parent"])))
        robot_keys, sensor_keys = dict(self._robot_topics), dict(self._sensor_topics)  # (the simulation thread adds)
        kept_robots = {ident: key for ident, key in robot_keys.items() if key in live}
        kept_sensors = {ident: key for ident, key in sensor_keys.items() if key in live}
        gone = ({*robot_keys.values(), *sensor_keys.values()} - {*kept_robots.values(), *kept_sensors.values()})
        if not gone:
            return
        self._robot_topics, self._sensor_topics = kept_robots, kept_sensors
        self._sent_empty.difference_update(gone)
        topics = [self.topics.pop(key) for key in gone]
        # Every sink told of every topic, whatever one of them raises (the first error then goes
        # to the job, counted): a topic left untold stayed in that sink with nothing to remove it.
        failure = None
        for topic in topics:
            for sink in self.sinks:
                try:
                    if hasattr(sink, "withdraw"):
                        sink.withdraw(topic)
                except Exception as error:
                    failure = failure or error
        if failure is not None:
            raise failure

    def robots(self, snapshot):
        """The robots (robots.Robot) of the snapshot's vehicles, in the World's order; made again
        when the vehicles' specs or the frame parameters change."""
        key = (snapshot.vehicle_specs, self.frames, self.parameters["localization"], self.parameters["publish_odom_tf"])
        cached = self._robots
        if cached is None or cached[0][0] is not key[0] or cached[0][1:] != key[1:]:
            made = [robot(spec, self.frames, key[2], key[3]) for spec in snapshot.vehicle_specs.values()]
            self._robots = cached = (key, made)
        return cached[1]

    def urdf_robots(self, snapshot):
        """The URDF robots (urdf_robots.UrdfRobot) of the snapshot, made again when they, the
        bodies' layout or the frame parameters change."""
        key = (snapshot.robot_specs, snapshot.names, self.parameters["localization"], self.parameters["publish_odom_tf"])
        cached = self._urdf_robots
        if cached is None or cached[0][0] is not key[0] or cached[0][1] is not key[1] or cached[0][2:] != key[2:]:
            rows = {name: row for row, name in enumerate(snapshot.names)} if key[0] else {}
            made = [publishing_view(spec, rows, key[2], key[3]) for spec in snapshot.robot_specs]
            self._urdf_robots = cached = (key, made)
        return cached[1]

    def wanted(self, key):
        topic = self.topics[key]
        return any(sink.subscribed(topic) for sink in self.sinks)

    # ------------------------------------------------------------------ schedule
    def _scenery_period(self):
        """The octree cells move with the bodies: while shown, the scenery follows marker_rate."""
        period = self.parameters["static_republish_period"]
        if self.parameters["show_octree"]:
            period = min(period, 1.0 / self.parameters["marker_rate"])
        return period

    def _on_parameters(self, changed):
        # A new period counts from now: the job next goes out at its first multiple after the
        # time last scheduled (it had waited for the time the old period made due: 10 s after
        # publish_rate 0.1 and back, an hour after static_republish_period 3600 and back).
        if "publish_rate" in changed:
            self._jobs["state"].period = 1.0 / changed["publish_rate"]
            self._reschedule(self._jobs["state"])
        if "marker_rate" in changed:
            self._jobs["markers"].period = 1.0 / changed["marker_rate"]
            self._reschedule(self._jobs["markers"])
        if {"show_octree", "static_republish_period", "marker_rate"} & set(changed):
            self._scenery.period = self._scenery_period()
            self._reschedule(self._scenery)
        if "show_octree" in changed:
            self.request_scenery()

    def _reschedule(self, job):
        if math.isfinite(self._schedule_time):  # before the first snapshot every job is due anyway
            job.advance(self._schedule_time)

    def request_scenery(self):
        """The scenery goes out at the next snapshot, which the command itself brings about
        (paused too): it runs on the simulation thread, where the octree can be read."""
        def due_now(_world):
            if not self._scenery_pending:
                self._scenery.due = -math.inf
        self.sim.submit(due_now)

    def scene_changed(self):
        """A new scene (which the schedule itself publishes at once): marker ids restart."""
        self.marker_ids.clear()
        self._ids_of = ([], np.zeros(0, np.int32))

    def publish_loaded(self):
        """The world as loaded, at its time (before the simulation thread starts): every job
        is due, so any speed starts with the same messages."""
        self._after_batch(self.sim.snapshot)

    def _after_batch(self, snapshot):
        """On the simulation thread after each batch (and each command): warnings for bodies
        the world removed, /clock (capped by clock_rate), and the jobs due at this time handed
        to the publisher thread."""
        while self._removed_reported < len(self.sim.removed):
            name = self.sim.removed[self._removed_reported]
            self._removed_reported += 1
            self.log.warning(f"removed {name}: its state went non-finite or it left the world")
        seconds = snapshot.time
        new_timeline = seconds < self._schedule_time
        if new_timeline:
            self._end_timeline()
            latched_before = dict(self._latched)
            self._last_clock = -math.inf  # clock_rate's cap counts in the new time (it had held /clock back
            # until the new time passed the old one's last: a reset after an hour, an hour)
        self._send_clock(snapshot)
        if seconds < self._schedule_time or self.sim.world is not self._scheduled_world:
            # A new scene or a reset of the time: every job at once, the schedule from here.
            for job in (*self._jobs.values(), self._scenery):
                job.due = seconds
        self._schedule_time, self._scheduled_world = seconds, self.sim.world
        due = [job for job in self._jobs.values() if job.is_due(seconds)]
        for job in due:
            job.advance(seconds)
        cells = None
        if self._scenery.is_due(seconds):
            self._scenery.advance(seconds)
            cells = self.sim.world.octree_cells() if self.parameters["show_octree"] else ()
            self._scenery_pending = True
        self._send_state(seconds, self._static_frames_changed(snapshot))
        if new_timeline:
            self._open_timeline(seconds, latched_before)
        self.sim.next_publish_time = min(job.due for job in (*self._jobs.values(), self._scenery))
        if due or cells is not None or snapshot.readings:
            self._hand_over((snapshot, due, cells))

    def _open_timeline(self, seconds, latched_before):
        """The bag's new file (new_timeline: it opens with nothing of the time before) gets the
        latched topics of the simulation thread that this batch did not send again, at the new
        time: what is gone was retracted, and what changed went out already. (Copied from the
        file before, it had opened with the old scene's car's robot_description and sensor
        frames, and static transforms add up: the new world's empty /tf_static removed none.)
        The markers' latched topics come with the first round, every job being due."""
        for key, entry in list(self._latched.items()):
            if latched_before.get(key) is entry and key not in ROUND_LATCHED:
                for sink in self.sinks:
                    if hasattr(sink, "new_timeline"):
                        sink.publish(self.topics[key], entry[0], seconds)

    def _send_clock(self, snapshot):
        """/clock at every step (capped by clock_rate): a batch of several steps (two in real
        time, Simulation.BATCH_PERIOD; up to FAST_BATCH_STEPS as fast as possible) sends one for
        each, in order, when it ends. When time jumped (a reset, another scene) or a late batch
        caught up on more than MAX_CLOCK_FILL steps, one a batch."""
        seconds, step = snapshot.time, snapshot.step
        if seconds == self._last_clock:
            return
        world, last = self.sim.world, self._last_clock_step
        steps = step - last[1] if last is not None and last[0] is world else 0
        times = (seconds,)
        if 1 < steps <= MAX_CLOCK_FILL and seconds > self._last_clock:
            dt = 1.0 / world.settings["steps_per_second"]
            times = tuple(seconds - k * dt for k in range(steps - 1, 0, -1)) + times
        rate = self.parameters["clock_rate"]
        for time_ in times:
            if rate <= 0.0 or time_ - self._last_clock >= 1.0 / rate - 1e-9:
                self._last_clock = time_
                self.send("clock", messages.clock(time_), time_)
        self._last_clock_step = (world, step)

    def _static_frames_changed(self, snapshot):
        """The sensors' static frames made again when the world, its sensors or the robots
        changed (on the simulation thread, which may read the world): True when they differ
        from those last sent."""
        world, robots, urdf_robots = self.sim.world, self.robots(snapshot), self.urdf_robots(snapshot)
        key = (world, world.sensor_specs, robots, urdf_robots)
        if self._static_key is not None and all(a is b for a, b in zip(key, self._static_key)):
            return False
        self._static_key = key
        carriers = link_carriers(snapshot.robot_specs)
        frames = sensor_messages.static_frames(world.sensor_specs, mount_frame(self.frames, robots, carriers),
                                               sensor_frame(robots, carriers))
        frames += [edge for r in urdf_robots for edge in fixed_edges(r)]
        changed = frames != self._sensor_frames
        # The bodies that carry a sensor, whose frames /tf must have: for the publisher thread,
        # which reads no World.
        # (a URDF robot's links are on /tf already)
        self._carriers = frozenset(spec["parent"] for spec in world.sensor_specs) - set(snapshot.vehicle_specs) - set(carriers)
        self._sensor_frames = frames
        self._describe_robots(snapshot, robots, urdf_robots, world.sensor_specs)
        return changed

    def _describe_robots(self, snapshot, robots, urdf_robots, sensor_specs):
        """Each robot's robot_description (URDF, latched; a URDF robot's as loaded), sent when it
        differs from the last one; a robot that is gone leaves no description for a newcomer, nor
        its entry in the topic table. (These are the simulation thread's: it makes, sends and
        retracts them, and they are not among _robot_topics, which the publisher thread prunes.)"""
        current = {}
        texts = [(r, robot_description(snapshot.vehicle_specs[r.name], sensor_specs, r.name, self.frames))
                 for r in robots] + [(r, r.description) for r in urdf_robots]
        for r, text in texts:
            topic = robot_topics(r, self.resolve_name)["robot_description"]
            key = topic.key
            self.topics.setdefault(key, topic)
            current[key] = text
            if self._descriptions.get(key) != text:
                self.send(key, messages.string(text), snapshot.time)
        # The URDF robots' visual elements, locked to their link frames: sent when robots come
        # or go (an empty message when the last goes).
        drawn = [(r.prefix, spec["model"].visuals) for r, spec in zip(urdf_robots, snapshot.robot_specs)]
        if [prefix for prefix, _ in drawn] != self._visuals_sent[0] or any(
                a is not b for a, b in zip([v for _, v in drawn], self._visuals_sent[1])):
            if drawn or self._visuals_sent[0]:
                self.send("robot_visuals", messages.robot_visuals(snapshot.time, drawn), snapshot.time)
            self._visuals_sent = ([prefix for prefix, _ in drawn], [v for _, v in drawn])
        for key in self._descriptions.keys() - current.keys():
            with self._retracting:  # (resend_latched)
                self.retract(key)
                del self.topics[key]
        self._descriptions = current

    def retract(self, key):
        """A latched topic that ended (a robot gone): newcomers no longer get it, a new bag file
        does not open with it, and the ROS publisher that kept it for late subscribers goes."""
        self._latched.pop(key, None)
        for sink in self.sinks:
            if hasattr(sink, "retract"):
                sink.retract(self.topics[key])

    def _send_state(self, seconds, frames_changed=False):
        """~/state when the state changes, and /tf_static (latched) when the static frames do:
        only then, as tf2 expects (a re-sent /tf_static made every listener start its buffer of
        them again at each pause and play)."""
        state = self.sim.state
        if state != self._last_state:
            self._last_state = state
            self.send("state", messages.uint8(state), seconds)
        if frames_changed or "tf_static" not in self._latched:
            frames = self._sensor_frames
            self.send("tf_static", self.tf_static_encoder.encode(seconds, [p for p, _, _ in frames], [c for _, c, _ in frames],
                                                          [pose for _, _, pose in frames]), seconds)

    def _hand_over(self, item):
        with self._ready:
            if self.sim.real_time_factor <= 0.0:  # as fast as possible: wait for the publisher
                self._ready.wait_for(lambda: len(self._pending) < PENDING_LIMIT, HAND_OVER_TIMEOUT)
            if len(self._pending) >= PENDING_LIMIT:
                self._pending.popleft()
                self.skipped += 1
            self._pending.append(item)
            self._ready.notify_all()

    def publish_next(self, timeout=0.1):
        """The publisher thread's round: publishes the next snapshot handed over, waiting up
        to `timeout` s for one; while paused, what the wall clock makes due, and the world to
        the sinks that gained a client (welcome)."""
        with self._ready:
            if not self._pending:
                self._ready.wait(self._paused_wait(timeout))
            if self._draining:
                return  # the simulation thread sends what is pending (_end_timeline)
            item = self._pending.popleft() if self._pending else None
            newcomers = {}
            if self._newcomers and time.monotonic() >= self._welcome_due:
                newcomers, self._newcomers = self._newcomers, {}
            self._in_round += 1
            self._ready.notify_all()
        try:
            if item is not None:
                self._publish_round(item)
            elif self.sim.paused:
                self._publish_paused()
            self._welcome(newcomers)
        finally:
            self._round_done()

    def _round_done(self):
        with self._ready:
            self._in_round -= 1
            self._ready.notify_all()

    def _begin_round(self, snapshot):
        """Before a round's messages (and a paused round's): the sinks that split files there
        are told, and the topics of entities gone are withdrawn."""
        for sink in self.sinks:
            if hasattr(sink, "round_begins"):
                sink.round_begins(snapshot.time)
        self._run(self._withdrawals, snapshot)

    def _publish_round(self, item):
        snapshot, jobs, cells = item
        self._begin_round(snapshot)
        for job in jobs:
            self._run(job, snapshot)
        if cells is not None:
            self._scenery_pending = False
            self._run(self._scenery, snapshot, cells)
        if snapshot.readings:
            self._run(self._sensor_job, snapshot)

    def _end_timeline(self):
        """Time went back (a reset, another scene): the rounds of the time before are sent
        first (here on the simulation thread, or by the publisher thread, which is waited for),
        and then the sinks that keep a timeline (the bag) are told: a bag holds one run of time
        a file, so seeking in it never mixes two worlds."""
        with self._ready:
            self._draining = True  # the publisher thread takes no more rounds
            self._ready.wait_for(lambda: self._in_round == 0, HAND_OVER_TIMEOUT)  # nor is in one
            items = list(self._pending)
            self._pending.clear()
        try:
            for item in items:  # in order, on this thread alone
                self._publish_round(item)
        finally:
            with self._ready:
                self._draining = False
                self._ready.notify_all()
        self._sent_empty.clear()  # a new file opens with each of them once
        for sink in self.sinks:
            if hasattr(sink, "new_timeline"):
                sink.new_timeline()

    def _welcome(self, newcomers):
        """What welcome() gathered: {sink: latched keys}."""
        for sink, keys in newcomers.items():
            for key in keys:
                self.resend_latched(sink, key)
            if not self.sim.paused:
                continue  # running, the next round comes within 1/marker_rate
            snapshot = self.sim.snapshot
            self._only.sink = sink
            try:
                for name in PAUSED_ON_CHANGE:
                    job = self._jobs[name]
                    published = job.published
                    self._run(job, snapshot)
                    job.published = published  # the other sinks' schedule is theirs
            finally:
                self._only.sink = None

    def _paused_wait(self, timeout):
        if not self.sim.paused:
            return timeout
        now = time.monotonic()
        due = [self._jobs[name].wall_due - now for name in PAUSED_JOBS]
        if self._newcomers:
            due.append(self._welcome_due - now)
        return max(0.0, min(timeout, *due))

    def _publish_paused(self):
        now, snapshot = time.monotonic(), self.sim.snapshot
        self._begin_round(snapshot)  # (a bag grown past its split size may split while paused too)
        for name in PAUSED_JOBS:
            job = self._jobs[name]
            if now < job.wall_due:
                continue
            job.wall_due = now + job.period
            if name in PAUSED_ON_CHANGE and job.published is not None and snapshot.version == job.published.version:
                continue
            self._run(job, snapshot)

    def flush(self):
        """After both threads stopped: what is still handed over, then the last state (the
        simulation's too: stopped)."""
        # At most what can be pending: a physics thread that outlived its join, still handing
        # snapshots over (or one that died draining), cannot keep this going.
        for _ in range(PENDING_LIMIT + 1):
            if not self._pending or self._draining:
                break
            self.publish_next(0.0)
        snapshot, state = self.sim.snapshot, self._jobs["state"]
        if state.published is None or state.published.time != snapshot.time:
            self._run(state, snapshot)
        self._send_state(snapshot.time)

    def _run(self, job, snapshot, *args):
        """One job; its failure is logged once with its traceback and counted on /diagnostics,
        and the other jobs go on."""
        try:
            job.publish(snapshot, *args)
        except Exception as error:
            self._failed(job, error)
        job.published = snapshot

    def _failed(self, job, error):
        job.errors += 1
        job.last_error = f"{type(error).__name__}: {error}"
        if job.errors == 1:
            self.log.error(f"publishing {job.name} failed (logged once, counted on /diagnostics):\n"
                           f"{traceback.format_exc()}")

    # ------------------------------------------------------------------ topics
    def publish_state(self, snap):
        frames = self.frames
        self.send("poses", cdr.pose_array_of(snap.time, frames.world, self.pose_block(snap)), snap.time)
        s = snap.state
        moving = []  # (parent, child, pose) of every robot: /tf's after the bodies
        if self._odometry.keys() - snap.vehicle_specs.keys():  # a robot gone: spawned again, it starts afresh
            self._odometry = {n: e for n, e in self._odometry.items() if n in snap.vehicle_specs}
        for r in self.robots(snap):
            row = snap.names.index(r.name)
            truth = (s["positions"][row], s["quaternions"][row])
            linear, angular = s["linear_velocities"][row], s["angular_velocities"][row]
            spec, state = snap.vehicle_specs[r.name], snap.vehicles[r.name]
            tracker = self.odometry_tracker(r.name, spec, snap, truth, linear)
            measured = truth if tracker.noiseless else tracker.update(*truth, snap.time)
            transforms = robot_transforms(r, truth, measured, state, spec["wheels"], frames.world)
            # base_footprint in odom; its twist in its own axes, which the true heading turns,
            # with the error the odometry made over its last interval. base_footprint stays
            # level, so it turns about the vertical only: the chassis' roll and pitch rates
            # are not its (wheel odometry measures neither).
            to_world = quaternions_to_matrices(np.asarray(truth[1], float)[None])[0]
            turn = angular + to_world @ tracker.twist_error[3:]
            self.send(self.robot_topic(r, "odom"), messages.odometry(
                snap.time, r.frames.odom, r.frames.footprint, footprint_pose(*measured, r.ride_height),
                footprint_pose(*truth, r.ride_height)[1], linear + to_world @ tracker.twist_error[:3],
                np.array([0.0, 0.0, turn[2]]), tracker.pose_covariance.ravel(),
                tracker.twist_covariance.ravel()), snap.time)
            self.send(self.robot_topic(r, "ground_truth"), messages.odometry(
                snap.time, frames.world, r.frames.base, truth, truth[1], linear, angular), snap.time)
            self.send(self.robot_topic(r, "joint_states"), messages.joint_states(snap, r.name), snap.time)
            self.send(self.robot_topic(r, "command"), messages.car_command(snap, r.name, r.frames.base), snap.time)
            moving += transforms
        moving += self.publish_urdf_robots(snap)
        for parent, child, pose in [*moving, *self._sensor_frames]:  # the sensors': static, the same each time
            self.send("transforms", cdr.transform_stamped(snap.time, parent, child, pose), snap.time)
        rows, parents, children = self.tf_frames(snap, moving)
        for row in rows.tolist():  # the bodies /tf carries, as /tf has them
            self.send("transforms", cdr.transform_stamped(
                snap.time, frames.world, snap.names[row], [*s["positions"][row], *s["quaternions"][row]]), snap.time)
        if self.wanted("tf") and not self._repeats_empty("tf", len(rows) == 0 and not moving):
            poses = self.pose_block(snap)
            poses = poses if len(rows) == len(snap.names) else poses[rows]
            if moving:
                poses = np.concatenate([poses, np.asarray([p for _, _, p in moving], float).reshape(-1, 7)])
            self.send("tf", self.tf_encoder.encode(snap.time, parents, children, poses), snap.time)

    def publish_urdf_robots(self, snap):
        """Each URDF robot's joint_states and, with a drive, its wheel odometry; returns the
        /tf edges of its moving links and of its root (in the world, or REP 105's chain)."""
        edges, world_frame = [], self.frames.world
        if self._wheel_odometry.keys() - snap.robot_joints.keys():  # a robot gone: spawned again, it starts afresh
            self._wheel_odometry = {n: o for n, o in self._wheel_odometry.items() if n in snap.robot_joints}
        for r in self.urdf_robots(snap):
            positions, velocities, efforts = snap.robot_joints[r.name]
            self.send(self.robot_topic(r, "joint_states"),
                      messages.joint_state(snap.time, r.joint_names, positions, velocities, efforts), snap.time)
            root = root_pose(r, snap.state)
            if r.drive is None:
                edges.append((world_frame, r.frame(r.root), root))
            else:
                edges += self._drive_odometry(r, snap, root, positions)
            edges += link_edges(r, snap.state)
        return edges

    def _drive_odometry(self, r, snap, root, positions):
        """A drive's odometry from its wheel joints (odom -> root, the message), and the true
        pose over it (<world_frame> -> odom) with ground_truth localization."""
        wheels = [positions[r.joint_names.index(joint)] for joint in drive_joints(r.drive)]
        odometry, seen = self._wheel_odometry.get(r.name, (None, None))
        velocity = snap.state["linear_velocities"][r.body_rows[0]]
        # Started at the true pose (world -> odom as at spawn) when the robot is new, its drive
        # changed, time went back or it was put where it could not have driven to (a teleport:
        # ~/edit, SetEntityState), as a vehicle's odometry (odometry_tracker).
        if (odometry is None or odometry.drive is not r.drive
                or not drove(seen, odometry.time, root[:3], velocity, snap.time)):
            level = footprint_pose(root[:3], root[3:], 0.0)[1]  # the heading alone
            yaw = 2.0 * math.atan2(level[2], level[3])
            odometry = WheelOdometry(r.drive, (root[0], root[1], yaw), wheels, snap.time)
        else:
            odometry.update(wheels, snap.time)
        self._wheel_odometry[r.name] = (odometry, root[:3])
        measured = odometry.pose()
        odom = r.frame(self.frames.odom)
        edges = []
        if r.localization == "ground_truth":
            truth = (root[:3], root[3:])
            edges.append((self.frames.world, odom, as_pose(compose(truth, inverse((measured[:3], measured[3:]))))))
        if r.publish_odom_tf:
            edges.append((odom, r.frame(r.root), measured))
        turn = quaternions_to_matrices(np.asarray(measured[3:], float)[None])[0]
        self.send(self.robot_topic(r, "odom"), messages.odometry(
            snap.time, odom, r.frame(r.root), (measured[:3], measured[3:]), measured[3:],
            turn @ [odometry.linear, 0.0, 0.0], [0.0, 0.0, odometry.angular], WHEEL_ODOMETRY_COVARIANCE,
            WHEEL_ODOMETRY_COVARIANCE), snap.time)
        return edges

    def odometry_tracker(self, name, spec, snap, truth, velocity):
        """The robot's OdometryTracker, started at the true pose when the robot is new (another
        car of its name, by body id, even one spawned within a round; or its error model
        changed; a robot removed is forgotten at the next round), when time went back (a reset,
        another scene) and when the robot moved farther than it can drive since the last round
        (a teleport: ~/edit, initialpose); the odom frame then starts where the robot stands, as
        a robot's driver starts again."""
        model, body_id = spec.get("odometry"), snap.vehicle_ids.get(name)
        entry = self._odometry.get(name)
        if entry is not None:
            tracker, last_model, last_id = entry
            if (last_model == model and last_id == body_id
                    and (tracker.noiseless or drove(tracker.position, tracker.time, truth[0], velocity, snap.time))):
                return tracker
        tracker = OdometryTracker(name, model)
        tracker.reset(*truth, snap.time)
        self._odometry[name] = (tracker, model, body_id)
        return tracker

    def pose_block(self, snap):
        """(N, 7) float64 rows of xyz + xyzw, read-only, made once per motion state: for
        ~/bodies/poses, the markers and /tf alike, and for as long as a settled world's
        snapshots share their arrays."""
        positions, quaternions = snap.state["positions"], snap.state["quaternions"]
        cached = self._pose_block
        if cached is None or cached[0] is not positions or cached[1] is not quaternions:
            block = np.concatenate([positions, quaternions], axis=1).astype("<f8", copy=False)
            block.flags.writeable = False
            self._pose_block = cached = (positions, quaternions, block)
        return cached[2]

    def tf_frames(self, snap, moving):
        """/tf's body rows (an index array: every body with publish_body_frames, else those that
        carry a sensor, whose frames hang from them), parents and children (tuples): world ->
        each of those bodies, then the robots' frames. Made again only when the names (a list
        shared by the snapshots of one layout), the sensors or the robots' frames change."""
        names, carriers = snap.names, self._carriers
        key = (names, carriers, self.parameters["publish_body_frames"], tuple((p, c) for p, c, _ in moving))
        cached = self._tf_frames
        if cached is None or cached[0][0] is not names or cached[0][1] is not carriers or cached[0][2:] != key[2:]:
            if key[2]:
                rows = np.arange(len(names))
            else:
                rows = np.array([row for row, name in enumerate(names) if name in carriers], np.int64)
            parents = (self.frames.world,) * len(rows) + tuple(p for p, _ in key[3])
            children = tuple(names[row] for row in rows.tolist()) + tuple(c for _, c in key[3])
            self._tf_frames = cached = (key, rows, parents, children)
        return cached[1], cached[2], cached[3]

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

    def publish_markers(self, snap):
        world_frame = self.frames.world
        ids, poses = self.marker_ids_of(snap.names), self.pose_block(snap)
        if self.wanted("body_markers") and not self._repeats_empty(
                "body_markers", self.body_markers.draws_nothing(snap, ids)):
            self.send("body_markers", self.body_markers.encode(snap, world_frame, ids, poses), snap.time)
        self._publish_resting_markers(snap, ids, poses)
        for r in self.robots(snap):
            key = self.robot_topic(r, "markers")
            if self.wanted(key):
                self.send(key, messages.car_markers(snap, r.name, world_frame, snap.vehicle_specs[r.name]["wheels"]),
                          snap.time)
        if snap.contacts is not None:
            # Turned off, the topics draw nothing, as with nothing touching: one message that
            # clears what they drew (the last contacts had stayed in the viewer and the bag).
            limit = self.parameters["contacts.max_points"] if self.parameters["contacts.publish"] else 0
            touching = len(snap.contacts["depths"]) > 0 and limit > 0
            if self.wanted("contact_points") and not self._repeats_empty("contact_points", not touching):
                self.send("contact_points", messages.contact_cloud(snap, world_frame, limit), snap.time)
            if self.wanted("contact_markers") and not self._repeats_empty("contact_markers", not touching):
                self.send("contact_markers", messages.contact_markers(snap, world_frame, limit), snap.time)

    def _repeats_empty(self, key, empty):
        """Whether the per-round topic's message would draw or carry nothing, as its last one
        did: a world at rest would repeat it every round, and a viewer (or a seek in the bag)
        shows the same from the last. Each such run starts with one message (its DELETEALL
        clears what the topic drew), and a newcomer's own round (welcome) always gets one."""
        if getattr(self._only, "sink", None) is not None:
            return False
        if not empty:
            self._sent_empty.discard(key)
            return False
        if key in self._sent_empty:
            return True
        self._sent_empty.add(key)
        return False

    def _publish_resting_markers(self, snap, ids, poses):
        """The bodies at rest (latched) when what they draw changed (a body froze, woke, was
        spawned, edited, removed or moved while frozen) and every static_republish_period, so a
        bag seeks to a complete scene; a round of a world at rest sends none. Built whether or
        not a sink wants it now: a client subscribing later gets the latched copy (welcome),
        which must be the current one. A newcomer's own round (welcome) has that copy already."""
        if getattr(self._only, "sink", None) is not None:
            return
        last, period = self._resting_sent, self.parameters["static_republish_period"]
        if (last is not None and 0.0 <= snap.time - last < period
                and self.resting_markers.draws_the_same(snap, ids, poses)):
            return
        self.send("resting_markers", self.resting_markers.encode(snap, self.frames.world, ids, poses), snap.time)
        self._resting_sent = snap.time

    def publish_scenery(self, snap, octree_cells):
        """The scenery, latched (octree_cells read on the simulation thread at this snapshot)."""
        self.send("scene_markers", messages.scene_markers(snap.time, self.frames.world, snap.scenery.ground,
                                                          snap.scenery.triangles, octree_cells), snap.time)

    def publish_rtf(self, snap):
        self.send("rtf", messages.float64(self.sim.achieved_rtf), snap.time)

    def publish_diagnostics(self, snap):
        sim = self.sim
        frozen = int(np.count_nonzero(snap.state["frozen"]))
        active, removed = len(snap.names) - frozen, len(sim.removed)
        target = f"{sim.real_time_factor:.2f}" if sim.real_time_factor > 0.0 else "max"
        step_ms = sim.mean_step_ms
        summary = (f"{STATE_NAMES[sim.state]}, RTF {sim.achieved_rtf:.2f}/{target}, "
                   f"step {step_ms:.2f} ms, {sim.late_ticks} late ticks")
        if sim.fault_count:
            summary += f", {sim.fault_count} errors survived (first: {sim.faults[0]})"
        statuses = [
            ("simulation", ERROR if sim.fault_count else OK, summary,
             {"target_real_time_factor": sim.real_time_factor, "achieved_real_time_factor": round(sim.achieved_rtf, 3),
              "step_ms": round(step_ms, 4), "late_ticks": sim.late_ticks, "errors": sim.fault_count,
              "simulation_thread_cpu_s": round(sim.thread_cpu_seconds, 3),
              "engine_cpu_s": round(sim.engine_cpu_seconds, 3), "time": round(snap.time, 4),
              # the solver threads the last batch ran with, and what the last trial of the
              # second one measured (thread_choice)
              "solver_threads_in_use": sim.solver_threads_in_use,
              "second_thread_speedup": round(sim.second_thread_speedup or 0.0, 3)}),
            ("bodies", WARN if removed else OK,
             f"{len(snap.names)} bodies: {active} active, {frozen} frozen, {removed} removed",
             {"active": active, "frozen": frozen, "removed": removed,
              "last_removed": sim.removed[-1] if sim.removed else ""}),
        ]
        for r in self.robots(snap):
            age = snap.vehicles[r.name]["command_age"]
            statuses.append((f"robot {r.name}", OK, f"{r.name}: last command {age:.1f} s ago",
                             {"command_age": round(age, 3), "namespace": r.namespace, "localization": r.localization}))
        failed = [job for job in (*self._jobs.values(), self._scenery, self._sensor_job, self._withdrawals)
                  if job.errors]
        statuses.append(("publisher", ERROR if failed else (WARN if self.skipped else OK),
                         "; ".join(f"{job.name} failed {job.errors} times: {job.last_error}" for job in failed)
                         or f"publishing, {self.skipped} snapshots skipped",
                         {**{f"{job.name}_errors": job.errors for job in failed}, "skipped": self.skipped}))
        for sink in self.sinks:
            statuses.extend(sink.statuses())
        self.send("diagnostics", messages.diagnostics(snap.time, statuses), snap.time)

    def publish_readings(self, snap):
        """The sensors read after this snapshot's step: each reading's messages, built when
        some sink wants one of its topics (the bag always does)."""
        robots = self.robots(snap)
        links = link_carriers(snap.robot_specs)
        carriers, frame_of = {**links, **{r.name: r for r in robots}}, sensor_frame(robots, links)
        for sensor, reading in snap.readings:
            try:  # one sensor's failure (a sink refusing its topic) leaves the others publishing
                self._publish_reading(sensor.spec, reading, carriers.get(sensor.spec["parent"]), frame_of)
            except Exception as error:
                self._failed(self._sensor_job, error)

    def _publish_reading(self, spec, reading, robot, frame_of):
        keys = {suffix: self.sensor_topic(spec, suffix, robot) for suffix, _ in sensor_messages.TOPIC_SUFFIXES[spec["type"]]}
        if any(self.wanted(key) for key in keys.values()):
            for suffix, data in sensor_messages.build(spec, reading, reading["time"], frame_of(spec)):
                self.send(keys[suffix], data, reading["time"])


def drove(seen, seen_time, position, velocity, seconds):
    """Whether a robot could have driven from where its odometry last saw it (`seen`, at
    `seen_time`) to its true `position` now, at `velocity` (not when time went back, or it was
    put somewhere else)."""
    dt = seconds - seen_time
    if dt < 0.0:
        return False
    reach = (float(np.linalg.norm(velocity)) + MAX_ACCELERATION * dt) * dt + TELEPORT_SLACK
    return float(np.linalg.norm(np.subtract(position, seen))) <= reach


def check_sensors(sensor_specs, world, frames):
    """The robots' and sensors' topics against each other's and the node's (check_topics), and
    the sensors' frames against each other's and the robots' under the frame names `frames`
    (parameters.Frames) (SpecError naming the key): `sensor_specs` as if the world's."""
    robots = world_robots(world, frames)
    check_topics(sensor_specs, robots, world.robot_specs)
    check_sensor_frames(sensor_specs, robots, world.robot_specs, frames)


def check_topics(sensor_specs, robots, robot_specs=()):
    """Refuses a robot or a sensor with a topic that the node, an earlier robot (in the World's
    order) or another sensor publishes on, or the node subscribes to (a second type on one name:
    the node's /tf with an Imu in it), naming both. `robots`: robots.Robot of the world's
    vehicles, whose own topics under ~/<name> are where the node's are (a car named `bodies`
    published its markers on the node's ~/bodies/markers), and which two names ('car.b',
    'car_b') would share; `robot_specs`: the URDF robots (World.robot_specs). Names compared
    as the root namespace resolves them: a node's namespace or remap moves them all alike."""
    from .inputs import SUBSCRIPTIONS, URDF_ROBOT_INPUTS  # (inputs imports the requests, which import this module)
    from .physics.specs import SpecError
    taken = {resolve(t.name): f"the node's {t.name}" for t in TOPICS}
    # The node's cmd_vel is the root namespace's robot's (when there is one).
    taken.update({resolve(s.name): f"the node's subscription {s.name}" for s in SUBSCRIPTIONS if s.key != "cmd_vel"})

    def claim(name, owner, path, hint=""):
        if name in taken:
            raise SpecError(path, f"{name} is {taken[name]} already{hint}")
        taken[name] = owner
    for r in robots:
        for which, t in robot_topics(r).items():
            claim(t.name, f"{r.name}'s {which}", f"{r.name}.name" if t.name.startswith(resolve("~/")) else
                  f"{r.name}.namespace", " (another name or namespace for the robot)")
        claim(resolve(r.topic("cmd_vel")), f"{r.name}'s cmd_vel", f"{r.name}.namespace")
    for spec in robot_specs:
        prefix = namespace_prefix(spec["namespace"])
        suffixes = ["joint_states", "robot_description", *(s.name for s in URDF_ROBOT_INPUTS)]
        suffixes += ["cmd_vel", "odom"] if spec.get("drive") else []
        for suffix in suffixes:
            claim(resolve(prefix + suffix), f"{spec['name']}'s {suffix}", f"{spec['name']}.namespace")
    taken.setdefault(resolve("cmd_vel"), "the node's subscription cmd_vel")
    carriers = {**link_carriers(robot_specs), **{robot.name: robot for robot in robots}}
    for spec in sensor_specs:
        for topic in sensor_messages.topics(spec, carriers.get(spec["parent"])):
            claim(resolve(topic.name), f"the sensor {spec['name']}'s", f"{spec['name']}.topic",
                  f" (give the sensor {'another' if 'topic' in spec else 'a'} `topic`)")


def sensor_key(topic):
    """The topic table's key of a sensor's topic (sensor_messages.SensorTopic): its name and type."""
    return f"sensor:{topic.name}:{topic.type}"


def robot_topics(robot, resolve_name=resolve):
    """{ROBOT_TOPICS key: Topic} of a robot, each keyed by its absolute name (unique, and what
    a reader asks for)."""
    out = {}
    for which, (suffix, kind, qos, private) in ROBOT_TOPICS.items():
        name = resolve_name(f"~/{specs.name_token(robot.name)}/{suffix}" if private else robot.topic(suffix))
        out[which] = Topic(name, name, kind, qos)
    return out
