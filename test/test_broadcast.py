"""The Broadcaster's bookkeeping over long runs."""
from unittest.mock import MagicMock

from vplayground_ros.broadcast import Broadcaster
from vplayground_ros.parameters import FRAMES


class Parameters(dict):
    def listen(self, fn):
        pass


def test_marker_ids_stay_stable_and_bounded():
    parameters = Parameters({"publish_rate": 30.0, "marker_rate": 30.0, "static_republish_period": 5.0,
                             "show_octree": False, **FRAMES})
    broadcaster = Broadcaster(MagicMock(), parameters, MagicMock())
    keeper = broadcaster.marker_id("keeper")
    for k in range(1000):  # a body spawned and removed every time, under a new name
        names = ["keeper", f"temporary_{k}"]
        broadcaster.forget_removed(names)
        broadcaster.marker_id(names[1])
    assert broadcaster.marker_id("keeper") == keeper
    assert len(broadcaster.marker_ids) <= 2 * 2 + 64 + 1
    assert len(set(broadcaster.marker_ids.values())) == len(broadcaster.marker_ids)  # ids never reused


# ---------------------------------------------------------------- through a running Runtime
import logging  # noqa: E402
import re  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import yaml  # noqa: E402

from vplayground_ros.cli import parse_args  # noqa: E402
from vplayground_ros.interfaces import decoder  # noqa: E402
from vplayground_ros.runtime import Runtime  # noqa: E402
from vplayground_ros.scene import load_world  # noqa: E402
from vplayground_ros.simulation import Simulation  # noqa: E402
from helpers import wait_for  # noqa: E402

MARKERS = decoder("visualization_msgs/msg/MarkerArray")
POSES = decoder("geometry_msgs/msg/PoseArray")
DIAGNOSTICS = decoder("diagnostic_msgs/msg/DiagnosticArray")
CLOUD = decoder("sensor_msgs/msg/PointCloud2")
SPHERE_LIST, LINE_LIST, CUBE_LIST = 7, 5, 6
CAR = {"name": "car", "position": [0, 0, 1.6], "chassis": {"size": [4.0, 1.8, 0.6], "mass": 1200},
       "engine_power": 6000, "brake_power": 9000, "max_steer": 0.6,
       "wheels": [{"mount": [x, y, -0.3], "radius": 0.35, "mass": 20, "power_gain": 0.5, "steered": x > 0,
                   "spring_stiffness": 40000, "damper": 4000, "spring_length": 0.5,
                   "static_friction": 1.0, "dynamic_friction": 0.8}
                  for x, y in ((1.3, 0.8), (1.3, -0.8), (-1.3, 0.8), (-1.3, -0.8))]}
# A car dropped from just above the ground (its wheels touch it after 0.3 s) and a box far from it.
SCENE = {"version": 1, "bodies": [{"name": "crate", "position": [10, 0, 0.5]}], "vehicles": [CAR]}


class Collector:
    """A sink that keeps everything: (topic key, simulated s, CDR bytes)."""

    def __init__(self, fail_on=None):
        self.messages = []
        self.fail_on = fail_on

    def publish(self, topic, data, seconds):
        if topic.key == self.fail_on:
            raise RuntimeError(f"sink bug on {topic.key}")
        self.messages.append((topic.key, seconds, data))

    def subscribed(self, topic):
        return True

    def statuses(self):
        return []

    def of(self, key, decode=None):
        return [(t, decode(d) if decode else d) for k, t, d in list(self.messages) if k == key]



@pytest.fixture
def running():
    """start(scene, *cli options, sink=...) -> (runtime, sink): a Runtime with a Collector,
    stepping; stopped after the test."""
    started = []

    def start(scene=SCENE, *args, sink=None, log=None):
        options = parse_args(["--no-record", *args])
        sim = Simulation(load_world(scene), real_time_factor=options.real_time_factor,
                         start_paused=options.start_paused, duration=options.duration)
        runtime = Runtime(sim, options, log or logging.getLogger("test_broadcast"))
        sink = sink or Collector()
        runtime.broadcaster.add_sink(sink)
        runtime.start()
        started.append(runtime)
        return runtime, sink
    yield start
    for runtime in started:
        runtime.stop()


def test_the_car_is_drawn_once_and_no_list_marker_is_empty(running):
    runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "0.5")
    runtime.sim.wait(60)
    runtime.stop()
    first_time, first = sink.of("/vplayground/car/markers", MARKERS)[0]
    assert first_time == 0.0  # in the air: no ray hits, no contacts
    resting = sink.of("resting_markers", MARKERS)
    for seconds, array in sink.of("body_markers", MARKERS):
        at_rest = [a for t, a in resting if t <= seconds][-1]
        assert array.markers[0].action == 3 and at_rest.markers[0].action == 3
        # the crate only, on one topic or the other (it freezes on the ground)
        assert [m.ns for m in array.markers[1:] + at_rest.markers[1:]] == ["box"]
    for key in ("/vplayground/car/markers", "contact_markers", "scene_markers"):
        for _, array in sink.of(key, MARKERS):
            assert array.markers[0].action == 3, key  # DELETEALL: a marker left out disappears
            lists = [m for m in array.markers if m.type in (SPHERE_LIST, LINE_LIST, CUBE_LIST)]
            assert all(len(m.points) > 0 for m in lists), key
    assert "ray_hits" not in {m.ns for m in first.markers}
    assert {"chassis", "wheels", "springs"} <= {m.ns for m in first.markers}
    assert not sink.of("contact_markers", MARKERS)[0][1].markers[1:]  # nothing touches yet
    landed = sink.of("/vplayground/car/markers", MARKERS)[-1][1]
    assert "ray_hits" in {m.ns for m in landed.markers}  # on the ground by 0.5 s


