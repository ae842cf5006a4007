"""MCAP bags (SPEC 7), read back with independent readers: the `mcap` library with
mcap_ros2's decoder, and Foxglove's own JavaScript stack where node and npm are installed."""
import contextlib
import json
import logging
import signal
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest
import yaml
import zstandard
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

from foxglove_js import needs_node, run_script
from helpers import wait_for
from vplayground_ros import cdr
from vplayground_ros.cli import parse_args
from vplayground_ros import recorder as recorder_module
from vplayground_ros.recorder import Recorder, recover
from vplayground_ros.runtime import Runtime
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import Simulation

LATCHED = {"/vplayground/scene/markers", "/vplayground/bodies/resting_markers", "/tf_static", "/vplayground/state",
           "/robot_description"}


def run(*args, wait=True):
    process = subprocess.Popen([sys.executable, "-m", "vplayground_ros.cli", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if not wait:
        return process
    output, _ = process.communicate(timeout=180)
    assert process.returncode == 0, output
    return output


def read_all(path):
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        header, summary = reader.get_header(), reader.get_summary()
        decoded = [(channel.topic, message.log_time, message.publish_time, msg)
                   for _, channel, message, msg in reader.iter_decoded_messages(log_time_order=False)]
    return header, summary, decoded


def stamp_ns(msg):
    for holder in (msg, getattr(msg, "clock", None)):
        if holder is None:
            continue
        if hasattr(holder, "header"):
            return holder.header.stamp.sec * 10**9 + holder.header.stamp.nanosec
        if hasattr(holder, "sec"):
            return holder.sec * 10**9 + holder.nanosec
    return None


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "run.mcap"
    run("--duration", "3", "--real-time-factor", "2", "--record", str(path))
    return path


def test_bag_opens_with_an_independent_reader_and_every_message_decodes(bag):
    header, summary, messages = read_all(bag)
    assert header.profile == "ros2"
    assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
    assert all(c.message_encoding == "cdr" for c in summary.channels.values())
    assert summary.statistics.message_count == len(messages) > 100
    topics = {topic for topic, *_ in messages}
    for topic in ("/clock", "/vplayground/bodies/poses", "/vplayground/bodies/markers",
                  "/vplayground/bodies/resting_markers", "/odom",
                  "/joint_states", "/tf", "/tf_static", "/vplayground/scene/markers", "/diagnostics",
                  "/vplayground/contacts/points", "/vplayground/car/markers"):
        assert topic in topics, topic
    last = {}
    for topic, log_time, publish_time, msg in messages:
        assert log_time == publish_time
        assert log_time >= last.get(topic, 0), topic  # monotonic per channel
        last[topic] = log_time
        stamped = stamp_ns(msg)
        if stamped is not None and topic != "/diagnostics":
            assert stamped == log_time, topic  # log time = simulation time
    assert max(last.values()) <= 3 * 10**9


def test_a_seek_anywhere_draws_every_body_once(bag):
    """Issue 36.4: what moves is on ~/bodies/markers every round, what rests on the latched
    ~/bodies/resting_markers when it changes: at the end of every round the last of each
    together draw every body but the car (~/car/markers draws it) exactly once."""
    _, _, messages = read_all(bag)
    latest, rounds = {}, []

    def judge():
        moving, resting = latest["/vplayground/bodies/markers"], latest["/vplayground/bodies/resting_markers"]
        ids = [(m.ns, m.id) for m in moving.markers[1:] + resting.markers[1:]]
        assert len(ids) == len(set(ids)) == len(latest["/vplayground/bodies/poses"].poses) - 1, round_time
        rounds.append((round_time, len(moving.markers) - 1))

    round_time = None
    # In log-time order, as a player seeks: the simulation thread's /clock comes between a
    # round's messages in the file.
    for topic, log_time, _, msg in sorted(messages, key=lambda message: message[1]):
        if round_time is not None and log_time != round_time:
            judge()
            round_time = None
        latest[topic] = msg
        if topic == "/vplayground/bodies/markers":
            round_time = log_time
    judge()
    assert len(rounds) >= 3 * 30 - 2  # marker_rate
    assert rounds[0][1] > 0  # the default scene's pile falls: its boxes on the per-round topic at first


@pytest.fixture(scope="module")
def bags_at_two_speeds(tmp_path_factory):
    """The default scene for 2 s, in real time and as fast as possible."""
    directory = tmp_path_factory.mktemp("speeds")
    paths = {rtf: directory / f"rtf_{rtf}.mcap" for rtf in ("1", "0")}
    for rtf, path in paths.items():
        run("--duration", "2", "--real-time-factor", rtf, "--record", str(path))
    return {rtf: read_all(path)[2] for rtf, path in paths.items()}


def log_times(messages):
    """{topic: [log time, ns]}; ~/transforms per child frame (one message per frame and time)."""
    times = {}
    for topic, log_time, _, msg in messages:
        key = f"{topic} {msg.child_frame_id}" if topic == "/vplayground/transforms" else topic
        times.setdefault(key, []).append(log_time)
    return times


def test_a_bag_has_the_same_message_times_at_any_speed(bags_at_two_speeds):
    real_time, fast = (log_times(bags_at_two_speeds[rtf]) for rtf in ("1", "0"))
    step = 10**9 / 128
    assert set(real_time) == set(fast)
    for topic in set(real_time) - {"/clock"}:  # /clock: every batch, and batches follow the speed
        assert len(real_time[topic]) == len(fast[topic]), topic
        assert max(abs(a - b) for a, b in zip(sorted(real_time[topic]), sorted(fast[topic]))) < step, topic
    # 30 Hz of simulated time: the first step at or after each 1/30 s.
    poses = np.array(sorted(fast["/vplayground/bodies/poses"])) / step
    assert np.allclose(poses, np.ceil(np.arange(61) * 128 / 30 - 1e-6))
    assert sorted(fast["/diagnostics"]) == [0, 10**9, 2 * 10**9]  # spread over the run, not all at 0
    rtf = {speed: [msg.data for topic, _, _, msg in bags_at_two_speeds[speed]
                   if topic == "/vplayground/real_time_factor"] for speed in ("1", "0")}
    assert all(value > 0.0 for value in rtf["0"][1:] + rtf["1"][1:]), rtf  # after t = 0 nothing was measured


def reading(topic, msg):
    """What a sensor message read: its numbers (the stamps are compared above)."""
    if topic.endswith("/scan"):
        return np.asarray(msg.ranges, np.float32).tobytes()
    if topic.endswith("/data"):
        return tuple(getattr(getattr(msg, part), axis) for part in ("linear_acceleration", "angular_velocity")
                     for axis in "xyz")
    return bytes(msg.data)


def test_a_bag_holds_the_same_scans_at_any_speed(bags_at_two_speeds):
    """The default car's sensors, read on simulated time from the state after the step: the
    same readings in real time as as fast as possible (seeded noise included)."""
    for topic in ("/scan", "/points", "/depth/image_raw", "/camera/image_raw", "/imu/data"):
        real_time, fast = ([(log_time, reading(topic, msg)) for name, log_time, _, msg in bags_at_two_speeds[rtf]
                            if name == topic] for rtf in ("1", "0"))
        assert len(fast) >= 19 and real_time == fast, topic


def test_no_topic_repeats_a_log_time(bags_at_two_speeds):
    """The first batch (Numba loading the engine) once filled a bag's start with 30-40 copies
    of each state topic at t = 0."""
    for speed, messages in bags_at_two_speeds.items():
        for topic, times in log_times(messages).items():
            assert len(times) == len(set(times)), (speed, topic, sorted(times)[:5])


def test_tf_has_the_robots_frames_and_tf_static_the_sensors(bag):
    """Issue 39: /tf carries the robot's REP 105 chain and wheels (the bodies only with
    publish_body_frames, or when they carry a sensor); /tf_static the sensors' mounts, once."""
    _, _, messages = read_all(bag)
    tf = [msg for topic, _, _, msg in messages if topic == "/tf"]
    parent_of = {t.child_frame_id: t.header.frame_id for t in tf[-1].transforms}
    assert (parent_of["odom"], parent_of["base_footprint"], parent_of["base_link"]) == ("world", "odom", "base_footprint")
    assert parent_of["wheel_front_left"] == "steering_front_left" and "tower_1" not in parent_of
    static = [msg for topic, _, _, msg in messages if topic == "/tf_static"]
    assert len(static) == 1
    mounts = {t.child_frame_id: t.header.frame_id for t in static[-1].transforms}
    assert {mounts[name] for name in ("laser", "lidar", "depth_camera", "camera", "imu")} == {"base_link"}
    assert mounts["camera_optical"] == "camera" and mounts["depth_camera_optical"] == "depth_camera"


@pytest.fixture(scope="module")
def split_files(tmp_path_factory):
    """The default scene for 4 s split at 150 kB: its files in order."""
    directory = tmp_path_factory.mktemp("split")
    output = run("--duration", "4", "--real-time-factor", "2", "--record", str(directory / "split.mcap"),
                 "--record-split-size", "150000")
    files = sorted(directory.glob("split*.mcap"), key=lambda f: (len(f.name), f.name))
    assert len(files) >= 3, output
    return files


def test_split_files_each_open_on_their_own(split_files):
    """Every file has the latched topics, logged when it starts: they kept their first stamps
    (0 s), so each file claimed the run from its start."""
    end = None
    for f in split_files:
        _, _, messages = read_all(f)
        assert LATCHED - {"/vplayground/state"} <= {topic for topic, *_ in messages}, f
        times = [log_time for _, log_time, *_ in messages]
        if end is not None:
            assert min(times) >= end - 10**9, f  # near where the file before ended (a 1 Hz topic may lag)
        end = max(times)


def assert_one_schema_per_type(path):
    """One Schema record per message type, shared by every channel of that type, as rosbag2's
    MCAP storage writes them: every Schema record of the file (the chunks' and the summary's)
    read. Returns the summary."""
    ids = {}
    with open(path, "rb") as stream:
        for record in StreamReader(stream, skip_magic=False).records:
            if isinstance(record, Schema):
                ids.setdefault(record.name, set()).add(record.id)
        stream.seek(0)
        summary = make_reader(stream).get_summary()
    assert ids == {s.name: {s.id} for s in summary.schemas.values()}, (path, ids)  # one id a name
    types = {summary.schemas[channel.schema_id].name for channel in summary.channels.values()}
    assert summary.statistics.schema_count == len(summary.schemas) == len(types), path
    return summary


def test_a_bag_has_one_schema_per_message_type(bag):
    """A bag held 24 Schema records for 24 channels: PointCloud2 twice, MarkerArray four times."""
    summary = assert_one_schema_per_type(bag)
    channels = {}
    for channel in summary.channels.values():
        channels.setdefault(summary.schemas[channel.schema_id].name, []).append(channel.topic)
    assert len(channels["sensor_msgs/msg/PointCloud2"]) >= 2
    assert len(channels["visualization_msgs/msg/MarkerArray"]) >= 3


def test_every_split_file_has_one_schema_per_message_type(split_files):
    """Each file opens on its own: its own schemas, one per type."""
    for f in split_files:
        assert_one_schema_per_type(f)


def test_a_point_cloud_reader_finds_every_point_cloud_topic(bag):
    """What KISS-ICP's MCAP loader does: the PointCloud2 schema is the first of that name, its
    topics the channels with that schema id; it never saw the lidar's cloud."""
    with open(bag, "rb") as stream:
        summary = make_reader(stream).get_summary()
    schema_id = [s.id for s in summary.schemas.values() if s.name == "sensor_msgs/msg/PointCloud2"][0]
    topics = {c.topic for c in summary.channels.values() if c.schema_id == schema_id}
    assert {"/points", "/vplayground/contacts/points"} <= topics


def test_every_channel_offers_its_qos_as_rosbag2_records_it(bag):
    """The ROS 2 profile's offered_qos_profiles (rosbag2's YAML, Jazzy's spelling): ros2 bag
    play offers the publishers' QoS again, so the latched topics stay latched in a replay."""
    with open(bag, "rb") as stream:
        channels = make_reader(stream).get_summary().channels.values()
    assert len(channels) > 10
    for channel in channels:
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert len(profiles) == 1, channel.topic
        qos = profiles[0]
        assert (qos["history"], qos["reliability"], qos["liveliness"]) == ("keep_last", "reliable", "automatic")
        latched = channel.topic in LATCHED
        assert qos["durability"] == ("transient_local" if latched else "volatile"), channel.topic
        assert qos["depth"] >= 1 and (qos["depth"] == 1 or not latched)
        assert qos["deadline"] == qos["lifespan"] == {"sec": 0, "nsec": 0}


def test_sigterm_leaves_a_finished_bag(tmp_path):
    path = tmp_path / "term.mcap"
    process = run("--real-time-factor", "1", "--record", str(path), wait=False)
    time.sleep(6)
    process.send_signal(signal.SIGTERM)
    output, _ = process.communicate(timeout=60)
    assert process.returncode == 0, output
    _, summary, messages = read_all(path)  # has a summary: it was finished properly
    assert summary.statistics.message_count == len(messages) > 0


def test_a_round_like_the_one_before_costs_little_in_the_bag(tmp_path):
    # A resting world's snapshots repeat the round before but for their stamps, and one round
    # of 10,000 bodies is megabytes, longer than zstd's default window: the bag must still find
    # the repetition, and give every message back intact.
    rng = np.random.default_rng(0)
    positions, quaternions = rng.normal(size=(45_000, 3)), rng.normal(size=(45_000, 4))  # 2.5 MB a round
    rounds = [cdr.pose_array(k / 30, "world", positions, quaternions) for k in range(12)]
    path = tmp_path / "resting.mcap"
    recorder = Recorder(path)
    for k, data in enumerate(rounds):
        recorder.write("/vplayground/bodies/poses", "geometry_msgs/msg/PoseArray", data, k / 30)
    recorder.close()
    assert recorder.dropped == 0 and recorder.error is None
    _, _, decoded = read_all(path)
    assert [stamp_ns(msg) for _, _, _, msg in decoded] == [round(k / 30 * 1e9) for k in range(12)]
    assert all(msg.poses[-1].orientation.w == quaternions[-1, 3] for _, _, _, msg in decoded)
    assert path.stat().st_size < 0.4 * sum(map(len, rounds))


def test_the_recorder_writes_every_message_intact_and_checksums_every_chunk(tmp_path, monkeypatch):
    # The recorder's chunks carry the CRC-32 of their records (computed by zlib-ng where it is
    # installed): zlib's own must agree on every chunk, and every message read back equals the
    # bytes handed over.
    monkeypatch.setattr(recorder_module, "CHUNK_SIZE", 64 * 1024)  # many chunks from a few rounds
    rng = np.random.default_rng(1)
    written = []
    path = tmp_path / "checked.mcap"
    recorder = Recorder(path)
    for k in range(40):
        data = cdr.pose_array(k / 30, "world", rng.normal(size=(300, 3)), rng.normal(size=(300, 4)))
        written.append(data)
        recorder.write("/vplayground/bodies/poses", "geometry_msgs/msg/PoseArray", data, k / 30)
    recorder.close()
    assert recorder.dropped == 0 and recorder.error is None
    chunks = 0
    with open(path, "rb") as stream:
        for record in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
            if isinstance(record, Chunk):
                chunks += 1
                records = zstandard.ZstdDecompressor().decompress(record.data, max_output_size=record.uncompressed_size)
                assert record.uncompressed_crc != 0 and record.uncompressed_crc == zlib.crc32(records)
    assert chunks > 5
    with open(path, "rb") as stream:
        read = [message.data for _, _, message in make_reader(stream, validate_crcs=True).iter_messages()]
    assert read == written


def test_a_chunk_reaches_the_file_once_it_is_old_though_not_full(tmp_path, monkeypatch):
    # A crash loses the chunk being filled: a slow trickle of messages (a small or paused world)
    # must still reach the file within CHUNK_MAX_AGE, not only when 16 MiB have gathered.
    monkeypatch.setattr(recorder_module, "CHUNK_MAX_AGE", 0.3)
    path = tmp_path / "trickle.mcap"
    recorder = Recorder(path)
    try:
        recorder.write("/clock", "rosgraph_msgs/msg/Clock", cdr.clock(1.0), 1.0)
        deadline, chunks = time.monotonic() + 20, []
        while not chunks and time.monotonic() < deadline:
            time.sleep(0.1)
            with open(path, "rb") as stream:  # the file as a crash would leave it: no end
                try:
                    for record in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
                        if isinstance(record, Chunk):
                            chunks.append(record)
                except (McapError, EOFError):
                    pass
        assert len(chunks) == 1 and chunks[0].message_start_time == 10**9
    finally:
        recorder.close()
    assert recover(path, tmp_path / "fixed.mcap") == 1


def test_the_bag_writer_writes_what_mcaps_writer_writes_byte_for_byte():
    # recorder.BagWriter frames messages itself (mcap's Writer spent most of the recorder's
    # Python on them): for the same calls, the file must be mcap's own, chunks, message indexes,
    # statistics, summary and footer alike: schemas and channels registered between messages,
    # log times out of order, empty messages and messages larger than a chunk included.
    import io
    import random

    from mcap.writer import CompressionType, Writer

    def write(make):
        rng, out = random.Random(3), io.BytesIO()
        register_schema, register_channel, add, finish = make(out)
        channels = {}
        for k in range(2500):
            topic = "/a" if k < 5 else rng.choice(["/a", "/b", "/c", "/d"])
            if topic not in channels:
                channels[topic] = register_channel(topic, "cdr", register_schema(f"pkg/msg/{topic[1:]}", "ros2msg", b"int32 x"))
            size = 300_000 if k % 997 == 5 else rng.randint(0, 3000)
            add(channels[topic], max(0, 1000 * k + rng.randint(-5000, 5000)), rng.randbytes(size))
        finish()
        return out.getvalue()

    def mcap_writer(out):
        writer = Writer(out, chunk_size=200_000, compression=CompressionType.ZSTD)
        writer.start(profile=recorder_module.PROFILE, library="vplayground_ros")
        return (lambda name, encoding, data: writer.register_schema(name=name, encoding=encoding, data=data),
                lambda topic, encoding, schema: writer.register_channel(topic=topic, message_encoding=encoding,
                                                                        schema_id=schema),
                lambda channel, stamp, data: writer.add_message(channel_id=channel, log_time=stamp,
                                                                publish_time=stamp, data=data), writer.finish)

    def bag_writer(out):
        writer = recorder_module.BagWriter(out, 200_000, recorder_module.PROFILE, "vplayground_ros")
        return writer.register_schema, writer.register_channel, writer.add_message, writer.finish

    ours = write(bag_writer)
    assert ours == write(mcap_writer)
    with io.BytesIO(ours) as stream:
        summary = make_reader(stream, validate_crcs=True).get_summary()
    assert summary.statistics.message_count == 2500 and len(summary.chunk_indexes) > 10


def test_a_killed_run_recovers(tmp_path):
    path = tmp_path / "killed.mcap"
    process = run("--real-time-factor", "4", "--record", str(path), wait=False)
    time.sleep(10)
    process.kill()
    process.wait(30)
    with pytest.raises(Exception):
        read_all(path)  # no summary, torn end
    saved = recover(path, tmp_path / "fixed.mcap")
    _, summary, messages = read_all(tmp_path / "fixed.mcap")
    assert saved == len(messages) > 50



def small_bag(path):
    """A finished bag as the recorder writes it, small enough to cut at every byte: chunks of
    ~500 bytes, two channels, so each chunk is followed by two message indexes. Returns the
    messages' (log time, data) in order."""
    rng, written = np.random.default_rng(2), []
    with open(path, "wb") as out:
        writer = recorder_module.BagWriter(out, 500, recorder_module.PROFILE, "vplayground_ros")
        channels = [writer.register_channel(topic, "cdr", writer.register_schema(f"pkg/msg/{topic[1:]}", "ros2msg",
                                                                                 b"int32 x"))
                    for topic in ("/a", "/b")]
        for k in range(24):
            data = rng.bytes(int(rng.integers(0, 120)))
            writer.add_message(channels[k % 2], 1000 * k, data)
            written.append((1000 * k, data))
        writer.finish()
    return written


def test_a_bag_cut_off_anywhere_recovers_every_complete_chunk(tmp_path):
    # A crash can stop the file at any byte; cut inside the message indexes that follow a
    # chunk, the salvage once died of a struct.error and left an unfinished file.
    path = tmp_path / "whole.mcap"
    written = small_bag(path)
    data = path.read_bytes()
    with open(path, "rb") as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert len(chunks) >= 4
    cut, fixed = tmp_path / "cut.mcap", tmp_path / "fixed.mcap"
    for size in range(len(data) + 1):
        cut.write_bytes(data[:size])
        whole = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= size]
        expected = [message for stamp, message in written
                    if any(c.message_start_time <= stamp <= c.message_end_time for c in whole)]
        assert recover(cut, fixed) == len(expected), size
        with open(fixed, "rb") as stream:
            reader = make_reader(stream, validate_crcs=True)
            assert reader.get_summary().statistics.message_count == len(expected), size  # finished
            assert [message.data for _, _, message in reader.iter_messages()] == expected, size


def test_a_finished_bag_recovers_as_it_was(tmp_path):
    # Its summary repeats the schemas and channels: they once came out twice.
    path, fixed = tmp_path / "whole.mcap", tmp_path / "fixed.mcap"
    written = small_bag(path)
    assert recover(path, fixed) == len(written)
    summaries = []
    for bag in (path, fixed):
        with open(bag, "rb") as stream:
            summaries.append(make_reader(stream).get_summary())
    original, recovered = summaries
    assert len(recovered.schemas) == len(original.schemas) == 2
    assert len(recovered.channels) == len(original.channels) == 2
    assert recovered.statistics.channel_message_counts == original.statistics.channel_message_counts


def test_a_schema_per_channel_recovers_as_one_per_type(tmp_path):
    """A file with a Schema record per channel (as the recorder wrote them before) is salvaged
    with one per type; a schema of the same name but other bytes stays apart."""
    path, fixed = tmp_path / "repeated.mcap", tmp_path / "fixed.mcap"
    with open(path, "wb") as out:
        writer = recorder_module.BagWriter(out, 500, recorder_module.PROFILE, "vplayground_ros")
        for topic, definition in (("/a", b"int32 x"), ("/b", b"int32 x"), ("/c", b"int64 x")):
            schema_id = writer.register_schema("pkg/msg/T", "ros2msg", definition)
            writer.add_message(writer.register_channel(topic, "cdr", schema_id), 0, b"")
        writer.finish()
    assert recover(path, fixed) == 3
    with open(fixed, "rb") as stream:
        summary = make_reader(stream).get_summary()
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert len(summary.schemas) == summary.statistics.schema_count == 2
    assert schemas["/a"].id == schemas["/b"].id != schemas["/c"].id and schemas["/c"].data == b"int64 x"


@pytest.mark.parametrize("source", ["missing.mcap", "not_mcap.txt"])
def test_recover_names_a_source_it_cannot_read_in_one_line(tmp_path, source):
    (tmp_path / "not_mcap.txt").write_text("hello, this is no bag\n")
    result = subprocess.run([sys.executable, "-m", "vplayground_ros.recorder", str(tmp_path / source),
                             str(tmp_path / "fixed.mcap")], capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert result.stderr.count("\n") == 1 and str(tmp_path / source) in result.stderr, result.stderr
    assert not (tmp_path / "fixed.mcap").exists()

FOXGLOVE_READER = r"""
const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { loadDecompressHandlers } = require("@mcap/support");

(async () => {
  const data = fs.readFileSync(process.argv[2]);
  const readable = { size: async () => BigInt(data.length),
                     read: async (offset, length) => data.subarray(Number(offset), Number(offset + length)) };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });
  const readers = new Map();
  for (const [id, channel] of reader.channelsById) {
    const schema = reader.schemasById.get(channel.schemaId);
    const definitions = parse(new TextDecoder().decode(schema.data), { ros2: true });
    readers.set(id, new MessageReader(definitions));
  }
  const counts = {};
  for await (const message of reader.readMessages()) {
    readers.get(message.channelId).readMessage(message.data);
    const topic = reader.channelsById.get(message.channelId).topic;
    counts[topic] = (counts[topic] || 0) + 1;
  }
  console.log(JSON.stringify(counts));
})();
"""


@needs_node
def test_foxglove_javascript_stack_decodes_every_message(bag):
    counts = json.loads(run_script("read_bag.js", FOXGLOVE_READER, bag))
    _, summary, _ = read_all(bag)
    expected = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts == expected


def test_foxglove_layout_names_only_what_the_node_offers():
    from vplayground_ros.resources import find_shared
    layout = json.loads(find_shared("config/foxglove_layout.json").read_text())
    panels = layout["configById"]
    kinds = {key.split("!")[0] for key in panels}
    assert {"3D", "Teleop", "CallService", "Parameters", "DiagnosticSummary", "Plot"} <= kinds
    assert panels["3D!scene"]["followTf"] == "world"
    assert panels["Teleop!drive"]["topic"] == "/cmd_vel" and panels["Teleop!drive"]["publishRate"] == 10
    services = {p["serviceName"] for k, p in panels.items() if k.startswith("CallService")}
    assert services == {"/vplayground/pause", "/vplayground/step", "/vplayground/reset",
                        "/vplayground/spawn", "/vplayground/wake_all"}
    # Every panel in the mosaic has a config, and every config is placed.
    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert sorted(leaves(layout["layout"])) == sorted(panels)


@contextlib.contextmanager
def recording(path, speed, scene=None):
    """A running Runtime recording to `path` (ROS-free) at real-time factor `speed`, on `scene`
    (the default scene when None); stopped and the bag finished on leaving."""
    options = parse_args(["--record", str(path), "--real-time-factor", str(speed)])
    recorder = Recorder(path)
    runtime = Runtime(Simulation(load_world(scene or options.scene), real_time_factor=speed), options,
                      logging.getLogger("test_bag"), recorder)
    runtime.start()
    try:
        yield runtime
    finally:
        runtime.stop()
        recorder.close()


def assert_channels_go_forward(name, messages):
    """Within one file, no channel's log time goes back; returns each channel's last."""
    last = {}
    for topic, log_time, *_ in messages:
        assert log_time >= last.get(topic, 0), (name, topic)
        last[topic] = log_time
    return last


def test_a_reset_or_another_scene_continues_the_bag_in_a_new_file(tmp_path):
    """Time starts again at 0 after ~/reset and ~/load_scene: in one file, a seek showed both
    worlds (every channel went back in time). Each run of time gets its own file, which opens
    on its own (the latched topics) and whose channels only go forward."""
    path = tmp_path / "run.mcap"
    with recording(path, 4.0) as runtime:
        sim = runtime.sim
        assert wait_for(lambda: sim.snapshot.time > 1.0)
        assert runtime.requests.reset(255)[0]
        # The reply can come before the new world's first snapshot: the old one's time passed
        # the wait, the scene was loaded at 0 s still, and time never went back for a third file.
        assert wait_for(lambda: len(runtime.recorder.files) == 2)
        assert wait_for(lambda: sim.snapshot.time > 1.0)
        other = tmp_path / "other.yaml"  # the bag's folder is a scene directory
        other.write_text("version: 1\nbodies: [{name: crate, position: [0, 0, 2]}]\n")
        assert runtime.requests.load_scene(str(other))[0] == 0
        assert wait_for(lambda: len(runtime.recorder.files) == 3)
        assert wait_for(lambda: sim.snapshot.time > 1.0)
    files = [path, tmp_path / "run_1.mcap", tmp_path / "run_2.mcap"]
    assert sorted(tmp_path.glob("*.mcap")) == sorted(files)
    for f in files:
        _, _, messages = read_all(f)
        last = assert_channels_go_forward(f, messages)
        robots = set() if f == files[2] else {"/robot_description"}  # the other scene has no car
        assert (LATCHED - {"/robot_description"}) | robots == LATCHED & set(last) and last["/clock"] > 10**9, f
        assert_one_schema_per_type(f)
        assert min(log_time for topic, log_time, *_ in messages if topic == "/clock") < 10**8, f


def test_each_new_file_opens_with_the_latched_topics_as_they_were_then(tmp_path):
    """A reset, then a pause 30 ms later: the new file opened at 0 s with state 'paused' and a
    /tf_static stamped at the pause (the recorder re-wrote the latched messages as last
    queued, not as they stood where the file began)."""
    with recording(tmp_path / "run.mcap", 1.0) as runtime:
        assert wait_for(lambda: runtime.sim.snapshot.time > 0.5)
        for _ in range(3):
            assert runtime.requests.reset(255)[0]
            time.sleep(0.03)
            runtime.requests.pause(True)
            time.sleep(0.2)
            runtime.requests.pause(False)
            time.sleep(0.3)
    for index in (1, 2, 3):
        _, _, messages = read_all(tmp_path / f"run_{index}.mcap")
        start = min(log_time for _, log_time, *_ in messages)
        opening = {topic: msg for topic, log_time, _, msg in messages if log_time == start and topic in LATCHED}
        assert opening["/vplayground/state"].data == 1, index  # playing: the pause came later
        assert all(stamp_ns(t) <= start for t in opening["/tf_static"].transforms), index


def test_a_reset_under_load_keeps_each_files_channels_in_order(tmp_path):
    """As fast as possible with 600 boxes and a reset every 0.15 s: the simulation thread sent
    the pending rounds while the publisher thread was inside one, so a file's markers went
    back in time."""
    scene = {"version": 1, "bodies": [{"position": [float(x), float(y), 0.5 + z]} for x in range(-10, 10)
                                      for y in range(-5, 5) for z in range(3)]}
    with recording(tmp_path / "run.mcap", 0.0, scene) as runtime:
        for _ in range(8):
            time.sleep(0.15)
            assert runtime.requests.reset(255)[0]
    files = sorted(tmp_path.glob("run*.mcap"))
    assert len(files) >= 8
    for f in files:
        assert_channels_go_forward(f.name, read_all(f)[2])


def test_a_removed_robots_description_does_not_open_the_next_file(tmp_path):
    """Issue 39: a robot's latched robot_description ends with the robot: a later file (after a
    reset here) opens with the latched topics of the robots that are there only."""
    scene = load_world(parse_args([]).scene)
    car = scene.vehicle("car")
    other = {**{k: v for k, v in car.items() if k not in ("name", "namespace")}, "name": "car_b",
             "position": [-20.0, 20.0, 1.2]}
    path = tmp_path / "run.mcap"
    with recording(path, 4.0) as runtime:
        ok, message = runtime.requests.spawn(json.dumps(other))
        assert ok, message
        assert wait_for(lambda: runtime.sim.snapshot.time > 0.5, 30)
        assert runtime.requests.remove("{entity: car_b}")[0]
        assert wait_for(lambda: "car_b" not in runtime.sim.snapshot.vehicles, 30)
        assert runtime.requests.reset(1)[0]  # the time alone: a new file
        assert wait_for(lambda: len(runtime.recorder.files) >= 2, 30)
        started = runtime.sim.snapshot.time
        assert wait_for(lambda: runtime.sim.snapshot.time > started + 0.5, 30)
    first, second = runtime.recorder.files[:2]
    topics = lambda p: {c.topic for c in make_reader(open(p, "rb")).get_summary().channels.values()}  # noqa: E731
    assert "/car_b/robot_description" in topics(first)
    assert "/car_b/robot_description" not in topics(second) and "/robot_description" in topics(second)


@pytest.mark.parametrize("other", ["bodies: [{name: crate, position: [0, 0, 2]}]",
                                   "robots: [{name: car, urdf: car.urdf, position: [0, 0, 1]}]"])
def test_another_scene_opens_its_file_without_the_old_ones_robots_and_frames(tmp_path, other):
    """~/load_scene of a world with one box, or with the car and none of its sensors: its file
    had opened with the old scene's car's robot_description and its sensor frames on /tf_static
    (the old file's latched topics were copied into it; static transforms add up: the new
    world's /tf_static removed none of them)."""
    path = tmp_path / "run.mcap"
    with recording(path, 4.0) as runtime:
        assert wait_for(lambda: runtime.sim.snapshot.time > 0.5)
        scene = tmp_path / "other.yaml"
        scene.write_text(f"version: 1\n{other}\n")
        assert runtime.requests.load_scene(str(scene))[0] == 0
        assert wait_for(lambda: len(runtime.recorder.files) == 2)
        assert wait_for(lambda: runtime.sim.snapshot.time > 0.5)
    _, _, before = read_all(path)
    _, _, after = read_all(tmp_path / "run_1.mcap")
    frames = lambda messages: {t.child_frame_id for topic, _, _, msg in messages if topic == "/tf_static"  # noqa: E731
                               for t in msg.transforms}
    assert "laser" in frames(before) and "laser" not in frames(after)
    descriptions = [msg.data for topic, _, _, msg in after if topic == "/robot_description"]
    assert all("laser" not in text for text in descriptions) and bool(descriptions) == ("robots" in other)
    assert {"/tf_static", "/vplayground/state", "/vplayground/scene/markers"} <= {topic for topic, *_ in after}


def test_size_split_files_go_forward_and_open_with_what_a_seek_needs(tmp_path):
    """As fast as possible, the simulation thread's /clock runs rounds ahead of the publisher's:
    a file split at a /clock opened with the latched topics logged later than the rounds that
    followed them (a stale marker copy then replaced the newer one). Each file now starts at a
    round, with the latched topics first, and every channel goes forward."""
    scene = tmp_path / "one.yaml"
    scene.write_text("version: 1\nbodies: [{name: crate, position: [0, 0, 0.5]}]\n")
    run("--scene", str(scene), "--duration", "300", "--real-time-factor", "0", "--record",
        str(tmp_path / "split.mcap"), "--record-split-size", "65536",
        "--ros-args", "-p", "static_republish_period:=0.1")
    files = sorted(tmp_path.glob("split*.mcap"), key=lambda f: (len(f.name), f.name))
    # How many files: as the chunks happen to fill. 300 s give many splits: before the change,
    # 40 s met a split at a /clock ahead of the rounds one run in two, 300 s in each of 2 runs.
    assert len(files) >= 2
    for f in files:
        _, _, messages = read_all(f)
        assert_channels_go_forward(f.name, messages)
        start = min(log_time for _, log_time, *_ in messages)
        opening = {topic for topic, log_time, *_ in messages if log_time == start}
        assert LATCHED - {"/robot_description"} <= opening, f.name


def test_a_topic_back_with_another_type_starts_a_file(tmp_path):
    """A sensor of another kind spawned on a removed one's topic: one file had /probe as a
    LaserScan and as a PointCloud2, which a bag player takes as one topic of one type."""
    recorder = Recorder(tmp_path / "run.mcap")
    payload = b"\x00\x01\x00\x00"  # the recorder files bytes by topic and type; only the summaries are read
    recorder.write("/probe", "sensor_msgs/msg/LaserScan", payload, 1.0)
    recorder.write("/clock", "rosgraph_msgs/msg/Clock", payload, 1.5)
    recorder.write("/probe", "sensor_msgs/msg/PointCloud2", payload, 2.0)
    recorder.close()
    assert recorder.error is None and len(recorder.files) == 2
    for f, kind in zip(recorder.files, ("sensor_msgs/msg/LaserScan", "sensor_msgs/msg/PointCloud2")):
        summary = make_reader(open(f, "rb")).get_summary()
        types = {summary.schemas[c.schema_id].name for c in summary.channels.values() if c.topic == "/probe"}
        assert types == {kind}, f
