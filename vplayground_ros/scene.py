"""Scene files (SPEC 3) <-> World.

`load_world` takes a path to a YAML file or a dict in the same schema. Everything is checked,
and the playground mesh read, before the World is built: an error names the file, the key path
and the problem, and nothing is half-loaded.
"""
import copy
import logging
import re
from collections import namedtuple
import stat
from pathlib import Path

import numpy as np
import yaml

from .broadcast import check_sensors
from .frame_names import DEFAULT_FRAMES, node_frames, sensor_frames, sensor_frames_taken
from .mesh_files import MeshError, read_obj, read_with_trimesh
from .physics import World
from .physics import specs
from .physics.math3d import rpy_to_quat
from .physics.math3d import quaternions_to_matrices
from .resources import find_shared, is_file
from .robots import validate_robot
from .sensors import lumped_links, validate_sensors
from .urdf_robots import (ENTRY_KEYS, VEHICLE_ENTRY_KEYS, add_robot_entry, check_against_model, description_source,
                          is_description_text, validate_entry, vehicle_entry)

SCENE_VERSION = 1
TOP_LEVEL_KEYS = {"version", "settings", "ground", "playground", "bodies", "vehicles", "robots",
                  "joints", "sensors"}
PLAYGROUND_KEYS = {"mesh", "position", "rpy", "scale"}
MAX_PLAYGROUND_TRIANGLES = 500_000  # beyond this the octree and the viewer stop being real-time
# Files are measured before they are read, so a hostile or mistaken path (a multi-gigabyte file)
# costs a stat, not the machine's memory. A 16 MiB scene holds ~100,000 bodies; a mesh within
# MAX_PLAYGROUND_TRIANGLES is ~20 MB of .obj text.
MAX_SCENE_BYTES = 16 << 20
MAX_MESH_BYTES = 64 << 20
# Self-contained formats only: glTF, COLLADA and others can make trimesh open further files.
MESH_TYPES = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off"}


class YamlLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """The safe loader (libyaml when it is there: ~5x faster than the pure-Python one, and it
    refuses nesting deeper than 1,000 levels itself) reading `1e-3` and `2E6` as numbers, as
    YAML 1.2 and JSON do: YAML 1.1 wants a dot (`1.0e-3`) and made them strings, which a
    `mass: 1e4` was then refused as."""


def construct_mapping(loader, node, deep=False):
    """A mapping whose keys, as written, are each there once (merge keys `<<:` aside, whose keys
    the mapping's own override): YAML keeps the last of a key given twice, so a scene with two
    `bodies:` lists had quietly lost the first."""
    seen = set()
    for key, _ in node.value:
        if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
            if key.value in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"the key {key.value[:80]!r} is given twice in one mapping", key.start_mark)
            seen.add(key.value)
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


YamlLoader.construct_mapping = construct_mapping
YamlLoader.add_implicit_resolver("tag:yaml.org,2002:float",
                                 re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))

# Written out, a document holds at most about one value per character; its aliases may repeat
# what it holds up to this many times that, beyond a small document's allowance.
ALIAS_EXPANSION = 2
ALIAS_ALLOWANCE = 10_000


class YamlExpansion(yaml.YAMLError):
    """A YAML document whose aliases build far more than its text holds, or a structure that
    contains itself."""


def load_yaml(text):
    """YAML text (size-capped by the caller) as plain data, refusing aliases that multiply it:
    the text's limit is what bounds a scene's or a request's work, and an alias to a list of
    100,000 points repeated by 10,000 bodies (810 KB of text) had built 10^9 values (an hour and
    ~190 GB), and one that contains itself (`&a {parts: [*a]}`) recursed without end."""
    loader = YamlLoader(text)
    try:
        node = loader.get_single_node()
        if node is not None and "*" in text:  # an alias starts with '*'
            check_aliases(node, ALIAS_EXPANSION * len(text) + ALIAS_ALLOWANCE, len(text))
        return None if node is None else loader.construct_document(node)
    finally:
        loader.dispose()


