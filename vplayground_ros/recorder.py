"""MCAP bags (SPEC 7), written with the `mcap` library's records (BagWriter frames the messages
itself, into the file mcap's Writer would write).

Why `mcap` and not foxglove-sdk's writer: the bytes we record are the CDR the publishers already
send, so the writer only frames and compresses them, and the pure-Python `mcap` writer keeps
the package free of a native extension wherever it is built (colcon, pip); zstd runs in
`zstandard`'s C code either way.

- ROS 2 profile, `ros2msg` schemas with full definitions (interfaces.schema), `cdr` messages,
  zstd chunks, message indexes and a summary.
- One Schema record per message type in each file, shared by every channel of that type, as
  rosbag2's MCAP storage writes them: readers find a type's channels by its first schema of
  that name (KISS-ICP's MCAP loader saw one PointCloud2 topic of two).
- log time = publish time = simulation time (ns).
- Each channel carries the ROS 2 profile's `offered_qos_profiles` (rosbag2's YAML, Jazzy's
  spelling): `ros2 bag play` offers the publishers' QoS again, so the latched topics (the
  scenery, /tf_static, the state) are latched in a replay too.
- Writes happen on the recorder's own thread, every WAKE_PERIOD, from a bounded queue: the
  simulation and the publishers never wait on the disk; what does not fit is dropped and counted.
- record_split_size: a new file <stem>_<n>.mcap starts past that many bytes, and the latched
  topics (the scenery, /tf_static, the state) are written again at its start, at the time it
  starts, so every file opens on its own and covers its own stretch of time. When the
  simulation's time goes back (~/reset, ~/load_scene: new_timeline) a new file starts too: a
  file never holds two runs over the same times.
- A disk that fills or a path that cannot be written stops the recording, never the simulation:
  the first failure is kept in `error` (the node puts it on /diagnostics) and later messages are
  dropped.
- Chunks are written to the file as they fill or after CHUNK_MAX_AGE, so after a crash
  (kill -9) every complete chunk is still there: `vplayground-recover crashed.mcap fixed.mcap`
  rewrites them into a proper, summarised file (as `mcap recover` does).
"""
import argparse
import io
import os
import struct
import sys
import threading
import time
import types
import zlib
from collections import deque, namedtuple
from pathlib import Path

import mcap.writer
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, Schema, Statistics,
                          SummaryOffset)
from mcap.stream_reader import breakup_chunk
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

from .interfaces import schema

PROFILE = "ros2"
# Larger chunks compress better, and keep the writer's memory flat: it holds a ~1.6 kB index
# entry per chunk until the file is finished, which at 256 KiB was ~27 MB an hour for the
# default scene (~1.3 MB/s of messages). Most of a bag is the 30 Hz snapshots of every body,
# each much like the one before it when the bodies rest: zstd finds that only when the round
# before (3.8 MB at 10,000 bodies) is in the same chunk and in its window, so a chunk's first
# round costs what a new scene does. Replaying a settled 10,000-body pile's chunks (zstd as
# below), 16 MiB chunks made the bag 2.4 times smaller than 8 MiB and took 25 % less CPU; a
# 1,000-body pile that never rests, the same size and 10 % less CPU. Foxglove's decoder
# (@mcap/support's wasm zstd) reads them; zstd-codec, a 16 MB heap, cannot.
CHUNK_SIZE = 16 * 1024 * 1024
MIN_CHUNK_SIZE = 64 * 1024  # and the smallest split size (--record-split-size)
# What a crash (kill -9) loses is the chunk being filled: it is written once full or once its
# first message is this old (wall-clock s), so at most ~4 s of the default scene (~5 MB), ~1.4 s
# of 1,000 bodies (~11 MB/s of snapshots).
CHUNK_MAX_AGE = 4.0
# zstd's fast level -2 with a hash table of 2^17 entries. Replaying recorded bags' chunks (best
# of 3 runs), against the level 2 with 2^18 entries used before, a settled 10,000-body pile took
# 0.43 instead of 0.61 ms of CPU per MB for a 9 % larger bag, a 1,000-body pile that never rests
# 0.97 instead of 2.0 ms per MB for a 9 % larger bag. Counting what the larger file costs to
# write (~2 ms per MB into this VM's page cache), that is ~20 % (settled) to ~30 % (moving) less
# of the writer's CPU; levels -3 and -5 save little more and make the bags 18-30 % larger. The
# fast levels find the previous round only with a table this size (level 1 as it comes, 2^13,
# made 4 times the bag at 10,000 settled bodies).
ZSTD_LEVEL = -2
ZSTD_HASH_LOG = 17
# zstd windows decoders take by default (libzstd, the mcap readers): 2^27 bytes.
MAX_WINDOW_LOG = 27
QUEUE_MESSAGES = 4096
# The writer wakes this often (s) and writes what has queued, rather than at every message: a
# wake-up per message (128 Hz of /clock alone) cost more CPU than the writing, and made the
# simulation thread and the writer take the GIL from each other. Each wake-up costs more than
# its work here (work after a sleep runs ~10 times slower than hot on this VM): 0.1 s instead of
# 0.05 took the writer at 1,000 resting bodies from 0.80-0.90 to 0.60-0.75 % of a core (ROS-free,
# 20 s runs). The queue holds 4096: 0.1 s of the default scene at 4x real time is ~400.
WAKE_PERIOD = 0.1
# ... and this often when it found nothing (a paused simulation sends ~1 message a second): the
# queue has no wake-up of its own, and close() is answered within it.
IDLE_WAKE_PERIOD = 0.25


