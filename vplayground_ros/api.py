"""The simulator's requests (SPEC 6.3), ROS-free: one code path for the ROS services and the
Foxglove server. Payloads are YAML or JSON text in the simulation_interfaces field names;
replies start with an SI result code (`RESULT_OK:`, `NAME_NOT_UNIQUE:`, ...).

Anyone on the ROS domain can call these, so every handler:
- parses and validates the whole request on the caller's thread (a 1 MiB payload never holds
  up the physics), then changes the world in one command on the simulation thread, between
  batches, only after everything that can be checked has been;
- answers with a coded error naming the key path and the problem, and changes nothing, for
  any input: wrong types, non-finite or huge numbers, alias bombs, deep nesting;
- keeps within limits: MAX_PAYLOAD bytes of request, `max_bodies` bodies in the world, scene
  files only inside `scene_directories`, bounded regular-expression matching.
"""
import copy
import functools
import json
import logging
import os
import time
from pathlib import Path

import numpy as np
import regex
import yaml

from .physics import specs
from .physics.shapes import SHAPES, half_extents, solid
from .resources import find_shared
from .scene import YAML_LOADER, SceneError, load_world, world_to_scene
from .physics.math3d import rpy_to_quat
from .sensors import TYPES as SENSOR_TYPES, matrix_to_quaternion, pose_matrix, validate_sensor
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
SENSOR_SIZE = 0.1  # m: the cube ~/get_entities draws a sensor as
MAX_PAYLOAD = 1 << 20  # bytes of YAML a request may carry
DEFAULT_MAX_BODIES = 10_000  # bodies (vehicles included) the world may hold; ~real time at 128 Hz
MAX_STEPS = 1_000_000  # steps one ~/step may queue (~2 h of simulated time at 128 Hz)
MAX_PATH = 4096  # characters of a scene path (PATH_MAX)
MAX_FILTER = 1000  # characters of a ~/remove filter
# Wall time a ~/remove filter may spend matching names: a backtracking pattern such as (a+)+$
# would otherwise take longer than the age of the universe on a 64-character name.
FILTER_SECONDS = 0.5
SCENE_SUFFIXES = (".yaml", ".yml")  # ~/save_scene with overwrite never replaces anything else
YAML_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

log = logging.getLogger(__name__)


def sensor_named(world, name):
    """The spec of the world's sensor `name`, or None."""
    return next((s for s in world.sensor_specs if s["name"] == name), None)


def drop_sensors_of(world, removed):
    """The sensors whose parent was just removed go with it, with a warning."""
    removed = set(removed)
    orphans = [s["name"] for s in world.sensor_specs if s["parent"] in removed]
    if orphans:
        log.warning(f"sensors {', '.join(orphans)} removed with their parent")
        world.sensor_specs = [s for s in world.sensor_specs if s["parent"] not in removed]
    return orphans


class RequestError(Exception):
    def __init__(self, code, message):
        super().__init__(f"{code}: {message}")
        self.code = code


def reply(code, message):
    return code == OK, f"{code}: {message}"


def parse(text, what="request"):
    if not isinstance(text, str):
        raise RequestError(FAILED, f"{what} must be YAML or JSON text")
    if len(text) > MAX_PAYLOAD or len(text.encode("utf-8", "surrogatepass")) > MAX_PAYLOAD:
        raise RequestError(FAILED, f"{what} is larger than {MAX_PAYLOAD} bytes")
    try:
        if text.lstrip()[:1] in ("{", "["):
            try:
                return json.loads(text)  # JSON, what programs send: ~50x faster than YAML
            except json.JSONDecodeError:
                pass  # flow-style YAML such as {name: a}
        return yaml.load(text, Loader=YAML_LOADER)
    except yaml.YAMLError as error:
        raise RequestError(FAILED, f"{what} is not valid YAML/JSON: {str(error)[:300]}") from None
    except RecursionError:
        raise RequestError(FAILED, f"{what} is nested too deeply") from None
    except ValueError as error:  # integers of more than 4,300 digits, unencodable characters
        raise RequestError(FAILED, f"{what} is not valid YAML/JSON: {str(error)[:300]}") from None


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