def check_aliases(root, limit, characters):
    """Counts the nodes of the document (of `characters`) as its aliases expand it (each node
    once where it is written, again wherever an alias repeats it), up to `limit`; YamlExpansion
    beyond it, or for a node inside itself. Iterative: a document may nest a thousand levels
    deep."""
    sizes = {}      # id(node) -> nodes it expands to, itself included
    open_ = set()   # nodes being counted (the path down to where the walk is): met again, a cycle
    stack = [(root, False)]
    while stack:
        node, counted = stack.pop()
        key = id(node)
        if counted:
            sizes[key] = 1 + sum(sizes[id(child)] for child in node_children(node))
            open_.discard(key)
            if sizes[key] > limit:
                raise YamlExpansion(f"its aliases expand its {characters:,} characters to more than {limit:,} "
                                    "values (twice what they could hold written out, and 10,000): write the "
                                    "values out, or repeat fewer")
        elif key not in sizes:
            if isinstance(node, yaml.ScalarNode):
                sizes[key] = 1
                continue
            open_.add(key)
            stack.append((node, True))
            for child in node_children(node):
                if id(child) in open_:
                    raise YamlExpansion("an alias is inside the node it names (a structure that contains itself)")
                if id(child) not in sizes:
                    stack.append((child, False))


def node_children(node):
    """A sequence's items, a mapping's keys and values."""
    return node.value if isinstance(node, yaml.SequenceNode) else [part for pair in node.value for part in pair]


log = logging.getLogger(__name__)


class SceneError(ValueError):
    """A scene that cannot be loaded: the message names the file, the key path and the problem;
    `code` the simulation_interfaces result of a missing or unsupported mesh or an unknown key
    (MISSING_ASSETS, UNSUPPORTED_ASSETS, UNSUPPORTED_ELEMENTS), else None."""

    def __init__(self, message, cause=None):
        super().__init__(message)
        self.code = next((code for kind, code in ASSET_CODES if isinstance(cause, kind)), None)


class MissingMesh(specs.SpecError):
    """A mesh file that is not there (or not where a request may read)."""


class UnsupportedMesh(specs.SpecError):
    """A mesh file of a type no reader here takes."""


ASSET_CODES = ((MissingMesh, "MISSING_ASSETS"), (UnsupportedMesh, "UNSUPPORTED_ASSETS"),
               (specs.UnknownKey, "UNSUPPORTED_ELEMENTS"))


def read_capped(path, limit, what):
    """The bytes of a regular file of at most `limit` bytes, measured before it is read (and
    while, should it grow); else ValueError saying why. Devices and pipes are refused."""
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ValueError(f"the {what} is not a regular file")
        if info.st_size > limit:
            raise ValueError(f"the {what} has {info.st_size} bytes, more than the {limit} allowed")
        with open(path, "rb") as stream:
            data = stream.read(limit + 1)
    except OSError as error:
        raise ValueError(f"cannot read the {what}: {error.strerror or error}") from None
    if len(data) > limit:
        raise ValueError(f"the {what} has more than the {limit} bytes allowed")
    return data


def read_scene(path_or_dict):
    """The scene as a dict, a label for error messages, and the folder mesh paths start from."""
    if isinstance(path_or_dict, dict):
        return path_or_dict, "<scene>", Path.cwd()
    path = Path(path_or_dict)
    try:
        text = read_capped(path, MAX_SCENE_BYTES, "scene file").decode("utf-8")
    except ValueError as error:  # UnicodeDecodeError is a ValueError too
        raise SceneError(f"{path}: {str(error)[:200]}") from None
    try:
        data = load_yaml(text)
    except yaml.YAMLError as error:
        raise SceneError(f"{path}: not valid YAML: {error}") from None
    except (ValueError, RecursionError) as error:  # e.g. an integer of more than 4,300 digits
        raise SceneError(f"{path}: not valid YAML: {type(error).__name__}: {error}") from None
    return data, str(path), path.resolve().parent


