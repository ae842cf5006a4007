"""The entity services: ~/spawn, ~/edit, ~/remove, ~/get_entity, ~/get_entities. Bodies,
vehicles and sensors are entities; their names are unique among all three, and are frames, so
they are none of the frames the node publishes besides (world, odom, base_link, the wheels', the
cameras' optical frames, a URDF robot's links': frame_names.frames_taken). A pose's frame_id may be any frame the node publishes (frames.py).
"""
import logging
from pathlib import Path

import numpy as np
import yaml

from ..broadcast import check_sensors
from ..frame_names import frames_taken as frames_of_world, sensor_frames, urdf_robot_frames
from ..physics import specs
from ..physics.math3d import matrix_to_quaternion, rpy_to_quat
from ..physics.world import prepare_body
from ..robots import validate_robot
from ..scene import body_mesh_points
from ..sensors import TYPES as SENSOR_TYPES, lumped_links, pose_matrix, validate_sensor
from ..urdf_robots import (add_robot_entry, check_against_model, description_source, is_description_text,
                           robot_namespace, robot_spec, validate_entry, vehicle_entry)
from .descriptions import describe, describe_robot, describe_sensor
from .file_access import allowed_directories, find_description
from .frames import frame_pose, pose_in_world
from .name_filter import MAX_FILTER, match_names
from .naming import unique_name
from .payload import YAML_DUMPER, as_mapping, header_frame, parse, pose_fields, xyz
from .results import (FAILED, INVALID_POSE, MISSING_ASSETS, NAME_NOT_UNIQUE, NOT_FOUND, OK, RESOURCE_PARSE_ERROR,
                      UNSUPPORTED_ASSETS, RequestError, handled, reply)

log = logging.getLogger(__name__)
ROBOT_EDIT_KEYS = {"position", "quaternion", "rpy", "linear_velocity", "angular_velocity"}  # a robot's, as one


def sensor_named(world, name):
    """The spec of the world's sensor `name`, or None."""
    return next((s for s in world.sensor_specs if s["name"] == name), None)


def world_lumped_links(world, adding=()):
    """sensors.lumped_links of the world's URDF robots and those `adding` ((robot name, model)
    of a spawn): where a sensor whose parent is such a link rides."""
    return lumped_links([(robot["name"], robot["model"]) for robot in world.robot_specs] + list(adding))


def drop_sensors_of(world, removed):
    """The sensors whose parent was just removed go with it, with a warning naming both."""
    removed = set(removed)
    orphans = [s for s in world.sensor_specs if s["parent"] in removed]
    for parent in dict.fromkeys(s["parent"] for s in orphans):
        names = [s["name"] for s in orphans if s["parent"] == parent]
        log.warning(f"{'sensors' if len(names) > 1 else 'sensor'} {', '.join(names)} removed with "
                    f"{parent}, {'their' if len(names) > 1 else 'its'} parent")
    if orphans:
        world.sensor_specs = [s for s in world.sensor_specs if s["parent"] not in removed]
    return [s["name"] for s in orphans]


def in_world(world, frame, fields, path, frames):
    """Body keys given in `frame` in the world frame (frames.pose_in_world); INVALID_POSE naming
    the frame unless the node publishes it."""
    transform = frame_pose(world, frame, frames)
    if transform is None:
        raise RequestError(INVALID_POSE, f"{path}.header.frame_id: {specs.quote(frame)} is not a frame the node "
                                         f"publishes (world, odom, base_link, wheel, sensor or body frames)")
    return pose_in_world(transform, fields)


def taken_name(name, frames_taken):
    """Why `name` is taken, for a NAME_NOT_UNIQUE message."""
    if name in frames_taken:
        return f"{name!r} is {frames_taken[name]}, a frame the node publishes"
    return f"{name!r} is taken"


def described(read):
    """What `read()` reads of a robot description; its UrdfError a RequestError with the result
    code the standard services give it."""
    from ..urdf_import import MissingMesh, UnreadableUrdf, UrdfError
    try:
        return read()
    except UrdfError as error:
        code = (MISSING_ASSETS if isinstance(error, MissingMesh) else
                RESOURCE_PARSE_ERROR if isinstance(error, UnreadableUrdf) else UNSUPPORTED_ASSETS)
        raise RequestError(code, str(error)) from None


def check_inside(world, position, path):
    try:
        world.check_inside(position, path)
    except specs.SpecError as error:
        raise RequestError(INVALID_POSE, str(error)) from None