def pose_fields(pose, path):
    """{position, orientation} (or a PoseStamped's {header, pose}) as body keys; INVALID_POSE
    naming the key when a value is bad."""
    try:
        specs.mapping(pose, path, {"position", "orientation", "header", "pose"})
        if "pose" in pose:
            path = f"{path}.pose"
            pose = specs.mapping(pose["pose"], path, {"position", "orientation"})
        fields = {}
        if "position" in pose:
            fields["position"] = xyz(pose["position"], f"{path}.position")
        if "orientation" in pose:
            fields["quaternion"] = specs.quaternion(xyz(pose["orientation"], f"{path}.orientation", 4),
                                                    f"{path}.orientation")
        return fields
    except specs.SpecError as error:
        raise RequestError(INVALID_POSE, str(error)) from None


def check_inside(world, position, path):
    try:
        world.check_inside(position, path)
    except specs.SpecError as error:
        raise RequestError(INVALID_POSE, str(error)) from None


def handled(fn):
    """Turns every failure into a coded reply: the callers are services, whose node must not
    fall over whatever it is sent."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except RequestError as error:
            return False, str(error)
        except specs.SpecError as error:
            code = NAME_INVALID if error.path.endswith("name") and "invalid name" in error.problem else FAILED
            return False, f"{code}: {error}"
        except KeyError as error:
            return False, f"{NOT_FOUND}: {error.args[0] if error.args else 'no such entity'}"
        except TimeoutError as error:
            return False, f"{FAILED}: {error}"
        except ValueError as error:
            return False, f"{FAILED}: {str(error)[:500]}"
        except Exception as error:  # a bug: answered and logged, never a dead service
            log.exception("%s failed", fn.__name__)
            return False, f"{FAILED}: internal error: {type(error).__name__}: {str(error)[:300]}"
    return wrapper


def default_scene_directories(bag_directory=None):
    """The package's config/, the current working directory, and the bag's directory."""
    config = find_shared("config/default_scene.yaml")
    directories = [config.parent] if config is not None else []
    directories.append(Path.cwd())
    if bag_directory is not None:
        directories.append(Path(bag_directory))
    return directories


class Requests:
    """The SPEC 6.3 handlers, bound to a Simulation. Each public method runs on the caller's
    thread and hands the work to the simulation thread.

    `scene_directories` (paths) and `max_bodies` are plain attributes: the parameter layer may
    replace them at any time, and each request reads them once."""

    def __init__(self, simulation, scene_label="", scene_directories=None, bag_directory=None,
                 max_bodies=DEFAULT_MAX_BODIES):
        self.sim = simulation
        self.scene_label = scene_label
        self.scene_directories = ([Path(d) for d in scene_directories] if scene_directories is not None
                                  else default_scene_directories(bag_directory))
        self.max_bodies = max_bodies
        self.initial = copy.deepcopy(world_to_scene(simulation.world))

    # ------------------------------------------------------------------ entities
    @handled
    def spawn(self, text):
        request = parse(text)
        items = request if isinstance(request, list) else [request]
        if not items:
            raise RequestError(FAILED, "nothing to spawn")
        cap = int(self.max_bodies)
        if len(items) > cap:  # before validating any of them: a million boxes fail at once
            raise RequestError(FAILED, f"spawn of {len(items)} entities: more than max_bodies ({cap})")
        prepared = [self._prepare_spawn(raw, f"[{k}]" if isinstance(request, list) else "spawn")
                    for k, raw in enumerate(items)]
        return self.sim.call(lambda world: self._spawn(world, prepared, cap))

    @staticmethod
    def _prepare_spawn(raw, path):
        """(path, is vehicle, validated spec, allow_renaming) of one spawn entry."""
        item = dict(as_mapping(raw, path))
        rename = specs.boolean(item.pop("allow_renaming", False), f"{path}.allow_renaming")
        if "initial_pose" in item:
            pose = as_mapping(item.pop("initial_pose"), f"{path}.initial_pose")
            item.update(pose_fields(pose, f"{path}.initial_pose"))
            if "quaternion" in item:
                item.pop("rpy", None)  # the pose's orientation wins over the spec's
        if item.get("type") in SENSOR_TYPES:  # its parent is checked against the world
            return path, "sensor", item, rename
        vehicle = "wheels" in item or "chassis" in item
        spec = specs.validate_vehicle(item, path) if vehicle else specs.validate_body(item, path)
        return path, vehicle, spec, rename

    def _spawn(self, world, prepared, cap):
        existing = world.body_names()
        if len(existing) + len(prepared) > cap:
            raise RequestError(FAILED, f"spawn of {len(prepared)} entities: the world has {len(existing)} "
                                       f"bodies and max_bodies is {cap}")
        names, suffixes = set(existing) | {s["name"] for s in world.sensor_specs}, {}
        parents = set(existing) | {spec.get("name") for _, kind, spec, _ in prepared if kind != "sensor"}
        sensors = []
        for path, vehicle, spec, rename in prepared:
            if vehicle == "sensor":
                sensor = validate_sensor(spec, path, parents)
                if sensor["name"] in names or sensor["name"] == "world":
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {sensor['name']!r} is taken "
                                                        "(sensor names are frames, unique among entities)")
                names.add(sensor["name"])
                sensors.append(sensor)
                continue
            name = spec.get("name")
            if name is not None and name in names:
                if not rename:
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {name!r} is taken "
                                                        "(allow_renaming: true picks a free name)")
                spec["name"] = name = unique_name(name, names, suffixes)
            if name is not None:
                names.add(name)
            check_inside(world, spec["position"], f"{path}.position")
        added = []
        try:
            for _, vehicle, spec, _ in prepared:
                if vehicle != "sensor":
                    added.append(world.add_vehicle(spec) if vehicle else world.add_body(spec))
        except Exception:
            world.remove_bodies(added)  # all or nothing
            raise
        if sensors:  # a new list: whoever follows the sensors sees them change
            world.sensor_specs = [*world.sensor_specs, *sensors]
        return reply(OK, ", ".join(added + [s["name"] for s in sensors]))

    @handled
    def edit(self, text):
        request = dict(as_mapping(parse(text), "edit"))
        name = request.pop("entity", None)
        if not isinstance(name, str):
            raise RequestError(FAILED, "edit.entity: the name of the entity to edit is missing")
        label = name if specs.NAME_PATTERN.fullmatch(name) else specs.quote(name)  # for messages
        if self.sim.call(lambda world: sensor_named(world, name) is not None):
            return self.sim.call(lambda world: self._edit_sensor(world, name, request))
        state = as_mapping(request.pop("state", {}) or {}, "edit.state")
        specs.mapping(state, "edit.state", {"pose", "twist", "header", "acceleration"})
        set_pose = specs.boolean(request.pop("set_pose", "pose" in state), "edit.set_pose")
        set_twist = specs.boolean(request.pop("set_twist", "twist" in state), "edit.set_twist")
        vehicle_edit = request.pop("vehicle", None)
        fields = dict(request)
        if set_pose:
            fields.update(pose_fields(as_mapping(state.get("pose", {}), "edit.state.pose"), "edit.state.pose"))
        if set_twist:
            twist = as_mapping(state.get("twist", {}), "edit.state.twist")
            specs.mapping(twist, "edit.state.twist", {"linear", "angular"})
            if "linear" in twist:
                fields["linear_velocity"] = xyz(twist["linear"], "edit.state.twist.linear")
            if "angular" in twist:
                fields["angular_velocity"] = xyz(twist["angular"], "edit.state.twist.angular")
        # Validate everything before changing anything.
        fields = specs.validate_body_fields(fields, label, specs.BODY_KEYS - {"name", "shape"})
        if vehicle_edit is not None:
            specs.validate_vehicle_edit(as_mapping(vehicle_edit, f"{label}.vehicle"), f"{label}.vehicle")
        return self.sim.call(lambda world: self._edit(world, name, label, fields, vehicle_edit))

    @staticmethod
    def _edit(world, name, label, fields, vehicle_edit):
        if name not in world.body_names():
            raise RequestError(NOT_FOUND, f"no entity named {label}")
        if vehicle_edit is not None and name not in world.vehicle_names():
            raise RequestError(FAILED, f"{label}.vehicle: {specs.quote(name)} is not a vehicle")
        if "position" in fields:
            check_inside(world, fields["position"], f"{label}.position")
        if fields:
            world.edit_body(name, **fields)
        if vehicle_edit:
            world.edit_vehicle(name, **vehicle_edit)
        return reply(OK, f"edited {name}: {', '.join(sorted(fields) + (['vehicle'] if vehicle_edit else []))}")

    @staticmethod
    def _edit_sensor(world, name, fields):
        """A sensor's keys replaced and the whole spec validated again (its name and type stay)."""
        spec = sensor_named(world, name)
        if spec is None:
            raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
        for key in ("name", "type"):
            if key in fields and fields[key] != spec[key]:
                raise RequestError(FAILED, f"{name}.{key}: a sensor's {key} cannot be edited "
                                           "(remove it and spawn another)")
        parents = set(world.body_names())
        edited = validate_sensor({**spec, **fields}, name, parents)
        world.sensor_specs = [edited if s is spec else s for s in world.sensor_specs]
        return reply(OK, f"edited {name}: {', '.join(sorted(set(fields) - {'name', 'type'}))}")

    @handled
    def remove(self, text):
        request = as_mapping(parse(text), "remove")
        specs.mapping(request, "remove", {"entity", "filter", "all"})
        if len(request) != 1:
            raise RequestError(FAILED, "remove takes exactly one of entity, filter, all")
        if "entity" in request:
            name = request["entity"]
            if not isinstance(name, str):
                raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
            return self.sim.call(lambda world: self._remove(world, [name], strict=True))
        if "filter" in request:
            pattern = request["filter"]
            if not isinstance(pattern, str) or not pattern or len(pattern) > MAX_FILTER:
                raise RequestError(FAILED, f"remove.filter: expected a regular expression of 1-{MAX_FILTER} "
                                           f"characters, got {specs.quote(pattern)}")
            names = self.sim.call(lambda world: world.body_names() + [s["name"] for s in world.sensor_specs])
            doomed = match_names(pattern, names)  # here, not on the simulation thread
            if not doomed:
                raise RequestError(NOT_FOUND, f"no entity matches {specs.quote(pattern)}")
            return self.sim.call(lambda world: self._remove(world, doomed, strict=False))
        if request["all"] is not True:
            raise RequestError(FAILED, "remove.all: must be true")
        return self.sim.call(lambda world: self._remove(world, world.body_names(), strict=True))

    @staticmethod
    def _remove(world, doomed, strict):
        present = set(world.body_names())
        sensors = {s["name"] for s in world.sensor_specs} & set(doomed)
        if strict and doomed and doomed[0] not in present and doomed[0] not in sensors:
            raise RequestError(NOT_FOUND, f"no entity named {specs.quote(doomed[0])}")
        doomed = [name for name in doomed if name in present]  # a filter's may have gone meanwhile
        world.remove_bodies(doomed)
        if sensors:
            world.sensor_specs = [s for s in world.sensor_specs if s["name"] not in sensors]
        orphans = drop_sensors_of(world, doomed)
        return reply(OK, ", ".join(doomed + sorted(sensors) + orphans))

    @handled
    def get_entity(self, text):
        request = as_mapping(parse(text), "get_entity")
        specs.mapping(request, "get_entity", {"entity"})
        name = request.get("entity")
        if not isinstance(name, str):
            raise RequestError(FAILED, f"get_entity.entity: expected an entity name, got {specs.quote(name)}")

        def read(world):
            sensor = sensor_named(world, name)
            if sensor is not None and (sensor["parent"] == "world" or sensor["parent"] in world.body_names()):
                return describe_sensor(world, sensor)
            if name not in world.body_names():
                raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
            return describe(world, name)
        return True, yaml.dump(self.sim.call(read), Dumper=YAML_DUMPER, sort_keys=False)

    def entities(self):
        """[(name, description dict)] of every entity: the bodies in the order of
        ~/bodies/poses, then the sensors."""
        def read(world):
            vehicles = set(world.vehicle_names())  # once, not per entity: 10,000 bodies stay linear
            names = world.body_names()
            present = set(names)
            # A sensor whose parent left the world goes at its next sample: not listed meanwhile.
            return ([(name, describe(world, name, vehicles)) for name in names]
                    + [(s["name"], describe_sensor(world, s)) for s in world.sensor_specs
                       if s["parent"] == "world" or s["parent"] in present])
        return self.sim.call(read)

    # --------------------------------------------------------------- simulation state
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
        scope = specs.integer(scope, "reset.scope", 1, SCOPE_ALL)
        if scope != SCOPE_ALL and scope & ~(SCOPE_TIME | SCOPE_STATE | SCOPE_SPAWNED):
            raise RequestError(FAILED, f"reset scope {scope} is not a combination of 1 TIME, 2 STATE, 4 SPAWNED")
        return self.sim.call(lambda world: self._reset(world, scope))

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
        return self.sim.call(lambda world: self._set_freezing(world, enabled))

    @staticmethod
    def _set_freezing(world, enabled):
        if world.settings["freezing"]["enabled"] == enabled:
            return reply(ALREADY, f"freezing already {'on' if enabled else 'off'}")
        world.update_settings({"freezing": {"enabled": enabled}})
        return reply(OK, f"freezing {'on' if enabled else 'off'}")

    @handled
    def wake_all(self):
        return self.sim.call(lambda world: (world.wake_all(), reply(OK, "every body awake"))[1])

    def features(self):
        return True, yaml.safe_dump({"features": sorted(SIMULATOR_FEATURES.values()),
                                     "spawn_formats": ["vplayground_yaml"]},
                                    default_flow_style=True).strip()

    # ------------------------------------------------------------------ scene files
    def allowed_directories(self):
        """scene_directories resolved (symbolic links, `..`), the ones that exist."""
        roots = []
        for directory in list(self.scene_directories):
            try:
                root = Path(directory).resolve()
            except (OSError, ValueError, RuntimeError):
                continue
            if root.is_dir():
                roots.append(root)
        return roots

    def confine(self, raw, what):
        """The absolute, resolved path of a scene file named in a request, refused (FAILED)
        unless it lies inside one of scene_directories and ends in .yaml or .yml. Relative
        paths start from the current working directory, as on the command line."""
        if not isinstance(raw, str) or not raw:
            raise RequestError(FAILED, f"{what}: the path is missing")
        if len(raw) > MAX_PATH or "\0" in raw:
            raise RequestError(FAILED, f"{what}: {specs.quote(raw)} is not a usable path")
        try:
            resolved = (Path.cwd() / raw).resolve()
        except (OSError, ValueError, RuntimeError) as error:  # too long, unencodable, a link loop
            raise RequestError(FAILED, f"{what}: cannot resolve {specs.quote(raw)}: {error}") from None
        roots = self.allowed_directories()
        if not any(resolved.is_relative_to(root) for root in roots):
            raise RequestError(FAILED, f"{what}: {specs.quote(raw)} resolves to {specs.quote(str(resolved))}, "
                                       f"outside the scene directories ({', '.join(map(str, roots)) or 'none'}; "
                                       "the scene_directories parameter)")
        if resolved.suffix.lower() not in SCENE_SUFFIXES:
            raise RequestError(FAILED, f"{what}: {specs.quote(raw)}: scene files end in .yaml or .yml")
        return resolved

    def load_scene(self, path):
        """(LoadMap result code, message). The old world stays on any failure."""
        try:
            target = self.confine(path, "load_scene")
        except RequestError as error:
            return MAP_DOES_NOT_EXIST, str(error)
        if not target.is_file():
            return MAP_DOES_NOT_EXIST, f"{NOT_FOUND}: no scene file at {specs.quote(path)}"
        try:
            world = load_world(target, max_bodies=int(self.max_bodies), directories=self.allowed_directories())
            initial = copy.deepcopy(world_to_scene(world))
        except SceneError as error:
            return INVALID_MAP_DATA, f"{FAILED}: {str(error)[:1000]}"
        except Exception as error:  # an unexpected failure must not take the node down
            log.exception("load_scene %s", target)
            return UNDEFINED_FAILURE, f"{FAILED}: {type(error).__name__}: {str(error)[:300]}"

        def install(_):
            self.sim.world = world
            self.initial = initial
            self.scene_label = str(target)
        try:
            self.sim.call(install)
        except TimeoutError as error:
            return UNDEFINED_FAILURE, f"{FAILED}: {error}"
        return MAP_SUCCESS, f"{OK}: loaded {target} ({len(world.body_names())} bodies)"

    @handled
    def save_scene(self, text):
        if not isinstance(text, str):
            raise RequestError(FAILED, "save_scene: expected a path or {path: ..., overwrite: true}")
        request = parse(text) if text.strip().startswith("{") else {"path": text.strip()}
        request = as_mapping(request, "save_scene")
        specs.mapping(request, "save_scene", {"path", "overwrite"})
        overwrite = specs.boolean(request.get("overwrite", False), "save_scene.overwrite")
        target = self.confine(request.get("path"), "save_scene.path")
        if target.is_dir():
            raise RequestError(FAILED, f"save_scene.path: {target} is a directory")
        if (target.exists() or target.is_symlink()) and not overwrite:
            raise RequestError(FAILED, f"{target} exists (pass {{path: ..., overwrite: true}} to replace it)")

        def scene(world):
            data = world_to_scene(world)
            data["vehicles"] = copy.deepcopy(data["vehicles"])  # edits replace wheel entries in place
            return data
        body = yaml.dump(self.sim.call(scene), Dumper=YAML_DUMPER, sort_keys=False).encode("utf-8")
        try:
            write_file(target, body, overwrite)
        except OSError as error:
            raise RequestError(FAILED, f"cannot write {target}: {error.strerror or error}") from None
        return reply(OK, str(target))