# How a scene names a mesh of the package's meshes/ wherever the package is installed (the ROS
# resource URI): what saved scenes write, so a file of the same name beside them is not taken.
PACKAGE_MESHES = "package://vplayground_ros/meshes/"
# What resolve_mesh calls a robot's description file it looks for the same way.
DESCRIPTION_FILE = "robot description"


def resolve_mesh(name, base, directories=None, key="playground.mesh", shared_folder="meshes", kind="mesh file"):
    """A mesh path as written in a scene: `package://vplayground_ros/meshes/<file>`, absolute,
    else relative to the scene file's folder, else one of the package's `shared_folder` (meshes/;
    config/ for a robot's description: the built-in car's, wherever its scene was copied to).
    With `directories` (scenes loaded for a service call), a mesh outside them and the package's
    folder is refused, symbolic links resolved. Returns the path or raises SpecError listing
    where it looked, naming the file as `kind` (what the caller looks for)."""
    if name.startswith("package://") and not name.startswith(PACKAGE_MESHES):
        raise specs.SpecError(key, f"{kind} {specs.quote(name)}: package:// names only this package's "
                                   f"meshes ({PACKAGE_MESHES}<file>); give another file by its path")
    if name.startswith(PACKAGE_MESHES):
        file_name = name[len(PACKAGE_MESHES):]
        shared = find_shared(f"meshes/{file_name}") if file_name and Path(file_name).name == file_name else None
        if shared is None:
            raise MissingMesh(key, f"{kind} {specs.quote(name)}: the package has no mesh {specs.quote(file_name)}")
        return shared
    candidate = Path(name)
    tried = [candidate] if candidate.is_absolute() else [base / candidate]
    if is_file(tried[0]):
        if directories is not None and not inside(tried[0], directories) and not is_shared(tried[0], shared_folder):
            raise MissingMesh(key, f"{kind} {specs.quote(name)} resolves outside the allowed directories")
        return tried[0]
    if not candidate.is_absolute() and ".." not in candidate.parts:  # (no way out of the folder)
        shared = find_shared(f"{shared_folder}/{name}")
        if shared is not None:
            return shared
        tried.append(Path(f"<package>/{shared_folder}") / name)
    raise MissingMesh(key, f"{kind} {specs.quote(name)} not found (looked in: "
                           f"{', '.join(str(p) for p in tried)})")


def is_shared(path, shared_folder):
    """Whether `path` is one of the package's own files in `shared_folder` (readable by any path
    to it, as by its name)."""
    shared = find_shared(f"{shared_folder}/{Path(path).name}")
    try:
        return shared is not None and shared.resolve() == Path(path).resolve()
    except (OSError, RuntimeError):
        return False


def inside(path, directories):
    """Whether `path`, symbolic links and `..` resolved, lies within one of `directories`."""
    try:
        resolved = Path(path).resolve()
        return any(resolved.is_relative_to(Path(d).resolve()) for d in directories)
    except (OSError, ValueError, RuntimeError):  # unreadable, NUL byte, symlink loop
        return False


# A face statement: `f` at the start of a line (after blanks, which .obj allows), its corners.
OBJ_FACE = re.compile(rb"^[ \t]*f[ \t]([^\r\n]*)", re.MULTILINE)


def count_obj_triangles(data, path, key):
    """Triangles an .obj's faces make once fanned (a face of n corners is n - 2), counted from
    the raw bytes so a file of millions is refused before they are parsed one by one (faces
    indented or on classic Mac OS line ends as well: they had been parsed, 6 million of them in
    8 s and 440 MB, before their count was refused)."""
    if data.count(b"\nf ") + data.count(b"\nf\t") > MAX_PLAYGROUND_TRIANGLES:  # the usual form, at once
        raise specs.SpecError(key, f"mesh {path} has more than the "
                                                 f"{MAX_PLAYGROUND_TRIANGLES} triangles allowed")
    if b"\n" not in data:  # line ends as obj_text reads them
        data = data.replace(b"\r", b"\n")
    triangles = 0
    for match in OBJ_FACE.finditer(data):
        triangles += max(0, len(match.group(1).split()) - 2)
        if triangles > MAX_PLAYGROUND_TRIANGLES:
            raise specs.SpecError(key, f"mesh {path} has more than the "
                                                     f"{MAX_PLAYGROUND_TRIANGLES} triangles allowed")
    return triangles