def move_robot(world, robot, fields, label, frame="", frames=None):
    """A URDF robot (its world.robot_specs entry) moved by `fields` (ROBOT_EDIT_KEYS, in `frame`
    if given: any frame the node publishes, named by `frames`): every link as one rigid body with
    its root (its joints stay as they are)."""
    if "rpy" in fields:
        fields = dict(fields)
        fields["quaternion"] = rpy_to_quat(fields.pop("rpy")).tolist()
    if frame:
        fields = in_world(world, frame, fields, "edit.state", frames)
    root = world.body(robot["bodies"][0])
    old = pose_matrix(root["position"], root["quaternion"])
    new = pose_matrix(fields.get("position", root["position"]), fields.get("quaternion", root["quaternion"]))
    check_inside(world, new[:3, 3].tolist(), f"{label}.position")
    move = new @ np.linalg.inv(old)
    linear, angular = fields.get("linear_velocity"), fields.get("angular_velocity")
    if (linear is not None and any(linear) or angular is not None and any(angular)) and root["immovable"]:
        raise RequestError(FAILED, f"{label}.twist: its base is fixed (immovable)")
    edits = {}
    for body in robot["bodies"]:
        link = world.body(body)
        placed = move @ pose_matrix(link["position"], link["quaternion"])
        edit = {"position": placed[:3, 3].tolist(), "quaternion": matrix_to_quaternion(placed[:3, :3]).tolist()}
        if linear is not None or angular is not None:
            spin = np.asarray(angular if angular is not None else root["angular_velocity"], float)
            base = np.asarray(linear if linear is not None else root["linear_velocity"], float)
            if not link["immovable"]:
                edit["linear_velocity"] = (base + np.cross(spin, placed[:3, 3] - new[:3, 3])).tolist()
                edit["angular_velocity"] = spin.tolist()
        edits[body] = edit
    for body, edit in edits.items():  # every link checked before any moves: all or nothing
        specs.validate_body_fields(edit, f"{label}.{body}", set(edit))
        check_inside(world, edit["position"], f"{label}.{body}.position")
    for body, edit in edits.items():
        world.edit_body(body, **edit)


