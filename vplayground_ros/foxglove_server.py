"""The built-in Foxglove WebSocket server (SPEC 6.5): the live window without a ROS install.

foxglove-sdk's server runs inside the simulator process and offers what the ROS graph offers,
from the same Runtime:
- every Broadcaster topic as a channel (`cdr` messages, `ros2msg` schemas from interfaces.py):
  the server is one more Broadcaster sink, so it logs the very bytes the bag and the ROS
  publishers get, with log time = simulation time; /clock also feeds the server's time;
- the services (services.py) with ros2msg/cdr request and response schemas;
- the parameters: get, set through the Runtime's Parameters (their one owner and validation),
  updates to subscribers;
- client publish: cmd_vel, clicked_point, initialpose and ~/push (cdr or json) into the same
  handlers as the ROS subscriptions.
A latched topic (scenery, state, /tf_static) is sent again when a client subscribes to it.
Viewers connect to foxglove_front.py's relay, which speaks both protocol generations and names
the ROS distribution; the sdk server itself listens on a loopback port behind it.
"""
import logging
import threading
from contextlib import nullcontext

import foxglove
from foxglove import Channel, Context, MessageSchema, Parameter, ParameterType, Schema, Service, ServiceSchema
from foxglove.websocket import Capability, StatusLevel

from .foxglove_front import ProtocolFront
from .inputs import TWIST, TWIST_STAMPED, from_cdr, from_json, subscriptions
from .interfaces import decoder, encode, schema
from .runtime import BUSY
from .services import failure
from .throttle import Throttle

DEFAULT_PORT = 8765
# The message definitions every channel and service uses are Jazzy's (interfaces.py); viewers
# take a server naming a ROS_DISTRO for a ROS 2 source and then offer the 3D publish tools.
METADATA = {"ROS_DISTRO": "jazzy"}
# Topics the 3D panel's pose tool publishes a navigation goal on (Nav2's goal_pose; older
# layouts' default /move_base_simple/goal). The simulator has no planner: it takes them quietly.
NAVIGATION_GOALS = {"/goal_pose", "/move_base_simple/goal"}
# /clock goes out at every step (128 Hz), and each log (a WebSocket frame) wakes the sdk's
# sender thread and the relay (~25 µs on the simulation thread alone), as did the server time
# sent with each: the /clock messages are held and logged just before the next other message
# (the next round of poses, ~30 Hz), or once this many are held, each at its own log time and
# in order; the server time (the viewers' timeline) goes out once before them, at the last one,
# and before a message of a newer time (the sdk sends time and messages on separate paths, so a
# viewer may still see a message a little ahead of it). A viewer gets /clock up to a round late.
CLOCK_BATCH = 8
# The sdk logs its own loopback port and the relay's connections: the relay logs the viewers.
logging.getLogger("foxglove.websocket").setLevel(logging.WARNING)
# What a client does wrong (drops its connection, sends garbage, fails its handshake) the sdk
# logs as ERROR, a line each: anyone on the network could fill the log. Such lines are debug.
CLIENT_FAULTS = ("Error receiving from client", "Connection reset without closing handshake", "Invalid message from",
                 "attempted to subscribe to unknown channel", "handshake failed",
                 "Received message for unknown channel")


class ClientFaultsAreDebug(logging.Filter):
    def filter(self, record):
        if record.levelno >= logging.ERROR and any(text in record.getMessage() for text in CLIENT_FAULTS):
            record.levelno, record.levelname = logging.DEBUG, "DEBUG"
            return logging.getLogger(record.name).isEnabledFor(logging.DEBUG)
        return True


# A logger's filters see only its own records, not its children's: each of the sdk's that log them.
for name in ("foxglove.websocket.server", "foxglove.websocket.connected_client",
             "foxglove.websocket.connected_client.poller"):
    logging.getLogger(name).addFilter(ClientFaultsAreDebug())


def ros2msg(type_name):
    return Schema(name=type_name, encoding="ros2msg", data=schema(type_name).encode())


