"""Scene files (SPEC 3) <-> World.

`load_world` takes a path to a YAML file or a dict in the same schema. Everything is checked,
and the playground mesh read, before the World is built: an error names the file, the key path
and the problem, and nothing is half-loaded.
"""
import logging
from pathlib import Path

import numpy as np
import yaml

from .physics import World
from .physics import specs
from .physics.math3d import rpy_to_quat
from .physics.world import quaternions_to_matrices
from .resources import find_shared

SCENE_VERSION = 1
TOP_LEVEL_KEYS = {"version", "settings", "ground", "playground", "bodies", "vehicles"}
PLAYGROUND_KEYS = {"mesh", "position", "rpy", "scale"}
MAX_PLAYGROUND_TRIANGLES = 500_000  # beyond this the octree and the viewer stop being real-time

log = logging.getLogger(__name__)


class SceneError(ValueError):
    """A scene that cannot be loaded: the message names the file, the key path and the problem."""


def read_scene(path_or_dict):
    """The scene as a dict, a label for error messages, and the folder mesh paths start from."""
    if isinstance(path_or_dict, dict):
        return path_or_dict, "<scene>", Path.cwd()
    path = Path(path_or_dict)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or str(error)
        raise SceneError(f"{path}: cannot read the scene file: {reason}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise SceneError(f"{path}: not valid YAML: {error}") from None
    return data, str(path), path.resolve().parent


def resolve_mesh(name, base):
    """A mesh path as written in a scene: absolute, else relative to the scene file's folder,
    else one of the package's meshes/. Returns the path or raises SpecError listing where it
    looked."""
    candidate = Path(name)
    tried = [candidate] if candidate.is_absolute() else [base / candidate]
    if tried[0].is_file():
        return tried[0]
    if not candidate.is_absolute():
        shared = find_shared(f"meshes/{name}")
        if shared is not None:
            return shared
        tried.append(Path("<package>/meshes") / name)
    raise specs.SpecError("playground.mesh", f"mesh file {name!r} not found (looked in: "
                                             f"{', '.join(str(p) for p in tried)})")


def read_mesh(path):
    """(vertices (V, 3), faces (T, 3)) of a Wavefront .obj (or any format trimesh reads)."""
    import trimesh  # only scenes with a playground need it

    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds for broken files
        raise specs.SpecError("playground.mesh", f"cannot read mesh {path}: {error}") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise specs.SpecError("playground.mesh", f"mesh {path} has no triangles")
    if len(faces) > MAX_PLAYGROUND_TRIANGLES:
        raise specs.SpecError("playground.mesh", f"mesh {path} has {len(faces)} triangles, more "
                                                 f"than the {MAX_PLAYGROUND_TRIANGLES} allowed")
    return vertices, faces


def validate_playground(raw, base):
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
    mesh_path = resolve_mesh(spec["mesh"], base)
    vertices, faces = read_mesh(mesh_path)
    rotation = quaternions_to_matrices(rpy_to_quat(spec["rpy"])[None])[0]
    world_vertices = (spec["scale"] * vertices) @ rotation.T + np.asarray(spec["position"])
    return {**spec, "mesh": str(mesh_path)}, world_vertices, faces


def validate_list(raw, key):
    items = raw.get(key) or []
    if not isinstance(items, list):
        raise specs.SpecError(key, f"expected a list, got {type(items).__name__}")
    return items


def validate_scene(scene, base):
    """Checks the whole scene; returns what load_world builds from."""
    specs.mapping(scene, "", TOP_LEVEL_KEYS)
    if "version" not in scene:
        raise specs.SpecError("version", f"missing (this program reads version {SCENE_VERSION})")
    if scene["version"] != SCENE_VERSION:
        raise specs.SpecError("version", f"unsupported version {scene['version']!r:.20} "
                                         f"(this program reads version {SCENE_VERSION})")
    settings = specs.validate_settings(scene.get("settings"))
    ground = specs.validate_ground(scene.get("ground", specs.DEFAULT_GROUND))
    playground = None
    if scene.get("playground") is not None:
        playground = validate_playground(scene["playground"], base)
    names = set()

    def claim(entry, path):
        if "name" in entry:
            if entry["name"] in names:
                raise specs.SpecError(f"{path}.name", f"duplicate name {entry['name']!r}")
            names.add(entry["name"])
        return entry

    bodies = [claim(specs.validate_body(raw, f"bodies[{k}]"), f"bodies[{k}]")
              for k, raw in enumerate(validate_list(scene, "bodies"))]
    vehicles = [claim(specs.validate_vehicle(raw, f"vehicles[{k}]"), f"vehicles[{k}]")
                for k, raw in enumerate(validate_list(scene, "vehicles"))]
    return settings, ground, playground, bodies, vehicles


def load_world(path_or_dict):
    scene, label, base = read_scene(path_or_dict)
    try:
        settings, ground, playground, bodies, vehicles = validate_scene(scene, base)
    except specs.SpecError as error:
        raise SceneError(f"{label}: {error}") from None
    world = World(settings, ground, capacity=max(64, len(bodies) + len(vehicles)))
    if playground is not None:
        spec, vertices, faces = playground
        try:
            dropped = world.set_playground(vertices, faces, spec)
        except ValueError as error:
            raise SceneError(f"{label}: playground.mesh: {spec['mesh']}: {error}") from None
        if dropped:
            log.warning("%s: playground mesh %s: dropped %d degenerate triangles", label,
                        spec["mesh"], dropped)
    for body in bodies:
        world.add_body(body)
    for vehicle in vehicles:
        world.add_vehicle(vehicle)
    return world


def packaged_mesh_name(path):
    """The bare file name when `path` is the package's own copy of it, so a saved scene keeps
    working wherever the package is installed; otherwise the absolute path."""
    name = Path(path).name
    shared = find_shared(f"meshes/{name}")
    return name if shared is not None and shared.resolve() == Path(path).resolve() else str(path)


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
    scene["bodies"] = [world.body(name) for name in world.body_names() if name not in vehicles]
    scene["vehicles"] = [world.vehicle(name) for name in vehicles]
    return scene
