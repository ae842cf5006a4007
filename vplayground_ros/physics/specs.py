"""Validation of the SPEC 3 schema pieces the engine takes: settings, ground, body specs.

Every check names the key path (`bodies[3].size[1]`) and the problem; callers prefix the file.
Validators return normalised plain-Python values and never touch a World, so a failure leaves
everything as it was.
"""
import math
import numbers
import re
import reprlib
from collections import namedtuple

import numpy as np

from .shapes import SHAPES
from .shapes.compound import MAX_PARTS

NAME_PATTERN = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]{0,63}$")

DEFAULT_SETTINGS = {
    "gravity": [0.0, 0.0, -9.81],
    "steps_per_second": 128,
    "resolve_iterations": 5,
    "octree_depth": 5,
    "freezing": {"enabled": True, "time": 0.5, "linear_speed": 0.05, "angular_speed": 0.05},
    "seed": 0,  # of the sensors' noise: the same scene gives bit-identical readings
}
DEFAULT_GROUND = {"height": 0.0, "elasticity": 0.1, "static_friction": 0.8, "dynamic_friction": 0.6}
DEFAULT_DENSITY = 500.0
BODY_DEFAULTS = {
    "shape": "box", "position": [0.0, 0.0, 0.0],
    "linear_velocity": [0.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 0.0],
    "elasticity": 0.2, "static_friction": 0.6, "dynamic_friction": 0.4,
    "immovable": False, "allow_freezing": True, "frozen": False, "collides": True,
}
MAX_FRICTION = 10.0
MAX_SIZE = 1.0e4       # m: larger boxes break the octree's and the solver's scales
# m: the smallest edge, diameter or cylinder length. Far below the contact margin (2 cm) a body
# is not resolved anyway, and its inertia (mass x size^2) nears the floating-point floor.
MIN_SIZE = 1.0e-3
MIN_MASS = 1.0e-9      # kg: a body's least mass, given or density x volume (1/m must stay finite)
MAX_MASS = 1.0e12      # kg: a body's most mass, given or density x volume (saved as its `mass`)
MAX_COORDINATE = 1.0e6  # m
MAX_SPEED = 1.0e4      # m/s, rad/s
MAX_POINTS = 100_000   # of a convex body's `points`, before its hull is taken


# Values quoted in error messages: a few items of a few levels, whatever the caller sent (a YAML
# alias bomb is a small document whose full repr would not fit in memory).
_quote = reprlib.Repr()
_quote.maxlevel, _quote.maxstring, _quote.maxlong, _quote.maxother = 2, 40, 40, 40
_quote.maxlist = _quote.maxtuple = _quote.maxdict = _quote.maxset = 4


def quote(value):
    """A short repr of any value, for error messages."""
    return _quote.repr(value)


class SpecError(ValueError):
    """A ValueError whose message starts with the key path of the bad value."""

    def __init__(self, path, problem):
        self.path, self.problem = path, problem
        super().__init__(f"{path}: {problem}" if path else problem)


class InvalidName(SpecError):
    """A name that breaks NAME_PATTERN: its own type, so that callers answering with result
    codes (the requests' NAME_INVALID) tell it from other bad values without reading the text."""


class UnknownKey(SpecError):
    """A key the schema does not have: its own type, so that a scene refused for one answers
    simulation_interfaces' UNSUPPORTED_ELEMENTS (LoadWorld) without its text being read."""