def read_mesh(path, key="playground.mesh"):
    """(vertices (V, 3), faces (T, 3)) of a Wavefront .obj (or .stl, .ply, .off); errors name
    `key`, the scene key that gave the path."""
    file_type = MESH_TYPES.get(Path(path).suffix.lower())
    if file_type is None:
        raise UnsupportedMesh(key, f"mesh {path}: unsupported file type (supported: "
                                   f"{', '.join(sorted(MESH_TYPES))})")
    try:
        data = read_capped(Path(path), MAX_MESH_BYTES, "mesh file")
    except ValueError as error:
        raise specs.SpecError(key, f"mesh {path}: {error}") from None
    if file_type == "obj":
        count_obj_triangles(data, path, key)
    try:
        vertices, faces = read_obj(data) if file_type == "obj" else read_with_trimesh(data, file_type)
    except MeshError as error:
        raise specs.SpecError(key, f"mesh {path}: {error}") from None
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise specs.SpecError(key, f"mesh {path} has no triangles")
    if len(faces) > MAX_PLAYGROUND_TRIANGLES:
        raise specs.SpecError(key, f"mesh {path} has {len(faces)} triangles, more "
                                                 f"than the {MAX_PLAYGROUND_TRIANGLES} allowed")
    return vertices, faces


def validate_playground(raw, base, directories=None):
    """The playground spec over its defaults, and its world-space vertices and faces."""
    path = "playground"
    specs.mapping(raw, path, PLAYGROUND_KEYS)
    if "mesh" not in raw:
        raise specs.SpecError("playground.mesh", "missing (a mesh file, e.g. playground.obj)")
    if not isinstance(raw["mesh"], str) or not raw["mesh"]:
        raise specs.SpecError("playground.mesh", "expected a file name")
    spec = {"mesh": raw["mesh"],
            "position": specs.vector(raw.get("position", [0, 0, 0]), "playground.position", 3,
                                     -specs.MAX_COORDINATE, specs.MAX_COORDINATE),
            "rpy": specs.vector(raw.get("rpy", [0, 0, 0]), "playground.rpy", 3, -1.0e3, 1.0e3),
            "scale": specs.number(raw.get("scale", 1.0), "playground.scale", 0.0, 1.0e4,
                                  low_open=True)}
    mesh_path = resolve_mesh(spec["mesh"], base, directories)
    vertices, faces = read_mesh(mesh_path)
    rotation = quaternions_to_matrices(rpy_to_quat(spec["rpy"])[None])[0]
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite vertices are refused below
        world_vertices = (spec["scale"] * vertices) @ rotation.T + np.asarray(spec["position"])
    # Beyond this the octree's cells and the world's bounds (centred on the mesh) lose meaning.
    far = np.nonzero(~(np.abs(world_vertices) <= specs.MAX_COORDINATE).all(axis=1))[0]
    if len(far):
        raise specs.SpecError("playground.mesh", f"mesh {mesh_path}: vertex {far[0]} is at "
                                                 f"{world_vertices[far[0]].tolist()}, beyond "
                                                 f"{specs.MAX_COORDINATE:g} m (or not finite)")
    return {**spec, "mesh": str(mesh_path)}, world_vertices, faces


def validate_list(raw, key):
    items = raw.get(key)
    if items is None:  # missing or `key:` alone; any other non-list (false, 0, {}) is a mistake
        return []
    if not isinstance(items, list):
        raise specs.SpecError(key, f"expected a list, got {type(items).__name__}")
    return items


