"""The SPEC 6.4 parameters, ROS-free: one table, one owner of the values, one validation.

`Parameters` holds every value; everything else is told of changes (`listen`) and never
writes a value itself:
- the Runtime applies physics values to the World, and limits to the Requests, one way: the
  World never writes back. A newly loaded scene (`~/load_scene`, `~/reset`) brings its own
  settings, which the requests hand to `load_settings`; `~/set_freezing` is a set of
  `freezing.enabled` like any other;
- the transports (the rclpy node, the Foxglove server) set through `set` and listen to tell
  their clients (the node keeps rclpy's copy in step, so `ros2 param get` agrees), so a value
  refused on one is refused on the other, with the same reason, and nothing changes;
- read-only values found at start-up (the command line's overrides, the port the Foxglove server
  bound) come in through `set_read_only`, checked like a set.
"""
import math
import threading
from collections import namedtuple
from dataclasses import dataclass
from types import MappingProxyType

from .physics import specs

PHYSICS = ("gravity", "steps_per_second", "resolve_iterations", "octree_depth", "freezing.enabled",
           "freezing.time", "freezing.linear_speed", "freezing.angular_speed")
# The frames the node publishes (REP 105), read-only parameters: their defaults, in Frames' order.
FRAMES = {"world_frame": "world", "odom_frame": "odom", "footprint_frame": "base_footprint",
          "base_frame": "base_link"}
Frames = namedtuple("Frames", "world odom footprint base")


def frames(values):
    """The Frames of parameter values (a Parameters, or a mapping)."""
    return Frames(*(values[name] for name in FRAMES))


def check_frames(values):
    """Refuses frame names that would give a frame two parents or make it its own parent (tf2
    rejects an odom -> odom transform): each must be distinct; ValueError naming both."""
    seen = {}
    for name in FRAMES:
        frame = values[name]
        if not frame or frame.startswith("/") or any(c.isspace() for c in frame):
            raise ValueError(f"{name}: {frame!r} is not a frame name (no leading '/', no spaces, not empty)")
        if frame in seen:
            raise ValueError(f"{name} and {seen[frame]} are both {frame!r}: one frame would be its own parent "
                             "or have two")
        seen[frame] = name


def localization(value, name):
    """What sits above a robot's odom frame (robots.py): the true pose's transform, or nothing."""
    if value not in specs.LOCALIZATIONS:
        raise ValueError(f"{name}: {value!r} is not one of {', '.join(specs.LOCALIZATIONS)}")
# ~/reset scopes (simulation_interfaces ResetSimulation): `reset_scope` and ~/reset take the
# same values, by the one rule of reset_scope().
SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 1, 2, 4, 255


def reset_scope(value, path):
    """A reset scope: 255 ALL (0, simulation_interfaces' SCOPE_DEFAULT, is ALL too) or a
    combination of 1 TIME, 2 STATE, 4 SPAWNED; SpecError otherwise."""
    scope = specs.integer(value, path, 0, SCOPE_ALL) or SCOPE_ALL
    if scope != SCOPE_ALL and scope & ~(SCOPE_TIME | SCOPE_STATE | SCOPE_SPAWNED):
        raise specs.SpecError(path, f"{scope} is not a combination of 1 TIME, 2 STATE, 4 SPAWNED (or 255 ALL)")
    return scope


# The longest run a duration may ask for, s (about 31 years): a step count, duration x steps per
# second, stays an integer (1e308 s had ended the physics thread with an overflow).
MAX_DURATION = 1e9
MAX_REAL_TIME_FACTOR = 1000.0
MAX_SPLIT_SIZE = 1 << 50  # bytes after which a bag goes on in a new file (a petabyte: no limit in practice)


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    default: object
    description: str
    kind: str              # "bool", "int", "float", "str", "float[3]", "str[]"
    low: float = None      # inclusive range of numbers
    high: float = None
    read_only: bool = False
    rule: object = None    # fn(value, name) raising ValueError: what a range cannot say


def setting(name, default, description, kind):
    """A physics parameter, its range the schema's (specs.SETTINGS_RANGES), so what the node
    advertises is what the World accepts."""
    low, high = specs.SETTINGS_RANGES[name]
    return ParameterSpec(name, default, description, kind, low, high)