def child(path, key):
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def _is_number(value):
    """A real number, numpy's scalars included (np.float32, np.int64: what arrays hand the
    World's callers); not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def number(value, path, low=-math.inf, high=math.inf, low_open=False):
    if not _is_number(value):
        raise SpecError(path, f"expected a number, got {type(value).__name__} {quote(value)}")
    try:
        value = float(value)
    except OverflowError:  # an int beyond the float range
        raise SpecError(path, f"must be finite, got {quote(value)}") from None
    if not math.isfinite(value):
        raise SpecError(path, f"must be finite, got {value}")
    if value < low or (low_open and value == low):
        raise SpecError(path, f"must be {'>' if low_open else '>='} {low:g}, got {value:g}")
    if value > high:
        raise SpecError(path, f"must be <= {high:g}, got {value:g}")
    return value


def integer(value, path, low, high):
    if isinstance(value, bool):
        pass  # refused below: True is no count
    elif isinstance(value, numbers.Integral):
        value = int(value)  # numpy's integers too (an int of any size stays itself)
    elif isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise SpecError(path, f"expected an integer, got {type(value).__name__} {quote(value)}")
    if not low <= value <= high:
        raise SpecError(path, f"must be between {low} and {high}, got {quote(value)}")
    return value


def boolean(value, path):
    if not isinstance(value, (bool, np.bool_)):
        raise SpecError(path, f"expected true or false, got {type(value).__name__} {quote(value)}")
    return bool(value)


def vector(value, path, length, low=-math.inf, high=math.inf, low_open=False):
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise SpecError(path, f"expected a list of {length} numbers, got {type(value).__name__}")
    if len(value) != length:
        raise SpecError(path, f"expected {length} numbers, got {len(value)}")
    return [number(v, child(path, k), low, high, low_open) for k, v in enumerate(value)]


def mapping(value, path, allowed):
    if not isinstance(value, dict):
        raise SpecError(path, f"expected a mapping, got {type(value).__name__}")
    for key in value:
        if key not in allowed:
            short = isinstance(key, (int, str)) and not isinstance(key, bool) and len(str(key)) <= 64
            raise UnknownKey(child(path, key if short else quote(key)),
                             f"unknown key (allowed: {', '.join(sorted(allowed))})")
    return value


def name(value, path):
    if not isinstance(value, str):
        raise SpecError(path, f"expected a string, got {type(value).__name__}")
    if not NAME_PATTERN.fullmatch(value):  # fullmatch: `$` alone lets a trailing newline in
        raise InvalidName(path, f"invalid name {value[:80]!r}: 1-64 characters of letters, digits, "
                              "'_', '-', '.', starting with a letter or '_'")
    return value


def quaternion(value, path):
    q = vector(value, path, 4, -1.0e3, 1.0e3)
    length = math.sqrt(sum(v * v for v in q))
    if length < 1e-6:
        raise SpecError(path, "quaternion has zero length")
    if abs(length - 1.0) < 1e-12:
        # Already unit (a saved world's): dividing by a length an ulp off 1 would change its
        # last digits, and the world would not reload the same.
        return q
    return [v / length for v in q]


# The inclusive range of each numeric setting (gravity: of each component), the one table:
# validate_settings checks it and the node's parameters advertise it (parameters.py).
SETTINGS_RANGES = {
    "gravity": (-1.0e3, 1.0e3),
    "steps_per_second": (1, 10000),
    "resolve_iterations": (1, 100),
    "octree_depth": (1, 10),
    "seed": (0, 2**63 - 1),
    "freezing.time": (0.0, 1.0e6),
    "freezing.linear_speed": (0.0, 1.0e6),
    "freezing.angular_speed": (0.0, 1.0e6),
}


def validate_settings(raw, path="settings"):
    """Settings merged over the defaults (a partial mapping changes only its keys)."""
    raw = {} if raw is None else raw
    mapping(raw, path, DEFAULT_SETTINGS)
    out = {**DEFAULT_SETTINGS, "freezing": dict(DEFAULT_SETTINGS["freezing"])}
    if "gravity" in raw:
        out["gravity"] = vector(raw["gravity"], child(path, "gravity"), 3, *SETTINGS_RANGES["gravity"])
    for key in ("steps_per_second", "resolve_iterations", "octree_depth", "seed"):
        if key in raw:
            out[key] = integer(raw[key], child(path, key), *SETTINGS_RANGES[key])
    if "freezing" in raw:
        fpath = child(path, "freezing")
        freezing = mapping(raw["freezing"], fpath, DEFAULT_SETTINGS["freezing"])
        if "enabled" in freezing:
            out["freezing"]["enabled"] = boolean(freezing["enabled"], child(fpath, "enabled"))
        for key in ("time", "linear_speed", "angular_speed"):
            if key in freezing:
                out["freezing"][key] = number(freezing[key], child(fpath, key), *SETTINGS_RANGES[f"freezing.{key}"])
    return out


def validate_ground(raw, path="ground"):
    """None (no ground plane) or the ground's height and material over the defaults."""
    if raw is None:
        return None
    mapping(raw, path, DEFAULT_GROUND)
    out = dict(DEFAULT_GROUND)
    if "height" in raw:
        out["height"] = number(raw["height"], child(path, "height"), -MAX_COORDINATE, MAX_COORDINATE)
    if "elasticity" in raw:
        out["elasticity"] = number(raw["elasticity"], child(path, "elasticity"), 0.0, 1.0)
    for key in ("static_friction", "dynamic_friction"):
        if key in raw:
            out[key] = number(raw[key], child(path, key), 0.0, MAX_FRICTION)
    return out