def body_mesh_points(raw, path, base, directories=None):
    """A convex body's `mesh:` (a file, found as the playground's is) read into its `points`
    (the vertices its triangles use), and a compound's convex parts' likewise; any other body as
    it is."""
    if isinstance(raw, dict) and raw.get("shape") == "compound" and isinstance(raw.get("parts"), list):
        raw = {**raw, "parts": [body_mesh_points(part, specs.child(specs.child(path, "parts"), k), base, directories)
                                for k, part in enumerate(raw["parts"])]}
    if not isinstance(raw, dict) or "mesh" not in raw:
        return raw
    key = f"{path}.mesh"
    if raw.get("shape") != "convex":
        raise specs.SpecError(key, "only a convex body takes a mesh (shape: convex)")
    if "points" in raw:
        raise specs.SpecError(path, "give either mesh or points, not both")
    if not isinstance(raw["mesh"], str) or not raw["mesh"]:
        raise specs.SpecError(key, "expected a file name")
    vertices, faces = read_mesh(resolve_mesh(raw["mesh"], base, directories, key), key)
    body = {k: v for k, v in raw.items() if k != "mesh"}
    return {**body, "points": vertices[np.unique(faces)].tolist()}


def name_unnamed(bodies, vehicles, taken):
    """Gives the unnamed bodies and vehicles ([(path, entry)]) the names World._generate_name
    would (box_<n>, then car_<n>, one counter, in the order load_world adds them) but skipping
    every name in `taken`, so a name given further down the file still wins. `taken` gains them.
    Returns {name: what has it} for the sensors' messages."""
    owners, count = {}, 0
    for prefix, entries in (("box", bodies), ("car", vehicles)):
        for path, entry in entries:
            if "name" in entry:
                owners[entry["name"]] = f"{path}'s name"
                continue
            count += 1
            while f"{prefix}_{count}" in taken:
                count += 1
            entry["name"] = f"{prefix}_{count}"
            taken.add(entry["name"])
            owners[entry["name"]] = f"the name generated for {path}"
    return owners


def validate_scene(scene, base, max_bodies=None, directories=None, frames=DEFAULT_FRAMES):
    """Checks the whole scene; returns what load_world builds from, every body and vehicle named.
    `frames`: the node's (world, odom, base) frame names, which no entity may take."""
    specs.mapping(scene, "", TOP_LEVEL_KEYS)
    if "version" not in scene:
        raise specs.SpecError("version", f"missing (this program reads version {SCENE_VERSION})")
    if type(scene["version"]) is not int or scene["version"] != SCENE_VERSION:  # not True, not 1.0
        raise specs.SpecError("version", f"unsupported version {specs.quote(scene['version'])} "
                                         f"(this program reads version {SCENE_VERSION})")
    settings = specs.validate_settings(scene.get("settings"))
    ground = specs.validate_ground(scene.get("ground", specs.DEFAULT_GROUND))
    count = len(validate_list(scene, "bodies")) + len(validate_list(scene, "vehicles"))
    if max_bodies is not None and count > max_bodies:  # before any body is validated
        raise specs.SpecError("bodies", f"the scene has {count} bodies and vehicles, more than "
                                        f"max_bodies ({max_bodies})")
    playground = None
    if scene.get("playground") is not None:
        playground = validate_playground(scene["playground"], base, directories)
    names = set()

    def claim(entry, path):
        if "name" in entry:
            if entry["name"] in names:
                raise specs.SpecError(f"{path}.name", f"duplicate name {specs.quote(entry['name'])}")
            names.add(entry["name"])
        return entry

    # Each entry with the key its errors name: [(path, entry)].
    bodies = [(f"bodies[{k}]", claim(specs.validate_body(body_mesh_points(raw, f"bodies[{k}]", base, directories),
                                                         f"bodies[{k}]"), f"bodies[{k}]"))
              for k, raw in enumerate(validate_list(scene, "bodies"))]
    vehicles = [(f"vehicles[{k}]", claim(validate_robot(specs.validate_vehicle(raw, f"vehicles[{k}]"), f"vehicles[{k}]"),
                                         f"vehicles[{k}]"))
                for k, raw in enumerate(validate_list(scene, "vehicles"))]
    described = robot_sources(scene, base, directories)
    for k, (entry, _, label, (text, _)) in enumerate(described):  # a ray-cast vehicle's description: a vehicle
        vehicle = read_robot(lambda: vehicle_entry(entry, f"robots[{k}]", text, label))
        if vehicle is not None:
            vehicles.append((f"robots[{k}]", claim(vehicle, f"robots[{k}]")))
            described[k] = None
    # Named before the sensors are checked: a sensor's name is a frame and must not be a body's,
    # generated or not.
    owners = name_unnamed(bodies, vehicles, names)
    robots = validate_robots(described, directories, owners)
    count = len(bodies) + len(vehicles) + sum(len(model.bodies) for _, (_, model) in robots)
    if max_bodies is not None and count > max_bodies:
        raise specs.SpecError("robots", f"the scene has {count} bodies (vehicles and the robots' links counted), "
                                        f"more than max_bodies ({max_bodies})")
    sensors = validate_sensors(scene.get("sensors"), owners,
                               links=lumped_links((entry["name"], model) for _, (entry, model) in robots))
    # The names against the node's frames and the optical frames of the cameras named by them;
    # a frame_id is checked against everything below, naming the sensor's key.
    reserved = {**node_frames(frames), **sensor_frames_taken([s for s in sensors if "frame_id" not in s])}
    for path, entry in (*bodies, *vehicles, *((f"sensors[{k}]", sensor) for k, sensor in enumerate(sensors))):
        if entry["name"] in reserved:
            raise specs.SpecError(f"{path}.name", f"{specs.quote(entry['name'])} is {reserved[entry['name']]} "
                                                  "(names are frames: the node publishes that one)")
    # A sensor's frame_id is a frame too: none of the node's, no entity's name, no other sensor's.
    taken = {**reserved, **owners, **{s["name"]: f"the sensor {s['name']}" for s in sensors}}
    for k, sensor in enumerate(sensors):
        for frame in sensor_frames(sensor) if "frame_id" in sensor else ():
            if frame in taken:
                raise specs.SpecError(f"sensors[{k}].frame_id", f"the frame {specs.quote(frame)} is {taken[frame]}")
            taken[frame] = f"a frame of the sensor {sensor['name']}"
    joints = validate_joints(scene, owners)
    return settings, ground, playground, bodies, vehicles, robots, joints, sensors


