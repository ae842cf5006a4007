"""The real-time runner: a World stepped in its own thread, commands queued between batches,
snapshots for whoever publishes. ROS-free, so the node and the Foxglove server share it.

Data flows one way per batch: queued commands are applied -> the world steps (compiled, GIL
released) -> a snapshot is taken -> listeners read the snapshot. Nothing outside this thread
touches the World while it steps.
"""
import logging
import math
import queue
import threading
import time
from collections import namedtuple
from concurrent.futures import Future
from dataclasses import dataclass, field

import numpy as np

from .physics.jit_cache import compiler_activity
from .sensors import Sensors

# In real time the loop wakes this often (wall s) and runs the steps due: two at 128 steps/s.
# A wake-up costs ~50-100 us of CPU on a VM whatever the work after it (an empty 128 Hz loop
# took ~1 % of a core), so each one runs two steps rather than one; the broadcaster still
# sends a /clock for every step, and commands wake the loop at once whenever they come.
BATCH_PERIOD = 1.0 / 64
# A world at rest (every body frozen or immovable, no command since) moves nothing until a
# command comes, which wakes the loop at once: its batches run to the next time something is
# published or read, at most this long, halving its wake-ups at the default rates.
RESTING_BATCH_PERIOD = 4 * BATCH_PERIOD
# Steps per batch when running as fast as possible.
FAST_BATCH_STEPS = 16
# Falling further behind than this many batches is not caught up on: the loop drops the debt
# (counted as late ticks) instead of spiralling into ever longer catch-up batches.
MAX_DEBT_BATCHES = 5
# The achieved real-time factor is measured over this much wall time.
RTF_WINDOW = 0.5

# simulation_interfaces SimulationState: STOPPED is paused at the loaded scene's start (and a
# run that ended), NO_WORLD after UnloadWorld, QUITTING once asked to end.
STOPPED, PLAYING, PAUSED, QUITTING, NO_WORLD = 0, 1, 2, 3, 4
STATE_NAMES = {STOPPED: "stopped", PLAYING: "playing", PAUSED: "paused", QUITTING: "quitting", NO_WORLD: "no world"}

log = logging.getLogger(__name__)


def steps_per_batch(speed, period=BATCH_PERIOD):
    """Steps a real-time batch of `period` wall s runs at `speed` steps per wall second (at
    least one)."""
    return max(1, int(round(period * speed)))


@dataclass
class Snapshot:
    """What the world looked like after a batch (copies, safe to read from any thread). The
    names and the property columns of `state` (sizes, masses, immovable) are shared by the
    snapshots of one layout (World.layout_version): read them, never change them (the arrays
    are read-only)."""
    time: float
    step: int
    names: list
    state: dict
    vehicles: dict = field(default_factory=dict)  # name -> vehicle_state()
    contacts: dict = None
    # [(sensors.Sensor, reading)] of the sensors read after this batch's last step, on the
    # simulation thread (the rays need the World); the publisher turns them into messages.
    readings: list = field(default_factory=list)
    vehicle_specs: dict = field(default_factory=dict)  # vehicle name -> World.vehicle() (shared)
    vehicle_ids: dict = field(default_factory=dict)  # vehicle name -> World.body_id (which car of that name; shared)
    scenery: "Scenery" = None
    robot_specs: list = field(default_factory=list)  # World.robot_specs (URDF robots; shared)
    robot_joints: dict = field(default_factory=dict)  # URDF robot name -> World.joint_states of its joints
    sensor_specs: list = field(default_factory=list)  # World.sensor_specs (shared: a new list when they change)
    # Counts the states: a snapshot taken after a command that changed nothing (a query) keeps
    # the one before's, and what goes out only on change while paused is not sent again.
    version: int = 0


# The static world as the publisher draws it (shared by snapshots until it changes):
# the ground spec (or None), the playground's triangles (T, 3, 3, read-only), and the World's
# scenery_version they were taken at.
Scenery = namedtuple("Scenery", "ground triangles version")

# What the snapshots of one world's layout share, taken once per layout rather than per batch.
SharedLayout = namedtuple("SharedLayout", "world version names vehicle_names properties vehicle_specs vehicle_ids "
                                         "scenery robot_specs")