# Keys bodies and vehicles share: where they are and how they move.
PLACEMENT = {
    "name": name,
    "position": lambda value, p: vector(value, p, 3, -MAX_COORDINATE, MAX_COORDINATE),
    "rpy": lambda value, p: vector(value, p, 3, -1.0e3, 1.0e3),
    "quaternion": quaternion,
    "linear_velocity": lambda value, p: vector(value, p, 3, -MAX_SPEED, MAX_SPEED),
    "angular_velocity": lambda value, p: vector(value, p, 3, -MAX_SPEED, MAX_SPEED),
}

# The keys that size a body, by shape (each shape module's SPEC_KEYS and DEFAULTS).
DIMENSION_KEYS = {key for shape in SHAPES.values() for key in shape.module.SPEC_KEYS}
BODY_KEYS = {"name", "shape", "position", "rpy", "quaternion", "linear_velocity",
             "angular_velocity", "density", "mass", "elasticity", "static_friction",
             "dynamic_friction", "immovable", "allow_freezing", "frozen", "collides"} | DIMENSION_KEYS
# A compound's part: a shape at a pose in the body's frame, with its own mass or density (else
# the body's density). Material and motion are the body's.
PART_KEYS = {"shape", "position", "rpy", "quaternion", "mass", "density"} | DIMENSION_KEYS - {"parts", "inertial"}
INERTIAL_KEYS = {"mass", "centre", "inertia"}


def validate_body_fields(raw, path, allowed=BODY_KEYS):
    """The given keys of a body spec, checked and normalised (no defaults filled in)."""
    mapping(raw, path, allowed)
    out = {}
    for key, value in raw.items():
        p = child(path, key)
        if key in PLACEMENT:
            out[key] = PLACEMENT[key](value, p)
        elif key == "shape":
            if not isinstance(value, str) or value not in SHAPES:
                raise SpecError(p, f"unsupported shape {quote(value)} (supported: {', '.join(SHAPES)})")
            out[key] = value
        elif key == "size":
            out[key] = vector(value, p, 3, MIN_SIZE, MAX_SIZE)
        elif key == "radius":
            out[key] = number(value, p, 0.5 * MIN_SIZE, 0.5 * MAX_SIZE)
        elif key == "length":
            out[key] = number(value, p, 0.0, MAX_SIZE)
        elif key == "points":
            if not isinstance(value, (list, tuple)) or not 4 <= len(value) <= MAX_POINTS:
                raise SpecError(p, f"expected a list of 4 to {MAX_POINTS} points [x, y, z], got {quote(value)}")
            out[key] = [vector(point, child(p, k), 3, -MAX_SIZE, MAX_SIZE) for k, point in enumerate(value)]
        elif key == "parts":
            out[key] = validate_parts(value, p)
        elif key == "inertial":
            out[key] = validate_inertial(value, p)
        elif key == "mass":
            out[key] = number(value, p, MIN_MASS, MAX_MASS)
        elif key == "density":
            out[key] = number(value, p, 0.0, 1.0e12, low_open=True)  # the mass it gives is checked
        elif key == "elasticity":
            out[key] = number(value, p, 0.0, 1.0)
        elif key in ("static_friction", "dynamic_friction"):
            out[key] = number(value, p, 0.0, MAX_FRICTION)
        else:
            out[key] = boolean(value, p)
    if "rpy" in out and "quaternion" in out:
        raise SpecError(path, "give either rpy or quaternion, not both")
    for key in ("mass", "density"):
        if key in out and "inertial" in out:
            raise SpecError(child(path, key), "the inertial gives the mass: give one or the other")
    return out