class WholeChunkZstd:
    """zstd as mcap's writer calls it (`zstandard.compress(chunk)`), with a window as long as
    the chunk instead of the level's default, so a snapshot finds its predecessor in it. A
    compressor per call: several recorders may write at once, and a ZstdCompressor is not
    thread-safe."""

    @staticmethod
    def compress(data):
        window_log = min(MAX_WINDOW_LOG, max(zstandard.WINDOWLOG_MIN, (len(data) - 1).bit_length()))
        parameters = zstandard.ZstdCompressionParameters.from_level(
            ZSTD_LEVEL, source_size=len(data), window_log=window_log,
            hash_log=max(zstandard.HASHLOG_MIN, min(ZSTD_HASH_LOG, window_log)))  # no table larger than the chunk
        return zstandard.ZstdCompressor(compression_params=parameters).compress(data)


# mcap 1.6 has no setting for the compressor it uses; this is its one call of zstandard.
mcap.writer.zstandard = WholeChunkZstd

# Each chunk's CRC-32 (over its uncompressed records, ~8 MiB) is mcap's other use of C code:
# zlib 1.2's crc32 runs at ~2 GB/s, ~15 % of the writer's CPU on a 10,000-body bag; zlib-ng's,
# the same checksum with the CPU's carry-less multiply, ~6 times faster. mcap reaches it as
# `zlib.crc32`; the bag is the same either way.
try:
    from zlib_ng import zlib_ng as _fast_zlib
    mcap.writer.zlib = types.SimpleNamespace(crc32=_fast_zlib.crc32)
except ImportError:  # zlib's own, slower
    mcap.writer.zlib = zlib


# A Message record's opening: opcode, record length, channel id, sequence, log time, publish time.
MESSAGE_HEAD = struct.Struct("<BQHIQQ")


def record_bytes(record):
    """One MCAP record (mcap.records) as bytes."""
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


