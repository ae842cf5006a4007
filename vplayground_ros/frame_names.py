"""The names of the frames the node publishes beside the entities' own (SPEC 6.1, 7; issue 39):
no body, vehicle or sensor may take one. A body's name is its frame on /tf and a sensor's name is
its frame too, so such a name would give a frame two parents, or a loop. A namespaced robot's
frames hold a '/', which no entity name does."""
from .parameters import FRAMES, Frames
from .physics.specs import SpecError
from .robots import STACK_FRAMES, frames_of, namespace_prefix, robot_frames, world_robots
from .sensor_messages import optical_frame
from .sensors import CAMERAS, WORLD
from .urdf_robots import link_carriers

DEFAULT_FRAMES = Frames(*FRAMES.values())  # as the parameters have them by default


def node_frames(frames=DEFAULT_FRAMES):
    """{frame: what it is} of the frames the node publishes beside the entities' own, for the
    frame names `frames` (parameters.Frames): the world frame, the frames a stack gives names of
    its own (map, earth), and a robot's in the root namespace (odom, base_footprint, base_link,
    its wheels' links)."""
    root = robot_frames(frames, "")
    wheel_links = {link: "a wheel link of the robot in the root namespace"
                   for links in (root.suspension, root.steering, root.wheel) for link in links}
    return {WORLD: "the world frame's name in a sensor's parent",
            **{frame: "a frame a ROS 2 stack publishes (REP 105)" for frame in STACK_FRAMES}, **wheel_links,
            frames.world: "the world_frame", root.odom: "the odom_frame", root.footprint: "the footprint_frame",
            root.base: "the base_frame (the robot in the root namespace)"}


def sensor_frames(spec):
    """The frames a sensor takes, as its keys name them (a namespaced robot's namespace comes
    before them, sensor_frame): its frame_id or name, and a camera's optical frame under it."""
    frame = spec.get("frame_id", spec["name"])
    return [frame] + ([optical_frame(frame)] if spec["type"] in CAMERAS else [])


def urdf_robot_frames(robot_specs, frames=DEFAULT_FRAMES):
    """{frame: what it is} of the URDF robots' frames (World.robot_specs): each link's, after its
    robot's namespace (`left_wheel` in the root namespace, `rover/left_wheel` in rover's), and
    with a drive its odom frame. No body or sensor may take one: /tf would give it two parents."""
    out = {}
    for spec in robot_specs:
        prefix = namespace_prefix(spec["namespace"])
        out.update({prefix + link: f"a link of the robot {spec['name']}" for link in spec["model"].link_frames})
        if spec.get("drive"):
            out.setdefault(prefix + frames.odom, f"the odom frame of the robot {spec['name']}")
    return out


def frames_taken(frames, world, sensor_specs=None):
    """{frame: what it is} of every frame a new body's or sensor's name may not be, beside the
    names of the entities there: the node's own (node_frames), the sensors' that are not their
    names (sensor_frames_taken; of `sensor_specs`, else the world's: an edited sensor's own are
    not taken) and the URDF robots' (urdf_robot_frames). ~/spawn's (and so SpawnEntity's) and a
    sensor edit's rule; its other side is check_robot_frames (a robot added where a body's or
    sensor's frame has one of its frames' names), which a scene's robots meet as they are
    added, and check_sensor_frames its sensors."""
    sensors = world.sensor_specs if sensor_specs is None else sensor_specs
    return {**node_frames(frames), **sensor_frames_taken(sensors), **urdf_robot_frames(world.robot_specs, frames)}


class FrameTaken(SpecError):
    """A name that is another entity's frame (NAME_NOT_UNIQUE over the services)."""


def check_robot_frames(world, name, model, namespace, path, frames=DEFAULT_FRAMES):
    """Refuses (FrameTaken) a URDF robot whose frames in `namespace` (its links', after the
    namespace) would be a body's name in `world` (a body's name is its frame on /tf, with a
    sensor or publish_body_frames) or a sensor's frame there: that frame would have two
    parents. Names the link, the frame and whose it is."""
    prefix = namespace_prefix(namespace)
    taken = {body: f"the name of the body {body!r}" for body in world.body_names()}
    frame_of = sensor_frame(world_robots(world, frames), link_carriers(world.robot_specs))
    for spec in world.sensor_specs:
        frame = frame_of(spec)
        taken[frame] = f"the frame of the sensor {spec['name']}"
        if spec["type"] in CAMERAS:
            taken[optical_frame(frame)] = f"the optical frame of the sensor {spec['name']}"
    clash = next((link for link in model.link_frames if prefix + link in taken), None)
    if clash is not None:
        frame = prefix + clash
        raise FrameTaken(f"{path}.namespace", f"the robot {name}'s link {clash!r} would be the frame {frame!r}, which "
                                              f"is {taken[frame]} (names are frames: another name for that, or a "
                                              "namespace for the robot)")


def check_sensor_frames(sensor_specs, robots, robot_specs, frames):
    """Refuses a sensor whose frame (or optical frame) is a robot's (`car_b/base_link` as a
    frame_id, or a robot spawned onto a sensor's `car_c/odom`; a URDF robot's link frames and,
    with a drive, its odom frame as `frames` name it, of `robot_specs`): that frame would have
    two parents. Names the sensor's frame_id."""
    taken = {**frames_of(robots), **urdf_robot_frames(robot_specs, frames)}
    frame_of = sensor_frame(robots, link_carriers(robot_specs))
    for spec in sensor_specs:
        frame = frame_of(spec)
        for name in (frame, optical_frame(frame)) if spec["type"] in CAMERAS else (frame,):
            if name in taken:
                raise SpecError(f"{spec['name']}.frame_id", f"the frame {name!r} is {taken[name]}")


def sensor_frame(robots, carriers=None):
    """A sensor's frame as a function of its spec: its frame_id, else its name, after the
    namespace of the robot that carries it (a vehicle, or a URDF robot's body: `carriers`,
    urdf_robots.link_carriers)."""
    prefixes = {robot.name: robot.prefix for robot in robots}
    prefixes.update({body: carrier.prefix for body, carrier in (carriers or {}).items()})
    return lambda spec: prefixes.get(spec["parent"], "") + spec.get("frame_id", spec["name"])


def sensor_frames_taken(sensor_specs):
    """{frame: what it is} of the sensors' frames that are not their names (a frame_id, a
    camera's optical frame): a name is a frame already, unique among the entities'."""
    out = {}
    for s in sensor_specs:
        frame, *optical = sensor_frames(s)
        if frame != s["name"]:
            out[frame] = f"the frame of the sensor {s['name']}"
        out.update({o: f"the optical frame of {s['name']}" for o in optical})
    return out


def mount_frame(frames, robots, carriers=None):
    """The frame a sensor's `parent` names, as a function of it: `world` the world frame, a
    robot (robots.Robot, by its vehicle's name) its base_link, a URDF robot's body its link's
    frame (`carriers`, urdf_robots.link_carriers), another body its own frame (its name)."""
    bases = {robot.name: robot.frames.base for robot in robots}
    bases.update({body: carrier.base for body, carrier in (carriers or {}).items()})
    return lambda parent: frames.world if parent == WORLD else bases.get(parent, parent)
