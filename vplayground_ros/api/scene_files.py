"""The scene-file services: ~/load_scene (LoadMap) and ~/save_scene, within the scene
directories (file_access.py); the worlds of simulation_interfaces (load_world from a file or
YAML text, unload_world, get_current_world, get_available_worlds) are the same scene files.
"""
import copy
import re
from pathlib import Path

import yaml

from ..physics import specs
from ..scene import SceneError, load_world, world_to_scene
from .file_access import allowed_directories, confine, local_path, write_file
from .payload import YAML_DUMPER, as_mapping, parse
from .results import (FAILED, INVALID_MAP_DATA, MAP_DOES_NOT_EXIST, MAP_SUCCESS, NO_WORLD_LOADED, NOT_FOUND, OK,
                      UNDEFINED_FAILURE, UNSUPPORTED_FORMAT, RequestError, handled, reply)

SCENE_SUFFIXES = (".yaml", ".yml")
MAX_LISTED_WORLDS = 1000  # scene files get_available_worlds lists


class SceneRequests:
    """Requests' scene-file handlers (see requests.py for the state they share)."""

    def load_scene(self, path, stopped=False):
        """(LoadMap result code, message). The old world stays on any failure. `stopped`: the
        new world waits paused at its start (simulation_interfaces LoadWorld)."""
        try:
            target = confine(path, "load_scene", self.scene_directories)
        except RequestError as error:
            return MAP_DOES_NOT_EXIST, str(error)
        if not target.is_file():
            return MAP_DOES_NOT_EXIST, f"{NOT_FOUND}: no scene file at {specs.quote(path)}"
        return self._load(target, str(target), stopped)

    def load_scene_text(self, text, stopped=False):
        """load_scene of a scene given as YAML text (meshes from the scene directories)."""
        try:
            scene = parse(text, "resource_string")
        except RequestError as error:
            return INVALID_MAP_DATA, str(error)
        if not isinstance(scene, dict):
            return INVALID_MAP_DATA, (f"{UNSUPPORTED_FORMAT}: a world is this package's scene YAML (a mapping "
                                      f"of settings, bodies, vehicles...), got {type(scene).__name__}")
        return self._load(scene, "", stopped, text)

    def _load(self, source, label, stopped, text=""):
        try:
            world = load_world(source, max_bodies=int(self.max_bodies),
                               directories=allowed_directories(self.scene_directories), frames=self.frames())
            initial = copy.deepcopy(world_to_scene(world))
        except SceneError as error:
            return INVALID_MAP_DATA, f"{error.code or FAILED}: {str(error)[:1000]}"

        def install(_):
            self.sim.world = world
            self.sim.clear_steps()  # none queued for the old world run on the new one
            self.initial = initial
            self.initial_robots = list(world.robot_specs)
            self.initial_recipe = world.recipe
            self.scene_label, self.scene_text = label, text
            self.sim.world_loaded = True
            if stopped:
                self.sim.paused = self.sim.stopped = True
        try:
            self.sim.call(install)
        except TimeoutError as error:
            return UNDEFINED_FAILURE, f"{FAILED}: {error}"
        self._follow_scene_settings()
        return MAP_SUCCESS, f"{OK}: loaded {label or 'a scene from text'} ({len(world.body_names())} bodies)"

    @handled
    def unload_world(self):
        """An empty world, paused, until a scene is loaded (simulation_interfaces NO_WORLD)."""
        empty = load_world({"version": 1})

        def unload(world):
            if not self.sim.world_loaded:
                raise RequestError(NO_WORLD_LOADED, "no world is loaded")
            self.sim.world = empty
            self.sim.clear_steps()
            self.initial = copy.deepcopy(world_to_scene(empty))
            self.initial_robots = []
            self.initial_recipe = empty.recipe
            self.scene_label = self.scene_text = ""
            self.sim.world_loaded, self.sim.paused, self.sim.stopped = False, True, False
            return reply(OK, "unloaded: every entity removed")
        answer = self.sim.call(unload)
        self._follow_scene_settings()  # the parameters show the empty world's settings, not the last scene's
        return answer

    def current_world(self):
        """(file of the loaded scene, or '' and the YAML it was loaded from), or None when no
        world is loaded."""
        return self.sim.call(lambda world: (self.scene_label, self.scene_text) if self.sim.world_loaded else None)

    def available_worlds(self, sources=()):
        """The scene files (.yaml, .yml that declare a `version:`) directly inside the scene
        directories and inside `sources` (directories, each within a scene directory): [(path,
        description)], the description being the file's first comment line. FAILED naming a
        source outside."""
        roots = allowed_directories(self.scene_directories)
        folders = list(roots)
        for source in sources:
            raw = local_path(source)
            folder = Path(raw).resolve() if raw else None
            if folder is None or not folder.is_dir() or not any(folder == r or r in folder.parents for r in roots):
                raise RequestError(FAILED, f"additional_sources: {specs.quote(source)} is not a directory inside "
                                           "the scene directories (the scene_directories parameter)")
            folders.append(folder)
        found = {}
        for folder in folders:
            for path in sorted(folder.iterdir()):
                description = (world_description(path) if path.suffix in SCENE_SUFFIXES and path.is_file()
                               and path not in found else None)
                if description is not None:
                    found[path] = description
                    if len(found) >= MAX_LISTED_WORLDS:
                        return list(found.items())
        return list(found.items())

    @handled
    def save_scene(self, text):
        if not isinstance(text, str):
            raise RequestError(FAILED, "save_scene: expected a path or {path: ..., overwrite: true}")
        request = parse(text) if text.strip().startswith("{") else {"path": text.strip()}
        request = as_mapping(request, "save_scene")
        specs.mapping(request, "save_scene", {"path", "overwrite"})
        overwrite = specs.boolean(request.get("overwrite", False), "save_scene.overwrite")
        target = confine(request.get("path"), "save_scene.path", self.scene_directories)
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



# A scene file says its `version:` at its top level (SPEC 3), an entity spec (spawn_entity's uri,
# in the same directories) does not: within the first this many bytes, as files begin.
SCENE_HEAD_BYTES = 64 * 1024
SCENE_VERSION = re.compile(rb"^version[ \t]*:", re.MULTILINE)


def world_description(path):
    """The description of the scene file at `path`, its first line if that is a comment (without
    the '#'; else ''), or None when the file is no scene, a world LoadWorld takes, but an entity
    spec (get_available_worlds had listed those, which load_world then refused) or unreadable."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(SCENE_HEAD_BYTES)
    except OSError:
        return None
    if SCENE_VERSION.search(head) is None:
        return None
    line = head[:2000].splitlines()[0].decode("utf-8", errors="replace")[:500].strip()
    return line.lstrip("#").strip() if line.startswith("#") else ""
