"""The ROS 2 node `vplayground` (SPEC 6): the Simulation in the ROS graph.

The physics runs in the Simulation's thread. ROS callbacks never touch the World: services and
subscriptions hand their work to the simulation thread (Requests, Simulation.submit), and
publishers read the snapshot taken after the latest batch.
"""
import math

import numpy as np
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.srv import AddDiagnostics
from geometry_msgs.msg import (PointStamped, PoseArray, PoseWithCovarianceStamped, TransformStamped,
                               Twist, TwistStamped, WrenchStamped)
from nav_msgs.msg import Odometry
from nav_msgs.srv import LoadMap
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64, UInt8
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import InteractiveMarker, InteractiveMarkerControl, Marker, MarkerArray
from visualization_msgs.srv import GetInteractiveMarkers

try:  # only a real ROS install has tf2_msgs (SPEC 6.1); ~/transforms serves Foxglove without it
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

from . import cdr, messages
from .api import Requests
from .physics import specs
from .physics.math3d import rpy_to_quat
from .physics.world import quaternions_to_matrices

RELIABLE_1 = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
RELIABLE_10 = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
RELIABLE_100 = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
# Best effort, depth 1: matches both reliable and best-effort publishers (Foxglove's Teleop).
COMMAND_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST)

PHYSICS = ("gravity", "steps_per_second", "resolve_iterations", "octree_depth", "freezing.enabled",
           "freezing.time", "freezing.linear_speed", "freezing.angular_speed")


def float_range(low, high):
    return dict(floating_point_range=[FloatingPointRange(from_value=float(low), to_value=float(high))])


def int_range(low, high):
    return dict(integer_range=[IntegerRange(from_value=int(low), to_value=int(high), step=1)])


def parameter_table(world, options):
    """(name, default, description, extra descriptor fields) of every SPEC 6.4 parameter; the
    physics ones default to the scene's values."""
    s = world.settings
    f = s["freezing"]
    return [
        ("scene", str(options.scene), "scene file loaded at start", dict(read_only=True)),
        ("real_time_factor", float(options.real_time_factor),
         "simulated seconds per wall-clock second; 0 = as fast as possible", float_range(0, 1000)),
        ("start_paused", bool(options.start_paused), "start paused (~/pause false to play)", dict(read_only=True)),
        ("duration", float(options.duration or 0.0),
         "stop after this much simulated time, s (0 = run until stopped)", dict(read_only=True)),
        ("gravity", [float(v) for v in s["gravity"]], "gravity vector, m/s^2, world frame", {}),
        ("steps_per_second", int(s["steps_per_second"]), "physics steps per simulated second", int_range(1, 10000)),
        ("resolve_iterations", int(s["resolve_iterations"]),
         "collision passes per step (contact passes are twice this)", int_range(1, 100)),
        ("octree_depth", int(s["octree_depth"]), "depth of the broad-phase octree", int_range(1, 10)),
        ("freezing.enabled", bool(f["enabled"]), "freeze bodies at rest", {}),
        ("freezing.time", float(f["time"]), "seconds below the thresholds before freezing", float_range(0, 1e6)),
        ("freezing.linear_speed", float(f["linear_speed"]), "freezing threshold, m/s", float_range(0, 1e6)),
        ("freezing.angular_speed", float(f["angular_speed"]), "freezing threshold, rad/s", float_range(0, 1e6)),
        ("publish_rate", 30.0, "Hz of poses, odometry, joint states, transforms", float_range(0.1, 1000)),
        ("marker_rate", 30.0, "Hz of marker topics (when subscribed)", float_range(0.1, 1000)),
        ("static_republish_period", 5.0, "s between re-sends of the static scene markers", float_range(0.1, 3600)),
        ("clock_rate", 0.0, "Hz cap of /clock (0 = after every batch of steps)", float_range(0, 10000)),
        ("contacts.publish", True, "publish the contact topics", {}),
        ("contacts.max_points", 5000, "most contact points published", int_range(0, 1000000)),
        ("show_octree", False, "draw the occupied octree cells in ~/scene/markers", {}),
        ("cmd_vel_timeout", 1.2, "s without cmd_vel before the car brakes to rest", float_range(0.01, 3600)),
        ("cmd_vel_stamped", False, "cmd_vel is geometry_msgs/TwistStamped", dict(read_only=True)),
        ("world_frame", "world", "fixed frame of the simulation", dict(read_only=True)),
        ("odom_frame", "odom", "the car's odometry frame", dict(read_only=True)),
        ("base_frame", "base_link", "the car's body frame", dict(read_only=True)),
        ("publish_body_frames", False, "publish a transform per body on ~/transforms", {}),
        ("step_count", 1, "steps one ~/step call advances", int_range(1, 1000000)),
        ("reset_scope", 255, "~/reset scope bits: 1 TIME, 2 STATE, 4 SPAWNED, 255 ALL", int_range(1, 255)),
        ("click_spawn_size", 0.5, "edge of the box a clicked_point drops, m", float_range(0.01, 100)),
        ("click_spawn_height", 2.0, "height above the clicked point it drops from, m", float_range(0, 1000)),
        ("record", str(options.record or ""), "MCAP bag being written ('' = not recording)", dict(read_only=True)),
        ("record_split_size", int(options.record_split_size), "bytes after which the bag continues in a new file (0 = one file)",
         dict(read_only=True, **int_range(0, 1 << 50))),
    ]