def check_dimension_keys(shape, body, path):
    """Refuses dimension keys that the shape does not have (a sphere's `size`), and a cylinder
    of no length (a capsule of length 0 is a sphere, a disc of no thickness has no volume)."""
    own = SHAPES[shape].module.SPEC_KEYS
    for key in sorted(DIMENSION_KEYS & set(body)):
        if key not in own:
            raise SpecError(child(path, key), f"a {shape} has no {key} (its keys: {', '.join(own)})")
    if shape == "cylinder" and body.get("length", 1.0) < MIN_SIZE:
        raise SpecError(child(path, "length"), f"must be >= {MIN_SIZE:g} for a cylinder, got {body['length']:g}")
    if shape == "convex" and "points" not in body:
        raise SpecError(child(path, "points"), "missing (a convex body's vertices; in a scene file "
                                               "`mesh:` names a file to take them from)")
    if shape == "compound" and "parts" not in body:
        raise SpecError(child(path, "parts"), "missing (a compound body's shapes, each at a pose in its frame)")


def validate_inertial(raw, path):
    """A compound's mass properties as given (a URDF link's inertial) instead of its parts'
    sums: `mass` (kg), `centre` of mass in the body's frame, `inertia` about it in the body's
    axes (3 x 3, symmetric, positive definite, each principal moment at most the other two's
    sum: a real body's)."""
    mapping(raw, path, INERTIAL_KEYS)
    for key in sorted(INERTIAL_KEYS - raw.keys()):
        raise SpecError(child(path, key), "missing (an inertial gives mass, centre and inertia)")
    inertia_path = child(path, "inertia")
    rows = raw["inertia"]
    if not isinstance(rows, (list, tuple)) or len(rows) != 3:
        raise SpecError(inertia_path, f"expected 3 rows of 3 numbers (kg m^2), got {quote(rows)}")
    tensor = np.array([vector(row, child(inertia_path, k), 3, -MAX_MASS, MAX_MASS) for k, row in enumerate(rows)])
    if not np.allclose(tensor, tensor.T, rtol=1e-9, atol=1e-12 * np.abs(tensor).max()):
        raise SpecError(inertia_path, "is not symmetric")
    moments = np.linalg.eigvalsh(tensor)
    if not (moments.min() > 0.0 and 2.0 * moments.max() <= moments.sum() * (1.0 + 1e-9)):
        raise SpecError(inertia_path, f"principal moments {', '.join(f'{m:g}' for m in moments)} kg m^2 are "
                                      "not a real body's: each must be positive and none more than the other two together")
    return {"mass": number(raw["mass"], child(path, "mass"), MIN_MASS, MAX_MASS),
            "centre": vector(raw["centre"], child(path, "centre"), 3, -MAX_SIZE, MAX_SIZE),
            "inertia": tensor.tolist()}


def validate_parts(raw, path):
    """A compound's `parts`: 1 to MAX_PARTS part specs, each checked as a body's keys are and
    completed with its shape's defaults (shape box, position at the frame's origin)."""
    if not isinstance(raw, (list, tuple)) or not 1 <= len(raw) <= MAX_PARTS:
        raise SpecError(path, f"expected a list of 1 to {MAX_PARTS} parts (shape, its size keys, position, rpy, "
                              f"mass or density), got {quote(raw)}")
    parts = []
    for k, part in enumerate(raw):
        p = child(path, k)
        fields = validate_body_fields(part, p, PART_KEYS)
        shape = fields.setdefault("shape", "box")
        if shape == "compound":
            raise SpecError(child(p, "shape"), "a part is one shape (box, sphere, capsule, cylinder or convex)")
        if "position" in fields:
            vector(fields["position"], child(p, "position"), 3, -MAX_SIZE, MAX_SIZE)
        check_dimension_keys(shape, fields, p)
        parts.append({**SHAPES[shape].module.DEFAULTS, "position": [0.0, 0.0, 0.0], **fields})
    return parts


