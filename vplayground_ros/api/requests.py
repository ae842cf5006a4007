"""Requests: the handlers of every service, bound to one Simulation, and the state they share.
Each group of services lives in its own file and is mixed in here:
entities.py (spawn, edit, remove, get_entity, get_entities), entity_queries.py (the
simulation_interfaces entity queries and filters), simulation_control.py (pause, step, reset,
set_freezing, wake_all, get_simulator_features, simulation states), scene_files.py (load_scene,
save_scene and the worlds).
"""
import copy
import logging
from pathlib import Path

from ..parameters import WorldSettings, frames
from ..scene import scene_recipe, world_to_scene
from .entities import EntityRequests
from .entity_queries import QueryRequests
from .file_access import default_scene_directories
from .scene_files import SceneRequests
from .simulation_control import ControlRequests

DEFAULT_MAX_BODIES = 10_000  # bodies (vehicles included) the world may hold; ~real time at 128 Hz

log = logging.getLogger(__name__)


class Requests(EntityRequests, QueryRequests, ControlRequests, SceneRequests):
    """The SPEC 6.3 handlers, bound to a Simulation. Each public method runs on the caller's
    thread and hands the work to the simulation thread.

    `scene_directories` (paths) and `max_bodies` are plain attributes: the parameter layer may
    replace them at any time, and each request reads them once. `settings` owns the physics
    settings (parameters.Parameters in the Runtime; without one, the World's own): ~/set_freezing
    sets `freezing.enabled` through it, and a scene load or reset hands it the new settings.
    `initial` is the loaded scene (what ~/reset returns to), `scene_label` its file, or
    `scene_text` the YAML it was loaded from."""

    def __init__(self, simulation, scene_label="", scene_directories=None, bag_directory=None,
                 max_bodies=DEFAULT_MAX_BODIES, settings=None):
        self.sim = simulation
        self.settings = settings if settings is not None else WorldSettings(simulation)
        self.scene_label = scene_label
        self.scene_text = ""
        self.scene_directories = ([Path(d) for d in scene_directories] if scene_directories is not None
                                  else default_scene_directories(bag_directory))
        self.max_bodies = max_bodies
        self.initial = copy.deepcopy(world_to_scene(simulation.world))
        self.initial_robots = list(simulation.world.robot_specs)  # as loaded: entries and models (a reset's)
        # What a full reset builds (a world made without a scene: the scene it saves as).
        self.initial_recipe = simulation.world.recipe or scene_recipe(copy.deepcopy(self.initial))

    def frames(self):
        """The frame names: the parameters' (read-only), parameters.Frames."""
        return frames(self.settings)

    def _follow_scene_settings(self):
        """The settings owner takes the loaded scene's settings, which the new World has."""
        ok, reason = self.settings.load_settings(self.initial["settings"])
        if not ok:
            log.warning(f"parameters not updated from the scene: {reason}")
