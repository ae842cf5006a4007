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

Where things are:
- requests.py          Requests, the handlers' shared state (simulation, limits, settings owner)
- entities.py          ~/spawn, ~/edit, ~/remove, ~/get_entity, ~/get_entities
- entity_queries.py    entities with categories and world bounds, their filters (simulation_interfaces)
- simulation_control.py  ~/pause, ~/step, ~/reset, ~/set_freezing, ~/wake_all, features, the
                       simulation states (STOPPED, NO_WORLD, QUITTING)
- scene_files.py       ~/load_scene, ~/save_scene, and the worlds (load from text, unload, list)
- results.py           result codes, RequestError, the coded reply of every failure
- payload.py           request text -> plain data (size and depth limits), poses
- frames.py            the frames the node publishes, in the world: frame_ids, reserved names
- file_access.py       scene directories, path confinement, O_EXCL and atomic writes
- name_filter.py       ~/remove's regular expressions, bounded in length and time
- naming.py            free names for allow_renaming
- descriptions.py      entities as plain data
A new service is a handler in the file of its group (or a new group mixed into Requests) and
a row in ../services.py (the YAML services) or ../standard_services.py (simulation_interfaces).
"""
from .file_access import default_scene_directories
from .payload import MAX_PAYLOAD
from .requests import DEFAULT_MAX_BODIES, Requests
from .results import (ALREADY, FAILED, INCORRECT_STATE, INVALID_MAP_DATA, INVALID_POSE, MAP_DOES_NOT_EXIST,
                      MAP_SUCCESS, NAME_INVALID, NAME_NOT_UNIQUE, NOT_FOUND, OK, UNDEFINED_FAILURE)
from .simulation_control import MAX_STEPS, SCOPE_ALL, SCOPE_SPAWNED, SCOPE_STATE, SCOPE_TIME, SIMULATOR_FEATURES

__all__ = ["ALREADY", "DEFAULT_MAX_BODIES", "FAILED", "INCORRECT_STATE", "INVALID_MAP_DATA", "INVALID_POSE",
           "MAP_DOES_NOT_EXIST", "MAP_SUCCESS", "MAX_PAYLOAD", "MAX_STEPS", "NAME_INVALID", "NAME_NOT_UNIQUE",
           "NOT_FOUND", "OK", "Requests", "SCOPE_ALL", "SCOPE_SPAWNED", "SCOPE_STATE", "SCOPE_TIME",
           "SIMULATOR_FEATURES", "UNDEFINED_FAILURE", "default_scene_directories"]
