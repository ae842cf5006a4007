"""The ROS 2 node `vplayground` (SPEC 6): the Runtime in the ROS graph.

Everything the node offers comes from the Runtime's tables (broadcast.TOPICS, inputs.SUBSCRIPTIONS,
services.service_table, parameters.parameter_table); this file only maps them onto rclpy.
Publishers send the CDR bytes the Broadcaster made (the same bytes go to the bag and to the
Foxglove server); subscriptions and services hand rclpy messages to the shared handlers, which
only read attributes; the node registers with the Runtime's Parameters (their one owner and
validation) and keeps rclpy's copy of them in step.
"""
import array
import importlib
import logging
import threading
import time

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.task import Future

from .broadcast import NODE_NAME, TOPICS
from .inputs import subscriptions
from .runtime import BUSY
from .services import failure
from .standard_services import StandardServices


def reliable(depth, durability=DurabilityPolicy.VOLATILE):
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      durability=durability)


QOS = {"reliable_1": reliable(1), "reliable_10": reliable(10), "reliable_100": reliable(100),
       "latched": reliable(1, DurabilityPolicy.TRANSIENT_LOCAL)}
# Best effort, depth 1: matches both reliable and best-effort publishers (Foxglove's Teleop).
COMMAND_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST)
PARAMETER_TYPES = {"bool": Parameter.Type.BOOL, "int": Parameter.Type.INTEGER, "float": Parameter.Type.DOUBLE,
                   "str": Parameter.Type.STRING, "float[3]": Parameter.Type.DOUBLE_ARRAY,
                   "str[]": Parameter.Type.STRING_ARRAY}


def interface_class(type_name):
    """The rclpy class of 'package/msg/Type' or 'package/srv/Type' (ImportError if not installed)."""
    package, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


# Start-up parameters only the command line sets: they are opened before the node exists.
COMMAND_LINE_ONLY = {"scene": "--scene", "record": "--record / --no-record",
                     "record_split_size": "--record-split-size", "foxglove.port": "--foxglove PORT"}


def fill(msg, fields):
    """Sets an rclpy message's fields from nested dicts (lists of dicts for message sequences)."""
    types = msg.get_fields_and_field_types()
    for key, value in fields.items():
        if isinstance(value, dict):
            fill(getattr(msg, key), value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            package, name = types[key][len("sequence<"):-1].split("/")
            element = interface_class(f"{package}/msg/{name}")
            setattr(msg, key, [fill(element(), v) for v in value])
        else:
            setattr(msg, key, value)
    return msg


def descriptor(spec):
    extra = {}
    if spec.low is not None and spec.kind == "int":
        extra["integer_range"] = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    elif spec.low is not None and spec.kind == "float":
        extra["floating_point_range"] = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high))]
    elif spec.low is not None:  # rclpy ranges only scalars: an array's range in words
        extra["additional_constraints"] = f"each element in [{spec.low:g}, {spec.high:g}]"
    return ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                               type=PARAMETER_TYPES[spec.kind].value, **extra)


def plain(value):
    return list(value) if isinstance(value, (array.array, tuple)) else value


def own_group():
    """A callback group for one entity that comes and goes with a robot or a sensor (a publisher,
    for its event handlers; a robot's command subscription), which goes with it: rclpy's groups
    keep a weak reference to every entity ever added and never drop it (ros2/rclpy#1356), so
    the node's default group grew with each robot or sensor spawned and removed, a few entries
    for each of its topics. The executor is single-threaded: a group of its own changes no
    callback's order."""
    return MutuallyExclusiveCallbackGroup()


