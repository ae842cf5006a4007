"""The simulation-state services: ~/pause, ~/step, ~/reset, ~/set_freezing, ~/wake_all,
~/get_simulator_features, and the states of simulation_interfaces SetSimulationState.

States (simulation.py): PLAYING and PAUSED; STOPPED is paused at the loaded scene's start (a
SetSimulationState STOPPED resets everything, LoadWorld leaves the new world there); playing or
pausing leaves it (SimulationState.msg: a stopped simulation "can also be paused", so a scenario
loads a world, pauses and steps). NO_WORLD after UnloadWorld: nothing plays, steps, spawns or resets until a
scene is loaded. QUITTING ends the run a moment after the reply.
"""
import copy
import threading

import yaml

from ..parameters import SCOPE_ALL, SCOPE_SPAWNED, SCOPE_STATE, SCOPE_TIME, reset_scope
from ..physics import specs
from ..scene import build_world
from ..sensors import WORLD
from ..simulation import PAUSED, PLAYING, QUITTING, STATE_NAMES, STOPPED
from ..urdf_robots import add_robot_entry
from .entities import drop_sensors_of
from .results import (ALREADY, FAILED, INCORRECT_STATE, INCORRECT_TRANSITION, OK, RequestError, handled,
                      reply)

# Reset scopes (simulation_interfaces ResetSimulation): SCOPE_*, and the rule reset_scope()
# that the `reset_scope` parameter is checked by too, live in ../parameters.py.
# The features this simulator honours, as ~/get_simulator_features lists them: names and
# numbers as simulation_interfaces msg/SimulatorFeatures.msg has them (the tests check them
# against interfaces/simulation_interfaces/), each with the services that honour it.
SIMULATOR_FEATURES = {
    "SPAWNING": 0,                   # ~/spawn, spawn_entity
    "DELETING": 1,                   # ~/remove, delete_entity
    "ENTITY_BOUNDS": 5,              # get_entity_bounds: the box in the entity's frame
    "ENTITY_BOUNDS_BOX": 6,          # filters.bounds TYPE_BOX (and TYPE_SPHERE, which every simulator has)
    "ENTITY_CATEGORIES": 8,          # filters.categories, get_entity_info: robot, static object, object
    "SPAWNING_RESOURCE_STRING": 9,   # spawn_entity resource_string: this package's YAML entity spec
    "ENTITY_STATE_GETTING": 10,      # ~/get_entity, get_entity_state, get_entities_states
    "ENTITY_STATE_SETTING": 11,      # ~/edit, set_entity_state: pose and twist
    "ENTITY_INFO_GETTING": 12,       # get_entity_info
    "SIMULATION_RESET": 20,          # ~/reset, reset_simulation
    "SIMULATION_RESET_TIME": 21,     # scope 1
    "SIMULATION_RESET_STATE": 22,    # scope 2
    "SIMULATION_RESET_SPAWNED": 23,  # scope 4
    "SIMULATION_STATE_GETTING": 24,  # ~/state, get_simulation_state
    "SIMULATION_STATE_SETTING": 25,  # ~/pause false, set_simulation_state
    "SIMULATION_STATE_PAUSE": 26,    # ~/pause true, set_simulation_state PAUSED
    "STEP_SIMULATION_SINGLE": 31,    # ~/step with step_count 1, step_simulation
    "STEP_SIMULATION_MULTIPLE": 32,  # ~/step with step_count n, step_simulation, simulate_steps
    "STEP_SIMULATION_ACTION": 33,    # the simulate_steps action (ROS only: Foxglove has no actions)
    "WORLD_LOADING": 40,             # ~/load_scene, load_world
    "WORLD_RESOURCE_STRING": 41,     # load_world resource_string: a scene as YAML text
    "WORLD_UNLOADING": 43,           # unload_world
    "WORLD_INFO_GETTING": 44,        # get_current_world
    "AVAILABLE_WORLDS": 45,          # get_available_worlds: the scene files of scene_directories
    "SPAWNING_ENTITIES": 50,         # ~/spawn with a list, spawn_entities
}
SPAWN_FORMATS = ["yaml", "urdf"]  # this package's entity spec (README, "Scene files"), and robot descriptions
QUIT_DELAY = 0.5  # s from SetSimulationState QUITTING's reply to the end of the run
MAX_STEPS = 1_000_000  # steps one ~/step may queue (~2 h of simulated time at 128 Hz)