def test_diagnostics_name_each_status_once_and_summarise_the_figures(running):
    runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "1.1")
    runtime.sim.wait(60)
    runtime.stop()
    _, last = sink.of("diagnostics", DIAGNOSTICS)[-1]
    status = {s.name: s for s in last.status}
    assert set(status) == {"simulation", "bodies", "robot car", "publisher"}
    assert {s.hardware_id for s in last.status} == {"vplayground"}  # a viewer shows "vplayground: simulation"
    assert re.fullmatch(r"(playing|stopped), RTF \d+\.\d\d/max, step \d+\.\d\d ms, 0 late ticks",
                        status["simulation"].message), status["simulation"].message
    assert re.fullmatch(r"2 bodies: \d active, \d frozen, 0 removed", status["bodies"].message)
    figures = {v.key: v.value for v in status["simulation"].values}
    # The thread count the last batch ran with; two bodies never share work, so no trial yet (0).
    assert figures["solver_threads_in_use"] == str(runtime.sim.solver_threads)
    assert figures["second_thread_speedup"] == "0.0"
    assert re.fullmatch(r"car: last command 1\.\d s ago", status["robot car"].message)
    assert status["publisher"].level == 0


def test_a_failing_job_is_logged_once_counted_and_the_others_go_on(running):
    log = logging.getLogger("test_broadcast.failing")
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    log.addHandler(handler)
    try:
        runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "3",
                                sink=Collector(fail_on="/vplayground/car/markers"), log=log)
        runtime.sim.wait(60)
        runtime.stop()
    finally:
        log.removeHandler(handler)
    errors = [r for r in records if r.levelno == logging.ERROR]
    assert len(errors) == 1 and "publishing markers failed" in errors[0].getMessage()
    assert "Traceback" in errors[0].getMessage() and "sink bug on /vplayground/car/markers" in errors[0].getMessage()
    assert sink.of("poses")[-1][0] == pytest.approx(3.0)  # state went on to the end
    diagnostics = sink.of("diagnostics", DIAGNOSTICS)
    assert [t for t, _ in diagnostics] == [0.0, 1.0, 2.0, 3.0]
    publisher = next(s for s in diagnostics[-1][1].status if s.name == "publisher")
    assert publisher.level == 2 and publisher.message.startswith("markers failed 91 times: RuntimeError: sink bug")


def test_the_scenery_follows_show_octree_at_once_even_paused(running):
    runtime, sink = running(SCENE, "--real-time-factor", "1", "--start-paused")
    octree = lambda array: any(m.ns == "octree" for m in array.markers)  # noqa: E731
    assert runtime.requests.step(1)[0]  # the octree is fitted at the first step
    wait_for(lambda: runtime.sim.snapshot.step == 1 and sink.of("scene_markers"))
    assert not octree(sink.of("scene_markers", MARKERS)[-1][1])
    for shown in (True, False, True):
        count = len(sink.of("scene_markers"))
        assert runtime.parameters.set({"show_octree": shown})[0]
        wait_for(lambda: len(sink.of("scene_markers")) > count)
        assert octree(sink.of("scene_markers", MARKERS)[-1][1]) == shown
    assert runtime.sim.snapshot.step == 1  # paused all along: sent on the change, not on a timer


class ChannelSink(Collector):
    """A sink that, like the Foxglove server, makes a topic's channel as it publishes and drops
    it on withdraw or retract. Armed with a key, its next publish of that key on another thread
    (a newcomer's resend) waits for that key's retraction, for up to a second: the slow publish
    a robot's removal may meet."""

    def __init__(self):
        super().__init__()
        self.channels, self.armed, self.retracted = set(), None, threading.Event()

    def publish(self, topic, data, seconds):
        if topic.key == self.armed and threading.current_thread() is not threading.main_thread():
            self.armed = None
            self.retracted.wait(1.0)
        self.channels.add(topic.key)
        super().publish(topic, data, seconds)

    def withdraw(self, topic):
        self.channels.discard(topic.key)

    def retract(self, topic):
        self.channels.discard(topic.key)
        self.retracted.set()


