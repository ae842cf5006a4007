"""The simulator without a transport: the Simulation and everything around it that the ROS node
and the Foxglove server share (requests, parameters, what is published, what is subscribed,
the services). ROS-free: `vplayground --no-ros --foxglove` runs on this alone.
"""
import threading
from pathlib import Path

from .api import Requests
from .broadcast import BagSink, Broadcaster, resolve
from .inputs import Inputs
from .parameters import PHYSICS, Parameters, parameter_table, settings_from
from .services import service_table


class Runtime:
    def __init__(self, sim, options, log, recorder=None, resolve_name=resolve):
        self.sim = sim
        self.options = options
        self.log = log
        self.recorder = recorder
        self.resolve_name = resolve_name
        self.requests = Requests(sim, str(options.scene),
                                 bag_directory=recorder.path.parent if recorder is not None else None)
        self.parameters = Parameters(parameter_table(sim.world, options, self.requests), lambda: sim.world.settings)
        self.parameters.listen(self._apply)
        self.set_parameters = self.parameters.set  # the ROS node routes sets through rclpy
        self.broadcaster = Broadcaster(sim, self.parameters, log, resolve_name)
        if recorder is not None:
            self.broadcaster.add_sink(BagSink(recorder))
        self.inputs = Inputs(sim, self.requests, self.parameters, log, self.broadcaster.car)
        self.services = service_table(self)
        self.sim.real_time_factor = self.parameters["real_time_factor"]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._publish, name="vplayground-publisher", daemon=True)

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

    def sync_parameters(self):
        """After a service changed the world's settings (a scene load, a reset, ~/set_freezing):
        the physics parameters take the world's values, so `ros2 param get` and Foxglove's
        Parameters panel tell the truth."""
        current = parameter_table(self.sim.world, self.options, self.requests)
        changed = {p.name: p.default for p in current if p.name in PHYSICS and p.default != self.parameters[p.name]}
        if changed:
            ok, reason = self.set_parameters(changed)
            if not ok:
                self.log.warning(f"parameters not updated from the world: {reason}")

    def _apply(self, changed):
        """A validated parameter change, acting on the running simulation."""
        physics = settings_from({n: v for n, v in changed.items() if n in PHYSICS})
        if physics:
            self.sim.call(lambda world: world.update_settings(physics))
        if "real_time_factor" in changed:
            self.sim.real_time_factor = changed["real_time_factor"]
        if "max_bodies" in changed:
            self.requests.max_bodies = changed["max_bodies"]
        if "scene_directories" in changed:
            self.requests.scene_directories = [Path(d) for d in changed["scene_directories"]]
