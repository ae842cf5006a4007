"""The simulation-state services: ~/pause, ~/step, ~/reset, ~/set_freezing, ~/wake_all,
~/get_simulator_features.
"""
import copy

import yaml

from ..parameters import SCOPE_ALL, SCOPE_SPAWNED, SCOPE_STATE, SCOPE_TIME, reset_scope
from ..physics import specs
from ..scene import load_world
from ..simulation import PAUSED
from .entities import drop_sensors_of
from .results import ALREADY, FAILED, INCORRECT_STATE, OK, handled, reply

# Reset scopes (simulation_interfaces ResetSimulation): SCOPE_*, and the rule reset_scope()
# that the `reset_scope` parameter is checked by too, live in ../parameters.py.
# The features this simulator honours, as ~/get_simulator_features lists them: names and
# numbers copied from simulation_interfaces 2.1.0 msg/SimulatorFeatures.msg (the tests check
# them against the copy in test/simulation_interfaces-2.1.0/), each with what honours it.
SIMULATOR_FEATURES = {
    "SPAWNING": 0,                   # ~/spawn
    "DELETING": 1,                   # ~/remove
    "ENTITY_STATE_GETTING": 10,      # ~/get_entity: pose and twist
    "ENTITY_STATE_SETTING": 11,      # ~/edit: state.pose, state.twist
    "SIMULATION_RESET": 20,          # ~/reset
    "SIMULATION_RESET_TIME": 21,     # reset_scope 1
    "SIMULATION_RESET_STATE": 22,    # reset_scope 2
    "SIMULATION_RESET_SPAWNED": 23,  # reset_scope 4
    "SIMULATION_STATE_GETTING": 24,  # ~/state
    "SIMULATION_STATE_SETTING": 25,  # ~/pause false: playing
    "SIMULATION_STATE_PAUSE": 26,    # ~/pause true: paused
    "STEP_SIMULATION_SINGLE": 31,    # ~/step with step_count 1
    "STEP_SIMULATION_MULTIPLE": 32,  # ~/step with step_count n
}
MAX_STEPS = 1_000_000  # steps one ~/step may queue (~2 h of simulated time at 128 Hz)


class ControlRequests:
    """Requests' simulation-state handlers (see requests.py for the state they share)."""

    @handled
    def pause(self, paused):
        paused = specs.boolean(paused, "pause.data")
        return self.sim.call(lambda world: self._pause(paused))

    def _pause(self, paused):
        if self.sim.paused == paused:
            return reply(ALREADY, "already paused" if paused else "already playing")
        self.sim.paused = paused
        return reply(OK, "paused" if paused else "playing")

    @handled
    def step(self, count):
        count = specs.integer(count, "step.steps", 1, MAX_STEPS)
        return self.sim.call(lambda world: self._step(count))

    def _step(self, count):
        if self.sim.state != PAUSED:
            return reply(INCORRECT_STATE, "stepping needs the simulation paused (~/pause true)")
        if self.sim.pending_steps + count > MAX_STEPS:
            return reply(FAILED, f"{self.sim.pending_steps} steps are still queued; at most {MAX_STEPS} may be")
        self.sim.request_steps(count)
        return reply(OK, f"stepping {count}")

    @handled
    def reset(self, scope):
        scope = reset_scope(scope, "reset.scope")
        ok, message = self.sim.call(lambda world: self._reset(world, scope))
        if ok and scope == SCOPE_ALL:
            self._follow_scene_settings()
        return ok, message

    def _reset(self, world, scope):
        if scope == SCOPE_ALL:
            self.sim.world = load_world(copy.deepcopy(self.initial))
            return reply(OK, "reset everything to the loaded scene")
        initial = {b["name"]: b for b in self.initial["bodies"]}
        initial.update({v["name"]: v for v in self.initial["vehicles"]})
        done = []
        if scope & SCOPE_SPAWNED:
            spawned = [name for name in world.body_names() if name not in initial]
            world.remove_bodies(spawned)
            drop_sensors_of(world, spawned)
            loaded = {s["name"] for s in self.initial.get("sensors", [])}
            if any(s["name"] not in loaded for s in world.sensor_specs):
                world.sensor_specs = [s for s in world.sensor_specs if s["name"] in loaded]
            done.append("spawned removed")
        if scope & SCOPE_STATE:
            present = set(world.body_names())
            for name, spec in initial.items():
                if name not in present:
                    (world.add_vehicle if "wheels" in spec else world.add_body)(copy.deepcopy(spec))
                    continue
                world.edit_body(name, position=spec["position"], quaternion=spec["quaternion"],
                                linear_velocity=spec["linear_velocity"],
                                angular_velocity=spec["angular_velocity"])
            done.append("states restored")
        if scope & SCOPE_TIME:
            world.time, world.step_count = 0.0, 0
            done.append("time zeroed")
        return reply(OK, ", ".join(done))

    @handled
    def set_freezing(self, enabled):
        enabled = specs.boolean(enabled, "set_freezing.data")
        if self.settings["freezing.enabled"] == enabled:
            return reply(ALREADY, f"freezing already {'on' if enabled else 'off'}")
        ok, reason = self.settings.set({"freezing.enabled": enabled})
        return reply(OK, f"freezing {'on' if enabled else 'off'}") if ok else reply(FAILED, reason)

    @handled
    def wake_all(self):
        return self.sim.call(lambda world: (world.wake_all(), reply(OK, "every body awake"))[1])

    def features(self):
        return True, yaml.safe_dump({"features": sorted(SIMULATOR_FEATURES.values()),
                                     "spawn_formats": ["vplayground_yaml"]},
                                    default_flow_style=True).strip()