def test_a_newcomers_resend_does_not_bring_back_a_gone_robots_description(running):
    """A viewer subscribing to a robot's robot_description as the robot is removed: the resend
    (publisher thread) comes before the retraction (simulation thread) or not at all. Sent after
    it, the description's channel was made again, serving the gone robot's URDF, with nothing
    left to remove it."""
    runtime, sink = running(SCENE, "--real-time-factor", "1", sink=ChannelSink())
    key = "/robot_description"  # the car's, in the root namespace
    assert wait_for(lambda: sink.of(key))
    sink.armed = key
    runtime.broadcaster.welcome(sink, key)
    time.sleep(0.2)  # the publisher thread is in that publish
    assert runtime.requests.remove_entity("car")[0]
    assert wait_for(lambda: key not in runtime.broadcaster.topics)
    time.sleep(1.2)
    assert key not in sink.channels


class WithdrawingSink(Collector):
    """Keeps what it was told to withdraw; `failing`, each withdraw raises after that."""

    def __init__(self, failing=False):
        super().__init__()
        self.withdrawn, self.failing = [], failing

    def withdraw(self, topic):
        self.withdrawn.append(topic.key)
        if self.failing:
            raise RuntimeError(f"sink bug withdrawing {topic.key}")


def test_a_sink_failing_to_withdraw_leaves_no_topic_of_a_gone_entity_behind(running):
    """Two sensors removed while one sink's withdraw raises: every sink is told of both topics
    and the table keeps neither (the failure counted). The first failure had ended the loop:
    the other topic stayed in the table and in the sinks with nothing left to remove it."""
    runtime, sink = running(SCENE, "--real-time-factor", "1", sink=WithdrawingSink(failing=True))
    other = WithdrawingSink()
    runtime.broadcaster.add_sink(other)
    imus = [{"name": f"w_imu{k}", "type": "imu", "parent": "world", "pose": [0, 0, 1 + k, 0, 0, 0]} for k in range(2)]
    assert runtime.requests.spawn(yaml.safe_dump(imus))[0]
    keys = {f"sensor:w_imu{k}/data:sensor_msgs/msg/Imu" for k in range(2)}
    assert wait_for(lambda: keys <= {key for key, _, _ in list(sink.messages)})
    assert runtime.requests.remove("{filter: ^w_imu}")[0]
    assert wait_for(lambda: keys <= set(other.withdrawn))
    assert keys <= set(sink.withdrawn) and not keys & runtime.broadcaster.topics.keys()


def test_contact_topics_turned_off_clear_what_they_drew(running):
    """contacts.publish false: the last contact points and normals had stayed drawn, in a viewer
    and in the bag, for as long as the topics were off. Turned off, each sends one message that
    draws nothing (the markers' DELETEALL, an empty cloud), as with nothing touching, and then
    nothing until turned on again."""
    scene = {**SCENE, "settings": {"freezing": {"enabled": False}}}  # the crate keeps touching the ground
    runtime, sink = running(scene, "--real-time-factor", "1")
    clouds = lambda since=0: [c for _, c in sink.of("contact_points", CLOUD)[since:]]  # noqa: E731
    assert wait_for(lambda: clouds() and clouds()[-1].width > 0)
    rounds, sent = len(sink.of("poses")), len(sink.of("contact_points"))
    assert runtime.parameters.set({"contacts.publish": False})[0]
    assert wait_for(lambda: len(sink.of("poses")) > rounds + 10)  # the rounds go on
    after = clouds(sent)
    assert after and after[-1].width == 0 and [c.width for c in after].count(0) == 1  # (a round under way may draw first)
    markers = sink.of("contact_markers", MARKERS)[-1][1].markers
    assert [m.action for m in markers] == [3]  # DELETEALL alone
    assert runtime.parameters.set({"contacts.publish": True})[0]
    assert wait_for(lambda: clouds()[-1].width > 0)

def test_a_loaded_scene_is_drawn_at_once_even_paused(running, tmp_path):
    runtime, sink = running(SCENE, "--real-time-factor", "1", "--start-paused")
    wait_for(lambda: sink.of("scene_markers"))
    (tmp_path / "raised.yaml").write_text(yaml.safe_dump({**SCENE, "ground": {"height": 1.0}}))
    runtime.requests.scene_directories = [tmp_path]
    load = next(s.handler for s in runtime.services if s.name == "~/load_scene")
    assert load(SimpleNamespace(map_url=str(tmp_path / "raised.yaml"))) == {"result": 0}
    ground = lambda: [m.pose.position.z for m in sink.of("scene_markers", MARKERS)[-1][1].markers  # noqa: E731
                      if m.ns == "ground"]
    wait_for(lambda: ground() == [pytest.approx(1.0 - 0.005)])


def test_a_paused_world_answers_edits_and_repeats_nothing(running):
    runtime, sink = running(SCENE, "--real-time-factor", "1", "--start-paused")
    wait_for(lambda: len(sink.of("diagnostics")) >= 2)  # diagnostics go on by the wall clock
    assert len(sink.of("poses")) == 1  # the start, and no copies of it
    ok, message = runtime.requests.edit("{entity: crate, state: {pose: {position: [12, 3, 0.5]}}}")
    assert ok, message
    row = runtime.sim.snapshot.names.index("crate")
    wait_for(lambda: len(sink.of("poses")) == 2)
    seconds, poses = sink.of("poses", POSES)[-1]
    assert seconds == 0.0 and (poses.poses[row].position.x, poses.poses[row].position.y) == (12.0, 3.0)