def parameter_table(settings, options, scene_directories, max_bodies, solver_threads=1):
    """Every parameter; the physics ones default to the scene's `settings`, `solver_threads` to
    the World's (how many cores the host gives, not a scene setting)."""
    s = settings
    f = s["freezing"]
    P = ParameterSpec
    return [
        P("scene", str(options.scene), "scene file loaded at start", "str", read_only=True),
        P("real_time_factor", float(options.real_time_factor),
          "simulated seconds per wall-clock second; 0 = as fast as possible", "float", 0, MAX_REAL_TIME_FACTOR),
        P("start_paused", bool(options.start_paused), "start paused (~/pause false to play)", "bool", read_only=True),
        P("duration", float(options.duration or 0.0),
          "stop after this much simulated time, s (0 = run until stopped)", "float", 0.0, MAX_DURATION,
          read_only=True),
        setting("gravity", [float(v) for v in s["gravity"]], "gravity vector, m/s^2, world frame", "float[3]"),
        setting("steps_per_second", int(s["steps_per_second"]), "physics steps per simulated second", "int"),
        setting("resolve_iterations", int(s["resolve_iterations"]),
                "collision passes per step (contact passes are twice this)", "int"),
        P("solver_threads", int(solver_threads),
          "threads of the contact solve: 2 shares large passes with a second core (same results)", "int", 1, 2),
        setting("octree_depth", int(s["octree_depth"]), "depth of the broad-phase octree", "int"),
        P("freezing.enabled", bool(f["enabled"]), "freeze bodies at rest", "bool"),
        setting("freezing.time", float(f["time"]), "seconds below the thresholds before freezing", "float"),
        setting("freezing.linear_speed", float(f["linear_speed"]), "freezing threshold, m/s", "float"),
        setting("freezing.angular_speed", float(f["angular_speed"]), "freezing threshold, rad/s", "float"),
        P("publish_rate", 30.0, "simulated Hz of poses, odometry, joint states, transforms", "float", 0.1, 1000),
        P("marker_rate", 30.0, "simulated Hz of marker topics (when subscribed)", "float", 0.1, 1000),
        P("static_republish_period", 5.0, "simulated s between re-sends of the scenery and the bodies at rest", "float", 0.1, 3600),
        P("clock_rate", 0.0, "Hz cap of /clock (0 = every step)", "float", 0, 10000),
        P("contacts.publish", True, "publish the contact topics (false: they draw nothing)", "bool"),
        P("contacts.max_points", 5000, "most contact points published", "int", 0, 1000000),
        P("show_octree", False, "draw the occupied octree cells in ~/scene/markers", "bool"),
        P("cmd_vel_timeout", 1.2, "s without cmd_vel before the car brakes to rest", "float", 0.01, 3600),
        P("cmd_vel_stamped", False, "cmd_vel is geometry_msgs/TwistStamped", "bool", read_only=True),
        P("world_frame", FRAMES["world_frame"], "fixed frame of the simulation", "str", read_only=True),
        P("odom_frame", FRAMES["odom_frame"], "each robot's odometry frame (<namespace>/ before it)", "str",
          read_only=True),
        P("footprint_frame", FRAMES["footprint_frame"], "each robot's base_footprint: base_link on the ground, "
          "heading only", "str", read_only=True),
        P("base_frame", FRAMES["base_frame"], "each robot's body frame", "str", read_only=True),
        P("localization", "ground_truth", "above each robot's odom: ground_truth publishes world_frame -> odom "
          "(the odometry's drift), none nothing (for SLAM or AMCL); a vehicle's own key wins", "str",
          rule=localization),
        P("publish_odom_tf", True, "publish odom -> base_footprint (false: another node, an EKF, owns it); "
          "a vehicle's own key wins", "bool"),
        P("publish_body_frames", False, "publish world -> every body on /tf and ~/transforms (bodies that carry "
          "sensors always are)", "bool"),
        P("step_count", 1, "steps one ~/step call advances", "int", 1, 1000000),
        P("reset_scope", SCOPE_ALL, "~/reset scope bits: 1 TIME, 2 STATE, 4 SPAWNED, 255 ALL (0 too)", "int", 0, SCOPE_ALL,
          rule=reset_scope),
        P("click_spawn_size", 0.5, "edge of the box a clicked_point drops, m", "float", 0.01, 100),
        P("click_spawn_height", 2.0, "height above the clicked point it drops from, m", "float", 0, 1000),
        P("record", str(options.record or ""), "MCAP bag being written ('' = not recording)", "str", read_only=True),
        P("record_split_size", int(options.record_split_size),
          "bytes after which the bag continues in a new file (0 = one file)", "int", 0, MAX_SPLIT_SIZE,
          read_only=True),
        P("scene_directories", [str(d) for d in scene_directories],
          "directories ~/load_scene and ~/save_scene may use (set at start only)", "str[]", read_only=True),
        P("max_bodies", int(max_bodies), "most bodies the world may hold (spawns past it are refused)",
          "int", 1, 1_000_000),
        P("foxglove.port", int(options.foxglove or 0),
          "port of the built-in Foxglove WebSocket server (0 = off)", "int", 0, 65535, read_only=True),
    ]