class SimulatorNode(Node):
    def __init__(self, simulation, options, recorder=None):
        super().__init__("vplayground")
        self.sim = simulation
        self.recorder = recorder
        self.tf_encoder = cdr.TransformEncoder()
        self.requests = Requests(simulation, str(options.scene))
        self.marker_ids = {}
        self._last_clock = -math.inf
        self._last_static = -math.inf
        self._last_state = None
        self._removed_reported = 0
        self.marker_encoder = cdr.BodyMarkerEncoder()
        self._declare_parameters(options)
        if self.get_parameter("use_sim_time").value:
            self.get_logger().warning("use_sim_time is set: ignored, this node is the time source")
        self.frames = tuple(self.get_parameter(p).value for p in ("world_frame", "odom_frame", "base_frame"))
        self._make_publishers()
        self._make_subscriptions()
        self._make_services()
        self.sim.add_listener(self._after_batch)
        self._publish_timers = {}
        self._restart_timers()
        if self.recorder is not None:
            self._record_tf_static(self.sim.snapshot.time)
        self._static_timer = self.create_timer(0.1, self._publish_static)
        self.create_timer(0.5, self._publish_rtf)
        self.create_timer(1.0, self._publish_diagnostics)

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self, options):
        for name, default, description, extra in parameter_table(self.sim.world, options):
            self.declare_parameter(name, default, ParameterDescriptor(description=description, **extra))
        self.add_on_set_parameters_callback(self._on_parameters)
        # Overrides given with --ros-args -p act on the world at start.
        overrides = {p: self.get_parameter(p).value for p in PHYSICS}
        settings = self._settings_from(overrides)
        self.sim.call(lambda world: world.update_settings(settings))
        self.sim.real_time_factor = self.get_parameter("real_time_factor").value

    @staticmethod
    def _settings_from(values):
        settings, freezing = {}, {}
        for name, value in values.items():
            if name.startswith("freezing."):
                freezing[name.split(".", 1)[1]] = value
            else:
                settings[name] = list(value) if name == "gravity" else value
        if freezing:
            settings["freezing"] = freezing
        return settings

    def _on_parameters(self, parameters):
        physics = {p.name: p.value for p in parameters if p.name in PHYSICS}
        if physics:
            settings = self._settings_from(physics)
            try:
                merged = {**self.sim.world.settings, **settings}
                if "freezing" in settings:
                    merged["freezing"] = {**self.sim.world.settings["freezing"], **settings["freezing"]}
                specs.validate_settings(merged)
            except ValueError as error:
                return SetParametersResult(successful=False, reason=str(error))
            self.sim.call(lambda world: world.update_settings(settings))
        for p in parameters:
            if p.name == "real_time_factor":
                self.sim.real_time_factor = p.value
        if any(p.name in ("publish_rate", "marker_rate") for p in parameters):
            self._restart_timers({p.name: p.value for p in parameters})
        return SetParametersResult(successful=True)

    def _restart_timers(self, new=None):
        new = new or {}
        for name in list(self._publish_timers):
            self.destroy_timer(self._publish_timers.pop(name))
        rate = new.get("publish_rate") or self.get_parameter("publish_rate").value
        marker_rate = new.get("marker_rate") or self.get_parameter("marker_rate").value
        self._publish_timers["state"] = self.create_timer(1.0 / rate, self._publish_state)
        self._publish_timers["markers"] = self.create_timer(1.0 / marker_rate, self._publish_markers)

    # ------------------------------------------------------------------ publishers
    def _make_publishers(self):
        self.clock_pub = self.create_publisher(Clock, "/clock", RELIABLE_1)
        self.markers_pub = self.create_publisher(MarkerArray, "~/bodies/markers", RELIABLE_1)
        self.poses_pub = self.create_publisher(PoseArray, "~/bodies/poses", RELIABLE_1)
        self.scene_pub = self.create_publisher(MarkerArray, "~/scene/markers", LATCHED)
        self.contacts_pub = self.create_publisher(PointCloud2, "~/contacts/points", RELIABLE_1)
        self.contact_markers_pub = self.create_publisher(MarkerArray, "~/contacts/markers", RELIABLE_1)
        self.transforms_pub = self.create_publisher(TransformStamped, "~/transforms", RELIABLE_100)
        self.odom_pub = self.create_publisher(Odometry, "odom", RELIABLE_10)
        self.truth_pub = self.create_publisher(Odometry, "~/car/ground_truth", RELIABLE_10)
        self.joints_pub = self.create_publisher(JointState, "joint_states", RELIABLE_10)
        self.command_pub = self.create_publisher(TwistStamped, "~/car/command", RELIABLE_10)
        self.car_markers_pub = self.create_publisher(MarkerArray, "~/car/markers", RELIABLE_1)
        self.state_pub = self.create_publisher(UInt8, "~/state", LATCHED)
        self.rtf_pub = self.create_publisher(Float64, "~/real_time_factor", RELIABLE_10)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE_10)
        self.tf_pub = self.create_publisher(TFMessage, "/tf", RELIABLE_100) if TFMessage else None

    def send(self, publisher, msg, seconds, latched=False):
        """Serialises once (or takes CDR bytes as they are), publishes, and records the same
        bytes with log time = simulation time."""
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        publisher.publish(data)
        if self.recorder is not None:
            kind = publisher.msg_type
            self.recorder.write(publisher.topic_name, f"{kind.__module__.split('.')[0]}/msg/{kind.__name__}",
                                data, seconds, latched)

    def wanted(self, publisher):
        """Visual topics are built only for a subscriber or the bag."""
        return self.recorder is not None or publisher.get_subscription_count() > 0

    def _record_tf(self, snap, car, wheels):
        """The bag's /tf (tf2_msgs/TFMessage, written without tf2_msgs): world -> every body
        (child = its name), odom -> base_link and base_link -> each wheel."""
        s = snap.state
        parents = [self.frames[0]] * len(snap.names)
        children = list(snap.names)
        poses = [np.concatenate([p, q]) for p, q in zip(s["positions"], s["quaternions"])]
        if car is not None and wheels is not None:
            for t in messages.car_transforms(snap, car, self.frames, wheels)[1:]:
                parents.append(t.header.frame_id)
                children.append(t.child_frame_id)
                tr, rot = t.transform.translation, t.transform.rotation
                poses.append([tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w])
        self.recorder.write("/tf", "tf2_msgs/msg/TFMessage",
                            self.tf_encoder.encode(snap.time, parents, children, poses), snap.time)

    def _record_tf_static(self, seconds):
        """/tf_static: the fixed world -> odom (the car's start)."""
        data = self.tf_encoder.encode(seconds, [self.frames[0]], [self.frames[1]], [[0, 0, 0, 0, 0, 0, 1.0]])
        self.recorder.write("/tf_static", "tf2_msgs/msg/TFMessage", data, seconds, latched=True)

    def car(self, snapshot):
        """The driven car: the first vehicle of the world, or None."""
        return next(iter(snapshot.vehicles), None)

    def _after_batch(self, snapshot):
        """On the simulation thread after each batch: warnings for bodies the world removed,
        and /clock, capped by clock_rate."""
        while self._removed_reported < len(self.sim.removed):
            name = self.sim.removed[self._removed_reported]
            self._removed_reported += 1
            self.get_logger().warning(f"removed {name}: its state went non-finite or it left the world")
        rate = self.get_parameter("clock_rate").value
        if rate > 0.0 and snapshot.time - self._last_clock < 1.0 / rate - 1e-9:
            return
        self._last_clock = snapshot.time
        self.send(self.clock_pub, messages.clock(snapshot.time), snapshot.time)

    def _publish_state(self):
        snap = self.sim.snapshot
        world_frame, odom_frame, base_frame = self.frames
        self.send(self.poses_pub, messages.pose_array(snap, world_frame), snap.time)
        state = self.sim.state
        if state != self._last_state:
            self._last_state = state
            self.send(self.state_pub, UInt8(data=state), snap.time, latched=True)
        car = self.car(snap)
        if car is not None:
            self.send(self.odom_pub, messages.car_odometry(snap, car, odom_frame, base_frame), snap.time)
            self.send(self.truth_pub, messages.car_odometry(snap, car, world_frame, base_frame), snap.time)
            self.send(self.joints_pub, messages.joint_states(snap, car), snap.time)
            self.send(self.command_pub, messages.car_command(snap, car, base_frame), snap.time)
            wheels = self.car_wheels(car)
            if wheels is not None:
                transforms = messages.car_transforms(snap, car, self.frames, wheels)
                for t in transforms:
                    self.send(self.transforms_pub, t, snap.time)
                if self.tf_pub is not None:
                    self.tf_pub.publish(TFMessage(transforms=transforms))  # the bag's /tf: _record_tf
        if self.recorder is not None:
            self._record_tf(snap, car, self.car_wheels(car) if car is not None else None)
        if self.get_parameter("publish_body_frames").value:
            s = snap.state
            for row, name in enumerate(snap.names):
                self.send(self.transforms_pub, messages.transform(
                    snap.time, world_frame, name, s["positions"][row], s["quaternions"][row]), snap.time)

    def car_wheels(self, car):
        """The car's wheel specs (they change only through ~/edit), or None once it is gone."""
        try:
            return self.sim.world.vehicle(car)["wheels"]
        except KeyError:
            return None

    def marker_id(self, name):
        if name not in self.marker_ids:
            self.marker_ids[name] = len(self.marker_ids)
        return self.marker_ids[name]

    def _publish_markers(self):
        snap = self.sim.snapshot
        world_frame = self.frames[0]
        if self.wanted(self.markers_pub):
            self.send(self.markers_pub, messages.body_markers(snap, world_frame, self.marker_id,
                                                              self.marker_encoder), snap.time)
        car = self.car(snap)
        if car is not None and self.wanted(self.car_markers_pub):
            wheels = self.car_wheels(car)
            if wheels is not None:
                self.send(self.car_markers_pub, messages.car_markers(snap, car, world_frame, wheels), snap.time)
        if self.get_parameter("contacts.publish").value and snap.contacts is not None:
            limit = self.get_parameter("contacts.max_points").value
            if self.wanted(self.contacts_pub):
                self.send(self.contacts_pub, messages.contact_cloud(snap, world_frame, limit), snap.time)
            if self.wanted(self.contact_markers_pub):
                self.send(self.contact_markers_pub, messages.contact_markers(snap, world_frame, limit), snap.time)

    def _publish_static(self):
        """The scenery, latched: at start, after a scene load, every static_republish_period
        (so a bag seeks into a full scene), and at marker_rate while the octree is shown."""
        snap = self.sim.snapshot
        period = self.get_parameter("static_republish_period").value
        show_octree = self.get_parameter("show_octree").value
        if show_octree:
            period = min(period, 1.0 / self.get_parameter("marker_rate").value)
        if snap.time - self._last_static < period and self._last_static >= 0:
            return
        self._last_static = snap.time
        cells = self.sim.call(lambda world: world.octree_cells()) if show_octree else ()
        world = self.sim.world
        self.send(self.scene_pub, messages.scene_markers(snap.time, self.frames[0], world.ground,
                                                         world.playground_triangles, cells),
                  snap.time, latched=True)

    def _publish_rtf(self):
        self.send(self.rtf_pub, Float64(data=float(self.sim.achieved_rtf)), self.sim.snapshot.time)

    def _publish_diagnostics(self):
        snap, sim = self.sim.snapshot, self.sim
        steps = max(snap.step, 1)
        frozen = int(np.count_nonzero(snap.state["frozen"]))
        statuses = [
            ("vplayground: simulation", 0, ["stopped", "playing", "paused"][sim.state],
             {"target_real_time_factor": sim.real_time_factor, "achieved_real_time_factor": round(sim.achieved_rtf, 3),
              "step_ms": round(1e3 * sim.step_seconds / steps, 4), "late_ticks": sim.late_ticks,
              "simulation_thread_cpu_s": round(sim.thread_cpu_seconds, 3),
              "time": round(snap.time, 4)}),
            ("vplayground: bodies", 1 if sim.removed else 0, f"{len(snap.names)} bodies",
             {"active": len(snap.names) - frozen, "frozen": frozen, "removed": len(sim.removed),
              "last_removed": sim.removed[-1] if sim.removed else ""}),
        ]
        if self.recorder is not None:
            r = self.recorder
            level = 2 if r.error else (1 if r.dropped else 0)
            statuses.append(("vplayground: recorder", level, r.error or str(r.files[-1]),
                             {"path": r.files[-1], "files": len(r.files), "bytes": r.bytes_written,
                              "dropped": r.dropped}))
        car = self.car(snap)
        if car is not None:
            age = snap.vehicles[car]["command_age"]
            statuses.append(("vplayground: car", 0, car, {"command_age": round(age, 3)}))
        self.send(self.diagnostics_pub, messages.diagnostics(snap.time, statuses), snap.time)

    # ------------------------------------------------------------------ subscriptions
    def _make_subscriptions(self):
        stamped = self.get_parameter("cmd_vel_stamped").value
        self.create_subscription(TwistStamped if stamped else Twist, "cmd_vel", self._on_cmd_vel, COMMAND_QOS)
        self.create_subscription(PointStamped, "clicked_point", self._on_clicked_point, RELIABLE_10)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, RELIABLE_10)
        self.create_subscription(WrenchStamped, "~/push", self._on_push, RELIABLE_10)

    def _on_cmd_vel(self, msg):
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        speed, yaw_rate = twist.linear.x, twist.angular.z
        timeout = self.get_parameter("cmd_vel_timeout").value
        if not (math.isfinite(speed) and math.isfinite(yaw_rate)):
            self.get_logger().warning("cmd_vel with non-finite values ignored")
            return
        car = self.car(self.sim.snapshot)
        if car is None:
            return
        self.sim.submit(lambda world: world.drive(car, speed, yaw_rate, timeout))

    def to_world(self, frame, point):
        """A point in any frame this node publishes, in the world frame (None if unknown)."""
        snap = self.sim.snapshot
        world_frame, odom_frame, base_frame = self.frames
        if frame in ("", world_frame, odom_frame):
            return np.asarray(point, dtype=float)
        name = self.car(snap) if frame == base_frame or frame.startswith("wheel_") else frame
        if name not in snap.names:
            return None
        row = snap.names.index(name)
        rotation = quaternions_to_matrices(snap.state["quaternions"][row][None])[0]
        return snap.state["positions"][row] + rotation @ np.asarray(point, dtype=float)

    def _on_clicked_point(self, msg):
        p = self.to_world(msg.header.frame_id, (msg.point.x, msg.point.y, msg.point.z))
        if p is None or not np.all(np.isfinite(p)):
            self.get_logger().warning(f"clicked_point in unknown frame {msg.header.frame_id!r} ignored")
            return
        size = self.get_parameter("click_spawn_size").value
        height = self.get_parameter("click_spawn_height").value
        spec = yaml.safe_dump({"size": [size] * 3, "position": [float(p[0]), float(p[1]), float(p[2] + height + size / 2)]})
        ok, message = self.requests.spawn(spec)
        self.get_logger().info(f"clicked_point: {message}")

    def _on_initial_pose(self, msg):
        car = self.car(self.sim.snapshot)
        pose = msg.pose.pose
        p = self.to_world(msg.header.frame_id, (pose.position.x, pose.position.y, pose.position.z))
        if car is None or p is None:
            self.get_logger().warning("initialpose ignored: no car, or an unknown frame")
            return
        q = (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
        yaw = math.atan2(2 * (q[3] * q[2] + q[0] * q[1]), 1 - 2 * (q[1] ** 2 + q[2] ** 2))

        def teleport(world):
            wheels = world.vehicle(car)["wheels"]
            lift = max(w["spring_length"] + w["radius"] - w["mount"][2] for w in wheels)
            world.edit_body(car, position=[float(p[0]), float(p[1]), float(p[2]) + lift],
                            quaternion=list(rpy_to_quat((0.0, 0.0, yaw))),
                            linear_velocity=[0, 0, 0], angular_velocity=[0, 0, 0])
            world.drive(car, 0.0, 0.0)
        self.sim.submit(teleport)

    def _on_push(self, msg):
        name = msg.header.frame_id
        force = (msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z)
        torque = (msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z)

        def push(world):
            dt = 1.0 / world.settings["steps_per_second"]
            try:
                world.apply_impulse(name, [f * dt for f in force], [t * dt for t in torque])
            except (KeyError, ValueError) as error:
                self.get_logger().warning(f"~/push ignored: {error}")
        self.sim.submit(push)

    # ------------------------------------------------------------------ services
    def _make_services(self):
        def text_service(name, handler):
            def callback(request, response):
                response.success, response.message = handler(request.load_namespace)
                return response
            self.create_service(AddDiagnostics, name, callback)

        text_service("~/spawn", self.requests.spawn)
        text_service("~/edit", self.requests.edit)
        text_service("~/remove", self.requests.remove)
        text_service("~/get_entity", self.requests.get_entity)
        text_service("~/save_scene", self.requests.save_scene)
        self.create_service(GetInteractiveMarkers, "~/get_entities", self._get_entities)
        self.create_service(SetBool, "~/pause", self._bool_service(self.requests.pause))
        self.create_service(SetBool, "~/set_freezing", self._bool_service(self.requests.set_freezing))
        self.create_service(Trigger, "~/step", self._trigger_service(
            lambda: self.requests.step(self.get_parameter("step_count").value)))
        self.create_service(Trigger, "~/reset", self._trigger_service(
            lambda: self.requests.reset(self.get_parameter("reset_scope").value)))
        self.create_service(Trigger, "~/wake_all", self._trigger_service(self.requests.wake_all))
        self.create_service(Trigger, "~/get_simulator_features", self._trigger_service(self.requests.features))
        self.create_service(LoadMap, "~/load_scene", self._load_scene)

    @staticmethod
    def _bool_service(handler):
        def callback(request, response):
            response.success, response.message = handler(bool(request.data))
            return response
        return callback

    @staticmethod
    def _trigger_service(handler):
        def callback(request, response):
            response.success, response.message = handler()
            return response
        return callback

    def _load_scene(self, request, response):
        response.result, message = self.requests.load_scene(request.map_url)
        if response.result == 0:
            self.get_logger().info(f"~/load_scene: {message}")
        else:
            self.get_logger().warning(f"~/load_scene: {message}")
        self._last_static = -math.inf  # the new scenery goes out at once
        self.marker_ids.clear()
        return response

    def _get_entities(self, request, response):
        snap = self.sim.snapshot
        for name, description in self.requests.entities():
            marker = InteractiveMarker(header=messages.header(snap.time, self.frames[0]), name=name,
                                       description=yaml.safe_dump(description, sort_keys=False))
            marker.pose = messages.pose(description["pose"]["position"], description["pose"]["orientation"])
            shape = Marker(type=Marker.CUBE, action=Marker.ADD)
            shape.scale.x, shape.scale.y, shape.scale.z = (float(v) for v in description["bounds"]["size"])
            shape.pose.orientation.w = 1.0
            marker.controls.append(InteractiveMarkerControl(name="shape", markers=[shape], always_visible=True))
            response.markers.append(marker)
        return response