class BagWriter:
    """The MCAP file as mcap's Writer(chunk_size, CompressionType.ZSTD) writes it, byte for byte
    (test_bag compares the two), for what the recorder does: schemas, channels, messages whose
    publish time is their log time. mcap's writer makes a Message object for each message and
    writes it field by field into a BytesIO (~30 us a message, most of the recorder's CPU at
    1,000 bodies beside zstd); here a message's head is packed in place in one buffer kept for
    the whole file, which zstd and the CRC then read. The other records are mcap's own."""

    def __init__(self, stream, chunk_size, profile, library):
        self._stream = stream
        self._chunk_size = chunk_size
        self._buffer = bytearray(chunk_size + 1024 * 1024)  # grows to the largest chunk yet
        self._schemas, self._channels, self._chunk_indexes = [], [], []
        self._counts = {}  # channel id -> messages, in the order of their first ones (mcap's)
        self._message_count = self._start_time = self._end_time = 0
        self._new_chunk()
        stream.write(MCAP0_MAGIC)
        stream.write(record_bytes(Header(profile, library)))

    @property
    def has_messages(self):
        return self._message_count > 0

    def _new_chunk(self):
        self.chunk_opened = None  # time.monotonic() at the chunk's first message
        self._size = 0      # bytes of the chunk's records in _buffer
        self._indexes = {}  # channel id -> [log time, offset in the chunk, ...]
        self._chunk_messages = self._chunk_start = self._chunk_end = 0

    def register_schema(self, name, encoding, data):
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._add_record(record_bytes(schema))
        return schema.id

    def register_channel(self, topic, message_encoding, schema_id, metadata=None):
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          metadata=metadata or {}, schema_id=schema_id)
        self._channels.append(channel)
        self._add_record(record_bytes(channel))
        return channel.id

    def _room(self, count):
        """The buffer's offset for `count` more bytes of the chunk."""
        start = self._size
        if start + count > len(self._buffer):
            self._buffer += bytes(start + count - len(self._buffer))
        self._size = start + count
        return start

    def _add_record(self, data):
        start = self._room(len(data))
        self._buffer[start:self._size] = data
        if self._size > self._chunk_size and self._chunk_messages:
            self.finish_chunk()

    def add_message(self, channel_id, log_time, data):
        if self._message_count == 0 or log_time < self._start_time:
            self._start_time = log_time
        if log_time > self._end_time:
            self._end_time = log_time
        self._message_count += 1
        self._counts[channel_id] = self._counts.get(channel_id, 0) + 1
        if self._chunk_messages == 0:
            self._chunk_start, self.chunk_opened = log_time, time.monotonic()
        elif log_time < self._chunk_start:
            self._chunk_start = log_time
        if log_time > self._chunk_end:
            self._chunk_end = log_time
        self._chunk_messages += 1
        start = self._room(MESSAGE_HEAD.size + len(data))
        index = self._indexes.get(channel_id)
        if index is None:
            index = self._indexes[channel_id] = []
        index += (log_time, start)
        MESSAGE_HEAD.pack_into(self._buffer, start, Opcode.MESSAGE, 22 + len(data), channel_id, 0, log_time, log_time)
        self._buffer[start + MESSAGE_HEAD.size:self._size] = data
        if self._size > self._chunk_size:
            self.finish_chunk()

    def finish_chunk(self):
        """Writes the chunk being filled (mcap's Writer does at chunk_size; the Recorder also
        when it grew old)."""
        if not self._chunk_messages:
            return
        with memoryview(self._buffer) as buffer, buffer[:self._size] as data:
            compressed = mcap.writer.zstandard.compress(data)
            crc = mcap.writer.zlib.crc32(data)
        chunk = record_bytes(Chunk(compression="zstd", data=compressed, message_start_time=self._chunk_start,
                                   message_end_time=self._chunk_end, uncompressed_crc=crc,
                                   uncompressed_size=self._size))
        chunk_start = self._stream.tell()
        self._stream.write(chunk)
        index_start, offsets, indexes = chunk_start + len(chunk), {}, []
        for channel_id, entries in self._indexes.items():
            offsets[channel_id] = index_start + sum(len(i) for i in indexes)
            indexes.append(struct.pack(f"<BQHI{len(entries)}Q", Opcode.MESSAGE_INDEX, 6 + 8 * len(entries),
                                       channel_id, 8 * len(entries), *entries))
        indexes = b"".join(indexes)
        self._stream.write(indexes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=self._chunk_start, message_end_time=self._chunk_end, chunk_start_offset=chunk_start,
            chunk_length=len(chunk), message_index_offsets=offsets, message_index_length=len(indexes),
            compression="zstd", compressed_size=len(compressed), uncompressed_size=self._size))
        self._new_chunk()

    def finish(self):
        """The last chunk, the summary (schemas, channels, statistics, chunk indexes, the empty
        attachment and metadata indexes, their offsets) and the footer; the stream stays open."""
        self.finish_chunk()
        self._stream.write(record_bytes(DataEnd(0)))
        summary_start = self._stream.tell()
        summary, offsets = RecordBuilder(), []
        statistics = Statistics(attachment_count=0, channel_count=len(self._channels),
                                channel_message_counts=self._counts, chunk_count=len(self._chunk_indexes),
                                message_count=self._message_count, metadata_count=0,
                                message_start_time=self._start_time, message_end_time=self._end_time,
                                schema_count=len(self._schemas))
        for opcode, records in ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                                (Opcode.STATISTICS, [statistics]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                                (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, [])):
            group_start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + group_start,
                                         group_length=summary.count - group_start))
        offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        summary = summary.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start), zlib.crc32(summary))
        self._stream.write(summary)
        self._stream.write(record_bytes(Footer(summary_start=summary_start, summary_offset_start=offset_start,
                                               summary_crc=crc)))
        self._stream.write(MCAP0_MAGIC)