def validate_body(raw, path="body"):
    """A complete body spec: the given keys over BODY_DEFAULTS and the shape's DEFAULTS (name
    stays optional)."""
    body = {**BODY_DEFAULTS, **validate_body_fields(raw, path)}
    check_dimension_keys(body["shape"], body, path)
    return {**SHAPES[body["shape"]].module.DEFAULTS, **body}


WHEEL_DEFAULTS = {
    "radius": 0.35, "mass": 20.0, "power_gain": 0.0, "steered": False,
    "spring_stiffness": 40000.0, "damper": 4000.0, "spring_length": 0.5,
    "static_friction": 1.0, "dynamic_friction": 0.8,
}
VEHICLE_DEFAULTS = {
    "position": [0.0, 0.0, 1.0], "engine_power": 6000.0, "brake_power": 9000.0, "max_steer": 0.6,
    "max_steer_rate": 1.5,
}
VEHICLE_KEYS = {"name", "position", "rpy", "quaternion", "linear_velocity", "angular_velocity",
                "chassis", "engine_power", "brake_power", "max_steer", "max_steer_rate", "wheels"}
# What a vehicle is as a ROS robot (vplayground_ros.robots): kept with it, no physics. Its
# `odometry` error model is a mapping whose keys vplayground_ros.odometry checks (scene files and
# ~/spawn do, before the World is asked).
ROBOT_KEYS = {"namespace", "localization", "publish_odom_tf", "odometry"}
LOCALIZATIONS = ("ground_truth", "none")
# A ROS namespace, relative: tokens of letters, digits and '_' (not starting with a digit), '/'
# between them; '' for none.
NAMESPACE_PATTERN = re.compile(r"(?:[A-Za-z_][A-Za-z0-9_]*(?:/[A-Za-z_][A-Za-z0-9_]*)*)?")


def name_token(name):
    """An entity name as one token of a ROS name (a robot's default namespace, a topic's part):
    the '.' and '-' a name may have and a ROS name may not become '_'."""
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


WHEEL_COUNT = 4  # front-left, front-right, rear-left, rear-right
# The chassis is a body: its material and flags, besides its size and (own) mass.
CHASSIS_BODY_KEYS = {"elasticity", "static_friction", "dynamic_friction", "immovable",
                     "allow_freezing", "frozen"}


def validate_wheel(raw, path):
    mapping(raw, path, set(WHEEL_DEFAULTS) | {"mount"})
    if "mount" not in raw:
        raise SpecError(child(path, "mount"), "missing (the wheel's mount point in the chassis frame)")
    out = {"mount": vector(raw["mount"], child(path, "mount"), 3, -MAX_SIZE, MAX_SIZE)}
    for key, default in WHEEL_DEFAULTS.items():
        if key not in raw:
            out[key] = default
            continue
        p = child(path, key)
        if key == "steered":
            out[key] = boolean(raw[key], p)
        elif key == "radius":
            out[key] = number(raw[key], p, 0.5 * MIN_SIZE, 1.0e9)
        elif key == "mass":
            out[key] = number(raw[key], p, MIN_MASS, 1.0e9)
        elif key in ("spring_stiffness", "spring_length"):
            out[key] = number(raw[key], p, 0.0, 1.0e9, low_open=True)
        elif key in ("static_friction", "dynamic_friction"):
            out[key] = number(raw[key], p, 0.0, MAX_FRICTION)
        else:  # power_gain, damper
            out[key] = number(raw[key], p, 0.0, 1.0e9)
    return out


def validate_wheel_fields(raw, path):
    """The given keys of a wheel (for edits): checked like validate_wheel, no defaults."""
    mapping(raw, path, set(WHEEL_DEFAULTS) | {"mount"})
    full = validate_wheel({"mount": [0.0, 0.0, 0.0], **raw}, path)
    return {key: full[key] for key in raw}