def write_file(target, data, overwrite):
    """Writes `data` to `target`: without overwrite, only if nothing is there (O_EXCL, so not
    even a file or link made since the check is replaced); with it, through a temporary file
    renamed over the old one, so a full disk leaves the old file whole."""
    if not overwrite:
        try:
            with open(target, "xb") as stream:
                stream.write(data)
        except FileExistsError:
            raise
        except OSError:
            target.unlink(missing_ok=True)
            raise
        return
    temporary = target.with_name(f".{target.name}.{os.getpid()}.{time.monotonic_ns()}.tmp")
    try:
        with open(temporary, "xb") as stream:
            stream.write(data)
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)


def match_names(pattern, names, seconds=FILTER_SECONDS):
    """The names `pattern` (a POSIX ERE, Python syntax) finds, with the matching bounded in
    wall time; FAILED naming the problem for a bad or too slow pattern."""
    try:
        compiled = regex.compile(pattern)
    except (regex.error, ValueError, OverflowError, RecursionError) as error:
        raise RequestError(FAILED, f"remove.filter: not a valid regular expression: {error}") from None
    deadline = time.monotonic() + seconds
    matched = []
    try:
        for name in names:
            # concurrent: the GIL is released while matching, so the physics keeps stepping.
            if compiled.search(name, timeout=max(deadline - time.monotonic(), 1e-3), concurrent=True):
                matched.append(name)
    except TimeoutError:
        raise RequestError(FAILED, f"remove.filter: matching took longer than {seconds:g} s "
                                   "(nested repetition such as (a+)+ backtracks without end)") from None
    return matched


