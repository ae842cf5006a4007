"""CDR bytes for the big messages, straight from numpy (SPEC 6, "cheap messages").

Building 1,000 Marker objects through rclpy costs tens of milliseconds; these encoders write
the serialised form the publishers (and the bag, and the Foxglove server) take directly.
Layout: the ROS 2 CDR encapsulation (little endian, header 00 01 00 00), every primitive
aligned to its size counted from the end of the 4-byte header, strings as uint32 length
(NUL included) + bytes + NUL, sequences as uint32 count + elements. Tests round-trip every
encoder through rclpy.serialization.deserialize_message.
"""
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

    def marker(self, stamp, frame, ns, marker_id, kind, action, pose, scale, rgba, frame_locked):
        """A visualization_msgs/Marker with empty sequences and strings after `color`."""
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
        self.u32(0)  # points
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


def split_stamp(seconds):
    sec = int(np.floor(seconds))
    return sec, int(round((seconds - sec) * 1e9)) % 1_000_000_000


class BodyMarkerEncoder:
    """~/bodies/markers: DELETEALL, then one CUBE per body. Each body marker is copied from a
    template (per namespace, frame and alignment) and only its numbers are written in."""

    def __init__(self):
        self._templates = {}

    def template(self, frame, ns, alignment):
        key = (frame, ns, alignment)
        if key not in self._templates:
            w = Writer(start=alignment)
            offsets = w.marker((0, 0), frame, ns, 0, CUBE, 0, [0.0] * 7, [0.0] * 3, [0.0] * 4, True)
            self._templates[key] = (bytes(w.data), {k: v - alignment for k, v in offsets.items()})
        return self._templates[key]

    def encode(self, seconds, frame, namespaces, ids, poses, sizes, colours):
        """namespaces (N,) str, ids (N,) int, poses (N, 7) xyz + xyzw, sizes (N, 3), colours
        (N, 4) RGBA: the MarkerArray's CDR bytes."""
        stamp = split_stamp(seconds)
        w = Writer()
        w.u32(len(ids) + 1)
        w.marker(stamp, frame, "", 0, 0, DELETEALL, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], [1.0] * 3,
                 [0.0] * 4, False)
        # The template's stamp is patched too: it is the first 8 bytes of every marker.
        stamp_bytes = struct.pack("<iI", *stamp)
        data = w.data
        for k in range(len(ids)):
            w.align(4)  # a Marker starts with its header's int32
            start = w.position
            template, offsets = self.template(frame, namespaces[k], start % 8)
            data += template
            data[start:start + 8] = stamp_bytes
            struct.pack_into("<i", data, start + offsets["id"], int(ids[k]))
            struct.pack_into("<7d", data, start + offsets["pose"], *poses[k])
            struct.pack_into("<3d", data, start + offsets["scale"], *sizes[k])
            struct.pack_into("<4f", data, start + offsets["color"], *colours[k])
        return ENCAPSULATION + bytes(data)


def pose_array(seconds, frame, positions, quaternions):
    """geometry_msgs/PoseArray: the poses are one contiguous block of float64."""
    w = Writer()
    w.header(split_stamp(seconds), frame)
    w.u32(len(positions))
    w.align(8)
    block = np.concatenate([positions, quaternions], axis=1).astype("<f8", copy=False)
    return ENCAPSULATION + bytes(w.data) + block.tobytes()


def point_cloud(seconds, frame, fields, rows):
    """sensor_msgs/PointCloud2 of one row: fields [(name, offset, datatype, count)] and a numpy
    structured array whose dtype is that layout."""
    w = Writer()
    w.header(split_stamp(seconds), frame)
    w.u32(1)  # height
    w.u32(len(rows))  # width
    w.u32(len(fields))
    for name, offset, datatype, count in fields:
        w.string(name)
        w.u32(offset)
        w.u8(datatype)
        w.u32(count)
    w.u8(0)  # is_bigendian
    w.u32(rows.dtype.itemsize)  # point_step
    w.u32(rows.dtype.itemsize * len(rows))  # row_step
    payload = rows.tobytes()
    w.u32(len(payload))
    w.data += payload
    w.u8(1)  # is_dense
    return ENCAPSULATION + bytes(w.data)