# The publishers' QoS (broadcast.Topic.qos: node.py makes them): history depth and durability;
# every one is reliable, keep-last, with the rmw defaults otherwise.
QOS_PROFILES = {"reliable_1": (1, "volatile"), "reliable_10": (10, "volatile"),
                "reliable_100": (100, "volatile"), "latched": (1, "transient_local")}
UNSPECIFIED = "{sec: 0, nsec: 0}"  # RMW_DURATION_UNSPECIFIED: compatible with any request


def offered_qos_profiles(qos):
    """The channel metadata rosbag2 writes for a topic published with `qos` (a QOS_PROFILES
    key): one offered profile, in the YAML of rosbag2_storage's qos.cpp (version 9, Jazzy)."""
    depth, durability = QOS_PROFILES[qos]
    return {"offered_qos_profiles": (
        f"- history: keep_last\n  depth: {depth}\n  reliability: reliable\n  durability: {durability}\n"
        f"  deadline: {UNSPECIFIED}\n  lifespan: {UNSPECIFIED}\n  liveliness: automatic\n"
        f"  liveliness_lease_duration: {UNSPECIFIED}\n  avoid_ros_namespace_conventions: false\n")}


NEW_TIMELINE = object()  # in the recorder's queue: what follows starts again in time
Retract = namedtuple("Retract", "topic")  # in the queue: a latched topic that ended (a robot gone)
# In the queue: a round of messages (one snapshot's) begins at `stamp` (ns). A file grown past the
# split size is split here: every message after it is of its time or later. (Split at any
# message, it had split at a /clock the simulation thread sent ahead of rounds the publisher had
# yet to send: their earlier times came after the latched copies, which went back in time.)
Round = namedtuple("Round", "stamp")