def test_as_fast_as_possible_publishes_at_the_simulated_rates(running):
    runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "2")
    runtime.sim.wait(60)
    runtime.stop()
    steps = np.array([t for t, _ in sink.of("poses")]) * 128
    # The first step at or after each 1/30 s: what the same scene gives at any speed.
    assert np.allclose(steps, np.ceil(np.arange(61) * 128 / 30 - 1e-6))
    assert [t for t, _ in sink.of("diagnostics")] == [0.0, 1.0, 2.0]
    assert [t for t, _ in sink.of("rtf")] == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert all(decoder("std_msgs/msg/Float64")(d).data > 0.0 for _, d in sink.of("rtf")[1:])


class ThreadRecordingWorld:
    """A World whose every attribute read records the reading thread's name."""

    def __init__(self, world):
        object.__setattr__(self, "_world", world)
        object.__setattr__(self, "threads", set())

    def __getattr__(self, name):
        import threading
        self.threads.add(threading.current_thread().name)
        return getattr(self._world, name)

    def __setattr__(self, name, value):
        setattr(self._world, name, value)


def test_real_time_sends_a_clock_for_every_step_in_order(running):
    # In real time a batch runs two steps (Simulation.BATCH_PERIOD): each has its /clock, sent
    # in order when the batch ends, before the messages of its last step.
    runtime, sink = running(SCENE, "--duration", "1.0")
    runtime.sim.wait(30)
    runtime.stop()
    rate = runtime.sim.world.settings["steps_per_second"]
    steps = [round(t * rate) for t, _ in sink.of("clock")]
    assert steps == list(range(steps[0], steps[0] + len(steps))) and len(steps) >= rate - 2
    clocks_sent = set()
    for key, t, _ in list(sink.messages):
        if key == "clock":
            clocks_sent.add(round(t * rate))
        elif key == "poses" and t > 0.0:  # the loaded world's own round comes before any step
            assert round(t * rate) in clocks_sent


def test_a_world_at_rest_wakes_at_its_publish_times_and_still_clocks_every_step(running):
    """Issue 36.4: in real time a world at rest runs its batches to the next publish time
    (Simulation.RESTING_BATCH_PERIOD), not two steps at a time: half the wake-ups at 30 Hz,
    /clock still at every step in order."""
    scene = {"version": 1, "bodies": [{"name": "sleeper", "position": [0, 0, 0.5], "frozen": True}]}
    runtime, sink = running(scene, "--duration", "2.0")
    batches = []
    runtime.sim.add_listener(lambda snapshot: batches.append(snapshot.time))
    runtime.sim.wait(30)
    runtime.stop()
    rate = runtime.sim.world.settings["steps_per_second"]
    steps = [round(t * rate) for t, _ in sink.of("clock")]
    assert steps == list(range(steps[0], steps[0] + len(steps))) and steps[-1] == 2 * rate
    per_second = (len(batches) - 1) / (batches[-1] - batches[0])
    # 30 publish rounds a second (78 batches a second before); fewer on a loaded machine (catching up)
    assert 5 <= per_second <= 36, per_second


def test_a_world_at_rest_runs_in_real_time_with_no_publisher():
    """Without a Broadcaster nothing is due (next_publish_time inf): the batches of a world at
    rest stop at RESTING_BATCH_PERIOD rather than asking for infinitely many steps."""
    sim = Simulation(load_world({"version": 1, "bodies": [{"name": "sleeper", "position": [0, 0, 0.5],
                                                           "frozen": True}]}), real_time_factor=1.0, duration=0.5)
    sim.start()
    assert sim.wait(30)
    assert sim.world.time == pytest.approx(0.5) and sim.fault_count == 0


def test_the_publisher_never_reads_the_world_it_only_reads_snapshots():
    # simulation.py's rule: nothing outside the simulation thread touches the World while it
    # steps. Scenery (scene markers) and wheels (car markers) come with the snapshots.
    options = parse_args(["--no-record", "--real-time-factor", "0", "--duration", "1.0"])
    world = ThreadRecordingWorld(load_world(SCENE))
    sim = Simulation(world, real_time_factor=0.0, duration=1.0)
    runtime = Runtime(sim, options, logging.getLogger("test_broadcast.threads"))
    sink = Collector()
    runtime.broadcaster.add_sink(sink)
    runtime.start()
    try:
        sim.wait(60)
    finally:
        runtime.stop()
    assert sink.of("scene_markers") and sink.of("/vplayground/car/markers") and sink.of("body_markers")
    # MainThread: this test's set-up and the Runtime's construction, before stepping.
    assert world.threads == {"MainThread", "vplayground-physics"}


