"""Scene files (SPEC 3) <-> World.

`load_world` takes a path to a YAML file or a dict in the same schema; every error names the
file, the key path and the problem, and nothing is built until everything has been checked.
"""
from pathlib import Path

import yaml

from .physics import World
from .physics import specs

SCENE_VERSION = 1
TOP_LEVEL_KEYS = {"version", "settings", "ground", "bodies"}


class SceneError(ValueError):
    """A scene that cannot be loaded: the message names the file, the key path and the problem."""


def read_scene(path_or_dict):
    """The scene as a dict, and a label for error messages."""
    if isinstance(path_or_dict, dict):
        return path_or_dict, "<scene>"
    path = Path(path_or_dict)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise SceneError(f"{path}: cannot read the scene file: {error.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise SceneError(f"{path}: not valid YAML: {error}") from None
    return data, str(path)


def validate_scene(scene):
    """Checks the whole scene; returns (settings, ground, [body specs])."""
    specs.mapping(scene, "", TOP_LEVEL_KEYS)
    if "version" not in scene:
        raise specs.SpecError("version", f"missing (this program reads version {SCENE_VERSION})")
    if scene["version"] != SCENE_VERSION:
        raise specs.SpecError("version", f"unsupported version {scene['version']!r:.20} "
                                         f"(this program reads version {SCENE_VERSION})")
    settings = specs.validate_settings(scene.get("settings"))
    ground = specs.validate_ground(scene.get("ground", specs.DEFAULT_GROUND))
    raw_bodies = scene.get("bodies") or []
    if not isinstance(raw_bodies, list):
        raise specs.SpecError("bodies", f"expected a list, got {type(raw_bodies).__name__}")
    bodies, names = [], set()
    for k, raw in enumerate(raw_bodies):
        body = specs.validate_body(raw, f"bodies[{k}]")
        if "name" in body:
            if body["name"] in names:
                raise specs.SpecError(f"bodies[{k}].name", f"duplicate name {body['name']!r}")
            names.add(body["name"])
        bodies.append(body)
    return settings, ground, bodies


def load_world(path_or_dict):
    scene, label = read_scene(path_or_dict)
    try:
        settings, ground, bodies = validate_scene(scene)
    except specs.SpecError as error:
        raise SceneError(f"{label}: {error}") from None
    world = World(settings, ground, capacity=max(64, len(bodies)))
    for body in bodies:
        world.add_body(body)
    return world


def save_world(world, path):
    """Writes the world as a scene file that load_world turns back into the same world."""
    scene = {
        "version": SCENE_VERSION,
        "settings": world.settings,
        "ground": world.ground,
        "bodies": [world.body(name) for name in world.body_names()],
    }
    Path(path).write_text(yaml.safe_dump(scene, sort_keys=False), encoding="utf-8")
