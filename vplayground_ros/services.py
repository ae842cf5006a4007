"""The SPEC 6.3 services, ROS-free: name, service type and a handler (request with attribute
access -> response as a dict of its fields). The ROS node and the Foxglove server both serve
this one table, so a call behaves the same whichever way it comes in.
"""
from collections import namedtuple

import numpy as np
import yaml

from . import messages
from .api import MAP_SUCCESS, UNDEFINED_FAILURE
from .api.results import internal_error
from .messages import header
from .physics.shapes import SHAPES, solid
from .physics.shapes.compound import frame_parts

# `aside`: the handler may take long (it waits for steps, or answers for every entity): the ROS
# node runs it on a thread of its own so that its executor serves everything else meanwhile.
Service = namedtuple("Service", "name type handler aside", defaults=(False,))

# What each service type answers when its handler raises (a bug, never a refused request): the
# type's own failure. GetInteractiveMarkers has none: no markers, and the log says why.
FAILURES = {
    "diagnostic_msgs/srv/AddDiagnostics": lambda text: {"success": False, "message": text},
    "std_srvs/srv/SetBool": lambda text: {"success": False, "message": text},
    "std_srvs/srv/Trigger": lambda text: {"success": False, "message": text},
    "nav_msgs/srv/LoadMap": lambda text: {"result": UNDEFINED_FAILURE},
    "visualization_msgs/srv/GetInteractiveMarkers": lambda text: {"markers": []},
}


def failure(service_type):
    """text -> the service type's failure: FAILURES' own, else a simulation_interfaces service's
    RESULT_OPERATION_FAILED (GetSimulatorFeatures has no result: no features, the text in
    custom_info)."""
    if service_type in FAILURES:
        return FAILURES[service_type]
    if service_type.endswith("/GetSimulatorFeatures"):
        return lambda text: {"features": {"custom_info": text}}
    return lambda text: {"result": {"result": 4, "error_message": text}}


def carriable(message):
    """A reply text every transport carries whole: what it repeats from a request (an unknown
    key, a name) may hold characters UTF-8 cannot encode (a lone surrogate from a JSON escape),
    on which rclpy's send_response raised after the handler had returned, and a NUL, at which
    ROS strings end. Both are written as backslash escapes."""
    return message.encode("utf-8", "backslashreplace").decode("utf-8").replace("\0", "\\x00")


def service_table(runtime):
    requests, parameters = runtime.requests, runtime.parameters

    def text(handler):
        def serve(request):
            success, message = handler(str(request.load_namespace))
            return {"success": success, "message": carriable(message)}
        return serve

    def boolean(handler):
        def serve(request):
            success, message = handler(bool(request.data))
            return {"success": success, "message": carriable(message)}
        return serve

    def trigger(handler):
        def serve(_request):
            success, message = handler()
            return {"success": success, "message": carriable(message)}
        return serve

    def load_scene(request):
        result, message = requests.load_scene(str(request.map_url))
        if result == MAP_SUCCESS:
            runtime.broadcaster.scene_changed()  # marker ids restart with the new bodies
            runtime.log.info(f"~/load_scene: {carriable(message)}")
        else:
            runtime.log.warning(f"~/load_scene: {carriable(message)}")
        return {"result": result}

    def get_entities(_request):
        return {"markers": [entity_marker(runtime, name, description)
                            for name, description in requests.entities()]}

    return [guarded(runtime, service) for service in [
        # aside: a robot's description may take a second to read (its meshes' hulls)
        Service("~/spawn", "diagnostic_msgs/srv/AddDiagnostics", text(requests.spawn), True),
        Service("~/edit", "diagnostic_msgs/srv/AddDiagnostics", text(requests.edit)),
        Service("~/remove", "diagnostic_msgs/srv/AddDiagnostics", text(requests.remove)),
        Service("~/get_entity", "diagnostic_msgs/srv/AddDiagnostics", text(requests.get_entity)),
        Service("~/save_scene", "diagnostic_msgs/srv/AddDiagnostics", text(requests.save_scene)),
        Service("~/get_entities", "visualization_msgs/srv/GetInteractiveMarkers", get_entities),
        Service("~/pause", "std_srvs/srv/SetBool", boolean(requests.pause)),
        Service("~/set_freezing", "std_srvs/srv/SetBool", boolean(requests.set_freezing)),
        Service("~/step", "std_srvs/srv/Trigger", trigger(lambda: requests.step(parameters["step_count"]))),
        Service("~/reset", "std_srvs/srv/Trigger",
                trigger(lambda: requests.reset(parameters["reset_scope"]))),
        Service("~/wake_all", "std_srvs/srv/Trigger", trigger(requests.wake_all)),
        Service("~/get_simulator_features", "std_srvs/srv/Trigger", trigger(requests.features)),
        Service("~/load_scene", "nav_msgs/srv/LoadMap", load_scene),
    ]]


def guarded(runtime, service):
    """The service, answering whatever happens: an exception of its handler (a bug) answers the
    type's failure with `RESULT_OPERATION_FAILED: internal error (...)`, and is logged with its
    traceback once and counted on /diagnostics (Simulation.fault). Unanswered, the caller waited
    out its own timeout."""
    failed = failure(service.type)

    def serve(request):
        try:
            return service.handler(request)
        except Exception as error:
            runtime.sim.fault(f"service {service.name}", error)
            return failed(carriable(internal_error(error)))
    return service._replace(handler=serve)


def entity_marker(runtime, name, description):
    """visualization_msgs/InteractiveMarker of an entity: its pose, YAML description, and its
    shape as controls[0].markers[0]."""
    snap = runtime.sim.snapshot
    position, orientation = description["pose"]["position"], description["pose"]["orientation"]
    return {
        "header": header(snap.time, runtime.parameters["world_frame"]),
        "name": name,
        "description": yaml.safe_dump(description, sort_keys=False),
        "pose": {"position": dict(zip("xyz", map(float, position))),
                 "orientation": dict(zip("xyzw", map(float, orientation)))},
        "controls": [{"name": "shape", "always_visible": True, "markers": shape_markers(description)}],
    }


def shape_markers(description):
    """The markers that draw an entity in its own frame (messages.shape_marker_layout: a capsule
    is a cylinder and two spheres, a compound its parts; a sensor a small cube, a URDF robot
    the box around its links, where that box is)."""
    shape, hull, parts, centre = description["shape"], None, None, np.zeros(3)
    if shape in ("box", "urdf"):
        low, high = np.asarray(description["bounds"]["low"], float), np.asarray(description["bounds"]["high"], float)
        shape, dimensions, centre = "box", 0.5 * (high - low), 0.5 * (high + low)
    else:
        solid_shape = solid(shape, description["properties"])
        dimensions, hull = np.asarray(solid_shape.dimensions, float), solid_shape.hull
        parts = None if solid_shape.compound is None else frame_parts(solid_shape.compound)
    layout = messages.shape_marker_layout(np.array([SHAPES[shape].code]), dimensions[None], [0],
                                          [None if hull is None else hull.triangles], [parts])
    poses = messages.shape_marker_poses(layout, np.array([[*centre, 0.0, 0.0, 0.0, 1.0]]))
    points = layout.points or (None,) * len(poses)
    return [{"type": int(t), "action": 0,  # ADD
             "pose": {"position": dict(zip("xyz", map(float, pose[:3]))), "orientation": dict(zip("xyzw", map(float, pose[3:])))},
             "scale": dict(zip("xyz", map(float, scale))),
             "points": [] if p is None else [dict(zip("xyz", map(float, v))) for v in p]}
            for t, pose, scale, p in zip(layout.types, poses, layout.scales, points)]