def test_bodies_at_rest_are_drawn_on_a_latched_topic_sent_when_they_change(running):
    """Issue 36.4: ~/bodies/markers (every round) draws what moves, ~/bodies/resting_markers
    (latched) the frozen and immovable bodies, sent when one freezes, wakes or is edited and
    every static_republish_period, not every round."""
    scene = {"version": 1, "bodies": [
        {"name": "sleeper", "position": [0, 0, 0.5], "frozen": True},
        {"name": "wall", "position": [5, 0, 1], "size": [0.2, 2, 2], "immovable": True},
        {"name": "faller", "position": [10, 0, 2]}]}
    runtime, sink = running(scene, "--real-time-factor", "0")
    sim = runtime.sim
    ids = {name: runtime.broadcaster.marker_id(name) for name in ("sleeper", "wall", "faller")}

    def drawn(key, index=-1):
        messages = sink.of(key, MARKERS)
        if not messages:
            return None, {}
        seconds, array = messages[index]
        assert array.markers[0].action == 3  # DELETEALL first: each is a complete snapshot of its set
        return seconds, {m.id: tuple(round(c, 3) for c in (m.color.r, m.color.g, m.color.b)) for m in array.markers[1:]}

    assert wait_for(lambda: drawn("resting_markers", 0)[0] is not None and drawn("body_markers", 0)[0] is not None)
    assert set(drawn("body_markers", 0)[1]) == {ids["faller"]}
    first = drawn("resting_markers", 0)[1]
    assert set(first) == {ids["sleeper"], ids["wall"]}
    assert first[ids["sleeper"]] == (0.6, 0.6, 0.6) and first[ids["wall"]] == (0.35, 0.35, 0.45)  # frozen grey

    # The faller lands and freezes: it moves to the resting topic, and the per-round one is empty.
    assert wait_for(lambda: drawn("resting_markers")[1].keys() == set(ids.values()), timeout=120)
    # the sink's rounds, which may trail the simulation by a few handed-over snapshots
    assert wait_for(lambda: sink.of("poses")[-1][0] > 12.0, timeout=120)
    # While something moves, ~/bodies/markers every round; once nothing does, one DELETEALL and
    # then nothing (so for the contact topics and /tf, which carry nothing here): a world at
    # rest sends what draws only when it changes.
    rounds = sink.of("body_markers", MARKERS)
    still = [t for t, array in rounds if len(array.markers) == 1]
    assert len(still) == 1 and rounds[-1][0] == still[0], [t for t, _ in rounds[-3:]]
    assert len(rounds) >= still[0] * 30 - 2  # marker_rate until then
    for key in ("contact_points", "contact_markers"):
        assert [t for t, _ in sink.of(key) if t > still[0]] == [], key
    assert [t for t, _ in sink.of("tf")] == [0.0]  # no robot, no sensor: /tf carries nothing
    assert len(sink.of("poses")) >= 12 * 30 - 2  # the state goes out every round (publish_rate)
    sent = [seconds for seconds, _ in sink.of("resting_markers")]
    # t=0, the faller frozen, then once per static_republish_period (5 s) of a world at rest.
    assert 3 <= len(sent) <= 6, sent
    gaps = np.diff(sent)
    assert all(gap >= 5.0 - 1e-9 for gap in gaps[2:]), sent

    # A push wakes the sleeper: it leaves the resting topic at once and moves on the other.
    woken = sim.call(lambda world: (world.apply_impulse("sleeper", (0.0, 0.0, 3000.0)), world.time)[1])
    assert wait_for(lambda: ids["sleeper"] in drawn("body_markers")[1])
    moving = [t for t, a in sink.of("body_markers", MARKERS) if t >= woken and ids["sleeper"] in {m.id for m in a.markers[1:]}]
    left = [(t, a) for t, a in sink.of("resting_markers", MARKERS) if t >= woken][0]
    # In the same round, so the viewer never draws it twice or not at all.
    assert left[0] == moving[0] and ids["sleeper"] not in {m.id for m in left[1].markers[1:]}
    assert wait_for(lambda: ids["sleeper"] in drawn("resting_markers")[1], timeout=120)  # it freezes again

    # Removed, or moved while frozen: the next round's resting markers say so.
    removed = sim.call(lambda world: (world.remove_body("wall"), world.time)[1])
    assert wait_for(lambda: drawn("resting_markers")[0] >= removed)
    assert ids["wall"] not in drawn("resting_markers")[1]
    moved = sim.call(lambda world: (world.edit_body("faller", position=[10.0, 3.0, 0.5], frozen=True), world.time)[1])
    assert wait_for(lambda: drawn("resting_markers")[0] >= moved)
    faller = next(m for m in sink.of("resting_markers", MARKERS)[-1][1].markers if m.id == ids["faller"])
    assert faller.pose.position.y == pytest.approx(3.0)


def test_resting_markers_see_a_body_that_woke_moved_and_froze_again_between_two_rounds():
    """At a low marker_rate a body can be hit, move and freeze again between two rounds: the
    same layout and frozen flags, another pose. The resting topic must not keep the old one."""
    import dataclasses

    from vplayground_ros.messages import BodyMarkers
    sim = Simulation(load_world({"version": 1, "bodies": [{"name": "sleeper", "position": [0, 0, 0.5], "frozen": True}]}))
    before = sim.snapshot
    ids = np.array([0], np.int32)
    poses = np.concatenate([before.state["positions"], before.state["quaternions"]], axis=1)
    markers = BodyMarkers(resting=True)
    markers.encode(before, "world", ids, poses)
    assert markers.draws_the_same(before, ids, poses.copy())
    moved = poses.copy()
    moved[0, 0] += 1.0
    after = dataclasses.replace(before, state={**before.state, "positions": moved[:, :3]})
    assert not markers.draws_the_same(after, ids, moved)


