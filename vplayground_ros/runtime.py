"""The simulator without a transport: the Simulation and everything around it that the ROS node
and the Foxglove server share (requests, parameters, what is published, what is subscribed,
the services). ROS-free: `vplayground --no-ros --foxglove` runs on this alone.
"""
import threading
from contextlib import contextmanager
from pathlib import Path

from .api import DEFAULT_MAX_BODIES, Requests, default_scene_directories
from .broadcast import BagSink, Broadcaster, resolve
from .inputs import Inputs
from .parameters import FRAMES, PHYSICS, Parameters, frames, parameter_table, settings_from
from .services import guarded, service_table
from .standard_services import standard_service_table
from .urdf_robots import RobotControl

# Requests that may take long (Service.aside, SimulateSteps goals) run each on a thread of its own,
# in the ROS node and in the Foxglove server: at most this many at once over both.
MAX_LONG_REQUESTS = 8
BUSY = (f"RESULT_OPERATION_FAILED: {MAX_LONG_REQUESTS} long requests are running (steps, every entity's state, "
        "spawn lists, SimulateSteps goals): ask again once one has answered")


class Runtime:
    def __init__(self, sim, options, log, recorder=None, resolve_name=resolve):
        self.sim = sim
        self.options = options
        self.log = log
        self.recorder = recorder
        self.resolve_name = resolve_name
        # The parameters own every setting (parameters.py); the requests change them through it.
        directories = default_scene_directories(recorder.path.parent if recorder is not None else None,
                                                options.scene)
        self.parameters = Parameters(parameter_table(sim.world.settings, options, directories, DEFAULT_MAX_BODIES,
                                                     sim.world.solver_threads))
        self.parameters.listen(self._apply)
        self.requests = Requests(sim, str(options.scene), scene_directories=directories,
                                 max_bodies=DEFAULT_MAX_BODIES, settings=self.parameters)
        self.broadcaster = Broadcaster(sim, self.parameters, log, resolve_name)
        if recorder is not None:
            self.broadcaster.add_sink(BagSink(recorder))
        self.robot_control = RobotControl()
        sim.controllers.append(self.robot_control.before_batch)
        self.inputs = Inputs(sim, self.requests, self.parameters, log, self.broadcaster.robots, resolve_name,
                             self.broadcaster.urdf_robots, self.robot_control)
        self.services = service_table(self) + [guarded(self, s) for s in standard_service_table(self)]
        self.sim.real_time_factor = self.parameters["real_time_factor"]
        self.long_requests = threading.BoundedSemaphore(MAX_LONG_REQUESTS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._publish, name="vplayground-publisher", daemon=True)

    @contextmanager
    def long_request(self):
        """Whether a long request may run now: one of the MAX_LONG_REQUESTS slots, held until the
        block ends. Beyond them a request is answered BUSY at once, so that a flood does not start
        a thread each (0.4 s of CPU each for 10,000 entities)."""
        slots = self.long_requests
        admitted = slots.acquire(blocking=False)
        try:
            yield admitted
        finally:
            if admitted:
                slots.release()

    def start(self):
        """Starts the physics thread and the publishing thread."""
        self.broadcaster.publish_loaded()
        self.sim.start()
        self._thread.start()

    def stop(self):
        """Stops both; what was due and the last state go out."""
        self.sim.stop()
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)
        self.broadcaster.flush()

    def _publish(self):
        while not self._stop.is_set():
            self.broadcaster.publish_next()

    def _apply(self, changed):
        """A validated parameter change, acting on the running simulation: one way, the World
        and the Requests never write a parameter back."""
        physics = settings_from({n: v for n, v in changed.items() if n in PHYSICS})
        if physics:
            self.sim.call(lambda world: take_settings(world, physics))
        if "real_time_factor" in changed:
            self.sim.real_time_factor = changed["real_time_factor"]
        if "solver_threads" in changed:
            self.sim.solver_threads = changed["solver_threads"]
        if "max_bodies" in changed:
            self.requests.max_bodies = changed["max_bodies"]
        if "scene_directories" in changed:
            self.requests.scene_directories = [Path(d) for d in changed["scene_directories"]]
        # Start-up values a ROS override (--ros-args -p) may give after the command line's: they
        # come before the simulation starts (SimulatorNode.attach), and take effect like them.
        if "start_paused" in changed:
            self.sim.paused = changed["start_paused"]
        if "duration" in changed:
            self.sim.duration = changed["duration"] or None  # 0: until stopped
        if changed.keys() & FRAMES:
            self.broadcaster.frames = frames(self.parameters)


def take_settings(world, settings):
    """world.update_settings for the settings that differ from the world's: a newly loaded
    scene's own settings, handed on to the parameters, come back here unchanged and must not
    wake every body of the new world."""
    current = world.settings
    freezing = settings.get("freezing", {})
    if (any(current[key] != value for key, value in settings.items() if key != "freezing")
            or any(current["freezing"][key] != value for key, value in freezing.items())):
        world.update_settings(settings)