VEHICLE_EDIT_KEYS = {"engine_power", "brake_power", "max_steer", "max_steer_rate", "wheels"}


def validate_vehicle_edit(raw, path):
    """A partial vehicle edit: engine_power, brake_power, max_steer, max_steer_rate, and wheels as a mapping
    from wheel index (0-3: front-left, front-right, rear-left, rear-right) to wheel keys."""
    mapping(raw, path, VEHICLE_EDIT_KEYS)
    full = validate_vehicle({"chassis": {"size": [1, 1, 1], "mass": 1},
                             "wheels": [{"mount": [0, 0, 0]}] * WHEEL_COUNT,
                             **{k: v for k, v in raw.items() if k != "wheels"}}, path)
    out = {key: full[key] for key in raw if key != "wheels"}
    if "wheels" in raw:
        wheels = raw["wheels"]
        if not isinstance(wheels, dict):
            raise SpecError(child(path, "wheels"), "expected a mapping from wheel index (0-3) to wheel keys")
        out["wheels"] = {}
        for index, fields in wheels.items():
            if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < WHEEL_COUNT:
                raise SpecError(child(path, "wheels"), f"wheel index must be 0-3, got {quote(index)}")
            out["wheels"][index] = validate_wheel_fields(fields, child(child(path, "wheels"), index))
    return out


def validate_vehicle(raw, path="vehicle"):
    """A complete vehicle spec (SPEC 3 `vehicles` entry) over the defaults."""
    mapping(raw, path, VEHICLE_KEYS | ROBOT_KEYS)
    for key in ("chassis", "wheels"):
        if key not in raw:
            raise SpecError(child(path, key), "missing")
    out = dict(VEHICLE_DEFAULTS)
    for key, value in raw.items():
        p = child(path, key)
        if key in PLACEMENT:
            out[key] = PLACEMENT[key](value, p)
        elif key == "chassis":
            mapping(value, p, {"size", "mass"} | CHASSIS_BODY_KEYS)
            for required in ("size", "mass"):
                if required not in value:
                    raise SpecError(child(p, required), "missing")
            out[key] = {"size": vector(value["size"], child(p, "size"), 3, MIN_SIZE, MAX_SIZE),
                        "mass": number(value["mass"], child(p, "mass"), MIN_MASS, MAX_MASS),
                        **validate_body_fields({k: v for k, v in value.items() if k in CHASSIS_BODY_KEYS}, p)}
        elif key in ("engine_power", "brake_power"):
            out[key] = number(value, p, 0.0, 1.0e9)
        elif key == "max_steer":
            out[key] = number(value, p, 0.0, 1.5)
        elif key == "max_steer_rate":  # rad/s: the steering's actuator (0.001 to a turn a step at 1,000 Hz)
            out[key] = number(value, p, 1.0e-3, 1.0e4)
        elif key == "namespace":
            if not isinstance(value, str) or not NAMESPACE_PATTERN.fullmatch(value):
                raise SpecError(p, f"{quote(value)} is not a relative ROS namespace (letters, digits and '_' in "
                                   "tokens separated by '/', or '' for none)")
            out[key] = value
        elif key == "localization":
            if value not in LOCALIZATIONS:
                raise SpecError(p, f"{quote(value)} is not one of {', '.join(LOCALIZATIONS)}")
            out[key] = value
        elif key == "publish_odom_tf":
            out[key] = boolean(value, p)
        elif key == "odometry":
            out[key] = dict(mapping(value, p, value if isinstance(value, dict) else ()))
        else:  # wheels
            if not isinstance(value, list):
                raise SpecError(p, f"expected a list of {WHEEL_COUNT} wheels, got {type(value).__name__}")
            if len(value) != WHEEL_COUNT:
                raise SpecError(p, f"expected {WHEEL_COUNT} wheels (front-left, front-right, "
                                   f"rear-left, rear-right), got {len(value)}")
            out[key] = [validate_wheel(w, child(p, k)) for k, w in enumerate(value)]
    if "rpy" in out and "quaternion" in out:
        raise SpecError(path, "give either rpy or quaternion, not both")
    for key in ("mass", "density"):
        if key in out and "inertial" in out:
            raise SpecError(child(path, key), "the inertial gives the mass: give one or the other")
    return out


