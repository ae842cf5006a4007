"""The scene-file services: ~/load_scene (LoadMap) and ~/save_scene, within the scene
directories (file_access.py)."""
import copy

import yaml

from ..physics import specs
from ..scene import SceneError, load_world, world_to_scene
from .file_access import allowed_directories, confine, write_file
from .payload import YAML_DUMPER, as_mapping, parse
from .results import (FAILED, INVALID_MAP_DATA, MAP_DOES_NOT_EXIST, MAP_SUCCESS, NOT_FOUND, OK,
                      UNDEFINED_FAILURE, RequestError, handled, reply)


class SceneRequests:
    """Requests' scene-file handlers (see requests.py for the state they share)."""

    def load_scene(self, path):
        """(LoadMap result code, message). The old world stays on any failure."""
        try:
            target = confine(path, "load_scene", self.scene_directories)
        except RequestError as error:
            return MAP_DOES_NOT_EXIST, str(error)
        if not target.is_file():
            return MAP_DOES_NOT_EXIST, f"{NOT_FOUND}: no scene file at {specs.quote(path)}"
        try:
            world = load_world(target, max_bodies=int(self.max_bodies),
                               directories=allowed_directories(self.scene_directories), frames=self.frames())
            initial = copy.deepcopy(world_to_scene(world))
        except SceneError as error:
            return INVALID_MAP_DATA, f"{FAILED}: {str(error)[:1000]}"

        def install(_):
            self.sim.world = world
            self.initial = initial
            self.scene_label = str(target)
        try:
            self.sim.call(install)
        except TimeoutError as error:
            return UNDEFINED_FAILURE, f"{FAILED}: {error}"
        self._follow_scene_settings()
        return MAP_SUCCESS, f"{OK}: loaded {target} ({len(world.body_names())} bodies)"

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

