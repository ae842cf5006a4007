"""A small client of Foxglove's WebSocket protocol (subprotocol `foxglove.sdk.v1`, or its older
name `foxglove.websocket.v1`), written from the protocol's spec for the tests: it knows nothing
of the simulator's code. Messages are decoded and encoded with mcap_ros2 from the schemas the
server advertises."""
import json
import re
import struct
import threading
import time
from collections import defaultdict, deque

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
OLD_SUBPROTOCOL = "foxglove.websocket.v1"  # what viewers released before December 2025 ask for
MESSAGE_DATA, TIME, SERVICE_CALL_RESPONSE = 1, 2, 3          # server binary opcodes
CLIENT_MESSAGE_DATA, SERVICE_CALL_REQUEST = 1, 2             # client binary opcodes
# Where a server's URL is found: the line the simulator logs when it starts serving.
URL_IN_LOG = re.compile(r"open connection to (ws://\S+)")


def codec(make, name, schema_text):
    return make(name, schema_text)[name]


class FoxgloveClient:
    def __init__(self, url, timeout=10.0, keep=None, subprotocol=SUBPROTOCOL):
        """keep: frames and times kept per topic (None: all; a long run keeps a few)."""
        self.ws = connect(url, subprotocols=[subprotocol], max_size=None, open_timeout=timeout, legacy=True)
        self.timeout = timeout
        self.server_info = None
        self.channels = {}        # topic -> advertised channel (forgotten when unadvertised)
        self.services = {}        # name -> advertised service
        self.frames = defaultdict(lambda: deque(maxlen=keep))  # topic -> [(log time ns, payload)]
        self.received = 0         # frames received in all
        self.times = deque(maxlen=keep)  # server time messages, ns
        self.arrivals = deque(maxlen=keep)  # (topic, or "time" for a server time; its time ns) in order
        self.statuses = []
        self.parameter_values = {}  # request id -> [parameters]
        self.parameter_updates = []
        self.responses = {}       # call id -> (encoding, payload) or ("failure", message)
        self._subscriptions = {}  # subscription id -> topic
        self._next_id = 1
        self._changed = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    @property
    def connected(self):
        """The server has not closed the connection (the reader stops when it does)."""
        return self._thread.is_alive()

    def close(self):
        self._closed = True
        self.ws.close()
        self._thread.join(5)

    def _read(self):
        while not self._closed:
            try:
                message = self.ws.recv()
            except Exception:
                return
            with self._changed:
                if isinstance(message, bytes):
                    self._binary(message)
                else:
                    self._text(json.loads(message))
                self._changed.notify_all()

    def _binary(self, data):
        if data[0] == MESSAGE_DATA:
            subscription, stamp = struct.unpack_from("<IQ", data, 1)
            self.frames[self._subscriptions[subscription]].append((stamp, data[13:]))
            self.arrivals.append((self._subscriptions[subscription], stamp))
            self.received += 1
        elif data[0] == TIME:
            self.times.append(struct.unpack_from("<Q", data, 1)[0])
            self.arrivals.append(("time", self.times[-1]))
        elif data[0] == SERVICE_CALL_RESPONSE:
            _, call, length = struct.unpack_from("<III", data, 1)
            self.responses[call] = (data[13:13 + length].decode(), data[13 + length:])

    def _text(self, message):
        op = message["op"]
        if op == "serverInfo":
            self.server_info = message
        elif op == "advertise":
            self.channels.update({c["topic"]: c for c in message["channels"]})
        elif op == "unadvertise":
            gone = set(message["channelIds"])
            self.channels = {topic: c for topic, c in self.channels.items() if c["id"] not in gone}
        elif op == "advertiseServices":
            self.services.update({s["name"]: s for s in message["services"]})
        elif op == "status":
            self.statuses.append(message)
        elif op == "parameterValues":
            if message.get("id"):
                self.parameter_values[message["id"]] = message["parameters"]
            else:
                self.parameter_updates.extend(message["parameters"])
        elif op == "serviceCallFailure":
            self.responses[message["callId"]] = ("failure", message["message"])

    def wait(self, predicate, timeout=None):
        end = time.monotonic() + (timeout or self.timeout)
        with self._changed:
            while not predicate():
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._changed.wait(left)
        return True

    def _id(self):
        self._next_id += 1
        return self._next_id

    # ------------------------------------------------------------------ channels
    def decoder(self, topic):
        channel = self.channels[topic]
        return codec(generate_dynamic, channel["schemaName"], channel["schema"])

    def subscribe(self, *topics):
        subscriptions = []
        for topic in topics:
            sid = self._id()
            self._subscriptions[sid] = topic
            subscriptions.append({"id": sid, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def latest(self, topic, count=1, timeout=None):
        """Waits for `count` frames of the topic; returns the last one decoded (log time, msg)."""
        assert self.wait(lambda: len(self.frames[topic]) >= count, timeout), f"no {topic}"
        stamp, payload = self.frames[topic][-1]
        return stamp, self.decoder(topic)(payload)

    def advertise(self, topic, encoding, schema_name, schema=""):
        cid = self._id()
        self.ws.send(json.dumps({"op": "advertise", "channels": [{
            "id": cid, "topic": topic, "encoding": encoding, "schemaName": schema_name,
            "schema": schema, "schemaEncoding": "ros2msg" if encoding == "cdr" else "jsonschema"}]}))
        return cid

    def publish(self, channel_id, payload):
        self.ws.send(struct.pack("<BI", CLIENT_MESSAGE_DATA, channel_id) + payload)

    # ------------------------------------------------------------------ services
    def call(self, name, request):
        """Calls a service with a request dict; returns the decoded response, or raises with
        the server's failure message."""
        service = self.services[name]
        encode = codec(serialize_dynamic, service["request"]["schemaName"], service["request"]["schema"])
        call = self._id()
        encoding = b"cdr"
        self.ws.send(struct.pack("<BIII", SERVICE_CALL_REQUEST, service["id"], call, len(encoding))
                     + encoding + encode(request))
        assert self.wait(lambda: call in self.responses), f"no response from {name}"
        encoding, payload = self.responses.pop(call)
        if encoding == "failure":
            raise RuntimeError(payload)
        return codec(generate_dynamic, service["response"]["schemaName"], service["response"]["schema"])(payload)

    # ------------------------------------------------------------------ parameters
    def get_parameters(self, *names):
        rid = f"get{self._id()}"
        self.ws.send(json.dumps({"op": "getParameters", "parameterNames": list(names), "id": rid}))
        assert self.wait(lambda: rid in self.parameter_values)
        return {p["name"]: p.get("value") for p in self.parameter_values.pop(rid)}

    def subscribe_parameter_updates(self, *names):
        self.ws.send(json.dumps({"op": "subscribeParameterUpdates", "parameterNames": list(names)}))

    def unsubscribe_parameter_updates(self, *names):
        self.ws.send(json.dumps({"op": "unsubscribeParameterUpdates", "parameterNames": list(names)}))

    def set_parameters(self, values):
        rid = f"set{self._id()}"
        self.ws.send(json.dumps({"op": "setParameters", "id": rid,
                                 "parameters": [{"name": k, "value": v} for k, v in values.items()]}))
        assert self.wait(lambda: rid in self.parameter_values)
        return {p["name"]: p.get("value") for p in self.parameter_values.pop(rid)}


def watching_everything(url, channels, keep=4, timeout=30.0):
    """A client subscribed to every channel once `channels` of them are advertised, keeping its
    last `keep` frames per topic (for long runs, where only the count matters)."""
    client = FoxgloveClient(url, timeout, keep)
    if not client.wait(lambda: len(client.channels) >= channels, timeout):
        raise RuntimeError(f"the server advertised {len(client.channels)} channels, not {channels}")
    client.subscribe(*client.channels)
    return client
