"""MCAP bags (SPEC 7), written with the `mcap` library.

Why `mcap` and not foxglove-sdk's writer: the bytes we record are the CDR the publishers already
send, so the writer only frames and compresses them, and the pure-Python `mcap` writer keeps
the package free of a native extension wherever it is built (colcon, pip); zstd runs in
`zstandard`'s C code either way.

- ROS 2 profile, `ros2msg` schemas with full definitions (interfaces.schema), `cdr` messages,
  zstd chunks, message indexes and a summary.
- log time = publish time = simulation time (ns).
- Writes happen on the recorder's own thread, every WAKE_PERIOD, from a bounded queue: the
  simulation and the publishers never wait on the disk; what does not fit is dropped and counted.
- record_split_size: a new file <stem>_<n>.mcap starts past that many bytes, and the latched
  topics (the scenery, /tf_static, the state) are written again at its start, so every file
  opens on its own.
- A disk that fills or a path that cannot be written stops the recording, never the simulation:
  the first failure is kept in `error` (the node puts it on /diagnostics) and later messages are
  dropped.
- Chunks are written to the file as they fill, so after a crash (kill -9) every complete chunk
  is still there: `vplayground-recover crashed.mcap fixed.mcap` rewrites them into a proper,
  summarised file (as `mcap recover` does).
"""
import argparse
import queue
import sys
import threading
import time
import types
import zlib
from pathlib import Path

import mcap.writer
import zstandard
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Channel, Message, Schema
from mcap.writer import CompressionType, Writer

from .interfaces import schema

PROFILE = "ros2"
# Smaller chunks lose less on a crash; larger ones compress better, and keep the writer's
# memory flat: it holds a ~1.6 kB index entry per chunk until the file is finished, which at
# 256 KiB was ~27 MB an hour for the default scene (~1.3 MB/s of messages). Most of a bag is
# the 30 Hz snapshots of every body, each much like the one before it when the bodies rest:
# zstd finds that only when one round of them (3.8 MB at 10,000 bodies) fits in a chunk and in
# its window. Replaying recorded bags, 8 MiB chunks compressed with a window as long as the
# chunk took a settled 10,000-body pile 2.1:1 smaller and ~30 % less CPU than 4 MiB and zstd's
# default window (2 MiB), and a 1,000-body pile that never rests 7 % smaller at the same CPU;
# 16 MiB was smaller still on the settled pile but cost the moving one 30-50 % more CPU. A
# kill -9 loses the chunk being filled (~6 s of the default scene).
CHUNK_SIZE = 8 * 1024 * 1024
# zstd level 2 with a hash table of 2^18 entries (level 2's own is 2^17, level 3's too): replayed
# bags, against level 3, a settled 10,000-body pile took 15 % less of the writer's CPU for a
# 7 % smaller bag, a 1,000-body pile that never rests 21 % less CPU for a 10 % larger bag.
# Level 1 as it comes (a 2^13 table) misses the previous round: 4 times the bag at 10,000
# settled bodies, no faster there.
ZSTD_LEVEL = 2
ZSTD_HASH_LOG = 18
# zstd windows decoders take by default (libzstd, the mcap readers): 2^27 bytes.
MAX_WINDOW_LOG = 27
QUEUE_MESSAGES = 4096
# The writer wakes this often (s) and writes what has queued, rather than at every message: a
# wake-up per message (128 Hz of /clock alone) cost more CPU than the writing, and made the
# simulation thread and the writer take the GIL from each other. The queue holds 4096.
WAKE_PERIOD = 0.05


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