class ControlRequests:
    """Requests' simulation-state handlers (see requests.py for the state they share)."""

    actions_served = False  # a ROS node serves the SimulateSteps action (node.py sets it)

    @handled
    def pause(self, paused):
        paused = specs.boolean(paused, "pause.data")
        return self.sim.call(lambda world: self._pause(paused))

    def _pause(self, paused):
        self._check_world("playing or pausing")
        if self.sim.paused == paused and not (paused and self.sim.stopped):
            return reply(ALREADY, "already paused" if paused else "already playing")
        self.sim.paused, self.sim.stopped = paused, False
        return reply(OK, "paused" if paused else "playing")

    def _check_world(self, what):
        if not self.sim.world_loaded:
            raise RequestError(INCORRECT_STATE, f"{what} needs a world: none is loaded since unload_world "
                                                "(load_world or ~/load_scene loads one)")

    @handled
    def set_simulation_state(self, target):
        """simulation_interfaces SetSimulationState: PLAYING, PAUSED, STOPPED (paused at the
        loaded scene's start: everything reset) or QUITTING (the run ends just after the
        reply). NO_WORLD and LOADING_WORLD are reached through unload_world and load_world."""
        target = specs.integer(target, "state.state", 0, 255)
        names = {state: STATE_NAMES[state] for state in (STOPPED, PLAYING, PAUSED, QUITTING)}  # the settable ones
        if target == self.sim.state and target not in names:  # NO_WORLD asked for in NO_WORLD, say
            return reply(ALREADY, f"already in state {target}")
        if target not in names:
            raise RequestError(INCORRECT_TRANSITION, f"state.state: {target} cannot be set (0 STOPPED, 1 PLAYING, "
                                                     "2 PAUSED, 3 QUITTING; unload_world and load_world reach 4 and 5)")
        if target == QUITTING:  # paused now, and the run ends (as Ctrl-C ends it) once the reply is out
            if self.sim.quitting:
                return reply(ALREADY, "already quitting")
            self.sim.call(lambda world: setattr(self.sim, "paused", True))
            self.sim.quitting = True
            threading.Timer(QUIT_DELAY, self.sim.stop).start()
            return reply(OK, f"quitting in {QUIT_DELAY:g} s")
        ok, message = self.sim.call(lambda world: self._set_state(target, names[target]))
        if ok and target == STOPPED:
            self._follow_scene_settings()
        return ok, message

    def _set_state(self, target, name):
        if not self.sim.world_loaded:
            return reply(INCORRECT_TRANSITION, f"no world is loaded: nothing can be {name} (load_world first)")
        if self.sim.state == target:
            return reply(ALREADY, f"already {name}")
        if target == STOPPED:
            self._reset(self.sim.world, SCOPE_ALL)
        self.sim.paused, self.sim.stopped = target != PLAYING, target == STOPPED
        return reply(OK, name)

    @handled
    def step(self, count):
        return self.step_to(count)[0]

    def step_to(self, count):
        """~/step, and where its steps end: (reply, the world, its step_count once they have
        run), the last two None when refused. Steps queue in order behind those asked before."""
        queued = {}

        def queue():
            steps = specs.integer(count, "step.steps", 1, MAX_STEPS)
            answer, queued["world"], queued["target"] = self.sim.call(lambda world: self._step(world, steps))
            return answer
        return handled(queue)(), queued.get("world"), queued.get("target")

    def _step(self, world, count):
        self._check_world("stepping")
        if self.sim.state != PAUSED:
            return reply(INCORRECT_STATE, "stepping needs the simulation paused (~/pause true)"), None, None
        if self.sim.pending_steps + count > MAX_STEPS:
            return (reply(FAILED, f"{self.sim.pending_steps} steps are still queued; at most {MAX_STEPS} may be"),
                    None, None)
        self.sim.request_steps(count)
        return reply(OK, f"stepping {count}"), world, world.step_count + self.sim.pending_steps

    @handled
    def reset(self, scope):
        scope = reset_scope(scope, "reset.scope")
        ok, message = self.sim.call(lambda world: self._reset(world, scope))
        if ok and scope == SCOPE_ALL:
            self._follow_scene_settings()
        return ok, message

    def _reset(self, world, scope):
        self._check_world("a reset")
        if scope == SCOPE_ALL:
            self.sim.world = build_world(self.initial_recipe)  # as loaded, bit for bit
            self.sim.clear_steps()  # none queued for the old world run on the new one
            return reply(OK, "reset everything to the loaded scene")
        initial = {b["name"]: b for b in self.initial["bodies"]}
        initial.update({v["name"]: v for v in self.initial["vehicles"]})
        # The scene's URDF robots: their links are the scene's too; the state restores them whole.
        robots = {robot["name"]: robot for robot in self.initial_robots}
        links = {body for robot in world.robot_specs if robot["name"] in robots for body in robot["bodies"]}
        done = []
        if scope & SCOPE_SPAWNED:
            spawned = [name for name in world.body_names() if name not in initial and name not in links]
            world.remove_bodies(spawned)
            drop_sensors_of(world, spawned)
            loaded = {s["name"] for s in self.initial.get("sensors", [])}
            if any(s["name"] not in loaded for s in world.sensor_specs):
                world.sensor_specs = [s for s in world.sensor_specs if s["name"] in loaded]
            done.append("spawned removed")
        if scope & SCOPE_STATE:
            present, vehicles = set(world.body_names()), set(world.vehicle_names())
            for name, spec in initial.items():
                if name not in present:
                    (world.add_vehicle if "wheels" in spec else world.add_body)(copy.deepcopy(spec))
                    continue
                # Frozen as the scene has it: woken by the edit, a body frozen in mid-air fell.
                frozen = (spec["chassis"] if "wheels" in spec else spec)["frozen"]
                world.edit_body(name, position=spec["position"], quaternion=spec["quaternion"],
                                linear_velocity=spec["linear_velocity"],
                                angular_velocity=spec["angular_velocity"], frozen=frozen)
                if "wheels" in spec and name in vehicles:
                    # Its controller too, as a car the scene adds has it: the steering had stayed
                    # turned and the speed loop kept its memory of the drive, so the car set off again.
                    world.restart_vehicle(name)
            present = set(world.body_names())
            for robot in robots.values():  # as loaded: its links where they stood, its joints, its motors
                world.remove_bodies([body for body in robot["bodies"] if body in present])
                add_robot_entry(world, robot, robot["model"], f"robots.{robot['name']}", self.frames())
            # The scene's joints that went with a body removed since (or a robot's link) come
            # back with it, as the scene made them: the body had come back loose.
            joints = set(world.joint_names())
            for spec in self.initial.get("joints", []):
                if spec["name"] not in joints:
                    world.add_joint(copy.deepcopy(spec))
            # The sensors start again on the bodies as restored (the robots' are new bodies), and
            # the scene's sensors removed since come back on them (the bodies did: the sensors
            # had stayed gone), unless a body spawned since has taken a removed one's name.
            names, kept = set(world.body_names()), {spec["name"] for spec in world.sensor_specs}
            back = [copy.deepcopy(spec) for spec in self.initial.get("sensors", [])
                    if spec["name"] not in kept | names and spec["parent"] in names | {WORLD}]
            world.sensor_specs = [dict(spec) for spec in world.sensor_specs] + back
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

    def honoured_features(self):
        """The SIMULATOR_FEATURES numbers honoured here: the SimulateSteps action's only where
        a ROS node serves it (`actions_served`, set by the node; Foxglove has no actions)."""
        return sorted(number for name, number in SIMULATOR_FEATURES.items()
                      if name != "STEP_SIMULATION_ACTION" or self.actions_served)

    def features(self):
        return True, yaml.safe_dump({"features": self.honoured_features(), "spawn_formats": SPAWN_FORMATS},
                                    default_flow_style=True).strip()