MassProperties = namedtuple("MassProperties", "mass inv_mass inv_inertia")


def mass_properties(solid, mass, path):
    """Mass (kg), its inverse and the inverse inertia (3, 3, body frame) of `solid` (shapes.Solid) weighing
    `mass`, all computed before a body is written: a SpecError naming `path` (the key the mass
    came from) unless the mass is finite, within MIN_MASS and MAX_MASS, and the inertia is
    positive definite with a finite inverse."""
    if not (math.isfinite(mass) and MIN_MASS <= mass <= MAX_MASS):
        problem = ("is not positive" if not mass > 0.0 else "is not finite" if not math.isfinite(mass)
                   else f"is below {MIN_MASS:g} kg" if mass < MIN_MASS
                   else f"is more than {MAX_MASS:g} kg (a scene saves it as its mass, which may not be)")
        raise SpecError(path, f"the body's mass {mass:g} kg {problem}")
    inertia = mass * solid.unit_inertia
    with np.errstate(all="ignore"):
        moments = np.linalg.eigvalsh(inertia)
        inverse = np.linalg.inv(inertia) if moments.min() > 0.0 else None
    if inverse is None or not np.all(np.isfinite(inverse)):
        raise SpecError(path, f"the body's inertia (principal moments {', '.join(f'{m:g}' for m in moments)} "
                              "kg m^2) has no finite inverse")
    return MassProperties(float(mass), 1.0 / mass, inverse)


# Joints (World.add_joint): `parent` a body's name or absent (the world), `child` a body's name,
# `anchor` and `axis` in the world when the joint is made (the anchor defaults to the child's
# centre of mass), the joint's coordinate in that pose (`position`, default 0), limits along
# the axis (rad or m; revolute and prismatic), a motor.
JOINT_TYPES = ("fixed", "revolute", "continuous", "prismatic")
# How far past a limit a joint may be made (rad or m): what the solver lets a limit give.
JOINT_START_SLACK = 0.05


def within_limits(position, lower, upper):
    """Whether a joint at `position` may be made, or given these limits: past one, its
    correction would launch it across its range (a saved joint may be a little past, as the
    solver lets limits give by millimetres or milliradians)."""
    return lower - JOINT_START_SLACK <= position <= upper + JOINT_START_SLACK

JOINT_KEYS = {"name", "type", "parent", "child", "anchor", "axis", "position", "lower", "upper",
              "motor", "collide_connected"}
JOINT_EDIT_KEYS = {"lower", "upper", "motor", "collide_connected"}
MOTOR_KEYS = {"mode", "target", "velocity", "max_effort", "max_speed"}
MOTOR_MODES = ("none", "velocity", "position")
MOTOR_DEFAULTS = {"mode": "none", "target": 0.0, "velocity": 0.0, "max_effort": math.inf, "max_speed": math.inf}
MAX_EFFORT = 1.0e12  # N or N m


