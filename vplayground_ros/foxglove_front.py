"""The public port of the built-in Foxglove server: a thin TCP relay in front of foxglove-sdk.

foxglove-sdk 0.30 (the newest release) accepts only the `foxglove.sdk.v1` subprotocol and sends
no server metadata. Viewers released before December 2025 (Lichtblick up to at least 1.10.8,
older Foxglove) ask for `foxglove.websocket.v1`, which carries the same messages, and are refused
with HTTP 400; and viewers offer the 3D panel's publish tools (clicked_point, initialpose) only
to a data source whose serverInfo metadata names a `ROS_DISTRO`. The relay reads a viewer's
WebSocket handshake, accepts either subprotocol, hands the handshake to the sdk server on a
loopback port under the sdk's name, adds the metadata to the sdk's first frame (serverInfo), and
from then on copies bytes both ways untouched: no WebSocket framing in Python, so a client
subscribed to everything costs next to nothing here.
"""
import json
import socket
import struct
import threading
import time

SDK_SUBPROTOCOL = b"foxglove.sdk.v1"
# Preferred first: a viewer offering both gets the sdk's own name.
SUBPROTOCOLS = [SDK_SUBPROTOCOL, b"foxglove.websocket.v1"]
HANDSHAKE_LIMIT = 64 * 1024  # bytes: an HTTP head larger than this is not a viewer's
HANDSHAKE_TIMEOUT = 10.0  # s for a viewer (or the sdk) to send its handshake
DRAIN_LIMIT, DRAIN_TIMEOUT = 1024 * 1024, 1.0  # what a refused viewer may still send, read and dropped
CHUNK = 256 * 1024  # bytes per copy: a scenery mesh message is megabytes
# Towards the viewer: bytes per copy (a round of 10,000 bodies is ~4 MB), and how long the relay
# lets the sdk's frames gather after a read that did not fill its buffer (s). The sdk writes a
# frame per message (~250 a second at 1,000 bodies), and each read and write woke the relay and
# took the GIL from the simulation's threads; gathered, it wakes at most ~40 times a second
# below a buffer's worth. A frame waits at most this long (viewers draw at 30-60 Hz). 25 ms
# rather than 10: at 1,000 bodies with a client on every channel the relay and the sdk's
# sender took 1.7-1.8 % of a core instead of 2.2-2.5 (two pairs of runs, quiet VM). 4 MiB
# rather than 1 (a round of 10,000 bodies in one read and one write): at 10,000 + Foxglove the
# relay took 3.8-4.1 % of a core instead of 5.1-5.3 (two pairs); at most MAX_VIEWERS buffers.
VIEWER_CHUNK = 4 * 1024 * 1024
GATHER = 0.025
# Viewers served at once (each holds two threads; one in the handshake holds its slot up to
# HANDSHAKE_TIMEOUT): anyone who can reach the port could otherwise open connections without end.
MAX_VIEWERS = 16
# A viewer refused for want of a slot gets its 503 after its request is read (up to this long,
# s): a socket closed with an unread request is reset, and the reset can reach the viewer before
# the answer does. At most MAX_VIEWERS refusals wait at once; past that they answer at once.
REFUSE_READ_TIMEOUT = 2.0


BUSY = b"503 Service Unavailable"
BUSY_TEXT = f"too many viewers: at most {MAX_VIEWERS} at once"


class HandshakeError(Exception):
    """A peer's handshake the relay cannot pass on; the text goes back in an HTTP 400."""


def read_head(sock, timeout):
    """(HTTP head up to and without its blank line, the bytes read after it), all of it within
    `timeout` s (HandshakeError after: a peer sending a byte every few seconds had held its
    place for as long as it liked, each read within the timeout); the socket's own timeout is
    left as it was."""
    data = b""
    deadline = time.monotonic() + timeout
    previous = sock.gettimeout()
    try:
        while b"\r\n\r\n" not in data:
            if len(data) > HANDSHAKE_LIMIT:
                raise HandshakeError("HTTP head too large")
            left = deadline - time.monotonic()
            if left <= 0.0:
                raise HandshakeError(f"no whole HTTP head within {timeout:g} s")
            sock.settimeout(left)
            try:
                chunk = sock.recv(4096)
            except TimeoutError:
                raise HandshakeError(f"no whole HTTP head within {timeout:g} s") from None
            if not chunk:
                raise HandshakeError("connection closed during the handshake")
            data += chunk
    finally:
        sock.settimeout(previous)
    head, rest = data.split(b"\r\n\r\n", 1)
    return head, rest