def test_body_markers_draw_each_shape_and_follow_a_capsule(running):
    scene = {"version": 1, "bodies": [
        {"name": "ball", "shape": "sphere", "radius": 0.3, "position": [0, 0, 0.3]},
        {"name": "pill", "shape": "capsule", "radius": 0.2, "length": 0.6, "position": [2, 0, 0.2],
         "rpy": [0, 1.5707963267948966, 0]},
        {"name": "can", "shape": "cylinder", "radius": 0.25, "length": 0.5, "position": [4, 0, 0.25]},
        {"name": "crate", "position": [6, 0, 0.5]}]}
    runtime, sink = running(scene, "--real-time-factor", "0", "--duration", "0.2")
    runtime.sim.wait(60)
    runtime.stop()
    _, last = sink.of("body_markers", MARKERS)[-1]
    drawn = [(m.type, m.scale.x, m.scale.z) for m in last.markers[1:]]
    # SPHERE, the capsule's CYLINDER, CYLINDER, CUBE, then the capsule's two end spheres
    assert [t for t, _, _ in drawn] == [2, 3, 3, 1, 2, 2]
    assert drawn[1][1:] == pytest.approx((0.4, 0.6)) and drawn[4][1:] == pytest.approx((0.4, 0.4))
    capsule, ends = last.markers[2].pose.position, [m.pose.position for m in last.markers[5:]]
    # lying along x: its ends 0.3 m either side of its centre
    assert sorted(e.x - capsule.x for e in ends) == pytest.approx([-0.3, 0.3], abs=1e-3)


def test_solver_threads_is_a_parameter_that_every_world_of_the_run_keeps(running):
    """The contact solve's thread count is the host's choice: set as a parameter, it reaches the
    World stepping and the one a reset brings; a value outside 1..2 is refused unchanged."""
    runtime, _ = running(SCENE, "--real-time-factor", "0")
    store, sim = runtime.parameters, runtime.sim
    assert store["solver_threads"] == sim.world.solver_threads
    wait_for(lambda: sim.snapshot.step > 0, timeout=600)  # past the first batch (a cold Numba cache compiles)
    for threads in (1, 2, 1):
        assert store.set({"solver_threads": threads}) == (True, "")
        wait_for(lambda: sim.call(lambda world: world.solver_threads) == threads)
    ok, reason = store.set({"solver_threads": 3})
    assert not ok and "solver_threads" in reason and store["solver_threads"] == 1
    before = sim.world
    assert runtime.requests.reset(255)[0]
    wait_for(lambda: sim.call(lambda world: world is not before and world.solver_threads == 1))


def test_start_up_overrides_take_effect_like_the_command_line():
    """Values given as ROS overrides (--ros-args -p) arrive after the Runtime was built from the
    command line, before it starts: frames, the duration and start_paused must act, not only
    read back (the frames stayed world/odom/base_link, the run went on past its duration). A
    sensor fixed in the world hangs from the world frame, whatever its name (it hung from a
    `world` frame that nothing connected to `map`)."""
    options = parse_args(["--no-record", "--real-time-factor", "0"])
    post = {"name": "post", "type": "imu", "parent": "world", "pose": [1, 2, 3, 0, 0, 0]}
    sim = Simulation(load_world({**SCENE, "sensors": [post]}), real_time_factor=0.0)
    runtime = Runtime(sim, options, logging.getLogger("test_broadcast"))
    sink = Collector()
    runtime.broadcaster.add_sink(sink)
    runtime.parameters.override({"world_frame": "map", "odom_frame": "odom2", "base_frame": "chassis",
                                 "duration": 0.5})
    runtime.start()
    try:
        assert sim.wait(60)  # the run ended at its duration
    finally:
        runtime.stop()
    assert sim.world.time == pytest.approx(0.5)
    assert {message.header.frame_id for _, message in sink.of("poses", POSES)} == {"map"}
    odometry = sink.of("/odom", decoder("nav_msgs/msg/Odometry"))[-1][1]
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("odom2", "base_footprint")

    tf_static = sink.of("tf_static", decoder("tf2_msgs/msg/TFMessage"))[-1][1]
    assert {(t.header.frame_id, t.child_frame_id) for t in tf_static.transforms} == {("map", "post")}
    tf = sink.of("tf", decoder("tf2_msgs/msg/TFMessage"))[-1][1]
    edges = {(t.header.frame_id, t.child_frame_id) for t in tf.transforms}
    assert {("map", "odom2"), ("odom2", "base_footprint"), ("base_footprint", "chassis")} <= edges

    paused = Runtime(Simulation(load_world(SCENE), real_time_factor=0.0), options, logging.getLogger("test_broadcast"))
    paused.parameters.override({"start_paused": True})
    paused.start()
    try:
        time.sleep(0.5)
        assert paused.sim.paused and paused.sim.world.time == 0.0
    finally:
        paused.stop()


