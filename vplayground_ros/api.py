"""The simulator's requests (SPEC 6.3), ROS-free: one code path for the ROS services and the
Foxglove server. Payloads are YAML or JSON text in the simulation_interfaces field names;
replies start with an SI result code (`RESULT_OK:`, `NAME_NOT_UNIQUE:`, ...).

Every handler validates the whole request before it changes anything, and runs on the
simulation thread (through Simulation.call), between batches.
"""
import copy
import re
from pathlib import Path

import numpy as np
import yaml

from .physics import specs
from .scene import SceneError, load_world, save_world, world_to_scene
from .simulation import PAUSED

OK = "RESULT_OK"
NOT_FOUND = "RESULT_NOT_FOUND"
INCORRECT_STATE = "RESULT_INCORRECT_STATE"
FAILED = "RESULT_OPERATION_FAILED"
NAME_NOT_UNIQUE = "NAME_NOT_UNIQUE"
NAME_INVALID = "NAME_INVALID"
INVALID_POSE = "INVALID_POSE"
ALREADY = "ALREADY_IN_TARGET_STATE"

# nav_msgs/srv/LoadMap result codes.
MAP_SUCCESS, MAP_DOES_NOT_EXIST, INVALID_MAP_DATA, UNDEFINED_FAILURE = 0, 1, 2, 255
# Reset scopes (simulation_interfaces ResetSimulation).
SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 1, 2, 4, 255
# simulation_interfaces SimulatorFeatures numbers this simulator honours.
FEATURES = {"SPAWNING": 0, "DELETING": 1, "NAMED_POSES": None, "ENTITY_STATE_GETTING": 9,
            "ENTITY_STATE_SETTING": 10, "SIMULATION_RESET": 20, "SIMULATION_RESET_TIME": 21,
            "SIMULATION_RESET_STATE": 22, "SIMULATION_RESET_SPAWNED": 23,
            "SIMULATION_STATE_GETTING": 24, "SIMULATION_STATE_SETTING": 25,
            "SIMULATION_STATE_PAUSE": 26, "STEP_SIMULATION_SINGLE": 31,
            "STEP_SIMULATION_MULTIPLE": 32}
MAX_PAYLOAD = 1 << 20  # bytes of YAML a request may carry


class RequestError(Exception):
    def __init__(self, code, message):
        super().__init__(f"{code}: {message}")
        self.code = code


def reply(code, message):
    return code == OK, f"{code}: {message}"


def parse(text, what="request"):
    if not isinstance(text, str):
        raise RequestError(FAILED, f"{what} must be YAML or JSON text")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_PAYLOAD:
        raise RequestError(FAILED, f"{what} is larger than {MAX_PAYLOAD} bytes")
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise RequestError(FAILED, f"{what} is not valid YAML/JSON: {error}") from None
    except RecursionError:
        raise RequestError(FAILED, f"{what} is nested too deeply") from None


def as_mapping(value, what):
    if not isinstance(value, dict):
        raise RequestError(FAILED, f"{what} must be a mapping, got {type(value).__name__}")
    return value


def xyz(value, path, length=3):
    """[x, y, z] or {x:, y:, z:} (the geometry_msgs spelling) as a list."""
    if isinstance(value, dict):
        keys = "xyzw"[:length]
        specs.mapping(value, path, set(keys))
        value = [value.get(k, 1.0 if k == "w" else 0.0) for k in keys]
    return specs.vector(value, path, length, -specs.MAX_COORDINATE, specs.MAX_COORDINATE)


def handled(fn):
    """Turns RequestError / validation errors into coded replies."""
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except RequestError as error:
            return False, str(error)
        except specs.SpecError as error:
            code = NAME_INVALID if error.path.endswith("name") and "invalid name" in error.problem else FAILED
            return False, f"{code}: {error}"
        except KeyError as error:
            return False, f"{NOT_FOUND}: {error.args[0]}"
        except ValueError as error:
            return False, f"{FAILED}: {error}"
    wrapper.__name__ = fn.__name__
    wrapper.__doc__ = fn.__doc__
    return wrapper