def header_values(lines, name):
    """The comma-separated values of every header line called `name` (case-insensitive)."""
    values = []
    for line in lines[1:]:
        key, _, value = line.partition(b":")
        if key.strip().lower() == name:
            values += [v.strip() for v in value.split(b",") if v.strip()]
    return values


def with_header(lines, name, value):
    """The head's lines without any `name` header, plus `name: value` (None: none)."""
    kept = [lines[0]] + [line for line in lines[1:] if line.partition(b":")[0].strip().lower() != name]
    return kept + ([name + b": " + value] if value is not None else [])


def choose_subprotocol(request_lines):
    offered = header_values(request_lines, b"sec-websocket-protocol")
    chosen = next((s for s in SUBPROTOCOLS if s in offered), None)
    if chosen is None:
        raise HandshakeError(f"expected a Sec-WebSocket-Protocol of {', '.join(s.decode() for s in SUBPROTOCOLS)}")
    return chosen


def upstream_request(request_lines):
    """The viewer's handshake as the sdk takes it: its subprotocol, and no extensions offered
    (a compression the sdk accepted would hide serverInfo from the relay)."""
    lines = with_header(request_lines, b"sec-websocket-protocol", SDK_SUBPROTOCOL)
    return b"\r\n".join(with_header(lines, b"sec-websocket-extensions", None)) + b"\r\n\r\n"


def read_frame(sock, data):
    """(the first WebSocket frame a server sent, unmasked: fin, opcode, payload; bytes after it)."""
    def need(count):
        nonlocal data
        while len(data) < count:
            chunk = sock.recv(CHUNK)
            if not chunk:
                raise ConnectionError("the sdk server closed before its serverInfo")
            data += chunk
    need(2)
    fin, opcode, length, start = data[0] & 0x80, data[0] & 0x0F, data[1] & 0x7F, 2
    if length == 126:
        need(4)
        length, start = struct.unpack_from("!H", data, 2)[0], 4
    elif length == 127:
        need(10)
        length, start = struct.unpack_from("!Q", data, 2)[0], 10
    need(start + length)
    return bool(fin), opcode, data[start:start + length], data[start + length:]


def text_frame(payload):
    """An unmasked, final text frame (server to client)."""
    length = len(payload)
    if length < 126:
        size = struct.pack("!B", length)
    elif length < 1 << 16:
        size = struct.pack("!BH", 126, length)
    else:
        size = struct.pack("!BQ", 127, length)
    return b"\x81" + size + payload


def with_metadata(payload, metadata):
    """serverInfo's JSON with `metadata` merged into the sdk's own."""
    info = json.loads(payload)
    info["metadata"] = {**info.get("metadata", {}), **metadata}
    return json.dumps(info, separators=(",", ":")).encode()


def refuse(sock, status, text, drain=False):
    """An HTTP error answer with `text` as its body; a peer already gone is ignored. With
    `drain` (on the viewer's own thread), what the peer still sends is read and dropped, up to
    DRAIN_LIMIT bytes or DRAIN_TIMEOUT in all: closing a socket with unread bytes resets the
    connection, and the peer lost the answer (an HTTP head over HANDSHAKE_LIMIT got a reset)."""
    body = f"{text}\n".encode()
    try:
        sock.sendall(b"HTTP/1.1 %s\r\nContent-Type: text/plain\r\nConnection: close\r\n"
                     b"Content-Length: %d\r\n\r\n" % (status, len(body)) + body)
        if drain:
            sock.shutdown(socket.SHUT_WR)
            deadline = time.monotonic() + DRAIN_TIMEOUT
            drained = 0
            while drained < DRAIN_LIMIT and time.monotonic() < deadline:
                sock.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = sock.recv(65536)
                if not chunk:
                    break
                drained += len(chunk)
    except OSError:
        pass


def copy(source, target, size=CHUNK, gather=0.0):
    """Bytes from source to target until either side closes; then both are shut. With
    `gather`, a read that did not fill the buffer is followed by that long a pause, so what
    arrives meanwhile goes in one read and one write."""
    buffer = memoryview(bytearray(size))
    try:
        while True:
            count = source.recv_into(buffer)
            if not count:
                break
            target.sendall(buffer[:count])
            if gather and count < size:
                time.sleep(gather)
    except OSError:
        pass
    finally:
        for sock in (source, target):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


