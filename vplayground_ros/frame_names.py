"""The names of the frames the node publishes beside the entities' own (SPEC 6.1, 7): no body,
vehicle or sensor may take one. A body's name is its frame on /tf and a sensor's name is its
frame too, so such a name would give a frame two parents, or a loop."""
from .messages import WHEEL_NAMES
from .parameters import FRAMES
from .sensor_messages import optical_frame
from .sensors import CAMERAS, WORLD

WHEEL_FRAMES = tuple(f"wheel_{wheel}" for wheel in WHEEL_NAMES)  # base_link -> wheel_<position>
DEFAULT_FRAMES = tuple(FRAMES.values())  # (world, odom, base) as the parameters have them by default


def node_frames(frames=DEFAULT_FRAMES):
    """{frame: what it is} of the frames the node publishes beside the entities' own, for the
    (world, odom, base) frame names `frames`."""
    world_frame, odom_frame, base_frame = frames
    return {WORLD: "the world frame's name in a sensor's parent", **{wheel: "a wheel frame of the car" for wheel in WHEEL_FRAMES},
            world_frame: "the world_frame", odom_frame: "the odom_frame", base_frame: "the base_frame (the car)"}


def sensor_frames(spec):
    """The frames a sensor takes: its name, and a camera's optical frame under it."""
    return [spec["name"]] + ([optical_frame(spec["name"])] if spec["type"] in CAMERAS else [])


def optical_frames(sensor_specs):
    """{frame: what it is} of the cameras' optical frames."""
    return {optical_frame(s["name"]): f"the optical frame of {s['name']}" for s in sensor_specs if s["type"] in CAMERAS}


def mount_frame(frames, car):
    """The frame a sensor's `parent` names, as a function of it: `world` the world frame, the
    driven car (`car`, or None) the base frame, a body its own frame (its name)."""
    world_frame, _, base_frame = frames
    return lambda parent: world_frame if parent == WORLD else base_frame if parent == car else parent