def test_clock_goes_out_for_every_step_as_fast_as_possible(running):
    """SPEC 6.1: /clock every step (clock_rate 0), also when a batch runs 16 steps at once: it
    went out once a batch, 1,041 of 1,280 steps in a bag of the default scene."""
    runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "1.0")
    runtime.sim.wait(60)
    runtime.stop()
    times = np.array([t for t, _ in sink.of("clock")])
    steps = np.arange(1, 129) / 128.0
    assert np.allclose(times[times > 0.0], steps)


def test_clock_rate_caps_clock_in_the_new_time_after_a_reset(running):
    """With clock_rate, /clock had stayed silent after ~/reset until the new time passed the
    last one sent before it (use_sim_time nodes hung): the cap now counts in the new time."""
    runtime, sink = running(SCENE, "--real-time-factor", "4")
    assert runtime.parameters.set({"clock_rate": 10.0})[0]
    assert wait_for(lambda: runtime.sim.snapshot.time > 3.0)
    sent = len(sink.of("clock"))
    assert runtime.requests.reset(255)[0]
    assert wait_for(lambda: 1.0 < runtime.sim.snapshot.time < 3.0)
    clocks = [t for t, _ in sink.of("clock")[sent:]]
    # From the new time on: the old one's last /clock may go out between the count and the reset.
    times = clocks[next(k for k, t in enumerate(clocks) if t < 1.0):]
    assert len(times) >= 8 and max(times) < 3.0 and np.all(np.diff(times) >= 0.1 - 1e-9), clocks


def test_a_new_publish_rate_counts_from_now(running):
    """publish_rate 30 -> 0.1 -> 30: ~/bodies/poses had waited for the time the 0.1 Hz period
    made due (10 s) before it went out again."""
    runtime, sink = running(SCENE, "--real-time-factor", "4")
    assert wait_for(lambda: runtime.sim.snapshot.time > 0.5)
    assert runtime.parameters.set({"publish_rate": 0.1})[0]
    started = runtime.sim.snapshot.time
    assert wait_for(lambda: runtime.sim.snapshot.time > started + 0.5)
    assert runtime.parameters.set({"publish_rate": 30.0})[0]
    back = runtime.sim.snapshot.time
    assert wait_for(lambda: runtime.sim.snapshot.time > back + 1.0)
    assert len([t for t, _ in sink.of("poses") if back < t <= back + 1.0]) >= 25


def test_tf_carries_every_vehicles_wheels(running):
    """SPEC 7, issue 39: /tf has each robot's wheels, the first robot's under base_link, every
    other's under its namespace's (<name>/base_link: only the driven car's were sent once)."""
    other = {**CAR, "name": "car_b", "position": [0, 8, 1.6]}
    runtime, sink = running({**SCENE, "vehicles": [CAR, other]}, "--real-time-factor", "0", "--duration", "0.2")
    runtime.sim.wait(60)
    runtime.stop()
    _, tf = sink.of("tf", decoder("tf2_msgs/msg/TFMessage"))[-1]
    parent_of = {t.child_frame_id: t.header.frame_id for t in tf.transforms}
    positions = ("front_left", "front_right", "rear_left", "rear_right")
    for prefix in ("", "car_b/"):
        assert all(parent_of[f"{prefix}wheel_{p}"] == f"{prefix}steering_{p}" for p in positions)
        assert all(parent_of[f"{prefix}suspension_{p}"] == f"{prefix}base_link" for p in positions)
        assert parent_of[f"{prefix}base_link"] == f"{prefix}base_footprint"
        assert parent_of[f"{prefix}odom"] == "world"
    assert len(parent_of) == len(tf.transforms)  # no frame twice


def test_odometry_covariances_are_small_not_zero_and_joints_have_rates(running):
    """The odometry is exact, but all-zero covariances read as 'unknown' to robot_localization:
    a small diagonal. Joint states carry the suspension's rate as the car lands and sways
    (always 0 before) and the steering's (test_vehicle)."""
    runtime, sink = running(SCENE, "--real-time-factor", "0", "--duration", "2.0")
    runtime.sim.call(lambda world: world.drive(world.vehicle_names()[0], 2.0, 0.8, timeout=100))
    runtime.sim.wait(60)
    runtime.stop()
    odometry = sink.of("/odom", decoder("nav_msgs/msg/Odometry"))[-1][1]
    for covariance in (odometry.pose.covariance, odometry.twist.covariance):
        matrix = np.array(covariance).reshape(6, 6)
        assert np.all(np.diag(matrix) > 0.0) and np.all(matrix == np.diag(np.diag(matrix)))
    states = [message for _, message in sink.of("/joint_states", decoder("sensor_msgs/msg/JointState"))]
    suspension = [k for k, name in enumerate(states[0].name) if name.endswith("_suspension")]
    assert max(abs(m.velocity[k]) for m in states for k in suspension) > 0.01
    # base_footprint stays level: /odom turns it about the vertical only, while the chassis
    # (ground truth) rolls into the turn and pitches as it lands (/odom had the chassis' rates).
    odometries = [m for _, m in sink.of("/odom", decoder("nav_msgs/msg/Odometry"))]
    truth_key = next(k for k, _, _ in sink.messages if k.endswith("/ground_truth"))
    truths = [m for _, m in sink.of(truth_key, decoder("nav_msgs/msg/Odometry"))]
    assert all(m.twist.twist.angular.x == 0.0 == m.twist.twist.angular.y for m in odometries)
    assert max(abs(m.twist.twist.angular.x) + abs(m.twist.twist.angular.y) for m in truths) > 0.01
    assert odometries[-1].twist.twist.angular.z == pytest.approx(truths[-1].twist.twist.angular.z, rel=0.05)


