"""The names of the frames the node publishes beside the entities' own (SPEC 6.1, 7; issue 39):
no body, vehicle or sensor may take one. A body's name is its frame on /tf and a sensor's name is
its frame too, so such a name would give a frame two parents, or a loop. A namespaced robot's
frames hold a '/', which no entity name does."""
from .parameters import FRAMES, Frames
from .robots import STACK_FRAMES, frames_of, namespace_prefix, robot_frames
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


def check_sensor_frames(sensor_specs, robots, robot_specs=()):
    """Refuses a sensor whose frame (or optical frame) is a robot's (`car_b/base_link` as a
    frame_id, or a robot spawned onto a sensor's `car_c/odom`; a URDF robot's link frames and,
    with a drive, its odom, of `robot_specs`): that frame would have two parents. Names the
    sensor's frame_id."""
    from .physics.specs import SpecError
    taken = frames_of(robots)
    for spec in robot_specs:
        prefix = namespace_prefix(spec["namespace"])
        taken.update({prefix + link: f"a link of the robot {spec['name']}" for link in spec["model"].link_frames})
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