class Simulation:
    def __init__(self, world, real_time_factor=1.0, start_paused=False, duration=None,
                 with_contacts=True):
        self.world = world
        self.real_time_factor = real_time_factor
        # Threads of the contact solve (the `solver_threads` parameter), given to each world this
        # loop steps: a loaded scene or a reset brings a new World, which keeps the host's choice.
        self.solver_threads = world.solver_threads
        self.duration = duration
        self.with_contacts = with_contacts
        self.paused = start_paused
        self.stopped = False       # paused at the scene's start by SetSimulationState STOPPED or LoadWorld
        self.world_loaded = True   # False after UnloadWorld: an empty world, paused
        self.quitting = False      # SetSimulationState QUITTING: the run ends in a moment
        self.late_ticks = 0
        # Wall time inside world.step and the steps it ran, each world's first batch left out
        # (Numba's cache load or compile, up to minutes, is no step time): mean_step_ms.
        self.step_seconds = 0.0
        self.timed_steps = 0
        self._thread_cpu_seconds = 0.0  # the simulation thread's CPU time when it ended
        self._cpu_clock = None          # its CPU clock while it runs (thread_cpu_seconds)
        self.engine_cpu_seconds = 0.0  # the part of it inside the compiled step, over all worlds
        # The world's solver threads in its last batch and the last trial's speed-up of the
        # second (World.threads_in_use, second_thread_speedup; None before a trial), copied
        # after each batch: the publisher reads these, never the World.
        self.solver_threads_in_use = world.threads_in_use
        self.second_thread_speedup = None
        self.achieved_rtf = 0.0
        # The next simulated time a listener publishes at: a batch ends at the first step at or
        # after it, so what is published carries the same times at any real-time factor.
        self.next_publish_time = math.inf
        self.sensors = Sensors()  # the world's `sensors:`, read when due after a step
        self.controllers = []     # fn(world) run before each batch of steps (the robots' trajectories): True if it changed something
        self.removed = []          # names of bodies removed for going non-finite or away
        self.faults = []           # texts of the first exceptions survived (listeners, steps, ROS callbacks)
        self.fault_count = 0       # all of them
        self._commands = queue.SimpleQueue()
        self._listeners = []
        self._stop = threading.Event()
        self._finished = threading.Event()
        self._pending_steps = 0
        self._thread = None
        self._layout = None
        self._at_rest = None   # (layout, motion state) of the last snapshot if every body rested in it
        self._touched = False  # a command ran since the last snapshot
        self.snapshot = self._take_snapshot()

    # ---------------------------------------------------------------- control (any thread)
    @property
    def mean_step_ms(self):
        """Wall milliseconds per step, over the steps after each world's first batch."""
        return 1e3 * self.step_seconds / max(self.timed_steps, 1)

    @property
    def thread_cpu_seconds(self):
        """CPU time of the simulation thread (physics, snapshots, listeners), read from its
        clock when asked (/diagnostics, once a second) rather than stored after every batch."""
        clock = self._cpu_clock
        if clock is not None:
            try:
                return time.clock_gettime(clock)
            except OSError:  # the thread ended meanwhile
                pass
        return self._thread_cpu_seconds

    @property
    def state(self):
        if self.quitting:
            return QUITTING
        if self._finished.is_set() or (self.stopped and self.paused):
            return STOPPED
        if not self.world_loaded:
            return NO_WORLD
        return PAUSED if self.paused else PLAYING

    def submit(self, fn):
        """Runs fn(world) on the simulation thread between batches; returns a Future."""
        future = Future()
        self._commands.put((fn, future))
        if self._thread is None:  # not started (tests, batch use): run it now
            self._apply_commands()
        return future

    def call(self, fn, timeout=10.0):
        """submit(fn) and wait for its result. On timeout the command is withdrawn if it has
        not started, so a caller told "timed out" can rely on nothing having changed. A wait
        in which Numba loaded or compiled kernels does not run the clock out: a kernel compiles
        at its first call (minutes on a first run, or after an engine edit), and a request made
        meanwhile (a ~/load_scene just after start) waits for it instead of failing."""
        future = self.submit(fn)
        _, finished_before = compiler_activity()
        while True:
            try:
                return future.result(timeout)
            except TimeoutError:
                compiling, finished = compiler_activity()
                if (compiling or finished != finished_before) and not self._finished.is_set():
                    finished_before = finished
                    continue
                if future.cancel():
                    raise TimeoutError(f"the simulation thread did not take the command within {timeout:g} s") from None
                return future.result()  # it started meanwhile: its outcome is the answer

    def add_listener(self, fn):
        """fn(snapshot) runs on the simulation thread after every batch: keep it short."""
        self._listeners.append(fn)

    def start(self):
        self._thread = threading.Thread(target=self._run, name="vplayground-physics", daemon=True)
        self._thread.start()

    def stop(self, timeout=5.0):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def wait(self, timeout=None):
        """Blocks until the run ends (duration reached or stop()). True if it ended."""
        return self._finished.wait(timeout)

    # ------------------------------------------------ commands run on the simulation thread
    def request_steps(self, count):
        """While paused: advance exactly `count` steps (the ~/step service)."""
        self._pending_steps += count

    def withdraw_steps(self, target, count):
        """Takes back the last `count` steps asked for, those that would end at step `target`,
        if they are still the last queued and not yet run (a cancelled SimulateSteps); steps
        asked for after them, by others, stay."""
        if self.world.step_count + self._pending_steps == target:  # run between batches: none in flight
            self._pending_steps -= min(count, self._pending_steps)

    def clear_steps(self):
        """Forgets the steps asked for (a new world, a reset to the scene's start: STOPPED)."""
        self._pending_steps = 0

    @property
    def pending_steps(self):
        """Steps asked for by request_steps and not yet run."""
        return self._pending_steps

    # ---------------------------------------------------------------------- the loop
    def _run(self):
        self._cpu_clock = time.pthread_getcpuclockid(threading.get_ident())
        try:
            self._loop()
        finally:
            self._thread_cpu_seconds = time.thread_time()
            self._cpu_clock = None
            self._finished.set()

    def _loop(self):
        world, origin_sim, factor, first_batch = None, 0.0, None, False
        while not self._stop.is_set():
            self._apply_commands()
            if self.world is not world or world.time < origin_sim or self.real_time_factor != factor:
                # Started, or a command loaded another scene or reset the time, or the real-time
                # factor changed: it counts from now (applied back to the last anchor, a lower
                # one had stalled the simulation and a higher one run a debt of late ticks).
                first_batch = first_batch or self.world is not world or world.time < origin_sim
                world, factor = self.world, self.real_time_factor
                origin_wall, origin_sim = time.perf_counter(), world.time
                rtf_wall, rtf_sim, rtf_measured = origin_wall, world.time, False
            if world.solver_threads != self.solver_threads:
                world.solver_threads = self.solver_threads
            rate = world.settings["steps_per_second"]
            steps = 0
            if not self.paused:
                self._pending_steps = 0  # steps asked for while paused lapse when it plays
            if self.paused:
                # ~/step requests run a batch at a time, so commands between them stay prompt.
                steps = min(self._pending_steps, FAST_BATCH_STEPS)
                origin_wall, origin_sim = time.perf_counter(), world.time
            elif self.real_time_factor <= 0.0:
                steps = FAST_BATCH_STEPS
            else:
                due = (time.perf_counter() - origin_wall) * self.real_time_factor * rate
                steps = int(due - (world.time - origin_sim) * rate + 1e-9)
                per_batch = steps_per_batch(self.real_time_factor * rate)
                if steps > MAX_DEBT_BATCHES * per_batch:
                    self.late_ticks += steps - per_batch
                    steps = per_batch
                    origin_wall, origin_sim = time.perf_counter(), world.time
            if self.duration is not None:
                steps = min(steps, max(0, int(round((self.duration - world.time) * rate))))
            to_publish = (self._next_due_time(world) - world.time) * rate
            if 0.0 < to_publish < steps:
                steps = max(1, math.ceil(to_publish - 1e-6))
            if steps > 0:
                resting, second = self._resting(world), world.step_count // rate
                started, engine_before = time.perf_counter(), world.engine_cpu_seconds
                try:
                    for controller in self.controllers:
                        if controller(world):  # it moved targets: what rested may move
                            self._touched = True
                    world.step(steps)
                    if self.paused:  # only now: while a batch runs its steps are still pending
                        self._pending_steps -= steps
                except Exception as error:  # an engine bug: keep the loop (and the node) alive
                    self.paused, self._pending_steps = True, 0  # not the same failure 100 times a second
                    self.fault("step", error)
                self.engine_cpu_seconds += world.engine_cpu_seconds - engine_before
                self.solver_threads_in_use = world.threads_in_use
                self.second_thread_speedup = world.second_thread_speedup
                if not first_batch:
                    self.step_seconds += time.perf_counter() - started
                    self.timed_steps += steps
                else:
                    # A world's first batch loads its kernels from Numba's cache, or compiles them
                    # (a minute on a first run): real time starts after it, not as late ticks,
                    # and it is not step time either.
                    first_batch = False
                    origin_wall, origin_sim = time.perf_counter(), world.time
                    rtf_wall, rtf_sim, rtf_measured = origin_wall, world.time, False
                if not resting or world.step_count // rate != second:
                    # At rest nothing moved, nothing can have escaped; the World's check of
                    # every body once a simulated second still runs.
                    self.removed += world.remove_escaped()
                self._publish(self._read_sensors(world))
            if self.duration is not None and world.time >= self.duration - 0.5 / rate:
                break
            now = time.perf_counter()
            # Over the last window; until a first one is complete (a run as fast as possible may
            # be over sooner), over what has run so far.
            if now - rtf_wall >= RTF_WINDOW or (not rtf_measured and world.time > rtf_sim):
                self.achieved_rtf = (world.time - rtf_sim) / (now - rtf_wall)
                if now - rtf_wall >= RTF_WINDOW:
                    rtf_wall, rtf_sim, rtf_measured = now, world.time, True
            if self.paused:
                if steps == 0:
                    self._wait_for_work(BATCH_PERIOD)
            elif self.real_time_factor > 0.0:
                # Unless a step is due already (a batch cut short at a publish time), until a
                # batch's worth is: in this pass, not in one more that finds nothing due.
                speed = self.real_time_factor * rate
                done = (world.time - origin_sim) * rate
                if (time.perf_counter() - origin_wall) * speed - done < 1.0 - 1e-9:
                    batch, longest = steps_per_batch(speed), BATCH_PERIOD
                    if self._resting(world):
                        longest = RESTING_BATCH_PERIOD
                        to_due = (self._next_due_time(world) - world.time) * rate  # inf: no publisher
                        batch = max(batch, math.ceil(min(to_due, steps_per_batch(speed, longest)) - 1e-6))
                    wait = origin_wall + (done + batch) / speed - time.perf_counter()
                    if wait > 0.0:
                        self._wait_for_work(min(wait, longest))

    def _wait_for_work(self, timeout):
        """Sleeps `timeout` s or until a command arrives."""
        try:
            item = self._commands.get(timeout=timeout)
        except queue.Empty:
            return
        self._commands.put(item)  # keep order: applied at the top of the loop

    def _apply_commands(self):
        applied = False
        while True:
            try:
                fn, future = self._commands.get_nowait()
            except queue.Empty:
                break
            if not future.set_running_or_notify_cancel():
                continue
            try:
                future.set_result(fn(self.world))
            except BaseException as error:  # the caller gets it; the loop goes on
                future.set_exception(error)
            applied = True
        if applied:
            self._touched = True
            self._publish()

    def _next_due_time(self, world):
        """Where the batch ends: the next time a listener publishes at or a sensor is read (a
        sensor that cannot be made or scheduled is survived like a failing read: a fault, and
        the batch ends where the others are due)."""
        if not world.sensor_specs:
            return self.next_publish_time
        try:
            steps = self.sensors.steps_until_due(world)
        except Exception as error:
            self.fault("sensors", error)
            try:  # the sensors made (a SensorError leaves out only the failing ones)
                steps = self.sensors.steps_until_due(world)
            except Exception:
                return self.next_publish_time
        return min(self.next_publish_time, world.time + steps / world.settings["steps_per_second"])

    def _read_sensors(self, world):
        """The sensors due at this step, read from the state after it (a failing read is
        survived like a failing listener: the physics goes on)."""
        if not world.sensor_specs:
            return []
        try:
            return self.sensors.sample(world)
        except Exception as error:
            self.fault("sensors", error)
            return []

    def _publish(self, readings=()):
        before, snapshot = self.snapshot, self._take_snapshot()
        snapshot.readings = list(readings)
        if before is not None:
            # A query while paused had sent /tf again at the stamp it had gone out with, which
            # tf2 refuses with a TF_REPEATED_DATA warning each time (Foxglove polls).
            snapshot.version = before.version + (0 if same_state(snapshot, before) else 1)
        self.snapshot = snapshot
        for listener in self._listeners:
            try:
                listener(self.snapshot)
            except Exception as error:  # a publisher's bug must not stop the physics
                self.fault("listener", error)

    def fault(self, where, error):
        """Counts an exception a long-lived thread survived (this loop's, the ROS callbacks'):
        /diagnostics shows the count and the first ones; each distinct one is logged once."""
        self.fault_count += 1
        text = f"{where}: {type(error).__name__}: {error}"
        if len(self.faults) < 100 and text not in self.faults:
            # Each distinct error once, with its traceback: a listener failing every batch
            # would flood the log.
            self.faults.append(text)
            log.exception("survived an error in %s (logged once, counted on /diagnostics)", where)

    def _take_snapshot(self):
        world = self.world
        layout = self._shared_layout(world)
        return Snapshot(
            time=world.time, step=world.step_count, names=layout.names,
            state={**self._motion_state(world, layout), **layout.properties},
            vehicles={name: world.vehicle_state(name) for name in layout.vehicle_names},
            contacts=world.contacts() if self.with_contacts else None,
            vehicle_specs=layout.vehicle_specs, vehicle_ids=layout.vehicle_ids, scenery=layout.scenery,
            robot_specs=layout.robot_specs, sensor_specs=world.sensor_specs,
            robot_joints={robot["name"]: world.joint_states(robot["model"].joint_names.values())
                          for robot in layout.robot_specs})

    def _resting(self, world):
        """Every body was frozen or immovable in the last snapshot of this world and no command
        ran since: a step moves nothing (see _motion_state)."""
        rest = self._at_rest
        return rest is not None and rest[0].world is world and not self._touched

    def _motion_state(self, world, layout):
        """The bodies' motion columns (read-only): the last snapshot's arrays again when nothing
        can have moved since, that is the same layout, no command in between, and every body
        frozen or immovable in it (a step moves no body unless an awake one touches it). A
        settled world then costs no copies per batch, and its publishers tell an unchanged
        state by identity."""
        rest = self._at_rest
        if rest is not None and rest[0] is layout and not self._touched:
            return rest[1]
        self._touched = False
        motion = world.motion_state()
        for array in motion.values():
            array.flags.writeable = False
        resting = bool(np.all(motion["frozen"] | layout.properties["immovable"]))
        self._at_rest = (layout, motion) if resting else None
        return motion

    def _shared_layout(self, world):
        """Names, body properties, vehicle specs and scenery, taken again only when the world's layout
        or scenery changed: the publisher reads these from snapshots, never from the World."""
        layout = self._layout
        version = (world.layout_version, world.scenery_version)
        if layout is None or layout.world is not world or layout.version != version:
            properties = world.body_properties()
            for array in properties.values():
                array.flags.writeable = False
            properties["hull_triangles"] = world.hull_triangles()
            properties["parts"] = world.compound_parts()
            vehicle_names = world.vehicle_names()
            scenery = layout.scenery if layout is not None and layout.world is world else None
            if scenery is None or scenery.version != world.scenery_version:
                triangles = world.playground_triangles
                triangles.flags.writeable = False
                scenery = Scenery(world.ground, triangles, world.scenery_version)
            layout = self._layout = SharedLayout(
                world, version, world.body_names(), vehicle_names, properties,
                {name: world.vehicle(name) for name in vehicle_names},
                {name: world.body_id(name) for name in vehicle_names}, scenery, world.robot_specs)
        return layout


def same_state(a, b):
    """Whether two snapshots show the same world (readings aside: they belong to a step)."""
    return all(same_value(getattr(a, key), getattr(b, key)) for key in Snapshot.__dataclass_fields__
               if key not in ("readings", "version"))


def same_value(a, b):
    """Equal values, arrays element by element and containers item by item (a NaN differs)."""
    if a is b:
        return True
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and bool(np.array_equal(a, b)))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same_value(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return (type(a) is type(b) and len(a) == len(b)
                and all(same_value(x, y) for x, y in zip(a, b)))
    return bool(a == b)