class EntityRequests:
    """Requests' entity handlers (see requests.py for the state they share)."""

    @handled
    def spawn(self, text):
        return self.spawn_entities(parse(text))

    @handled
    def spawn_entities(self, request):
        """~/spawn of a request already parsed: one entity spec (a mapping) or a list of them."""
        items = request if isinstance(request, list) else [request]
        if not items:
            raise RequestError(FAILED, "nothing to spawn")
        cap = int(self.max_bodies)
        if len(items) > cap:  # before validating any of them: a million boxes fail at once
            raise RequestError(FAILED, f"spawn of {len(items)} entities: more than max_bodies ({cap})")
        prepared = [self._prepare_spawn(raw, f"[{k}]" if isinstance(request, list) else "spawn")
                    for k, raw in enumerate(items)]
        frames = self.frames()
        return self.sim.call(lambda world: self._spawn(world, prepared, cap, frames))

    def _prepare_spawn(self, raw, path):
        """(path, is vehicle, validated spec, allow_renaming, the initial pose's frame_id) of one
        spawn entry. A convex body's `mesh:` is read here (from the scene directories or the
        package's meshes/, as a loaded scene's playground) and its hull taken, off the
        simulation thread."""
        item = body_mesh_points(dict(as_mapping(raw, path)), path, Path.cwd(), self.scene_directories)
        rename = specs.boolean(item.pop("allow_renaming", False), f"{path}.allow_renaming")
        if item.get("type") in SENSOR_TYPES:  # its parent is checked against the world
            if "initial_pose" in item:
                raise RequestError(INVALID_POSE, f"{path}.initial_pose: a sensor is placed by `pose` "
                                                 "(x y z roll pitch yaw in its parent's frame)")
            return path, "sensor", item, rename, ""
        frame = ""
        if "initial_pose" in item:
            pose = as_mapping(item.pop("initial_pose"), f"{path}.initial_pose")
            frame = header_frame(pose, f"{path}.initial_pose")
            item.update(pose_fields(pose, f"{path}.initial_pose"))
            if "quaternion" in item:
                item.pop("rpy", None)  # the pose's orientation wins over the spec's
        if "urdf" in item:
            source, description, vehicle = self._prepare_description(item, path)
            if vehicle is not None:  # a ray-cast vehicle's description (the built-in car's)
                return path, True, vehicle, rename, frame
            return path, "robot", self._prepare_robot(item, source, description, path, frame), rename, ""
        vehicle = "wheels" in item or "chassis" in item
        # A body's hull and mass are checked here too: a list is refused before the world is
        # asked, not rolled back (which would wake what the bodies touched).
        spec = validate_robot(specs.validate_vehicle(item, path), path) if vehicle else prepare_body(item, path)[0]
        return path, vehicle, spec, rename, frame

    def _prepare_description(self, item, path):
        """(the description's source: a file found as a scene's robot is (the package's config/
        last: `car.urdf` is the built-in car's), in the scene directories, or the text itself;
        the description as read once, no xacro (read_description's text and folder); the
        vehicle it describes, or None for a URDF robot)."""
        from ..urdf_import import read_description
        source = description_source(item, path)
        if not is_description_text(source):
            source = str(find_description(source, self.scene_directories, f"{path}.urdf"))
        description = described(lambda: read_description(source, f"{path}.urdf", allow_xacro=False))
        return source, description, described(lambda: vehicle_entry({**item, "urdf": source}, path, description[0],
                                                                    f"{path}.urdf"))

    def _prepare_robot(self, item, source, description, path, frame):
        """(entry, RobotModel) of a URDF robot to spawn from its description's `source`, as read
        (`description`); placed in the world frame."""
        from ..urdf_import import robot_model
        if frame and frame != self.frames().world:
            raise RequestError(INVALID_POSE, f"{path}.initial_pose.header.frame_id: a robot is placed in the world "
                                             f"frame ({self.frames().world!r} or empty), not {specs.quote(frame)}")
        entry, fields = validate_entry({**item, "urdf": source}, path)
        model = described(lambda: robot_model(source, entry["name"], fields.get("position", [0.0, 0.0, 0.0]),
                                              fields.get("rpy", [0.0, 0.0, 0.0]), entry.get("fixed_base"),
                                              entry.get("self_collide", False), entry["joint_positions"],
                                              label=f"{path}.urdf", quaternion=fields.get("quaternion"),
                                              directories=allowed_directories(self.scene_directories),
                                              description=description))
        check_against_model(entry, model, path)
        entry.update({key: fields[key] for key in ("position", "rpy", "quaternion") if key in fields})
        return entry, model

    def _spawn(self, world, prepared, cap, frames):
        self._check_world("spawning")
        existing = world.body_names()
        adding = sum(len(spec[1].bodies) if kind == "robot" else 1 for _, kind, spec, _, _ in prepared)  # a robot: its links
        if len(existing) + adding > cap:
            raise RequestError(FAILED, f"spawn of {len(prepared)} entities ({adding} bodies): the world has "
                                       f"{len(existing)} bodies and max_bodies is {cap}")
        # Names are frames (a body's on /tf, a sensor's), so the node's own frames are taken too,
        # and the URDF robots' link frames.
        frames_taken = frames_of_world(frames, world)
        names, suffixes = (set(existing) | {s["name"] for s in world.sensor_specs} | set(frames_taken)
                           | {robot["name"] for robot in world.robot_specs}), {}
        # A robot's frames are taken for what follows it in the request, as for what is spawned
        # once it is there: in the namespace it will get, after the request's vehicles (added
        # first; the first without a namespace takes the root one, World.add_vehicle).
        namespaces = world.robot_namespaces()
        if any(kind is True and spec.get("namespace", "") == "" for _, kind, spec, _, _ in prepared):
            namespaces.setdefault("", "a vehicle of the request")
        # Bodies and vehicles first: a sensor of the request rides the body of the request that
        # its parent names, under the name that body gets.
        renamed = {}
        robots = []  # (path, entry, model) under the names they get
        for path, vehicle, spec, rename, frame in prepared:
            if vehicle == "robot":
                robots.append(self._name_robot(world, path, *spec, rename, names, suffixes, frames_taken))
                _, entry, model = robots[-1]
                namespace = robot_namespace(entry, model, namespaces, frames)
                namespaces[namespace] = entry["name"]
                own_frames = urdf_robot_frames([{**entry, "namespace": namespace, "model": model}], frames)
                frames_taken.update(own_frames)
                names.update(own_frames)
                continue
            if vehicle == "sensor":
                continue
            name = spec.get("name")
            if name is not None and name in names:
                if not rename:
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {taken_name(name, frames_taken)} "
                                                        "(allow_renaming: true picks a free name)")
                spec["name"] = renamed[name] = unique_name(name, names, suffixes)
                name = spec["name"]
            if name is not None:
                names.add(name)
            if frame:
                pose = {key: spec.pop(key) for key in ("position", "quaternion", "rpy") if key in spec}
                if "rpy" not in pose:
                    pose.setdefault("quaternion", [0.0, 0.0, 0.0, 1.0])  # none given: the frame's
                spec.update(in_world(world, frame, pose, f"{path}.initial_pose", frames))
            check_inside(world, spec["position"], f"{path}.position")
        parents = set(existing) | {spec.get("name") for _, kind, spec, _, _ in prepared if kind in (True, False)}
        parents |= {body["name"] for _, _, model in robots for body in model.bodies}
        sensors = []
        links = world_lumped_links(world, [(entry["name"], model) for _, entry, model in robots])
        for path, vehicle, spec, rename, _ in prepared:
            if vehicle != "sensor":
                continue
            if isinstance(spec.get("parent"), str):
                spec = {**spec, "parent": renamed.get(spec["parent"], spec["parent"])}
            sensor = validate_sensor(spec, path, parents, links)
            wanted = sensor["name"]
            while True:
                frame_names = sensor_frames(sensor)
                clash = next((n for n in frame_names if n in names), None)
                if clash is None:
                    break
                if "frame_id" in sensor and clash in sensor_frames({**sensor, "name": ""}):  # no new name frees it
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.frame_id: {taken_name(clash, frames_taken)}")
                if not rename:
                    raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {taken_name(clash, frames_taken)} (sensor names "
                                                        "are frames; allow_renaming: true picks a free name)")
                names.add(sensor["name"])  # the next candidate's search goes on past this one
                sensor["name"] = unique_name(wanted, names, suffixes)
            names.update(frame_names)
            sensors.append(sensor)
        added = []
        try:
            for _, vehicle, spec, _, _ in prepared:
                if vehicle in (True, False):
                    added.append(world.add_vehicle(spec) if vehicle else world.add_body(spec))
            for path, entry, model in robots:
                added += add_robot_entry(world, entry, model, path, frames)
            if sensors or added:  # with the robots' namespaces, which adding gave them
                check_sensors([*world.sensor_specs, *sensors], world, frames)
        except Exception:
            world.remove_bodies(added)  # all or nothing
            raise
        if sensors:  # a new list: whoever follows the sensors sees them change
            world.sensor_specs = [*world.sensor_specs, *sensors]
        robot_bodies = {body["name"] for _, _, model in robots for body in model.bodies}
        return reply(OK, ", ".join([name for name in added if name not in robot_bodies]
                                   + [entry["name"] for _, entry, _ in robots] + [s["name"] for s in sensors]))

    @staticmethod
    def _name_robot(world, path, entry, model, rename, names, suffixes, frames_taken):
        """A spawned robot's name and its bodies' against the world's and the request's others
        (`names`, which gains them): NAME_NOT_UNIQUE, or with `rename` the next free name."""
        from ..urdf_import import UrdfError, renamed
        taken = names | {robot["name"] for robot in world.robot_specs}

        def clash(name, bodies):
            return next((n for n in [name, *bodies] if n in taken), None)
        name, bodies = entry["name"], [body["name"] for body in model.bodies]
        found = clash(name, bodies)
        if found is not None:
            if not rename:
                raise RequestError(NAME_NOT_UNIQUE, f"{path}.name: {taken_name(found, frames_taken)} (a robot's name "
                                                    "and its links' bodies, <name>.<link>; allow_renaming: true "
                                                    "picks a free name)")
            while found is not None:
                taken.add(name)
                new = unique_name(entry["name"], taken, suffixes)
                try:
                    model = renamed(model, name, new)
                except UrdfError as error:
                    raise RequestError(FAILED, f"{path}.name: {error}") from None
                name, bodies = new, [body["name"] for body in model.bodies]
                found = clash(name, bodies)
            entry = {**entry, "name": name}
        names.update([name, *bodies])
        check_inside(world, model.bodies[0]["position"], f"{path}.position")
        return path, entry, model

    @handled
    def edit(self, text):
        return self.edit_entity(parse(text))

    @handled
    def edit_entity(self, request):
        """~/edit of a request already parsed."""
        request = dict(as_mapping(request, "edit"))
        name = request.pop("entity", None)
        if not isinstance(name, str):
            raise RequestError(FAILED, "edit.entity: the name of the entity to edit is missing")
        label = name if specs.NAME_PATTERN.fullmatch(name) else specs.quote(name)  # for messages

        def kind(world):
            if sensor_named(world, name) is not None:
                return "sensor"
            return "body" if robot_spec(world, name) is not None or name in world.body_names() else None
        # What it is decides which keys it takes: an entity that is not there is that, not a
        # key its kind would refuse (the body keys' list, for a sensor's `rate`).
        found = self.sim.call(kind)
        if found is None:
            raise RequestError(NOT_FOUND, f"no entity named {label}")
        if found == "sensor":
            frames = self.frames()
            return self.sim.call(lambda world: self._edit_sensor(world, name, request, frames))
        state = as_mapping(request.pop("state", {}) or {}, "edit.state")
        specs.mapping(state, "edit.state", {"pose", "twist", "header", "acceleration"})
        set_pose = specs.boolean(request.pop("set_pose", "pose" in state), "edit.set_pose")
        set_twist = specs.boolean(request.pop("set_twist", "twist" in state), "edit.set_twist")
        if specs.boolean(request.pop("set_acceleration", "acceleration" in state), "edit.set_acceleration"):
            raise RequestError(FAILED, "edit.state.acceleration: accelerations cannot be set (the forces on a body "
                                       "make them; set_acceleration: false ignores the field)")
        vehicle_edit = request.pop("vehicle", None)
        frame = header_frame(state, "edit.state")  # of the pose and the twist (EntityState.header)
        stamped = {}  # the state's keys, given in `frame`
        if set_pose:
            pose = as_mapping(state.get("pose", {}), "edit.state.pose")
            pose_frame = header_frame(pose, "edit.state.pose")  # a PoseStamped
            if frame and pose_frame and pose_frame != frame:
                raise RequestError(INVALID_POSE, f"edit.state.pose.header.frame_id: {specs.quote(pose_frame)} is not "
                                                 f"edit.state.header.frame_id {specs.quote(frame)}")
            frame = frame or pose_frame
            stamped.update(pose_fields(pose, "edit.state.pose"))
        if set_twist:
            twist = as_mapping(state.get("twist", {}), "edit.state.twist")
            specs.mapping(twist, "edit.state.twist", {"linear", "angular"})
            if "linear" in twist:
                stamped["linear_velocity"] = xyz(twist["linear"], "edit.state.twist.linear")
            if "angular" in twist:
                stamped["angular_velocity"] = xyz(twist["angular"], "edit.state.twist.angular")
        # Validate everything before changing anything.
        fields = specs.validate_body_fields({**request, **stamped}, label, specs.BODY_KEYS - {"name", "shape"})
        if vehicle_edit is not None:
            specs.validate_vehicle_edit(as_mapping(vehicle_edit, f"{label}.vehicle"), f"{label}.vehicle")
        frames = self.frames()
        return self.sim.call(lambda world: self._edit(world, name, label, fields, vehicle_edit,
                                                      frame, set(stamped), frames))

    @staticmethod
    def _edit(world, name, label, fields, vehicle_edit, frame, stamped, frames):
        robot = robot_spec(world, name)
        if robot is not None:
            other = sorted(set(fields) - ROBOT_EDIT_KEYS) + (["vehicle"] if vehicle_edit is not None else [])
            if other:
                raise RequestError(FAILED, f"{label}.{other[0]}: a robot takes a pose and a twist; edit its links "
                                           f"({robot['bodies'][0]}, ...) for anything else")
            move_robot(world, robot, fields, label, frame, frames)
            return reply(OK, f"edited {robot['name']}: {', '.join(sorted(fields))}")
        if name not in world.body_names():
            raise RequestError(NOT_FOUND, f"no entity named {label}")
        if vehicle_edit is not None and name not in world.vehicle_names():
            raise RequestError(FAILED, f"{label}.vehicle: {specs.quote(name)} is not a vehicle")
        if frame:
            fields = {**fields, **in_world(world, frame, {key: fields[key] for key in stamped}, "edit.state", frames)}
        if "position" in fields:
            check_inside(world, fields["position"], f"{label}.position")
        moving = [key for key in ("linear_velocity", "angular_velocity") if any(fields.get(key, ()))]
        if moving and fields.get("immovable", world.body(name)["immovable"]):
            raise RequestError(FAILED, f"{label}.{moving[0]}: an immovable body cannot move (immovable: false first)")
        if fields:
            world.edit_body(name, **fields)
        if vehicle_edit:
            world.edit_vehicle(name, **vehicle_edit)
        return reply(OK, f"edited {name}: {', '.join(sorted(fields) + (['vehicle'] if vehicle_edit else []))}")

    @staticmethod
    def _edit_sensor(world, name, fields, frames):
        """A sensor's keys replaced and the whole spec validated again (its name and type stay)."""
        spec = sensor_named(world, name)
        if spec is None:
            raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
        for key in ("name", "type"):
            if key in fields and fields[key] != spec[key]:
                raise RequestError(FAILED, f"{name}.{key}: a sensor's {key} cannot be edited "
                                           "(remove it and spawn another)")
        parents = set(world.body_names())
        edited = validate_sensor({**spec, **fields}, name, parents, world_lumped_links(world))
        others = [s for s in world.sensor_specs if s is not spec]
        if sensor_frames(edited) != sensor_frames(spec):
            taken = {**frames_of_world(frames, world, others), **dict.fromkeys(parents, "a body's name"),
                     **{s["name"]: "a sensor's name" for s in others}}
            clash = next((frame for frame in sensor_frames(edited) if frame in taken), None)
            if clash is not None:
                raise RequestError(NAME_NOT_UNIQUE, f"{name}.frame_id: {specs.quote(clash)} is {taken[clash]}")
        check_sensors([*others, edited], world, frames)
        world.sensor_specs = [edited if s is spec else s for s in world.sensor_specs]
        return reply(OK, f"edited {name}: {', '.join(sorted(set(fields) - {'name', 'type'}))}")

    @handled
    def remove(self, text):
        request = as_mapping(parse(text), "remove")
        specs.mapping(request, "remove", {"entity", "filter", "all"})
        if len(request) != 1:
            raise RequestError(FAILED, "remove takes exactly one of entity, filter, all")
        if "entity" in request:
            return self.remove_entity(request["entity"])
        if "filter" in request:
            pattern = request["filter"]
            if not isinstance(pattern, str) or not pattern or len(pattern) > MAX_FILTER:
                raise RequestError(FAILED, f"remove.filter: expected a regular expression of 1-{MAX_FILTER} "
                                           f"characters, got {specs.quote(pattern)}")
            # The names GetEntities filters too (entity_table): bodies, sensors and URDF robots,
            # a robot matched taking its links with it.
            names = self.sim.call(lambda world: world.body_names() + [s["name"] for s in world.sensor_specs]
                                  + [robot["name"] for robot in world.robot_specs])
            doomed = match_names(pattern, names)  # here, not on the simulation thread
            if not doomed:
                raise RequestError(NOT_FOUND, f"no entity matches {specs.quote(pattern)}")
            return self.sim.call(lambda world: self._remove(world, doomed, strict=False))
        if request["all"] is not True:
            raise RequestError(FAILED, "remove.all: must be true")
        # Every entity: the sensors too (~/get_entities lists them), fixed ones included.
        return self.sim.call(lambda world: self._remove(
            world, world.body_names() + [s["name"] for s in world.sensor_specs], strict=True))

    @handled
    def remove_entity(self, name):
        """~/remove of one entity by name (its sensors go with it)."""
        if not isinstance(name, str):
            raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
        return self.sim.call(lambda world: self._remove(world, [name], strict=True))

    @staticmethod
    def _remove(world, doomed, strict):
        robots = {robot["name"]: robot["bodies"] for robot in world.robot_specs}
        # A URDF robot: its links (once, should a filter have matched them too).
        doomed = list(dict.fromkeys(body for name in doomed for body in robots.get(name, [name])))
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
            robot = robot_spec(world, name)
            if robot is not None:
                return describe_robot(world, robot)
            if name not in world.body_names():
                raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
            return describe(world, name)
        return True, yaml.dump(self.sim.call(read), Dumper=YAML_DUMPER, sort_keys=False)

    def entities(self):
        """[(name, description dict)] of every entity, as GetEntities lists them (entity_table):
        the bodies in the order of ~/bodies/poses, then the sensors, then the URDF robots."""
        def read(world):
            vehicles = set(world.vehicle_names())  # once, not per entity: 10,000 bodies stay linear
            names = world.body_names()
            present = set(names)
            # A sensor whose parent left the world goes at its next sample: not listed meanwhile.
            return ([(name, describe(world, name, vehicles)) for name in names]
                    + [(s["name"], describe_sensor(world, s)) for s in world.sensor_specs
                       if s["parent"] == "world" or s["parent"] in present]
                    + [(robot["name"], describe_robot(world, robot)) for robot in world.robot_specs])
        return self.sim.call(read)