class ProtocolFront:
    def __init__(self, upstream_port, host, port, metadata, log):
        """Listens on host:port (0: any free port) at once; raises OSError if it cannot. `log`
        (the simulator's logger) hears of each viewer coming and going."""
        self.upstream = ("127.0.0.1", upstream_port)
        self.metadata = dict(metadata)
        self.log = log
        family = socket.AF_INET6 if ":" in host else socket.AF_INET  # ::1, ::, fe80::...
        self.listener = socket.create_server((host, port), family=family)
        self.port = self.listener.getsockname()[1]
        self.connections = set()
        self.serving = 0       # viewers with a thread of their own, at most MAX_VIEWERS
        self._full_logged = False  # the warning about refused viewers, once until a slot frees
        self._refusing = 0         # refusals reading their viewer's request (REFUSE_READ_TIMEOUT)
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._accept, name="foxglove-front", daemon=True)
        self._thread.start()

    def stop(self):
        self.listener.shutdown(socket.SHUT_RDWR)  # wakes accept()
        self.listener.close()
        self._thread.join(5.0)
        with self._lock:
            for sock in self.connections:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def _accept(self):
        while True:
            try:
                viewer, address = self.listener.accept()
            except OSError:  # stopped
                return
            with self._lock:
                full = self.serving >= MAX_VIEWERS
                if not full:
                    self.serving += 1
                warn = full and not self._full_logged
                self._full_logged |= full
                read_first = full and self._refusing < MAX_VIEWERS
                self._refusing += read_first
            if full:
                if warn:
                    self.log.warning(f"foxglove: {MAX_VIEWERS} viewers connected, refusing more "
                                     f"(first refused: {address[0]}:{address[1]})")
                if read_first:
                    threading.Thread(target=self._refuse_busy, args=(viewer,), daemon=True).start()
                else:
                    viewer.settimeout(HANDSHAKE_TIMEOUT)
                    refuse(viewer, BUSY, BUSY_TEXT)
                    viewer.close()
                continue
            threading.Thread(target=self._serve, args=(viewer, address), daemon=True).start()

    def _refuse_busy(self, viewer):
        """The 503 of a viewer past MAX_VIEWERS, once its request is read (or a silent peer's
        REFUSE_READ_TIMEOUT is up)."""
        try:
            viewer.settimeout(REFUSE_READ_TIMEOUT)
            try:
                read_head(viewer, REFUSE_READ_TIMEOUT)
            except (OSError, HandshakeError):
                pass  # silent, gone or not HTTP: the answer goes out all the same
            refuse(viewer, BUSY, BUSY_TEXT)
        finally:
            viewer.close()
            with self._lock:
                self._refusing -= 1

    def _serve(self, viewer, address):
        peer = f"{address[0]}:{address[1]}"
        sdk = None
        try:
            viewer.settimeout(HANDSHAKE_TIMEOUT)
            head, early = read_head(viewer, HANDSHAKE_TIMEOUT)
            lines = head.split(b"\r\n")
            subprotocol = choose_subprotocol(lines)
            sdk = socket.create_connection(self.upstream, timeout=HANDSHAKE_TIMEOUT)
            with self._lock:
                self.connections.update((viewer, sdk))
            sdk.sendall(upstream_request(lines) + early)
            response, rest = read_head(sdk, HANDSHAKE_TIMEOUT)
            response_lines = response.split(b"\r\n")
            upgraded = response_lines[0].split(b" ")[1:2] == [b"101"]
            if upgraded:
                response_lines = with_header(response_lines, b"sec-websocket-protocol", subprotocol)
            viewer.sendall(b"\r\n".join(response_lines) + b"\r\n\r\n")
            if upgraded:
                fin, opcode, payload, rest = read_frame(sdk, rest)
                if not (fin and opcode == 1):
                    raise ValueError(f"the sdk's first frame is not serverInfo (opcode {opcode})")
                viewer.sendall(text_frame(with_metadata(payload, self.metadata)) + rest)
                self.log.info(f"foxglove: viewer {peer} connected ({subprotocol.decode()})")
            for sock in (viewer, sdk):
                sock.settimeout(None)
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            upstream = threading.Thread(target=copy, args=(viewer, sdk), daemon=True)
            upstream.start()
            copy(sdk, viewer, VIEWER_CHUNK, GATHER)
            upstream.join()  # it ends at once: copy() shut both sockets
            if upgraded:
                self.log.info(f"foxglove: viewer {peer} left")
        except HandshakeError as error:
            refuse(viewer, b"400 Bad Request", error, drain=True)
        except (OSError, ValueError) as error:  # a peer gone or silent mid-handshake, serverInfo not JSON
            self.log.warning(f"foxglove: viewer {peer}: {error}")
        finally:
            with self._lock:
                self.connections.difference_update((viewer, sdk))
                self.serving -= 1
                self._full_logged = False
            for sock in (viewer, sdk):
                if sock is not None:
                    sock.close()