class Recorder:
    def __init__(self, path, split_size=0):
        self.path = Path(path)
        self.split_size = split_size
        # Splits are decided on the file's size, which grows a chunk at a time: chunks well
        # below the split size (each file's index is dropped when it is finished anyway).
        self.chunk_size = min(CHUNK_SIZE, max(MIN_CHUNK_SIZE, split_size // 4)) if split_size else CHUNK_SIZE
        self.bytes_written = 0   # over all files
        self.dropped = 0
        self.error = None        # the first failure (disk full, unwritable path); then nothing is written
        self.files = []
        self._latched = {}       # topic -> (type, data, qos) as far as the writer got: re-written into a new file
        self._rounds = False     # whether a round_begins came: size splits wait for one
        # Appended by any thread, taken by the writer (deque operations are atomic): a
        # queue.Queue's lock and condition per message cost more than the rest of write().
        self._queue = deque()
        self._thread = threading.Thread(target=self._run, name="vplayground-recorder", daemon=True)
        self._file = self._writer = None
        self._channels, self._schemas = {}, {}
        try:
            self._open(self.path)
        except OSError as error:  # the simulation runs on without a bag; `error` says why
            self.error = f"{self.path}: {error.strerror or error}"
        self._thread.start()

    # ------------------------------------------------------------- any thread
    def write(self, topic, type_name, data, seconds, qos="reliable_10"):
        """Queues one message (CDR bytes, encapsulation header included) of a topic published
        with `qos` (a QOS_PROFILES key)."""
        if self.error is not None:
            self.dropped += 1
            return
        stamp = int(round(seconds * 1e9))
        if len(self._queue) >= QUEUE_MESSAGES:
            self.dropped += 1
            return
        self._queue.append((topic, type_name, data, stamp, qos))

    def new_timeline(self):
        """The messages after this one start again in time: they go to a new file, which opens
        with none of the latched topics before it (the writer of the new time sends its own)."""
        self._queue.append(NEW_TIMELINE)

    def round_begins(self, seconds):
        """The messages after this one are of a round at `seconds` or later (where a file grown
        past split_size is split); without rounds, as a recorder used alone, at any message."""
        self._rounds = True
        self._queue.append(Round(int(round(seconds * 1e9))))

    def retract(self, topic):
        """A latched topic ended (its robot is gone): a later file does not open with it."""
        self._queue.append(Retract(topic))

    def close(self, timeout=30.0):
        """Writes what is queued and finishes the file (summary, footer)."""
        self._queue.append(None)
        self._thread.join(timeout)

    # ----------------------------------------------------------- writer thread
    def _open(self, path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "wb")
        self._writer = BagWriter(self._file, self.chunk_size, PROFILE, "vplayground_ros")
        self._channels, self._schemas = {}, {}  # ids of this file: each file opens on its own
        self._types = {}  # topic -> its type in this file
        self.files.append(path)

    def _finish(self):
        if self._file is None:
            return
        try:
            self._writer.finish()
        finally:
            self._file.close()  # whatever finish() hit, the descriptor is not leaked

    def _channel(self, topic, type_name, qos):
        key = (topic, type_name)
        if key not in self._channels:
            self._types[topic] = type_name
            if type_name not in self._schemas:
                self._schemas[type_name] = self._writer.register_schema(name=type_name, encoding="ros2msg",
                                                                        data=schema(type_name).encode("utf-8"))
            self._channels[key] = self._writer.register_channel(topic=topic, message_encoding="cdr",
                                                                schema_id=self._schemas[type_name],
                                                                metadata=offered_qos_profiles(qos))
        return self._channels[key]

    def _add(self, topic, type_name, data, stamp, qos):
        channel = self._channel(topic, type_name, qos)
        self._writer.add_message(channel, stamp, data)
        # A chunk reaches the disk as soon as it is complete (crash safety); with nothing
        # buffered this is no system call at all.
        self._file.flush()
        self.bytes_written += len(data)

    def _split(self, stamp):
        """A new file from time `stamp` on, opening with the latched topics' latest messages
        (logged at `stamp`: in the file before, they were sent long ago)."""
        self._finish()
        stem, suffix = self.path.stem, self.path.suffix or ".mcap"
        self._open(self.path.with_name(f"{stem}_{len(self.files)}{suffix}"))
        for topic, (type_name, data, qos) in list(self._latched.items()):
            self._add(topic, type_name, data, stamp, qos)

    def _run(self):
        closing = False
        new_timeline = False
        while not closing:
            batch = []
            while self._queue:  # everything queued meanwhile, taken at once
                batch.append(self._queue.popleft())
            for item in batch:
                if item is None:
                    closing = True
                    break
                if item is NEW_TIMELINE:
                    new_timeline = True
                    self._latched.clear()
                    continue
                if isinstance(item, Retract):
                    self._latched.pop(item.topic, None)
                    continue
                if self.error is not None:
                    continue  # the disk failed: keep draining so nobody blocks, record nothing
                try:
                    full = self.split_size and self._file.tell() > self.split_size
                    if isinstance(item, Round):
                        if full and not new_timeline:
                            self._split(item.stamp)
                        continue
                    # A topic that comes back with another type (a sensor of another kind spawned
                    # on a removed one's topic) starts a file: a file has one type a topic, as a
                    # player of bags (rosbag2) takes it.
                    if (new_timeline and self._writer.has_messages) or (full and not self._rounds) or \
                            self._types.get(item[0], item[1]) != item[1]:
                        self._split(item[3])
                    new_timeline = False
                    self._add(*item)
                    if item[4] == "latched":  # as of this point in the stream, not as last queued
                        self._latched[item[0]] = (item[1], item[2], item[4])
                except Exception as error:  # anything must not kill the thread
                    self._failed(error)
            opened = self._writer.chunk_opened if self.error is None else None
            if opened is not None and time.monotonic() - opened >= CHUNK_MAX_AGE:
                try:
                    self._writer.finish_chunk()
                    self._file.flush()
                except Exception as error:
                    self._failed(error)
            if not closing:
                time.sleep(WAKE_PERIOD if batch else IDLE_WAKE_PERIOD)
        try:
            self._finish()
        except Exception as error:
            self._failed(error)

    def _failed(self, error):
        """Keeps the first failure (OSError mostly: ENOSPC, EIO); nothing is recorded after it."""
        self.error = self.error or f"{self._file.name}: {getattr(error, 'strerror', None) or error}"


# Every record's opening: opcode, length of the rest.
RECORD_HEAD = struct.Struct("<BQ")


def whole_records(stream):
    """The records of an MCAP file after its magic, each read only once all the bytes its head
    announces are there: a file cut off anywhere (a crash) ends with its last whole record,
    instead of failing inside the next one (mcap's StreamReader raises whatever the cut-off
    field's read does: EndOfFile, struct.error, a zstd error). A whole record that does not
    parse (damaged bytes) ends it too. The records inside a chunk come in its place; indexes,
    statistics and the like are left out (a writer makes its own)."""
    size = os.fstat(stream.fileno()).st_size
    while True:
        head = stream.read(RECORD_HEAD.size)
        if len(head) < RECORD_HEAD.size:
            return
        opcode, length = RECORD_HEAD.unpack(head)
        if length > size - stream.tell():
            return  # torn here, or a damaged length: never read past the file's end
        body = ReadDataStream(io.BytesIO(stream.read(length)))
        try:
            if opcode == Opcode.CHUNK:
                records = breakup_chunk(Chunk.read(body), validate_crc=True)
            elif opcode == Opcode.MESSAGE:
                records = [Message.read(body, length)]
            elif opcode == Opcode.SCHEMA:
                records = [Schema.read(body)]
            elif opcode == Opcode.CHANNEL:
                records = [Channel.read(body)]
            else:
                continue
        except Exception:  # whatever damaged bytes make the reader raise: what came before is saved
            return
        yield from records


def recover(source, target):
    """Copies every complete message of a damaged MCAP (a crashed run's) into a new, summarised
    file. Returns how many messages were saved. Raises OSError for a source that cannot be
    read, McapError for one that is no MCAP file (the target is not made then)."""
    saved = 0
    with open(source, "rb") as stream:
        magic = stream.read(len(MCAP0_MAGIC))
        if magic != MCAP0_MAGIC[:len(magic)]:  # a file cut inside its magic is a torn MCAP still
            raise McapError(f"{source}: not an MCAP file")
        with open(target, "wb") as out:
            writer = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
            writer.start(profile=PROFILE, library="vplayground_ros recover")
            schemas, channels, copied = {}, {}, {}  # copied: (name, encoding, data) -> id in the target
            for record in whole_records(stream):
                # A finished bag's summary repeats its schemas and channels (and other writers
                # repeat them in every chunk): each is the one its id first named. Schemas the
                # same in all but id (a schema per channel, as the recorder once wrote) become one.
                if isinstance(record, Schema) and record.id not in schemas:
                    key = (record.name, record.encoding, record.data)
                    if key not in copied:
                        copied[key] = writer.register_schema(*key)
                    schemas[record.id] = copied[key]
                elif isinstance(record, Channel) and record.id not in channels:
                    channels[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schemas.get(record.schema_id, 0), record.metadata)
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    saved += 1
            writer.finish()
    return saved


def summary(path):
    """{topic: message count} of a finished bag (for tests and the command line)."""
    with open(path, "rb") as stream:
        info = make_reader(stream).get_summary()
    channels = {cid: ch.topic for cid, ch in info.channels.items()}
    return {channels[cid]: n for cid, n in info.statistics.channel_message_counts.items()}


def recover_main(argv=None):
    parser = argparse.ArgumentParser(prog="vplayground-recover",
                                     description="Salvage the complete chunks of a crashed run's MCAP bag.")
    parser.add_argument("source", type=Path)
    parser.add_argument("target", type=Path)
    args = parser.parse_args(argv)
    try:
        saved = recover(args.source, args.target)
    except OSError as error:
        print(f"vplayground-recover: {error.filename or args.source}: {error.strerror or error}", file=sys.stderr)
        return 1
    except McapError as error:
        print(f"vplayground-recover: {error}", file=sys.stderr)
        return 1
    print(f"{args.target}: {saved} messages recovered")
    return 0


if __name__ == "__main__":
    sys.exit(recover_main())