class FoxgloveServer:
    def __init__(self, runtime, host="127.0.0.1", port=DEFAULT_PORT):
        self.runtime = runtime
        self.context = Context()
        self.channels = {key: Channel(topic.name, schema=ros2msg(topic.type), message_encoding="cdr",
                                      context=self.context)
                         for key, topic in runtime.broadcaster.topics.items()}
        self.inputs = {runtime.resolve_name(sub.name): sub
                       for sub in subscriptions(runtime.parameters["cmd_vel_stamped"])}
        self._channels_lock = threading.Lock()  # making and dropping channels (channel, withdraw)
        self.client_channels = {}  # (client id, channel id) -> (subscription key, decode)
        self.subscriptions = 0
        self._time_sent = -1  # ns: the last server time sent (two threads send: under _time_lock)
        self._time_lock = threading.Lock()
        self._clocks = []     # [(data, stamp)] of the /clock messages held (under _clock_lock)
        self._clock_lock = threading.Lock()
        self.watched_parameters = set()  # names some client subscribed to updates of
        self._setting = threading.local()  # .names: a Foxglove client's set, on this thread
        self._lock = threading.Lock()
        self._throttle = Throttle()  # of _warn: a client may send garbage as fast as it likes
        try:
            self.server = foxglove.start_server(
                name="vplayground", host="127.0.0.1", port=0, context=self.context,
                capabilities=[Capability.ClientPublish, Capability.Parameters, Capability.Services, Capability.Time],
                server_listener=self, supported_encodings=["cdr", "json"],
                services=self._services(runtime))
        except RuntimeError as error:  # the SDK's FoxgloveError
            raise OSError(f"the Foxglove server cannot start: {error}") from None
        try:
            self.front = ProtocolFront(self.server.port, host, port, METADATA, runtime.log)
        except OSError as error:  # the port is taken, say
            self.server.stop()
            raise OSError(f"the Foxglove server cannot listen on {host}:{port}: {error}") from None
        self.port = self.front.port
        self.url = f"ws://[{host}]:{self.port}" if ":" in host else f"ws://{host}:{self.port}"
        runtime.parameters.set_read_only({"foxglove.port": self.port})  # the port bound (0 asks for any)
        runtime.parameters.listen(self._parameters_changed)
        runtime.broadcaster.add_sink(self)

    def stop(self):
        self.flush_clock()
        self.front.stop()
        self.server.stop()

    # ------------------------------------------------------------- the Broadcaster sink
    def publish(self, topic, data, seconds):
        stamp = int(round(seconds * 1e9))
        if topic.key == "clock":
            with self._clock_lock:
                self._clocks.append((data, stamp))
                if len(self._clocks) < CLOCK_BATCH:
                    return
            self.flush_clock()
            return
        if self._clocks:
            self.flush_clock()
        if stamp > self._time_sent:
            self._send_time(stamp)
        self.channel(topic).log(data, log_time=stamp)

    def flush_clock(self):
        """Logs the /clock messages held, in order, after the server time at the last of them
        (backwards too: the simulation's time went back, a reset or another scene). Under the
        lock: the simulation and the publisher thread never interleave them."""
        with self._clock_lock:
            if not self._clocks:
                return
            last = self._clocks[-1][1]
            if last != self._time_sent:
                self._send_time(last, back=last < self._time_sent)
            channel = self.channels["clock"]
            for data, stamp in self._clocks:
                channel.log(data, log_time=stamp)
            self._clocks = []

    def _send_time(self, stamp, back=False):
        """The server time, forward only (checked again under the lock: another thread may
        have sent a later one meanwhile) unless `back`."""
        with self._time_lock:
            if stamp > self._time_sent or back:
                self._time_sent = stamp
                self.server.broadcast_time(stamp)

    def subscribed(self, topic):
        return self.channel(topic).has_sinks()

    def channel(self, topic):
        """The topic's channel, advertised on first use (a scene's sensor topics). Made under
        _channels_lock: the publisher and simulation threads both publish, and a channel made
        twice was advertised twice."""
        channel = self.channels.get(topic.key)
        if channel is None:
            with self._channels_lock:
                channel = self.channels.get(topic.key)
                if channel is None:
                    channel = self.channels[topic.key] = Channel(topic.name, schema=ros2msg(topic.type),
                                                                 message_encoding="cdr", context=self.context)
        return channel

    def withdraw(self, topic):
        """A topic nothing publishes on any longer (its robot or sensor gone): its channel is
        closed, which unadvertises it (a viewer subscribed to it sees it go, and subscribes to
        the new channel should its entity come back), and dropped, also from the sdk's registry
        of every channel made (foxglove.channel._channels_by_id, for foxglove.log; a closed one is
        never logged to again): kept, each name ever spawned held its channels, ~4 kB each."""
        with self._channels_lock:
            channel = self.channels.pop(topic.key, None)
        if channel is not None:
            channel.close()
            foxglove.channel._channels_by_id.pop(channel.id(), None)

    retract = withdraw  # a latched topic that ended (a robot's robot_description)

    def statuses(self):
        return [("foxglove", 0, self.url, {"subscriptions": self.subscriptions,
                                                        "client_channels": len(self.client_channels)})]

    # ------------------------------------------------------------- services
    def _services(self, runtime):
        """The services whose definitions are found: simulation_interfaces' may be missing from
        an installed package (a ROS install without it, the vendored copy not installed)."""
        served, missing = [], []
        for service in runtime.services:
            try:
                served.append(self._service(service))
            except LookupError:
                missing.append(service.name)
        if missing:
            runtime.log.warning(f"Foxglove: {len(missing)} services not offered, their definitions are not "
                                f"installed: {', '.join(missing)}")
        return served

    def _service(self, service):
        request_type, response_type = f"{service.type}_Request", f"{service.type}_Response"

        busy = failure(service.type)

        def handle(request):  # CDR only: the SDK answers a call in another encoding itself
            # The sdk runs each call on a thread of its own: a long one counts with the node's.
            with self.runtime.long_request() if service.aside else nullcontext(True) as admitted:
                response = service.handler(decoder(request_type)(bytes(request.payload))) if admitted else busy(BUSY)
            return encode(response_type, response)
        return Service(self.runtime.resolve_name(service.name), handler=handle, schema=ServiceSchema(
            service.type, request=MessageSchema(encoding="cdr", schema=ros2msg(request_type)),
            response=MessageSchema(encoding="cdr", schema=ros2msg(response_type))))

    # ------------------------------------------------------------- ServerListener
    def on_subscribe(self, client, channel):
        """A newcomer gets the server time (a viewer without one shows time 0), the latched
        message of the channel it subscribed to (only that one: each subscription re-sent all
        three) and, while paused, the world as it stands (Broadcaster.welcome)."""
        self.subscriptions += 1
        if self._time_sent >= 0:
            with self._time_lock:
                self.server.broadcast_time(self._time_sent)
        # (a copy: the publishing threads add and withdraw channels meanwhile)
        key = next((key for key, known in list(self.channels.items()) if known.id() == channel.id), None)
        self.runtime.broadcaster.welcome(self, key)

    def on_unsubscribe(self, client, channel):
        self.subscriptions -= 1

    def on_client_advertise(self, client, channel):
        topic = channel.topic if channel.topic.startswith("/") else f"/{channel.topic}"
        sub = self.inputs.get(topic)
        if sub is None and topic in self.runtime.inputs.command_topics():  # a namespaced robot's cmd_vel
            sub = self.inputs[self.runtime.resolve_name("cmd_vel")]
        if sub is None:  # a URDF robot's command topic
            sub = self.runtime.inputs.robot_inputs().get(topic, (None,))[0]
        if sub is None and topic in NAVIGATION_GOALS:
            self.runtime.log.debug(f"foxglove: {channel.topic}: a navigation goal, ignored (no planner)")
            return
        if sub is None:
            self._warn(f"{channel.topic}: the simulator does not subscribe to it "
                       f"(it takes {', '.join(sorted(self.inputs))})", "advertise")
            return
        if channel.encoding == "json":
            decode = from_json
        elif channel.encoding == "cdr":
            # cmd_vel takes Twist and TwistStamped alike (a client's channel has its own type,
            # where a ROS topic has one: there cmd_vel_stamped chooses).
            kinds = (TWIST, TWIST_STAMPED) if sub.key == "cmd_vel" else (sub.type,)
            advertised = (channel.schema_name or sub.type).replace("/msg/", "/")
            kind = next((k for k in kinds if k.replace("/msg/", "/") == advertised), None)
            if kind is None:
                self._warn(f"{channel.topic}: expected {' or '.join(kinds)}, the client advertises {channel.schema_name}",
                           "advertise")
                return
            decode = lambda data, kind=kind: from_cdr(kind, data)  # noqa: E731
        else:
            self._warn(f"{channel.topic}: encoding {channel.encoding!r} not supported (cdr or json)", "advertise")
            return
        with self._lock:
            self.client_channels[(client.id, channel.id)] = (sub.key, decode, topic)

    def on_client_unadvertise(self, client, client_channel_id):
        with self._lock:
            self.client_channels.pop((client.id, client_channel_id), None)

    def on_message_data(self, client, client_channel_id, data):
        entry = self.client_channels.get((client.id, client_channel_id))
        if entry is None:
            return
        key, decode, topic = entry
        try:
            message = decode(data)
        except Exception as error:  # a client's bytes must never reach the loop as an exception
            self._warn(f"{key}: undecodable message ignored ({type(error).__name__}: {error})", ("undecodable", key))
            return
        self.runtime.inputs.handle(key, message, topic)

    def on_get_parameters(self, client, param_names, request_id=None):
        store = self.runtime.parameters
        return [self._parameter(name) for name in (param_names or list(store.specs)) if name in store.specs]

    def on_set_parameters(self, client, parameters, request_id=None):
        changes = {p.name: p.get_value() for p in parameters}
        self._setting.names = set(changes)  # the sdk sends what this returns to the subscribers itself
        try:
            ok, reason = self.runtime.parameters.set(changes)
        finally:
            self._setting.names = set()
        if not ok:
            self._warn(f"parameters refused: {reason}", "parameters")
        store = self.runtime.parameters
        return [self._parameter(name) for name in changes if name in store.specs]

    def on_parameters_subscribe(self, param_names):
        with self._lock:
            self.watched_parameters.update(param_names)

    def on_parameters_unsubscribe(self, param_names):
        with self._lock:
            self.watched_parameters.difference_update(param_names)

    # ------------------------------------------------------------- helpers
    def _parameter(self, name):
        store = self.runtime.parameters
        kind, value = store.specs[name].kind, store[name]
        if kind == "float":
            return Parameter(name, value=float(value), type=ParameterType.Float64)
        if kind == "float[3]":
            return Parameter(name, value=[float(v) for v in value], type=ParameterType.Float64Array)
        return Parameter(name, value=value)

    def _parameters_changed(self, changed):
        """Updates to the clients subscribed to them (the sdk sends each client its own names)."""
        with self._lock:
            watched = [name for name in changed if name in self.watched_parameters
                       and name not in getattr(self._setting, "names", ())]
        if watched:
            self.server.publish_parameter_values([self._parameter(name) for name in watched])

    def _warn(self, text, kind):
        """A warning to the log and a status to the clients (every one of them: the sdk has no
        status for one client), a few of each `kind` in a while (throttle.py)."""
        text = self._throttle.passes(kind, text)
        if text is not None:
            self.runtime.log.warning(f"foxglove: {text}")
            self.server.publish_status(text, StatusLevel.Warning)
