"""The standard simulation_interfaces services (ros-simulation/simulation_interfaces, the 1.5
series ROS 2 Jazzy ships; the 2.x field layout is read too), ROS-free like services.py: rows of
(name, type, handler), names relative so that a namespace applies. The ROS node serves them
where the types import; the Foxglove server always (it encodes from the .srv definitions).

Every handler maps the standard request onto the same Requests handler as the YAML services
(api/), so validation, limits and what changes are one code path; the reply's code becomes the
standard's number for that service (Result.result), its text the error_message.
"""
import re
import time
from pathlib import Path

from . import messages
from .api import INVALID_MAP_DATA, MAP_DOES_NOT_EXIST, MAP_SUCCESS
from .api.entity_queries import category_of
from .api.file_access import SCENE_SUFFIXES, confine, find_description, local_path
from .api.payload import MAX_PAYLOAD, parse
from .api.results import (FAILED, FEATURE_UNSUPPORTED, INCORRECT_STATE, NAME_INVALID, NO_RESOURCE, NO_WORLD_LOADED,
                          NOT_FOUND, RESOURCE_PARSE_ERROR, UNSUPPORTED_FORMAT, RequestError, handled)
from .api.simulation_control import SPAWN_FORMATS
from .physics import specs
from .scene import read_capped
from .services import Service, carriable
from .urdf_robots import is_description_text

PACKAGE = "simulation_interfaces"
# Result.result, and the numbers each service adds above 100, by the code names of api/results.py.
COMMON = {"RESULT_FEATURE_UNSUPPORTED": 0, "RESULT_OK": 1, "RESULT_NOT_FOUND": 2, "RESULT_INCORRECT_STATE": 3,
          "RESULT_OPERATION_FAILED": 4}
RESULT_OK, OPERATION_FAILED = COMMON["RESULT_OK"], COMMON["RESULT_OPERATION_FAILED"]
SPAWN_CODES = {"NAME_NOT_UNIQUE": 101, "NAME_INVALID": 102, "UNSUPPORTED_FORMAT": 103, "NO_RESOURCE": 104,
               "NAMESPACE_INVALID": 105, "RESOURCE_PARSE_ERROR": 106, "MISSING_ASSETS": 107,
               "UNSUPPORTED_ASSETS": 108, "INVALID_POSE": 109}
SET_STATE_CODES = {"INVALID_POSE": 101}
SIMULATION_STATE_CODES = {"ALREADY_IN_TARGET_STATE": 101, "STATE_TRANSITION_ERROR": 102, "INCORRECT_TRANSITION": 103}
LOAD_WORLD_CODES = {"UNSUPPORTED_FORMAT": 101, "NO_RESOURCE": 102, "RESOURCE_PARSE_ERROR": 103,
                    "MISSING_ASSETS": 104, "UNSUPPORTED_ASSETS": 105, "UNSUPPORTED_ELEMENTS": 106}
NO_WORLD_CODES = {"NO_WORLD_LOADED": 101}
ENTITIES_SPAWN_FAILED = 150
# What may take long: steps waited for, a message of every entity (10,000: ~0.4 s), a list of
# spawns, a robot's description (its meshes' hulls: up to a second).
ASIDE = {"step_simulation", "get_entities_states", "spawn_entities", "spawn_entity"}
STEP_POLL = 0.002  # s between looks at the step count while step_simulation waits


def result(reply, codes=None):
    """Result {result, error_message} of a handler's (success, "CODE: message") reply."""
    _, text = reply
    code, _, message = text.partition(": ")
    number = {**COMMON, **(codes or {})}.get(code)
    if number is None:  # a code this service does not define: the text keeps it
        return {"result": OPERATION_FAILED, "error_message": carriable(text)}
    return {"result": number, "error_message": "" if number == RESULT_OK else carriable(message)}


SUCCESS = {"result": RESULT_OK, "error_message": ""}


def failed(code, message, codes=None):
    return result((False, f"{code}: {message}"), codes)