def robot_sources(scene, base, directories):
    """The scene's `robots` entries, each with its description's source (the file, found as a
    mesh is, or the text itself), the label its errors start with and the description as read
    once (urdf_import.read_description's text and folder; xacro, which reads environment
    variables and any file, expanded for the command line's scene alone):
    [(raw entry, source, label, (text, folder))]."""
    from .urdf_import import read_description  # (urdf_import reads meshes through this module)
    sources = []
    for k, raw in enumerate(validate_list(scene, "robots")):
        path = f"robots[{k}]"
        specs.mapping(raw, path, ENTRY_KEYS | VEHICLE_ENTRY_KEYS)
        source = description_source(raw, path)
        text = is_description_text(source)
        file = str(source if text else resolve_mesh(source, base, directories, f"{path}.urdf", "config",
                                                            DESCRIPTION_FILE))
        label = f"{path}.urdf" + ("" if text else f": {file}")
        sources.append((raw, file, label, read_robot(lambda: read_description(file, label, directories is None))))
    return sources


def read_robot(read):
    """What `read()` reads of a description, its UrdfError a SpecError (the message names the file)."""
    from .urdf_import import UrdfError  # (urdf_import reads meshes through this module)
    try:
        return read()
    except UrdfError as error:
        raise specs.SpecError("", str(error)) from None