class Recorder:
    def __init__(self, path, split_size=0):
        self.path = Path(path)
        self.split_size = split_size
        # Splits are decided on the file's size, which grows a chunk at a time: chunks well
        # below the split size (each file's index is dropped when it is finished anyway).
        self.chunk_size = min(CHUNK_SIZE, max(64 * 1024, split_size // 4)) if split_size else CHUNK_SIZE
        self.bytes_written = 0   # over all files
        self.dropped = 0
        self.error = None        # the first failure (disk full, unwritable path); then nothing is written
        self.files = []
        self._latched = {}       # topic -> (type, data, time_ns): re-written into every split
        self._queue = queue.Queue(maxsize=QUEUE_MESSAGES)
        self._thread = threading.Thread(target=self._run, name="vplayground-recorder", daemon=True)
        self._file = self._writer = None
        self._channels = {}
        try:
            self._open(self.path)
        except OSError as error:  # the simulation runs on without a bag; `error` says why
            self.error = f"{self.path}: {error.strerror or error}"
        self._thread.start()

    # ------------------------------------------------------------- any thread
    def write(self, topic, type_name, data, seconds, latched=False):
        """Queues one message (CDR bytes, encapsulation header included)."""
        if self.error is not None:
            self.dropped += 1
            return
        stamp = int(round(seconds * 1e9))
        if latched:
            self._latched[topic] = (type_name, data, stamp)
        try:
            self._queue.put_nowait((topic, type_name, data, stamp))
        except queue.Full:
            self.dropped += 1

    def close(self, timeout=30.0):
        """Writes what is queued and finishes the file (summary, footer)."""
        self._queue.put(None)
        self._thread.join(timeout)

    # ----------------------------------------------------------- writer thread
    def _open(self, path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "wb")
        self._writer = Writer(self._file, chunk_size=self.chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="vplayground_ros")
        self._channels = {}
        self.files.append(path)

    def _finish(self):
        if self._file is None:
            return
        try:
            self._writer.finish()
        finally:
            self._file.close()  # whatever finish() hit, the descriptor is not leaked

    def _channel(self, topic, type_name):
        key = (topic, type_name)
        if key not in self._channels:
            schema_id = self._writer.register_schema(name=type_name, encoding="ros2msg",
                                                     data=schema(type_name).encode("utf-8"))
            self._channels[key] = self._writer.register_channel(topic=topic, message_encoding="cdr",
                                                                schema_id=schema_id)
        return self._channels[key]

    def _add(self, topic, type_name, data, stamp):
        channel = self._channel(topic, type_name)
        self._writer.add_message(channel_id=channel, log_time=stamp, publish_time=stamp, data=data)
        # A chunk reaches the disk as soon as it is complete (crash safety); with nothing
        # buffered this is no system call at all.
        self._file.flush()
        self.bytes_written += len(data)

    def _split(self):
        self._finish()
        stem, suffix = self.path.stem, self.path.suffix or ".mcap"
        self._open(self.path.with_name(f"{stem}_{len(self.files)}{suffix}"))
        for topic, (type_name, data, stamp) in list(self._latched.items()):
            self._add(topic, type_name, data, stamp)

    def _run(self):
        closing = False
        while not closing:
            batch = [self._queue.get()]
            while True:  # everything queued meanwhile, taken at once
                try:
                    batch.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            for item in batch:
                if item is None:
                    closing = True
                    break
                if self.error is not None:
                    continue  # the disk failed: keep draining so nobody blocks, record nothing
                try:
                    if self.split_size and self._file.tell() > self.split_size:
                        self._split()
                    self._add(*item)
                except Exception as error:  # OSError mostly (ENOSPC, EIO); anything else must not kill the thread
                    self.error = f"{self._file.name}: {getattr(error, 'strerror', None) or error}"
            if not closing:
                time.sleep(WAKE_PERIOD)
        try:
            self._finish()
        except Exception as error:
            self.error = self.error or f"{self._file.name}: {getattr(error, 'strerror', None) or error}"


def recover(source, target):
    """Copies every complete message of a damaged MCAP (a crashed run's) into a new, summarised
    file. Returns how many messages were saved."""
    saved = 0
    with open(source, "rb") as stream, open(target, "wb") as out:
        writer = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        writer.start(profile=PROFILE, library="vplayground_ros recover")
        schemas, channels = {}, {}
        try:
            for record in StreamReader(stream, skip_magic=False, emit_chunks=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel):
                    channels[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schemas.get(record.schema_id, 0), record.metadata)
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    saved += 1
        except (McapError, EOFError, ValueError, OSError):
            pass  # the torn end of the file: everything before it is saved
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
    saved = recover(args.source, args.target)
    print(f"{args.target}: {saved} messages recovered")
    return 0


if __name__ == "__main__":
    sys.exit(recover_main())