def refused(error, codes=None):
    """The Result of a RequestError."""
    return result((False, str(error)), codes)


def plain_pose(pose):
    """{position: [x y z], orientation: [x y z w]} of a geometry_msgs Pose."""
    return {"position": [pose.position.x, pose.position.y, pose.position.z],
            "orientation": [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w]}


# What SpawnEntity's uri may name: this package's YAML entity spec, or a robot description.
DESCRIPTION_SUFFIXES = (".urdf", ".xacro")
SPAWN_SUFFIXES = (".yaml", ".yml", *DESCRIPTION_SUFFIXES)


def is_urdf(uri, text):
    """A URDF (or xacro) robot description rather than this package's YAML entity spec;
    UNSUPPORTED_FORMAT for XML of another kind (SDFormat, MJCF), which had been read as a URDF
    that failed to parse."""
    if uri:
        return uri.lower().endswith(DESCRIPTION_SUFFIXES)
    if not is_description_text(text):
        return False
    root = XML_ROOT.search(text)
    if root is None or root.group(1) != "robot":
        raise RequestError(UNSUPPORTED_FORMAT, f"resource_string is XML with a <{root.group(1) if root else '?'}> "
                                               f"root, not a URDF <robot> (spawn_formats {SPAWN_FORMATS})")
    return True


# The root element of an XML text: the first element after its declaration, comments and
# processing instructions.
XML_ROOT = re.compile(r"^(?:\s|<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^>]*>)*<([A-Za-z_][\w.:-]*)", re.DOTALL)


def robot_name(text):
    """A spawned robot's name when the request gives none: its description's (the <robot> tag's
    name, looked for in the 1,000 characters after the tag opens), as a name may be."""
    start = text.find("<robot")
    found = re.search(r"\bname\s*=\s*[\"']([^\"']{1,200})", text[start:start + 1000]) if start >= 0 else None
    return re.sub(r"[^A-Za-z0-9_.-]", "_", found.group(1))[:64] if found else "robot"


def resource_of(request, resource="entity_resource"):
    """(uri, resource_string) of a 1.x request (fields of its own) or a 2.x one (a Resource)."""
    if hasattr(request, resource):
        request = getattr(request, resource)
    return str(request.uri), str(request.resource_string)


def state_message(table_or_entity, frame, row=None):
    """simulation_interfaces EntityState of an entity_table row or an entity() description."""
    if row is None:
        e = table_or_entity
        position, orientation = e["pose"]["position"], e["pose"]["orientation"]
        linear, angular, seconds = e["twist"]["linear"], e["twist"]["angular"], e["time"]
    else:
        t = table_or_entity
        position, orientation, linear, angular = t.positions[row], t.quaternions[row], t.linear[row], t.angular[row]
        seconds = t.time
    return {"header": messages.header(seconds, frame),
            "pose": {"position": messages.xyz(position), "orientation": messages.xyzw(orientation)},
            "twist": {"linear": messages.xyz(linear), "angular": messages.xyz(angular)}}