def validate_robots(described, directories, owners):
    """The scene's URDF robots (robot_sources' entries; None for those that are vehicles): each
    entry checked (urdf_robots.validate_entry) and its description read into a
    urdf_import.RobotModel; `owners` (body and vehicle names) gains their bodies. Returns
    [(path, (entry, model))]."""
    from .urdf_import import robot_model
    robots = []
    for k, item in enumerate(described):
        if item is None:
            continue
        raw, file, label, description = item
        path = f"robots[{k}]"
        entry, fields = validate_entry(raw, path)
        model = read_robot(lambda: robot_model(file, entry["name"], fields.get("position", [0.0, 0.0, 0.0]),
                                               fields.get("rpy", [0.0, 0.0, 0.0]), entry.get("fixed_base"),
                                               entry.get("self_collide", False), entry["joint_positions"],
                                               label=label, quaternion=fields.get("quaternion"),
                                               directories=directories, description=description))
        check_against_model(entry, model, path)
        if entry["name"] in owners:
            raise specs.SpecError(f"{path}.name", f"{specs.quote(entry['name'])} is {owners[entry['name']]}")
        owners[entry["name"]] = "a robot"
        for body in model.bodies:
            if body["name"] in owners:
                raise specs.SpecError(f"{path}.name", f"its link body {body['name']!r} is {owners[body['name']]}")
            owners[body["name"]] = f"a link of the robot {entry['name']}"
        entry.update({key: fields[key] for key in ("position", "rpy", "quaternion") if key in fields})
        entry["urdf"] = str(file)  # found once: a scene saved elsewhere must still find it
        robots.append((path, (entry, model)))
    return robots


def validate_joints(scene, owners):
    """The scene's `joints` (specs.validate_joint), each name given once, between bodies or
    vehicles of the scene (`owners`: their names): [(path, joint)]."""
    joints, names = [], set()
    for k, raw in enumerate(validate_list(scene, "joints")):
        path = f"joints[{k}]"
        joint = specs.validate_joint(raw, path)
        for key in ("parent", "child"):
            if key in joint and joint[key] not in owners:
                raise specs.SpecError(f"{path}.{key}", f"no body or vehicle named {specs.quote(joint[key])} "
                                                       "in the scene")
        if "name" in joint:
            if joint["name"] in names:
                raise specs.SpecError(f"{path}.name", f"duplicate joint name {specs.quote(joint['name'])}")
            names.add(joint["name"])
        joints.append((path, joint))
    return joints


def load_world(path_or_dict, max_bodies=None, directories=None, frames=DEFAULT_FRAMES):
    """A World from a scene file or dict. `max_bodies` caps its bodies (vehicles and robot links
    counted); `directories`
    confines the playground mesh to them (and the package's meshes/); `frames` are the node's
    frame names (parameters.Frames), which no body or sensor may take."""
    return build_world(scene_recipe(path_or_dict, max_bodies, directories, frames))


def scene_recipe(path_or_dict, max_bodies=None, directories=None, frames=DEFAULT_FRAMES):
    """A scene file or dict read and validated (load_world's arguments), not yet built."""
    scene, label, base = read_scene(path_or_dict)
    try:
        parts = validate_scene(scene, base, max_bodies, directories, frames)
    except specs.SpecError as error:
        raise SceneError(f"{label}: {error}", error) from None
    return SceneRecipe(label, frames, *parts)


class SceneRecipe(namedtuple("SceneRecipe", "label frames settings ground playground bodies vehicles robots "
                                            "joints sensor_specs")):
    """A scene as validated (its label, the frame names it was checked under and validate_scene's
    parts): what build_world makes a World of, kept on the World as `recipe`, so that a full
    reset makes the world as loaded again, bit for bit, without reading its files or validating
    it again. (Made again from the saved scene, world_to_scene's, it had differed in the last
    bits: a robot's root pose and joint angles as measured, a hull's inertia from its points
    centred, and a pile's rounding grows.)"""


