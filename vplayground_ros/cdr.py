"""CDR bytes for the big messages, straight from numpy (SPEC 6, "cheap messages").

Building 1,000 Marker objects through rclpy costs tens of milliseconds; these encoders write
the serialised form the publishers (and the bag, and the Foxglove server) take directly.
Layout: the ROS 2 CDR encapsulation (little endian, header 00 01 00 00), every primitive
aligned to its size counted from the end of the 4-byte header, strings as uint32 length
(NUL included) + bytes + NUL, sequences as uint32 count + elements. Tests round-trip every
encoder through rclpy.serialization.deserialize_message.
"""
import itertools
import struct

import numpy as np

ENCAPSULATION = b"\x00\x01\x00\x00"
DELETEALL, CUBE = 3, 1


class Writer:
    """Appends CDR primitives to a bytearray; positions count from the payload start."""

    def __init__(self, start=0):
        self.data = bytearray()
        self.start = start  # payload position of data[0] (for alignment)

    @property
    def position(self):
        return self.start + len(self.data)

    def align(self, size):
        self.data += b"\x00" * (-self.position % size)

    def u8(self, value):
        self.data.append(value)

    def i32(self, value):
        self.align(4)
        self.data += struct.pack("<i", value)

    def u32(self, value):
        self.align(4)
        self.data += struct.pack("<I", value)

    def f64s(self, values):
        self.align(8)
        self.data += struct.pack(f"<{len(values)}d", *values)

    def f32s(self, values):
        self.align(4)
        self.data += struct.pack(f"<{len(values)}f", *values)

    def string(self, text):
        raw = text.encode("utf-8") + b"\x00"
        self.u32(len(raw))
        self.data += raw

    def header(self, stamp, frame):
        self.i32(stamp[0])
        self.u32(stamp[1])
        self.string(frame)

    def marker(self, stamp, frame, ns, marker_id, kind, action, pose, scale, rgba, frame_locked, points=None):
        """A visualization_msgs/Marker: `points` (N, 3) or None; the other sequences and strings
        after `color` empty."""
        offsets = {}
        self.header(stamp, frame)
        self.string(ns)
        self.align(4)
        offsets["id"] = self.position
        self.i32(marker_id)
        self.i32(kind)
        self.i32(action)
        self.align(8)
        offsets["pose"] = self.position
        self.f64s(pose)
        offsets["scale"] = self.position
        self.f64s(scale)
        offsets["color"] = self.position
        self.f32s(rgba)
        self.i32(0)  # lifetime
        self.u32(0)
        self.u8(1 if frame_locked else 0)
        if points is None or len(points) == 0:
            self.u32(0)
        else:  # geometry_msgs/Point is three float64: the sequence is one block
            self.u32(len(points))
            self.align(8)
            self.data += np.ascontiguousarray(points, "<f8").tobytes()
        self.u32(0)  # colors
        self.string("")  # texture_resource
        self.header((0, 0), "")  # texture: CompressedImage header, format, data
        self.string("")
        self.u32(0)
        self.u32(0)  # uv_coordinates
        self.string("")  # text
        self.string("")  # mesh_resource
        self.string("")  # mesh_file: filename, data
        self.u32(0)
        self.u8(0)  # mesh_use_embedded_materials
        return offsets

    def transform(self, stamp, parent, child, pose):
        """A geometry_msgs/TransformStamped; pose = translation xyz + rotation xyzw."""
        offsets = {}
        self.header(stamp, parent)
        self.string(child)
        self.align(8)
        offsets["pose"] = self.position
        self.f64s(pose)
        return offsets


def split_stamp(seconds):
    sec = int(np.floor(seconds))
    nanosec = int(round((seconds - sec) * 1e9))
    return (sec + 1, 0) if nanosec == 1_000_000_000 else (sec, nanosec)


def restamped(message, seconds, offset):
    """CDR bytes `message` with the builtin_interfaces/Time at byte `offset` set to `seconds`."""
    return b"".join((message[:offset], struct.pack("<iI", *split_stamp(seconds)), message[offset + 8:]))