class Parameters:
    """Current values, validated sets, and listeners told of every applied change."""

    def __init__(self, table):
        self.specs = {p.name: p for p in table}
        self._values = {p.name: p.default for p in table}
        self.values = MappingProxyType(self._values)  # read them; change them through set()
        self._listeners = []
        # Held from a change's check until every listener has been told of it, so that the World
        # and rclpy's copy take crossing changes in the order the values were stored (told after
        # it, a ROS and a Foxglove set at once had left either on the other's value). Reentrant:
        # the node copies a change into rclpy under it, whose set comes back through `lock`.
        self.lock = threading.RLock()

    def __getitem__(self, name):
        return self._values[name]

    def listen(self, fn):
        """fn({name: value}) after every applied change, whoever made it."""
        self._listeners.append(fn)

    def check(self, name, value, read_only_ok=False):
        """The value as stored (ints accepted for floats), or ValueError naming the problem."""
        spec = self.specs.get(name)
        if spec is None:
            raise ValueError(f"{name}: no such parameter")
        if spec.read_only and not read_only_ok:
            raise ValueError(f"{name}: read-only")
        if spec.kind == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"{name}: expected a bool, got {type(value).__name__}")
            return value
        if spec.kind == "str":
            if not isinstance(value, str):
                raise ValueError(f"{name}: expected a string, got {type(value).__name__}")
            if spec.rule is not None:
                spec.rule(value, name)
            return value
        if spec.kind == "str[]":
            if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
                raise ValueError(f"{name}: expected a list of strings")
            return list(value)
        if spec.kind == "float[3]":
            if not isinstance(value, (list, tuple)) or len(value) != 3:
                raise ValueError(f"{name}: expected 3 numbers")
            return [self._number(name, v, float, spec) for v in value]
        value = self._number(name, value, int if spec.kind == "int" else float, spec)
        if spec.rule is not None:
            spec.rule(value, name)
        return value

    @staticmethod
    def _number(name, value, kind, spec):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and isinstance(value, float)):
            raise ValueError(f"{name}: expected {'an integer' if kind is int else 'a number'}, "
                             f"got {type(value).__name__}")
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value}")
        if spec.low is not None and not spec.low <= value <= spec.high:
            raise ValueError(f"{name}: {value} is outside [{spec.low:g}, {spec.high:g}]")
        return kind(value)

    def override(self, values):
        """Start-up values from the command line (--ros-args -p), read-only ones included:
        type- and range-checked like a set, then applied; ValueError naming the first problem."""
        checked = {name: self.check(name, value, read_only_ok=True) for name, value in values.items()}
        if checked.keys() & FRAMES:
            check_frames({**self._values, **checked})
        writable = {n: v for n, v in checked.items() if not self.specs[n].read_only}
        ok, reason = self.set(writable)
        if not ok:
            raise ValueError(reason)
        self.set_read_only({n: v for n, v in checked.items() if n not in writable})

    def set_read_only(self, values):
        """Read-only parameters are read-only to clients, not to the program: values known only
        at start-up (the command line's, the port the Foxglove server bound when asked for any)
        come in here, type- and range-checked like a set; ValueError naming the problem."""
        checked = {name: self.check(name, value, read_only_ok=True) for name, value in values.items()}
        with self.lock:
            changed = {n: v for n, v in checked.items() if v != self._values[n]}
            self._values.update(changed)
            self._tell(changed)

    def set(self, changes):
        """Applies {name: value} all together, or nothing: (True, "") or (False, reason)."""
        with self.lock:
            try:
                checked = {name: self.check(name, value) for name, value in changes.items()}
                physics = {n: v for n, v in checked.items() if n in PHYSICS}
                if physics:  # together with the other physics values, as the World will take them
                    specs.validate_settings(settings_from({**self.physics(), **physics}))
            except ValueError as error:
                return False, str(error)
            changed = {n: v for n, v in checked.items() if v != self._values[n]}
            self._values.update(checked)
            self._tell(changed)
        return True, ""

    def physics(self):
        """{name: value} of the physics parameters, the World's settings."""
        return {name: self._values[name] for name in PHYSICS}

    def load_settings(self, settings):
        """The physics parameters take a newly loaded scene's settings (the World built from it
        already has them): (True, "") or (False, reason)."""
        return self.set(physics_parameters(settings))

    def _tell(self, changed):
        if changed:
            for fn in self._listeners:
                fn(changed)


class WorldSettings:
    """The World's own settings behind the get and set of Parameters, for Requests used without
    a parameter layer (scripts, tests): there the World is the one owner."""

    def __init__(self, sim):
        self.sim = sim

    def __getitem__(self, name):
        if name in FRAMES:  # not the World's: the parameters' defaults
            return FRAMES[name]
        return self.sim.call(lambda world: physics_parameters(world.settings)[name])

    def set(self, changes):
        self.sim.call(lambda world: world.update_settings(settings_from(changes)))
        return True, ""

    def load_settings(self, settings):
        return True, ""  # the new World has them


def physics_parameters(settings):
    """{parameter name: value} of World settings ({..., "freezing": {...}})."""
    values = {name: settings[name] for name in PHYSICS if not name.startswith("freezing.")}
    values["gravity"] = [float(v) for v in settings["gravity"]]
    values.update({f"freezing.{key}": value for key, value in settings["freezing"].items()})
    return values


def settings_from(values):
    """World settings ({..., "freezing": {...}}) of physics parameters {name: value}."""
    settings, freezing = {}, {}
    for name, value in values.items():
        if name.startswith("freezing."):
            freezing[name.split(".", 1)[1]] = value
        else:
            settings[name] = list(value) if name == "gravity" else value
    if freezing:
        settings["freezing"] = freezing
    return settings