def validate_joint(raw, path="joint"):
    """A complete joint spec: the given keys, checked, over the defaults (name and anchor stay
    optional: the World names it and puts the anchor at the child's centre of mass)."""
    mapping(raw, path, JOINT_KEYS)
    if "type" not in raw:
        raise SpecError(child(path, "type"), f"missing (one of {', '.join(JOINT_TYPES)})")
    if "child" not in raw:
        raise SpecError(child(path, "child"), "missing (the name of the body the joint holds)")
    joint = {"type": raw["type"], "child": name(raw["child"], child(path, "child")),
             "axis": [0.0, 0.0, 1.0], "lower": -math.inf, "upper": math.inf,
             "motor": dict(MOTOR_DEFAULTS), "collide_connected": False}
    if joint["type"] not in JOINT_TYPES:
        raise SpecError(child(path, "type"), f"unsupported joint type {quote(joint['type'])} "
                                             f"(supported: {', '.join(JOINT_TYPES)})")
    for key in ("name", "parent"):
        if raw.get(key) is not None:
            joint[key] = name(raw[key], child(path, key))
    if joint.get("parent") == joint["child"]:
        raise SpecError(child(path, "parent"), f"{joint['child']!r} is the child too: a joint holds two bodies")
    if "anchor" in raw:
        joint["anchor"] = vector(raw["anchor"], child(path, "anchor"), 3, -MAX_COORDINATE, MAX_COORDINATE)
    if "axis" in raw:
        axis = vector(raw["axis"], child(path, "axis"), 3, -1.0e3, 1.0e3)
        length = math.sqrt(sum(v * v for v in axis))
        if length < 1e-6:
            raise SpecError(child(path, "axis"), "has zero length")
        joint["axis"] = [v / length for v in axis]
    if "position" in raw:
        if joint["type"] == "fixed":
            raise SpecError(child(path, "position"), "a fixed joint has no position")
        joint["position"] = number(raw["position"], child(path, "position"), -MAX_COORDINATE, MAX_COORDINATE)
    joint = {**joint, **validate_joint_edit({k: raw[k] for k in JOINT_EDIT_KEYS & raw.keys()},
                                            path, joint["type"], joint)}
    position = joint.get("position", 0.0)
    if not within_limits(position, joint["lower"], joint["upper"]):
        raise SpecError(child(path, "position"), f"{position:g} (where the joint is made) is outside its "
                                                 f"limits [{joint['lower']:g}, {joint['upper']:g}]")
    return joint


def validate_joint_edit(raw, path, joint_type, current):
    """The given editable keys of a joint (limits, motor, collide_connected), checked against
    the joint's type and its `current` values (validate_joint's complete spec)."""
    mapping(raw, path, JOINT_EDIT_KEYS)
    out = {}
    for key in ("lower", "upper"):
        if key in raw:
            value = raw[key]
            if value == (-math.inf if key == "lower" else math.inf):  # none (as a scene saves it)
                out[key] = float(value)
                continue
            if joint_type not in ("revolute", "prismatic"):
                raise SpecError(child(path, key), f"a {joint_type} joint has no limits")
            out[key] = number(value, child(path, key), -MAX_COORDINATE, MAX_COORDINATE)
    lower, upper = out.get("lower", current["lower"]), out.get("upper", current["upper"])
    if lower > upper:
        raise SpecError(child(path, "lower" if "lower" in out else "upper"),
                        f"lower limit {lower:g} is above the upper limit {upper:g}")
    if "motor" in raw:
        motor_path = child(path, "motor")
        motor = mapping(raw["motor"], motor_path, MOTOR_KEYS)
        merged = dict(current["motor"])
        if "mode" in motor:
            if motor["mode"] not in MOTOR_MODES:
                raise SpecError(child(motor_path, "mode"), f"unsupported motor mode {quote(motor['mode'])} "
                                                           f"(supported: {', '.join(MOTOR_MODES)})")
            merged["mode"] = motor["mode"]
        if "target" in motor:
            merged["target"] = number(motor["target"], child(motor_path, "target"), -MAX_COORDINATE, MAX_COORDINATE)
        if "velocity" in motor:  # a position motor's feed-forward: how fast its target moves
            merged["velocity"] = number(motor["velocity"], child(motor_path, "velocity"), -MAX_SPEED, MAX_SPEED)
        for key in ("max_effort", "max_speed"):
            if key in motor:
                value = motor[key]
                merged[key] = math.inf if value == math.inf else number(
                    value, child(motor_path, key), 0.0, MAX_EFFORT if key == "max_effort" else MAX_SPEED, low_open=True)
        if merged["mode"] != "none" and joint_type == "fixed":
            raise SpecError(child(motor_path, "mode"), "a fixed joint has no motor")
        out["motor"] = merged
    if "collide_connected" in raw:
        out["collide_connected"] = boolean(raw["collide_connected"], child(path, "collide_connected"))
    return out