class StandardServices:
    """The handlers, bound to a Runtime (its requests, parameters and simulation)."""

    def __init__(self, runtime):
        self.runtime = runtime
        self.requests = runtime.requests

    def table(self):
        s = f"{PACKAGE}/srv/"
        return [Service(name, s + kind, handler, name in ASIDE) for name, kind, handler in [
            ("get_simulator_features", "GetSimulatorFeatures", self.features),
            ("spawn_entity", "SpawnEntity", self.spawn_entity),
            ("spawn_entities", "SpawnEntities", self.spawn_entities),
            ("delete_entity", "DeleteEntity", self.delete_entity),
            ("get_entities", "GetEntities", self.get_entities),
            ("get_entities_states", "GetEntitiesStates", self.get_entities_states),
            ("get_entity_state", "GetEntityState", self.get_entity_state),
            ("set_entity_state", "SetEntityState", self.set_entity_state),
            ("get_entity_info", "GetEntityInfo", self.get_entity_info),
            ("get_entity_bounds", "GetEntityBounds", self.get_entity_bounds),
            ("get_simulation_state", "GetSimulationState", self.get_simulation_state),
            ("set_simulation_state", "SetSimulationState", self.set_simulation_state),
            ("reset_simulation", "ResetSimulation", self.reset_simulation),
            ("step_simulation", "StepSimulation", self.step_simulation),
            ("load_world", "LoadWorld", self.load_world),
            ("unload_world", "UnloadWorld", self.unload_world),
            ("get_current_world", "GetCurrentWorld", self.get_current_world),
            ("get_available_worlds", "GetAvailableWorlds", self.get_available_worlds),
        ]]

    # ------------------------------------------------------------------ features
    def features(self, _request):
        return {"features": {
            "features": self.requests.honoured_features(), "spawn_formats": SPAWN_FORMATS,
            "custom_info": "vplayground_ros: resource_string and uri hold this package's YAML entity spec or a URDF (spawn) "
                           "or scene (load_world); see its README"}}

    # ------------------------------------------------------------------ entities
    def spawn_entity(self, request):
        reply = self._spawn(request)
        name = reply[1].partition(": ")[2] if reply[0] else ""
        return {"result": result(reply, SPAWN_CODES), "entity_name": name}

    def spawn_entities(self, request):
        """Each entry spawned on its own (the standard answers a result per entry), after a
        count check: more entries than max_bodies fail at once."""
        cap = int(self.requests.max_bodies)
        if len(request.spawn_requests) > cap:
            return {"result": failed(FAILED, f"spawn_requests: {len(request.spawn_requests)} "
                                                                f"entries, more than max_bodies ({cap})")}
        results = [self.spawn_entity(item) for item in request.spawn_requests]
        failures = sum(r["result"]["result"] != RESULT_OK for r in results)
        overall = (SUCCESS if not failures else
                   {"result": ENTITIES_SPAWN_FAILED, "error_message": f"{failures} of {len(results)} spawn "
                                                                      "requests failed (see results)"})
        return {"result": overall, "results": results}

    @handled
    def _spawn(self, request):
        """~/spawn of one entity from a SpawnEntity request: the resource (uri, a file in the
        scene directories, or resource_string) is this package's YAML spec of a body, vehicle
        or sensor; name, allow_renaming, entity_namespace (a vehicle's) and initial_pose (unless
        it is the default, the origin in no frame, which leaves the spec's pose) override it."""
        uri, text = resource_of(request)
        if uri:
            uri, text = self._read_resource(uri)
        elif not text:
            raise RequestError(NO_RESOURCE, "both uri and resource_string are empty")
        if is_urdf(uri, text):  # a robot description: the file's path (confined above), or the text
            if len(text.encode("utf-8", "surrogatepass")) > MAX_PAYLOAD:
                raise RequestError(FAILED, f"the description is more than {MAX_PAYLOAD} bytes")
            spec = {"urdf": uri or text}
            if not request.name:
                spec["name"] = robot_name(text)
        else:
            try:
                spec = parse(text, "resource_string" if not uri else uri)
            except RequestError as error:
                raise RequestError(RESOURCE_PARSE_ERROR, str(error).partition(": ")[2]) from None
        if not isinstance(spec, dict):
            raise RequestError(UNSUPPORTED_FORMAT, f"the resource is {type(spec).__name__}, not this package's "
                                                     "YAML entity spec (a mapping: shape, size, mass...; spawn_formats "
                                                     f"{SPAWN_FORMATS})")
        spec = dict(spec)
        name = str(request.name)
        if name:
            spec["name"] = name
        elif not spec.get("name") and not request.allow_renaming:
            raise RequestError(NAME_INVALID, "name: empty, and the resource names no entity (allow_renaming: true "
                                               "picks one)")
        spec["allow_renaming"] = bool(request.allow_renaming)
        namespace = str(request.entity_namespace)
        if namespace:
            if not valid_namespace(namespace):
                raise RequestError("NAMESPACE_INVALID", f"entity_namespace: {specs.quote(namespace)} is not a ROS "
                                                        "namespace (letters, digits, _ and /)")
            if "wheels" not in spec and "chassis" not in spec and "urdf" not in spec:
                raise RequestError(FAILED, "entity_namespace: only a vehicle or a URDF robot has interfaces to "
                                           "put under a namespace")
            spec["namespace"] = namespace.strip("/")
        pose = request.initial_pose
        frame = str(pose.header.frame_id)
        plain = plain_pose(pose.pose)
        if frame or plain != {"position": [0.0, 0.0, 0.0], "orientation": [0.0, 0.0, 0.0, 1.0]}:
            spec["initial_pose"] = {"header": {"frame_id": frame}, "pose": plain}
        return self.requests.spawn_entities(spec)

    def _read_resource(self, uri):
        """(the file's path, its text) of a SpawnEntity uri: a robot description found as
        ~/spawn's `urdf` is (find_description: the package's config/ last, so `car.urdf` is
        the built-in car's), an entity spec in the scene directories; NOT_FOUND where none is."""
        suffix = Path(local_path(uri)).suffix.lower()
        if suffix not in SPAWN_SUFFIXES:
            raise RequestError(UNSUPPORTED_FORMAT, f"uri: {specs.quote(uri)}: entity files end in "
                                                   f"{' or '.join(SPAWN_SUFFIXES)} (spawn_formats {SPAWN_FORMATS})")
        if suffix in DESCRIPTION_SUFFIXES:
            try:
                target = find_description(local_path(uri), self.requests.scene_directories, "uri")
            except specs.SpecError as error:
                raise RequestError(NOT_FOUND, str(error)) from None
        else:
            try:
                target = confine(local_path(uri), "uri", self.requests.scene_directories, SPAWN_SUFFIXES,
                                 "entity files")
            except RequestError as error:
                raise RequestError(NOT_FOUND, str(error).partition(": ")[2]) from None
        if not target.is_file():
            raise RequestError(NOT_FOUND, f"uri: no file at {specs.quote(uri)}")
        try:  # ValueError: larger than a request may be, a device, not UTF-8 (UnicodeDecodeError)
            return str(target), read_capped(target, MAX_PAYLOAD, "uri").decode("utf-8")
        except ValueError as error:
            raise RequestError(RESOURCE_PARSE_ERROR, f"uri: cannot read {target}: {str(error)[:300]}") from None

    def delete_entity(self, request):
        return {"result": result(self.requests.remove_entity(str(request.entity)))}

    def get_entities(self, request):
        try:
            table, rows = self._filtered(request.filters)
        except RequestError as error:
            return {"result": refused(error)}
        return {"result": SUCCESS, "entities": [table.names[k] for k in rows]}

    def get_entities_states(self, request):
        try:
            table, rows = self._filtered(request.filters)
        except RequestError as error:
            return {"result": refused(error)}
        frame = self.runtime.parameters["world_frame"]
        return {"result": SUCCESS, "entities": [table.names[k] for k in rows],
                "states": [state_message(table, frame, k) for k in rows]}

    def _filtered(self, filters):
        return self.requests.entities_filtered(
            str(filters.filter), [int(c.category) for c in filters.categories], list(filters.tags.tags),
            int(filters.bounds.type), [(p.x, p.y, p.z) for p in filters.bounds.points])

    def get_entity_state(self, request):
        return self._about(request, lambda e: {"state": state_message(e, self.runtime.parameters["world_frame"])})

    def _about(self, request, answer):
        """SUCCESS and answer(entity() of request.entity), or why not (RESULT_NOT_FOUND)."""
        try:
            entity = self.requests.entity(str(request.entity))
        except RequestError as error:
            return {"result": refused(error)}
        return {"result": SUCCESS, **answer(entity)}

    def set_entity_state(self, request):
        """~/edit with the state: pose and twist in state.header.frame_id (the world when empty),
        set_pose/set_twist choosing what is set (2.x; 1.x sets both); a non-zero acceleration
        is refused (forces make it)."""
        state = request.state
        try:
            if self.requests.entity(str(request.entity))["category"] == "sensor":
                return {"result": failed(FAILED, f"{request.entity}: a sensor is placed by its mount "
                                         "in its parent's frame (~/edit {entity: NAME, pose: [x, y, z, roll, pitch, "
                                         "yaw]}); set_entity_state moves bodies and vehicles")}
        except RequestError as error:
            return {"result": refused(error)}
        set_pose, set_twist = getattr(request, "set_pose", True), getattr(request, "set_twist", True)
        accel = state.acceleration
        asked = getattr(request, "set_acceleration", any(
            (accel.linear.x, accel.linear.y, accel.linear.z, accel.angular.x, accel.angular.y, accel.angular.z)))
        edit = {"entity": str(request.entity), "set_pose": bool(set_pose), "set_twist": bool(set_twist),
                "set_acceleration": bool(asked),
                "state": {"header": {"frame_id": str(state.header.frame_id)}, "pose": plain_pose(state.pose),
                          "twist": {"linear": [state.twist.linear.x, state.twist.linear.y, state.twist.linear.z],
                                    "angular": [state.twist.angular.x, state.twist.angular.y, state.twist.angular.z]}}}
        return {"result": result(self.requests.edit_entity(edit), SET_STATE_CODES)}

    def get_entity_info(self, request):
        return self._about(request, lambda e: {"info": {"category": {"category": category_of(e)},
                                                        "description": entity_text(e), "tags": []}})

    def get_entity_bounds(self, request):
        """The box around the entity in its own frame (Bounds TYPE_BOX: lower, then upper corner)."""
        def bounds(entity):
            corners = [messages.xyz(entity["bounds"][corner]) for corner in ("low", "high")]
            return {"bounds": {"type": 1, "points": corners}}  # TYPE_BOX
        return self._about(request, bounds)

    # ------------------------------------------------------------------ simulation
    def get_simulation_state(self, _request):
        return {"state": {"state": self.runtime.sim.state}, "result": SUCCESS}

    def set_simulation_state(self, request):
        return {"result": result(self.requests.set_simulation_state(int(request.state.state)), SIMULATION_STATE_CODES)}

    def reset_simulation(self, request):
        return {"result": result(self.requests.reset(int(request.scope)))}

    def step_simulation(self, request):
        """~/step of `steps`, answered once they have run (the standard's service blocks)."""
        progress = self.stepping(int(request.steps))
        try:
            while True:
                next(progress)
                time.sleep(STEP_POLL)
        except StopIteration as end:
            return {"result": end.value}

    def stepping(self, steps):
        """~/step of `steps`, followed: yields (completed, remaining) as they change, None
        between looks, and returns the Result once they have run (or why not: refused, the
        world replaced or reset to its start, the simulation played or ended). Its steps end at
        a step count fixed when they were queued, behind any asked for before. Closing it early
        withdraws those not yet run while they are the last queued (SimulateSteps' cancel)."""
        sim = self.runtime.sim
        reply, world, target = self.requests.step_to(steps)
        if world is None:  # the standard: RESULT_OPERATION_FAILED when not paused
            return result(reply, {INCORRECT_STATE: OPERATION_FAILED})
        done = -1
        try:
            while True:
                now = min(max(world.step_count - (target - steps), 0), steps)
                if now != done:
                    done = now
                    yield done, steps - done
                if done >= steps:
                    return result(reply)
                # Pending steps count down only once their batch has run: none pending and the
                # count short means they will not run (played, a failed step, a time reset).
                if (sim.world is not world or sim.wait(0) or not sim.paused
                        or (not sim.pending_steps and world.step_count < target)):
                    return failed(FAILED, f"stepping stopped after {done} of {steps} steps (the "
                                                             "world was replaced or reset, or the simulation played "
                                                             "or ended)")
                yield None
        finally:
            if done < steps:
                remaining = steps - max(done, 0)
                sim.submit(lambda _: sim.withdraw_steps(target, remaining))

    # ------------------------------------------------------------------ worlds
    def load_world(self, request):
        """~/load_scene of a scene file (uri, in the scene directories) or of scene YAML text
        (resource_string); the new world waits STOPPED, as the standard says."""
        uri, text = resource_of(request, "world_resource")
        if uri and Path(local_path(uri)).suffix.lower() not in SCENE_SUFFIXES:
            return {"result": failed(UNSUPPORTED_FORMAT, f"uri: {specs.quote(uri)}: a world is this package's scene "
                                                         f"YAML, in a file ending in {' or '.join(SCENE_SUFFIXES)}",
                                     LOAD_WORLD_CODES)}
        if uri:
            code, message = self.requests.load_scene(local_path(uri), stopped=True)
        elif text:
            code, message = self.requests.load_scene_text(text, stopped=True)
        else:
            return {"result": failed(NO_RESOURCE, "both uri and resource_string are empty", LOAD_WORLD_CODES)}
        if code != MAP_SUCCESS:
            name = {MAP_DOES_NOT_EXIST: NOT_FOUND, INVALID_MAP_DATA: RESOURCE_PARSE_ERROR}.get(code, FAILED)
            code, _, detail = message.partition(": ")
            if code in LOAD_WORLD_CODES:  # a format, asset or element the scene reader refused
                name = code
            return {"result": failed(name, detail, LOAD_WORLD_CODES)}
        self.runtime.broadcaster.scene_changed()
        return {"result": SUCCESS, "world": self._world_resource(*self.requests.current_world())}

    def unload_world(self, _request):
        reply = self.requests.unload_world()
        if reply[0]:
            self.runtime.broadcaster.scene_changed()
        return {"result": result(reply, NO_WORLD_CODES)}

    def get_current_world(self, _request):
        current = self.requests.current_world()
        if current is None:
            return {"result": failed(NO_WORLD_LOADED, "no world is loaded (unload_world)", NO_WORLD_CODES)}
        return {"result": SUCCESS, "world": self._world_resource(*current)}

    def get_available_worlds(self, request):
        if list(request.filter.tags):
            return {"result": failed(FEATURE_UNSUPPORTED, "filter.tags: worlds have no tags here (WORLD_TAGS "
                                                                   "is not among get_simulator_features)"), "worlds": []}
        try:
            found = self.requests.available_worlds([str(s) for s in request.additional_sources])
        except RequestError as error:
            return {"result": refused(error)}
        return {"result": SUCCESS,
                "worlds": [self._world_resource(str(path), description=description) for path, description in found]}

    @staticmethod
    def _world_resource(label, text="", description=""):
        """WorldResource of a scene file, or of the YAML `text` a scene was loaded from (a
        Resource's uri or its resource_string is not empty; 1.x: `world_resource` is a Resource
        in both)."""
        name = Path(label).stem if label else "scene"
        return {"name": name, "world_resource": {"uri": label, "resource_string": "" if label else text},
                "description": description, "tags": []}


def valid_namespace(namespace):
    """A namespace a robot can take (specs.NAMESPACE_PATTERN), leading and trailing '/' aside."""
    relative = namespace.strip("/")
    return bool(relative) and specs.NAMESPACE_PATTERN.fullmatch(relative) is not None


def entity_text(entity):
    """GetEntityInfo's description: what the entity is, in a line."""
    if entity["category"] == "sensor":
        return f"{entity['properties']['type']} sensor on {entity['properties']['parent']}"
    kind = {"vehicle": "vehicle", "immovable": "immovable body"}.get(entity["category"], "body")
    return f"{entity['shape']} {kind}, {entity['mass']:g} kg"


def standard_service_table(runtime):
    return StandardServices(runtime).table()