def build_world(recipe):
    """A new World of `recipe` (SceneRecipe); the recipe is left as it was."""
    # Every part copied but the robots' models (read-only descriptions, as a reset of the state
    # shares them): adding an entry fills in its defaults.
    scene = copy.deepcopy(recipe, {id(model): model for _, (_, model) in recipe.robots})
    label, frames, settings, ground, playground, bodies, vehicles, robots, joints, sensor_specs = scene
    world = World(settings, ground, capacity=max(64, len(bodies) + len(vehicles)))
    if playground is not None:
        spec, vertices, faces = playground
        try:
            dropped = world.set_playground(vertices, faces, spec)
        except ValueError as error:
            raise SceneError(f"{label}: playground.mesh: {spec['mesh']}: {error}") from None
        if dropped == len(faces):
            raise SceneError(f"{label}: playground.mesh: {spec['mesh']}: all {dropped} triangles are "
                             "degenerate (repeated or collinear corners)")
        if dropped:
            log.warning("%s: playground mesh %s: dropped %d degenerate triangles", label,
                        spec["mesh"], dropped)
    # Vehicles before robots: the first of them stands in the root namespace.
    for entries, add in ((bodies, world.add_body), (vehicles, world.add_vehicle),
                         (robots, lambda pair, path: add_robot_entry(world, *pair, path, frames)),
                         (joints, world.add_joint)):
        for path, entry in entries:
            try:
                add(entry, path)
            except ValueError as error:  # checks that need the world (e.g. inside its bounds)
                raise SceneError(f"{label}: {error}") from None
    try:  # needs the robots' namespaces, which the World gave them
        check_sensors(sensor_specs, world, frames)
    except specs.SpecError as error:
        raise SceneError(f"{label}: sensors: {error}") from None
    world.sensor_specs = sensor_specs
    world.recipe = recipe
    return world


def packaged_mesh_name(path):
    """`package://vplayground_ros/meshes/<file>` when `path` is the package's own copy of it, so
    a saved scene keeps working wherever the package is installed (and a file of that name
    beside the saved scene is not taken for it); otherwise the absolute path."""
    name = Path(path).name
    shared = find_shared(f"meshes/{name}")
    return PACKAGE_MESHES + name if shared is not None and shared.resolve() == Path(path).resolve() else str(path)


def joint_spec(joint):
    """A joint as a scene holds it: World.joint's keys but its state (a fixed joint has no
    position)."""
    dropped = ("velocity", "effort") + (("position",) if joint["type"] == "fixed" else ())
    return {key: value for key, value in joint.items() if key not in dropped}


def saved_robots(world):
    """The world's URDF robots as scene entries (the root where it stands now, each joint's
    position; link velocities are not kept), and the names of the bodies and joints they hold.
    (A robot that lost a body is no longer listed: what is left is saved as bodies and joints.)"""
    entries, parts = [], set()
    for spec in world.robot_specs:
        root = world.body(spec["bodies"][0])
        joints = spec["model"].joint_names
        entry = {key: spec[key] for key in ("name", "urdf", "fixed_base", "self_collide", "hold", "namespace", "joints",
                                            "drive", "localization", "publish_odom_tf") if key in spec}
        if entry["joints"] == [joint for joint in joints if joint not in spec["model"].mimics]:  # the default
            del entry["joints"]
        entry.update(position=root["position"], quaternion=root["quaternion"],
                     joint_positions={joint: world.joint(entity)["position"] for joint, entity in joints.items()})
        entries.append(entry)
        parts |= set(spec["bodies"]) | set(joints.values())
    return entries, parts


def save_world(world, path):
    """Writes the world as a scene file that load_world turns back into the same world."""
    Path(path).write_text(yaml.safe_dump(world_to_scene(world), sort_keys=False), encoding="utf-8")


def world_to_scene(world):
    """The world as a scene dict (SPEC 3) that load_world turns back into the same world."""
    vehicles = world.vehicle_names()
    scene = {
        "version": SCENE_VERSION,
        "settings": world.settings,
        "ground": world.ground,
    }
    if world.playground_spec is not None:
        scene["playground"] = {**world.playground_spec,
                               "mesh": packaged_mesh_name(world.playground_spec["mesh"])}
    robots, robot_parts = saved_robots(world)
    scene["bodies"] = [world.body(name) for name in world.body_names()
                       if name not in vehicles and name not in robot_parts]
    scene["vehicles"] = [world.vehicle(name) for name in vehicles]
    if robots:
        scene["robots"] = robots
    joints = [joint_spec(world.joint(name)) for name in world.joint_names() if name not in robot_parts]
    if joints:
        scene["joints"] = joints
    present = set(world.body_names())
    sensors = [dict(s) for s in world.sensor_specs if s["parent"] == "world" or s["parent"] in present]
    if sensors:
        scene["sensors"] = sensors
    return scene