def unique_name(name, taken, suffixes):
    """name_2, name_3, ...: the first not taken. `suffixes` remembers where each name's search
    stopped, so renaming thousands of copies of one name stays linear."""
    k = suffixes.get(name, 2)
    while candidate(name, k) in taken:
        k += 1
    suffixes[name] = k + 1
    return candidate(name, k)


def candidate(name, k):
    """name_k, the name shortened so that it stays within the 64 characters a name may have."""
    suffix = f"_{k}"
    return name[:64 - len(suffix)] + suffix


def describe(world, name, vehicles=None):
    """An entity as plain data: category, pose and twist in `world`, properties, bounds.
    `vehicles`: the set of vehicle names, when describing many."""
    is_vehicle = name in (world.vehicle_names() if vehicles is None else vehicles)
    props = world.vehicle(name) if is_vehicle else world.body(name)
    body = world.body(name)
    size = 2.0 * np.asarray(half_extents(SHAPES[body["shape"]].code, solid(body["shape"], body).dimensions))
    return {
        "name": name,
        "category": "vehicle" if is_vehicle else ("immovable" if body["immovable"] else "box"),
        "frame": "world",
        "pose": {"position": body["position"], "orientation": body["quaternion"]},
        "twist": {"linear": body["linear_velocity"], "angular": body["angular_velocity"]},
        "mass": body["mass"],
        "frozen": body["frozen"],
        "properties": props,
        "shape": body["shape"],
        "bounds": {"size": size.tolist()},
    }


def describe_sensor(world, spec):
    """A sensor as plain data, like describe(): its pose in `world` now, its spec as properties
    and a 0.1 m cube as its bounds (for ~/get_entities' marker)."""
    mount = pose_matrix(spec["pose"][:3], rpy_to_quat(spec["pose"][3:]))
    if spec["parent"] != "world":
        body = world.body(spec["parent"])
        mount = pose_matrix(body["position"], body["quaternion"]) @ mount
    return {
        "name": spec["name"],
        "category": "sensor",
        "frame": "world",
        "pose": {"position": mount[:3, 3].tolist(), "orientation": matrix_to_quaternion(mount[:3, :3]).tolist()},
        "properties": dict(spec),
        "shape": "box",
        "bounds": {"size": [SENSOR_SIZE] * 3},
    }