class TemplateEncoder:
    """Sequences of one message type whose elements differ only in numbers: each element is
    copied from a template written once per (strings, alignment) and its numbers patched in.
    Every element starts with a header, so its first 8 bytes are the stamp."""

    def __init__(self, write_element):
        self._write = write_element  # (writer, key) -> {field: offset}, with zero numbers
        self._templates = {}
        self._last_layout = None
        self._filled = None  # (layout, its elements as last written, {number key: their bits})

    def template(self, key, alignment):
        if (key, alignment) not in self._templates:
            w = Writer(start=alignment)
            offsets = self._write(w, key)
            self._templates[(key, alignment)] = (bytes(w.data), {k: v - alignment for k, v in offsets.items()})
        return self._templates[(key, alignment)]

    def layout(self, keys, alignment, identity=None):
        """The elements of `keys` laid end to end from a payload position ≡ alignment (mod 8):
        (bytes as a uint8 array, (2N,) indices of the stamps' 32-bit words (sec, nanosec of
        each element in turn) counted from `alignment` bytes before the first element, {field: start offsets (N,)},
        {(field, type, count): indices, filled as asked}). An element's alignment depends
        on what came before it, so the layout is a whole; the last one is kept, since the keys
        (the bodies' names) rarely change between messages. `identity` stands for the keys when
        comparing with the last layout (cheaper than the keys: they are then only read on a
        change); by default the keys themselves."""
        if identity is None:
            keys = identity = tuple(keys)
        cache_key = (identity, alignment)
        if self._last_layout is not None and self._last_layout[0] == cache_key:
            return self._last_layout[1]
        chunks, stamps, fields = [], [], {}
        position = alignment
        used = {}  # the templates this layout needs: names of removed bodies are not kept forever
        for key in keys:
            pad = -position % 4  # every element starts with its header's int32
            if pad:
                chunks.append(b"\x00" * pad)
                position += pad
            template, offsets = used[(key, position % 8)] = self.template(key, position % 8)
            chunks.append(template)
            stamps.append(position - alignment)
            for field, at in offsets.items():
                fields.setdefault(field, []).append(position - alignment + at)
            position += len(template)
        layout = (np.frombuffer(b"".join(chunks), np.uint8),
                  spread((np.array(stamps, np.intp) + alignment) // 4, 2).ravel(),
                  {field: np.array(at, np.intp) for field, at in fields.items()}, {})
        self._templates = used
        self._last_layout = (cache_key, layout)
        return layout

    def elements(self, stamp_bytes, keys, numbers, alignment, identity=None):
        """One element per key, laid from a payload position ≡ alignment (mod 8): a memoryview
        of their bytes, valid until the next call. numbers: {field: array (N, k) of the field's
        values, its dtype the wire type ('<f8', '<f4', '<i4')}. The elements of the last layout
        are kept filled: a call writes the stamps and only the fields whose bits changed (a
        frozen body's pose, every size and colour of a settled pile: nothing), each through a
        numpy view of its type; a read-only array that is the one written last time is taken
        as unchanged without comparing (read-only: its owner promises not to change it).
        `identity`: see layout."""
        count = next(iter(numbers.values())).shape[0]
        if count == 0:
            return b""
        layout = self.layout(keys, alignment, identity)
        template, stamp_words, starts, indices = layout
        if self._filled is None or self._filled[0] is not layout:
            # The buffer starts `alignment` bytes before the elements, so every number sits at
            # a multiple of its size in it, as CDR aligns it in the payload: each field is
            # written through a view of its own type, one index per number rather than per byte.
            buffer = np.zeros(-(-(alignment + len(template)) // 8) * 8, np.uint8)
            buffer[alignment:alignment + len(template)] = template
            self._filled = (layout, buffer, {})
        _, buffer, written = self._filled
        # Flat indices and the stamp repeated: a third of the time of a broadcast (N, 2) index.
        buffer.view("<u4")[stamp_words] = np.frombuffer(stamp_bytes * count, "<u4")
        for field, values in numbers.items():
            key = (field, values.dtype.str, values.shape[1])
            last = written.get(key)
            if last is not None and last[0] is values:
                continue  # the very read-only array written last time (a settled world's)
            bits = np.ascontiguousarray(values).view(f"<u{values.dtype.itemsize}")
            if last is not None and np.array_equal(last[1], bits):
                written[key] = (values if not values.flags.writeable else None, last[1])
                continue
            if key not in indices:
                indices[key] = spread((starts[field] + alignment) // values.dtype.itemsize, values.shape[1])
            buffer.view(values.dtype)[indices[key]] = values
            written[key] = (values if not values.flags.writeable else None, bits.copy())
        return memoryview(buffer)[alignment:alignment + len(template)]


def spread(starts, count):
    """(N, count) indices: `count` consecutive ones from each of `starts`."""
    return starts[:, None] + np.arange(count)


class BodyMarkerEncoder:
    """~/bodies/markers: DELETEALL, then the bodies' shapes (a marker type each)."""

    def __init__(self):
        self._elements = TemplateEncoder(lambda w, key: w.marker(
            (0, 0), key[0], key[1], 0, key[2], 0, [0.0] * 7, [0.0] * 3, [0.0] * 4, True,
            np.frombuffer(key[3], "<f8").reshape(-1, 3)))
        self._head = (None, b"")  # (frame, the count and the DELETEALL marker with zero numbers)
        self._identity = (None,) * 5  # (namespaces, types, points, frame, the layout identity they make)

    def head(self, frame, count, stamp_bytes):
        """The array's count and its DELETEALL marker, written once per frame and patched."""
        if self._head[0] != frame:
            w = Writer()
            w.u32(0)
            w.marker((0, 0), frame, "", 0, 0, DELETEALL, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], [1.0] * 3,
                     [0.0] * 4, False)
            self._head = (frame, bytes(w.data))
        head = bytearray(self._head[1])
        head[0:4] = struct.pack("<I", count)
        head[4:12] = stamp_bytes  # the DELETEALL's header stamp follows the count
        return head

    def encode(self, seconds, frame, namespaces, types, ids, poses, sizes, colours, points=None):
        """namespaces (N,) str, types (N,) int Marker types, ids (N,) or (N, 1) int, poses (N, 7)
        xyz + xyzw, sizes (N, 3), colours (N, 4) RGBA, points: None, or a tuple of each
        marker's points as '<f8' bytes (b"" for none; part of the marker's template): the
        MarkerArray's CDR bytes. Read-only arrays (and the same points tuple) passed again
        unchanged (a settled world's) are neither compared nor rewritten."""
        stamp_bytes = struct.pack("<iI", *split_stamp(seconds))
        head = self.head(frame, len(ids) + 1, stamp_bytes)
        last = self._identity
        if (last[0] is namespaces and last[1] is types and last[2] is points and last[3] == frame
                and not namespaces.flags.writeable and not types.flags.writeable):
            identity = last[4]  # the same read-only arrays as last time
        else:
            namespaces, types = np.asarray(namespaces, str), np.asarray(types, np.int32)
            identity = (frame, namespaces.dtype.str, len(namespaces), namespaces.tobytes(),
                        types.tobytes(), points)  # no loop per body
            self._identity = (namespaces, types, points, frame, identity)
        ids = np.asarray(ids, "<i4")
        keys = ((frame, str(ns), int(t), p) for ns, t, p in
                zip(namespaces, types, points if points is not None else itertools.repeat(b"")))
        elements = self._elements.elements(stamp_bytes, keys, {
            "id": ids if ids.ndim == 2 else ids.reshape(-1, 1), "pose": np.asarray(poses, "<f8"),
            "scale": np.asarray(sizes, "<f8"), "color": np.asarray(colours, "<f4")}, len(head) % 8, identity)
        return b"".join((ENCAPSULATION, head, elements))


class TransformEncoder:
    """tf2_msgs/TFMessage of many transforms (the bag's /tf), written without tf2_msgs."""

    def __init__(self):
        self._elements = TemplateEncoder(lambda w, key: w.transform((0, 0), key[0], key[1], [0.0] * 7))

    def encode(self, seconds, parents, children, poses):
        count = struct.pack("<I", len(children))
        poses = np.asarray(poses, "<f8")
        # The frames, not a pair per transform, tell a changed layout: two flat tuples compare
        # at C speed (the same string objects every message), and pairs are made only then.
        parents, children = tuple(parents), tuple(children)
        elements = self._elements.elements(struct.pack("<iI", *split_stamp(seconds)), zip(parents, children),
                                           {"pose": poses if poses.shape[1:] == (7,) else poses.reshape(-1, 7)}, len(count),
                                           (parents, children))
        return b"".join((ENCAPSULATION, count, elements))


def clock(seconds):
    """rosgraph_msgs/Clock, one builtin_interfaces/Time: sent after every batch, so written
    directly rather than through the generic encoder (five times faster)."""
    return ENCAPSULATION + struct.pack("<iI", *split_stamp(seconds))


def marker_array(seconds, frame, markers):
    """visualization_msgs/MarkerArray of markers given as dicts of Writer.marker's arguments
    (ns, marker_id, kind, action, pose, scale, rgba, frame_locked, points), all stamped
    `seconds`, in `frame` unless a marker names its own (its key "frame")."""
    stamp = split_stamp(seconds)
    w = Writer()
    w.u32(len(markers))
    for m in markers:
        if "frame" in m:
            m = dict(m)
            w.marker(stamp, m.pop("frame"), **m)
        else:
            w.marker(stamp, frame, **m)
    return ENCAPSULATION + bytes(w.data)


def transform_stamped(seconds, parent, child, pose):
    """geometry_msgs/TransformStamped; pose = translation xyz + rotation xyzw."""
    w = Writer()
    w.transform(split_stamp(seconds), parent, child, [float(v) for v in pose])
    return ENCAPSULATION + bytes(w.data)


def pose_array(seconds, frame, positions, quaternions):
    """geometry_msgs/PoseArray: the poses are one contiguous block of float64."""
    w = Writer()
    w.header(split_stamp(seconds), frame)
    w.u32(len(positions))
    w.align(8)
    block = np.concatenate([positions, quaternions], axis=1).astype("<f8", copy=False)
    return b"".join((ENCAPSULATION, w.data, block))


def pose_array_of(seconds, frame, block):
    """geometry_msgs/PoseArray of an (N, 7) float64 block of xyz + xyzw rows."""
    w = Writer()
    w.header(split_stamp(seconds), frame)
    w.u32(len(block))
    w.align(8)
    return b"".join((ENCAPSULATION, w.data, np.ascontiguousarray(block, "<f8")))


_CLOUD_HEADS = {}  # (frame, fields, point step) -> the PointCloud2 up to point_step, zero stamp and width


def point_cloud(seconds, frame, fields, rows):
    """sensor_msgs/PointCloud2 of one row: fields [(name, offset, datatype, count)] and a numpy
    structured array whose dtype is that layout. What precedes the points is written once per
    frame and layout, then the stamp and the counts are patched in."""
    key = (frame, tuple(map(tuple, fields)), rows.dtype.itemsize)
    head = _CLOUD_HEADS.get(key)
    if head is None:
        w = Writer()
        w.header((0, 0), frame)
        w.u32(1)  # height
        w.align(4)
        width_at = w.position
        w.u32(0)  # width
        w.u32(len(fields))
        for name, offset, datatype, count in fields:
            w.string(name)
            w.u32(offset)
            w.u8(datatype)
            w.u32(count)
        w.u8(0)  # is_bigendian
        w.u32(rows.dtype.itemsize)  # point_step
        if len(_CLOUD_HEADS) > 64:  # frames come from parameters: never an unbounded table
            _CLOUD_HEADS.clear()
        head = _CLOUD_HEADS[key] = (bytes(w.data), width_at)
    data, width_at = head
    payload = rows.tobytes()
    out = bytearray(ENCAPSULATION)
    out += data
    struct.pack_into("<iI", out, 4, *split_stamp(seconds))
    struct.pack_into("<I", out, 4 + width_at, len(rows))
    out += b"\x00" * (-len(data) % 4)  # row_step, data's length: uint32s
    out += struct.pack("<II", rows.dtype.itemsize * len(rows), len(payload))
    out += payload
    out.append(1)  # is_dense
    return bytes(out)