class RosSink:
    """The ROS publishers as a Broadcaster sink. /tf and /tf_static exist only where tf2_msgs
    imports (a ROS install, or the wheels' venv that make built it into); everything else always."""

    def __init__(self, node):
        self.node = node
        self.publishers = {}
        for topic in TOPICS:
            self.publisher(topic)
        # Publishers withdrawn on the threads that publish, destroyed on the executor's: a
        # publisher's QoS event handler sits in the executor's wait set, and destroyed while the
        # executor built that set it raised InvalidHandle there, which ended the node's spin
        # (every service silent from then on).
        self._withdrawn = []
        self._withdrawn_lock = threading.Lock()
        self._reaper = node.create_guard_condition(self._destroy_withdrawn)

    def publisher(self, topic):
        """The topic's publisher, made on first use (a scene's sensor topics come and go with
        it); None where its type does not import."""
        if topic.key not in self.publishers:
            try:
                kind = interface_class(topic.type)
            except ImportError:
                self.node.get_logger().warning(
                    f"{topic.name}: {topic.type} is not installed, so the node does not publish it "
                    f"(the bag and the Foxglove server still have it; a ROS install has it: "
                    f"apt install ros-jazzy-{topic.type.split('/')[0].replace('_', '-')})")
                self.publishers[topic.key] = None
                return None
            self.publishers[topic.key] = self.node.create_publisher(kind, topic.name, QOS[topic.qos],
                                                                    callback_group=own_group())
        return self.publishers[topic.key]

    def publish(self, topic, data, seconds):
        publisher = self.publisher(topic)
        if publisher is not None:
            publisher.publish(data)

    def subscribed(self, topic):
        publisher = self.publisher(topic)
        return publisher is not None and publisher.get_subscription_count() > 0

    def retract(self, topic):
        """A latched topic that ended: its transient-local publisher would serve it for ever."""
        self.withdraw(topic)

    def withdraw(self, topic):
        """A topic nothing publishes on any longer (its robot or sensor gone): no longer
        advertised (made again should it come back). Its publisher goes on the executor's
        thread (_destroy_withdrawn)."""
        publisher = self.publishers.pop(topic.key, None)
        if publisher is not None:
            with self._withdrawn_lock:
                self._withdrawn.append(publisher)
            self._reaper.trigger()

    def _destroy_withdrawn(self):
        with self._withdrawn_lock:
            withdrawn, self._withdrawn = self._withdrawn, []
        for publisher in withdrawn:
            self.node.destroy_publisher(publisher)

    def statuses(self):
        return []


class RosLogHandler(logging.Handler):
    """The package's Python logging (its modules' warnings, the faults it survived with their
    tracebacks) into the node's logger: the ROS console and /rosout, where a ROS user looks.
    Without it they went to Python's last-resort stderr line, seen by no ROS tool."""

    def __init__(self, logger):
        super().__init__(logging.INFO)
        self.logger = logger

    def emit(self, record):
        try:
            text = f"{record.name}: {self.format(record)}"
            # One call per severity: rclpy refuses a call site whose severity changes.
            if record.levelno >= logging.ERROR:
                self.logger.error(text)
            elif record.levelno >= logging.WARNING:
                self.logger.warning(text)
            else:
                self.logger.info(text)
        except Exception:  # a log line must never fail what logged it
            self.handleError(record)


PACKAGE_LOGGER = logging.getLogger(__package__)