class Requests:
    """The SPEC 6.3 handlers, bound to a Simulation. Each public method runs on the caller's
    thread and hands the work to the simulation thread."""

    def __init__(self, simulation, scene_label=""):
        self.sim = simulation
        self.scene_label = scene_label
        self.initial = copy.deepcopy(world_to_scene(simulation.world))

    # ------------------------------------------------------------------ entities
    def spawn(self, text):
        return self.sim.call(lambda world: self._spawn(world, text))

    @handled
    def _spawn(self, world, text):
        request = parse(text)
        items = request if isinstance(request, list) else [request]
        if not items:
            raise RequestError(FAILED, "nothing to spawn")
        prepared, names = [], set(world.body_names())
        for k, raw in enumerate(items):
            path = f"[{k}]" if isinstance(request, list) else "spawn"
            item = dict(as_mapping(raw, path))
            rename = specs.boolean(item.pop("allow_renaming", False), f"{path}.allow_renaming")
            if "initial_pose" in item:
                pose = as_mapping(item.pop("initial_pose"), f"{path}.initial_pose")
                if "position" in pose:
                    item["position"] = xyz(pose["position"], f"{path}.initial_pose.position")
                if "orientation" in pose:
                    item["quaternion"] = specs.quaternion(xyz(pose["orientation"], f"{path}.initial_pose.orientation", 4),
                                                          f"{path}.initial_pose.orientation")
            vehicle = "wheels" in item or "chassis" in item
            spec = specs.validate_vehicle(item, path) if vehicle else specs.validate_body(item, path)
            name = spec.get("name")
            if name is not None and name in names:
                if not rename:
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {name!r} is taken "
                                                        "(allow_renaming: true picks a free name)")
                spec["name"] = name = unique_name(name, names)
            if name is not None:
                names.add(name)
            prepared.append((vehicle, spec))
        added = []
        try:
            for vehicle, spec in prepared:
                added.append(world.add_vehicle(spec) if vehicle else world.add_body(spec))
        except Exception:
            for name in added:  # all or nothing
                world.remove_body(name)
            raise
        return reply(OK, ", ".join(added))

    def edit(self, text):
        return self.sim.call(lambda world: self._edit(world, text))

    @handled
    def _edit(self, world, text):
        request = dict(as_mapping(parse(text), "edit"))
        name = request.pop("entity", None)
        if not isinstance(name, str):
            raise RequestError(FAILED, "edit.entity: the name of the entity to edit is missing")
        if name not in world.body_names():
            raise RequestError(NOT_FOUND, f"no entity named {name!r}")
        state = as_mapping(request.pop("state", {}) or {}, "edit.state")
        specs.mapping(state, "edit.state", {"pose", "twist", "header", "acceleration"})
        set_pose = specs.boolean(request.pop("set_pose", "pose" in state), "edit.set_pose")
        set_twist = specs.boolean(request.pop("set_twist", "twist" in state), "edit.set_twist")
        vehicle_edit = request.pop("vehicle", None)
        fields = dict(request)
        if set_pose:
            pose = as_mapping(state.get("pose", {}), "edit.state.pose")
            specs.mapping(pose, "edit.state.pose", {"position", "orientation"})
            try:
                if "position" in pose:
                    fields["position"] = xyz(pose["position"], "edit.state.pose.position")
                if "orientation" in pose:
                    fields["quaternion"] = specs.quaternion(
                        xyz(pose["orientation"], "edit.state.pose.orientation", 4), "edit.state.pose.orientation")
            except specs.SpecError as error:
                raise RequestError(INVALID_POSE, str(error)) from None
        if set_twist:
            twist = as_mapping(state.get("twist", {}), "edit.state.twist")
            specs.mapping(twist, "edit.state.twist", {"linear", "angular"})
            if "linear" in twist:
                fields["linear_velocity"] = xyz(twist["linear"], "edit.state.twist.linear")
            if "angular" in twist:
                fields["angular_velocity"] = xyz(twist["angular"], "edit.state.twist.angular")
        # Validate everything before changing anything.
        specs.validate_body_fields(fields, name, specs.BODY_KEYS - {"name", "shape"})
        if vehicle_edit is not None:
            if name not in world.vehicle_names():
                raise RequestError(FAILED, f"{name}.vehicle: {name!r} is not a vehicle")
            specs.validate_vehicle_edit(as_mapping(vehicle_edit, f"{name}.vehicle"), f"{name}.vehicle")
        if fields:
            world.edit_body(name, **fields)
        if vehicle_edit:
            world.edit_vehicle(name, **vehicle_edit)
        return reply(OK, f"edited {name}: {', '.join(sorted(fields) + (['vehicle'] if vehicle_edit else []))}")

    def remove(self, text):
        return self.sim.call(lambda world: self._remove(world, text))

    @handled
    def _remove(self, world, text):
        request = as_mapping(parse(text), "remove")
        specs.mapping(request, "remove", {"entity", "filter", "all"})
        if len(request) != 1:
            raise RequestError(FAILED, "remove takes exactly one of entity, filter, all")
        names = world.body_names()
        if "entity" in request:
            if request["entity"] not in names:
                raise RequestError(NOT_FOUND, f"no entity named {request['entity']!r:.80}")
            doomed = [request["entity"]]
        elif "filter" in request:
            try:
                pattern = re.compile(str(request["filter"]))
            except re.error as error:
                raise RequestError(FAILED, f"remove.filter: not a valid regular expression: {error}") from None
            doomed = [n for n in names if pattern.search(n)]
            if not doomed:
                raise RequestError(NOT_FOUND, f"no entity matches {request['filter']!r:.80}")
        else:
            if request["all"] is not True:
                raise RequestError(FAILED, "remove.all: must be true")
            doomed = names
        for name in doomed:
            world.remove_body(name)
        return reply(OK, ", ".join(doomed))

    def get_entity(self, text):
        return self.sim.call(lambda world: self._get_entity(world, text))

    @handled
    def _get_entity(self, world, text):
        request = as_mapping(parse(text), "get_entity")
        specs.mapping(request, "get_entity", {"entity"})
        name = request.get("entity")
        if name not in world.body_names():
            raise RequestError(NOT_FOUND, f"no entity named {name!r:.80}")
        return True, yaml.safe_dump(describe(world, name), sort_keys=False)

    def entities(self):
        """[(name, description dict)] of every entity, in the order of ~/bodies/poses."""
        return self.sim.call(lambda world: [(name, describe(world, name)) for name in world.body_names()])

    # --------------------------------------------------------------- simulation state
    def pause(self, paused):
        return self.sim.call(lambda world: self._pause(paused))

    def _pause(self, paused):
        if self.sim.paused == paused:
            return reply(ALREADY, "already paused" if paused else "already playing")
        self.sim.paused = paused
        return reply(OK, "paused" if paused else "playing")

    def step(self, count):
        return self.sim.call(lambda world: self._step(count))

    def _step(self, count):
        if self.sim.state != PAUSED:
            return reply(INCORRECT_STATE, "stepping needs the simulation paused (~/pause true)")
        self.sim.request_steps(count)
        return reply(OK, f"stepping {count}")

    def reset(self, scope):
        return self.sim.call(lambda world: self._reset(world, scope))

    @handled
    def _reset(self, world, scope):
        if scope != SCOPE_ALL and (scope <= 0 or scope & ~(SCOPE_TIME | SCOPE_STATE | SCOPE_SPAWNED)):
            raise RequestError(FAILED, f"reset scope {scope} is not a combination of 1 TIME, 2 STATE, 4 SPAWNED")
        if scope == SCOPE_ALL:
            self.sim.world = load_world(copy.deepcopy(self.initial))
            return reply(OK, "reset everything to the loaded scene")
        initial = {b["name"]: b for b in self.initial["bodies"]}
        initial.update({v["name"]: v for v in self.initial["vehicles"]})
        done = []
        if scope & SCOPE_SPAWNED:
            for name in world.body_names():
                if name not in initial:
                    world.remove_body(name)
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

    def set_freezing(self, enabled):
        return self.sim.call(lambda world: self._set_freezing(world, enabled))

    def _set_freezing(self, world, enabled):
        if world.settings["freezing"]["enabled"] == enabled:
            return reply(ALREADY, f"freezing already {'on' if enabled else 'off'}")
        world.update_settings({"freezing": {"enabled": enabled}})
        return reply(OK, f"freezing {'on' if enabled else 'off'}")

    def wake_all(self):
        return self.sim.call(lambda world: (world.wake_all(), reply(OK, "every body awake"))[1])

    def features(self):
        honoured = sorted(v for v in FEATURES.values() if v is not None)
        return True, yaml.safe_dump({"features": honoured, "spawn_formats": ["vplayground_yaml"]},
                                    default_flow_style=True).strip()

    # ------------------------------------------------------------------ scene files
    def load_scene(self, path):
        """(LoadMap result code, message). The old world stays on any failure."""
        if not isinstance(path, str) or not path or not Path(path).is_file():
            return MAP_DOES_NOT_EXIST, f"{NOT_FOUND}: no scene file at {path!r:.200}"
        try:
            world = load_world(path)
        except SceneError as error:
            return INVALID_MAP_DATA, f"{FAILED}: {error}"
        except Exception as error:  # an unexpected failure must not take the node down
            return UNDEFINED_FAILURE, f"{FAILED}: {type(error).__name__}: {error}"

        def install(_):
            self.sim.world = world
            self.initial = copy.deepcopy(world_to_scene(world))
            self.scene_label = path
        self.sim.call(install)
        return MAP_SUCCESS, f"{OK}: loaded {path} ({len(world.body_names())} bodies)"

    def save_scene(self, text):
        return self.sim.call(lambda world: self._save_scene(world, text))

    @handled
    def _save_scene(self, world, text):
        request = parse(text) if text.strip().startswith("{") else {"path": text.strip()}
        request = as_mapping(request, "save_scene")
        specs.mapping(request, "save_scene", {"path", "overwrite"})
        path = request.get("path")
        if not isinstance(path, str) or not path:
            raise RequestError(FAILED, "save_scene: the output path is missing")
        overwrite = specs.boolean(request.get("overwrite", False), "save_scene.overwrite")
        target = Path(path)
        if target.exists() and not overwrite:
            raise RequestError(FAILED, f"{path} exists (pass {{path: ..., overwrite: true}} to replace it)")
        try:
            save_world(world, target)
        except OSError as error:
            raise RequestError(FAILED, f"cannot write {path}: {error.strerror}") from None
        return reply(OK, str(target))


def unique_name(name, taken):
    k = 2
    while f"{name}_{k}" in taken:
        k += 1
    return f"{name}_{k}"


def describe(world, name):
    """An entity as plain data: category, pose and twist in `world`, properties, bounds."""
    is_vehicle = name in world.vehicle_names()
    props = world.vehicle(name) if is_vehicle else world.body(name)
    body = world.body(name)
    size = np.asarray(body["size"])
    return {
        "name": name,
        "category": "vehicle" if is_vehicle else ("immovable" if body["immovable"] else "box"),
        "frame": "world",
        "pose": {"position": body["position"], "orientation": body["quaternion"]},
        "twist": {"linear": body["linear_velocity"], "angular": body["angular_velocity"]},
        "mass": body["mass"],
        "frozen": body["frozen"],
        "properties": props,
        "bounds": {"size": size.tolist()},
    }