def test_a_query_while_paused_sends_nothing_again_and_an_edit_once(running):
    """tf2 refuses a transform at a stamp it already holds, with a TF_REPEATED_DATA warning each
    time: paused, every query (~/get_entity, Foxglove's polling) had sent /tf again at the
    paused stamp. What changed nothing goes out no more; an edit goes out (once)."""
    runtime, sink = running(SCENE, "--start-paused")
    assert wait_for(lambda: sink.of("tf") and sink.of("poses"))
    time.sleep(0.6)  # past the paused jobs' period
    before = {key: len(sink.of(key)) for key in ("tf", "poses", "scene_markers")}
    for _ in range(5):
        runtime.sim.call(lambda world: world.body("crate"))
        time.sleep(0.15)
    time.sleep(0.6)
    assert {key: len(sink.of(key)) for key in before} == before
    runtime.sim.call(lambda world: world.edit_body("crate", position=[12.0, 0.0, 0.5]))
    wait_for(lambda: len(sink.of("poses")) > before["poses"])
    time.sleep(0.6)
    assert len(sink.of("tf")) == before["tf"] + 1 and len(sink.of("poses")) == before["poses"] + 1


def test_a_newcomer_is_welcomed_while_another_keeps_subscribing(running):
    """Paused, a client re-subscribing every 20 ms pushed the welcome back each time: nobody got
    the world. A burst of re-subscriptions to a latched topic re-sends it once, not each time."""
    runtime, sink = running(SCENE, "--start-paused")
    newcomer = Collector()
    runtime.broadcaster.sinks.append(newcomer)
    started = time.monotonic()
    while time.monotonic() - started < 0.6:
        runtime.broadcaster.welcome(newcomer, "poses")
        time.sleep(0.02)
    assert newcomer.of("poses", POSES)
    before = len(newcomer.of("scene_markers", MARKERS))
    for _ in range(300):
        runtime.broadcaster.welcome(newcomer, "scene_markers")
    time.sleep(0.3)
    assert 1 <= len(newcomer.of("scene_markers", MARKERS)) - before <= 2


def test_flush_ends_even_if_snapshots_keep_coming(running):
    """Runtime.stop flushes after joining both threads; a physics thread that outlived its join
    (5 s) still hands snapshots over: the flush sends at most what can be pending, and ends."""
    runtime, sink = running(SCENE, "--real-time-factor", "0")
    broadcaster = runtime.broadcaster
    assert wait_for(lambda: len(sink.messages) > 0)
    runtime.sim.stop()
    runtime._stop.set()
    runtime._thread.join(5.0)
    item = (runtime.sim.snapshot, [], None)

    class Endless(list):  # as if the physics thread refilled it at once, for ever
        def popleft(self):
            return item

        def __bool__(self):
            return True

        def __len__(self):
            return 1

    broadcaster._pending = Endless()
    done = threading.Event()
    threading.Thread(target=lambda: (broadcaster.flush(), done.set()), daemon=True).start()
    assert done.wait(10.0), "flush did not end"


def test_the_topic_table_keeps_no_entry_of_a_robot_gone(running):
    """A robot's topics join the table as it publishes and leave it when it goes, so spawning
    and removing under new names does not grow it. Its robot_description, latched, was retracted
    (its publisher destroyed) but its entry stayed: one more for every name ever spawned."""
    runtime, sink = running(SCENE, "--real-time-factor", "0")
    topics = runtime.broadcaster.topics
    before = None
    for k in range(6):
        name = f"arm_{k}"
        ok, message = runtime.requests.spawn(yaml.safe_dump({"name": name, "urdf": "arm.urdf",
                                                             "position": [-10, 12, 0]}))
        assert ok, message
        assert wait_for(lambda: {f"/{name}/robot_description", f"/{name}/joint_states"} <= set(topics),
                        explain=lambda: sorted(topics))
        assert runtime.requests.remove_entity(name)[0]
        assert wait_for(lambda: f"/{name}/joint_states" not in topics, explain=lambda: sorted(topics))
        assert [key for key in list(topics) if key.startswith("/arm_")] == []
        before = len(topics) if before is None else before
        assert len(topics) == before
    assert sink.of(f"/{name}/robot_description")  # it went out while the robot was there