class SimulatorNode(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        if self.has_parameter("use_sim_time") and self.get_parameter("use_sim_time").value:
            self.get_logger().warning("use_sim_time is set: ignored, this node is the time source")
        self._log_handler = RosLogHandler(self.get_logger())
        self._logging_before = PACKAGE_LOGGER.level, PACKAGE_LOGGER.propagate
        PACKAGE_LOGGER.addHandler(self._log_handler)
        PACKAGE_LOGGER.setLevel(logging.INFO)
        PACKAGE_LOGGER.propagate = False  # once is enough: not again on stderr

    def destroy_node(self):
        PACKAGE_LOGGER.removeHandler(self._log_handler)
        PACKAGE_LOGGER.level, PACKAGE_LOGGER.propagate = self._logging_before
        return super().destroy_node()

    def attach(self, runtime):
        """Declares the runtime's parameters and serves its topics, subscriptions and services."""
        self.runtime = runtime
        self._declare_parameters()
        runtime.broadcaster.add_sink(RosSink(self))
        table = subscriptions(runtime.parameters["cmd_vel_stamped"])
        for sub in table:
            self.create_subscription(interface_class(sub.type), sub.name,
                                     lambda msg, key=sub.key: runtime.inputs.handle(key, msg),
                                     COMMAND_QOS if sub.key == "cmd_vel" else QOS["reliable_10"])
        self._command_type = interface_class(next(sub.type for sub in table if sub.key == "cmd_vel"))
        self._commands = {}  # absolute topic -> subscription of a robot's (a namespaced cmd_vel, a URDF robot's commands)
        # Robots come and go with the snapshot's vehicles and URDF robots: the simulation thread
        # wakes the executor when those change. (A timer looking 4 times a second cost ~0.3 % of
        # a core in a world at rest: each wake rebuilds the executor's wait set of every service.)
        # Watched before the first look, so a robot that comes in between (a Foxglove client's
        # spawn, served already) is either seen by it or triggers the next.
        self._robots_seen = (runtime.sim.snapshot.vehicle_specs, runtime.sim.snapshot.robot_specs)
        self._robots_changed = self.create_guard_condition(self._follow_robots)
        runtime.sim.add_listener(self._watch_robots)
        self._follow_robots()
        missing = []
        # The default group runs one callback at a time and holds it across an await: what
        # runs aside gets a group that lets everything else through meanwhile.
        self._aside_group = ReentrantCallbackGroup()
        for service in runtime.services:
            try:
                kind = interface_class(service.type)
            except (ImportError, AttributeError):  # simulation_interfaces not installed, or older
                missing.append(service.name)
                continue
            if service.aside:
                self.create_service(kind, service.name, self._serve_aside(service),
                                    callback_group=self._aside_group)
            else:
                self.create_service(kind, service.name, self._serve(service.handler))
        if missing:
            self.get_logger().warning(
                f"simulation_interfaces is not installed (or older than 1.5): {len(missing)} standard services "
                f"are not served ({', '.join(missing)}) "
                "(make builds it into the venv; in a ROS install: apt install ros-$ROS_DISTRO-simulation-interfaces)")
        else:
            self._simulate_steps = simulate_steps_action(self, runtime)
            runtime.requests.actions_served = True

    def _watch_robots(self, snapshot):
        """On the simulation thread after each batch: wakes _follow_robots when the snapshot's
        robots are others than last seen (the specs are shared while unchanged)."""
        seen = self._robots_seen
        if snapshot.vehicle_specs is not seen[0] or snapshot.robot_specs is not seen[1]:
            self._robots_seen = (snapshot.vehicle_specs, snapshot.robot_specs)
            self._robots_changed.trigger()

    def _follow_robots(self):
        """Each namespaced robot's cmd_vel and each URDF robot's command topics, subscribed as
        robots come (a spawn, another scene) and dropped as they go; the root namespace's
        cmd_vel is the table's own subscription."""
        inputs = self.runtime.inputs
        wanted = {topic: ("cmd_vel", self._command_type) for topic in inputs.command_topics()}
        wanted.update({topic: (sub.key, interface_class(sub.type)) for topic, (sub, _) in inputs.robot_inputs().items()})
        wanted.pop(inputs.resolve("cmd_vel"), None)
        for topic in wanted.keys() - self._commands.keys():
            key, kind = wanted[topic]
            self._commands[topic] = self.create_subscription(
                kind, topic, lambda msg, t=topic, k=key: inputs.handle(k, msg, t),
                COMMAND_QOS if key == "cmd_vel" else QOS["reliable_10"], callback_group=own_group())
        for topic in self._commands.keys() - wanted:
            self.destroy_subscription(self._commands.pop(topic))

    @staticmethod
    def _serve(handler):
        def callback(request, response):
            return fill(response, handler(request))
        return callback

    def _serve_aside(self, service):
        """A handler that may take long (Service.aside) runs on a thread of its own (run_aside)."""
        busy = failure(service.type)  # ~/spawn's is AddDiagnostics', the others the standard's Result

        async def callback(request, response):  # filling a response of 10,000 states is 0.3 s too
            return await self.run_aside(lambda: fill(response, service.handler(request)),
                                        lambda: fill(response, busy(BUSY)))
        return callback

    async def run_aside(self, fn, busy):
        """fn() on a thread of its own, a long request (Runtime.long_request; else busy() at
        once): the executor serves everything else meanwhile and sends the answer when it is done."""
        with self.runtime.long_request() as admitted:
            return await self.aside(fn) if admitted else busy()

    def aside(self, fn):
        """An awaitable of fn() run on a new thread; its end wakes the executor."""
        future = Future(executor=self.executor)
        future.add_done_callback(lambda _: None)  # a done callback is what wakes the executor

        def run():
            try:
                future.set_result(fn())
            except Exception as error:  # noqa: BLE001 - handed to the awaiting callback
                future.set_exception(error)
        threading.Thread(target=run, name="vplayground-aside", daemon=True).start()
        return future

    # ------------------------------------------------------------------ parameters
    # The Runtime's Parameters own the values; rclpy holds a copy so that `ros2 param get` and
    # /parameter_events work. A set through rclpy goes to Parameters.set from the callback; a
    # change made anywhere else (the Foxglove server, ~/set_freezing, a scene load) is copied
    # into rclpy by the listener, whose own callback then accepts the already validated values.
    def _declare_parameters(self):
        store = self.runtime.parameters
        for spec in store.specs.values():
            try:
                self.declare_parameter(spec.name, store[spec.name], descriptor(spec))
            except ParameterException as error:  # an override of the wrong type or out of range
                hint = (f" (a decimal parameter: {spec.name}:=1.0, not 1)"
                        if "'INTEGER', expecting type 'DOUBLE'" in str(error) else "")
                raise ValueError(f"--ros-args -p {spec.name}: {error}{hint}") from None
        # Overrides given with --ros-args -p: validated and applied like any other set, before
        # the simulation starts. What was opened from the command line before the node existed
        # (the scene, the bag, the Foxglove port) cannot follow one: refused, naming the option.
        overrides = {name: plain(self.get_parameter(name).value) for name in store.specs}
        overrides = {name: value for name, value in overrides.items() if value != store[name]}
        for name in overrides.keys() & COMMAND_LINE_ONLY:
            raise ValueError(f"{name}: give it on the command line ({COMMAND_LINE_ONLY[name]}), "
                             f"not as a ROS parameter override")
        store.override(overrides)
        # An override of a name the node does not have (a typo: -p steps_per_secnd:=200) is
        # taken by rclpy and used by nothing: said, not silent.
        unknown = sorted(name for name in getattr(self, "_parameter_overrides", {}) if not self.has_parameter(name))
        if unknown:
            self.get_logger().warning(f"--ros-args -p {', '.join(unknown)}: no such parameter of this node, ignored "
                                      f"(ros2 param list {self.get_fully_qualified_name()} lists them)")
        self._from_rclpy = threading.local()  # .active: inside our set-parameters callback
        self._copying = threading.local()     # .active: copying a change into rclpy
        self.add_on_set_parameters_callback(self._on_parameters)
        store.listen(self._copy_into_rclpy)

    def set_parameters_atomically(self, parameter_list):
        """rclpy's parameter services and _copy_into_rclpy set through here: rclpy stores the
        values once _on_parameters has accepted them, so under the Parameters' lock, lest a change
        made meanwhile from elsewhere be copied in before them and then overwritten."""
        with self.runtime.parameters.lock:
            return super().set_parameters_atomically(parameter_list)

    def _on_parameters(self, parameters):
        if getattr(self._copying, "active", False):  # values Parameters has already taken
            return SetParametersResult(successful=True)
        if any(p.name == "use_sim_time" for p in parameters):  # rclpy's own, declared by every node
            return SetParametersResult(successful=False, reason="use_sim_time: this node is the time source "
                                                                "(it publishes /clock): it takes no other")
        self._from_rclpy.active = True
        try:
            ok, reason = self.runtime.parameters.set({p.name: plain(p.value) for p in parameters})
        finally:
            self._from_rclpy.active = False
        return SetParametersResult(successful=ok, reason=reason)

    def _copy_into_rclpy(self, changed):
        if getattr(self._from_rclpy, "active", False):  # rclpy stores these itself
            return
        self._copying.active = True
        try:
            result = self.set_parameters_atomically([Parameter(name, value=value) for name, value in changed.items()])
        finally:
            self._copying.active = False
        if not result.successful:
            self.get_logger().warning(f"parameters {', '.join(changed)} not copied into rclpy: {result.reason}")


def simulate_steps_action(node, runtime):
    """simulation_interfaces' SimulateSteps action (relative name `simulate_steps`): the steps of
    ~/step followed with feedback as they run, cancel withdrawing those not yet run."""
    from rclpy.action import ActionServer, CancelResponse
    from simulation_interfaces.action import SimulateSteps

    standard = StandardServices(runtime)
    failed = failure("simulation_interfaces/action/SimulateSteps")  # RESULT_OPERATION_FAILED

    def run_goal(goal_handle):
        """The goal's steps followed on a thread of its own, feedback as they complete."""
        progress = standard.stepping(int(goal_handle.request.steps))
        outcome = SimulateSteps.Result()
        try:
            while True:
                tick = next(progress)
                if goal_handle.is_cancel_requested:
                    progress.close()  # withdraws the steps not yet run
                    fill(outcome, failed("cancelled"))
                    goal_handle.canceled()
                    return outcome
                if tick is None:
                    time.sleep(ACTION_POLL)
                else:
                    goal_handle.publish_feedback(SimulateSteps.Feedback(completed_steps=tick[0],
                                                                        remaining_steps=tick[1]))
        except StopIteration as end:
            fill(outcome.result, end.value)
        (goal_handle.succeed if outcome.result.result == 1 else goal_handle.abort)()
        return outcome

    def refuse(goal_handle):
        outcome = fill(SimulateSteps.Result(), failed(BUSY))
        goal_handle.abort()
        return outcome

    async def execute(goal_handle):
        return await node.run_aside(lambda: run_goal(goal_handle), lambda: refuse(goal_handle))

    return ActionServer(node, SimulateSteps, "simulate_steps", execute_callback=execute,
                        cancel_callback=lambda _goal: CancelResponse.ACCEPT, callback_group=node._aside_group)


ACTION_POLL = 0.005  # s between looks at the steps a SimulateSteps goal has run
