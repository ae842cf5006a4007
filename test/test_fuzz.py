"""Hostile input (issue 9, SPEC 9), property-based: malformed requests to every SPEC 6.3 handler
that takes input, malformed scene files and corrupt .obj meshes.

The requests go through api.Requests to a real, running Simulation (started paused so its state
can be compared). For every request that is refused: a coded reply naming the problem, no
internal error, the world byte-identical to before (state arrays, names, properties, settings,
time), and the simulation still steps afterwards.

Bounded for `make test` (FUZZ_EXAMPLES per property, default 200, derandomised so CI is
repeatable); `make fuzz` sets VPLAYGROUND_FUZZ_EXAMPLES for a longer, randomised run. The counts
tried are printed at the end of the module.
"""
import collections
import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from vplayground_ros import api
from vplayground_ros.api import Requests
from vplayground_ros.physics import specs
from vplayground_ros.physics.shapes import SHAPES
from vplayground_ros.resources import find_shared
from vplayground_ros.scene import MAX_PLAYGROUND_TRIANGLES, SceneError, load_world
from vplayground_ros.simulation import Simulation

FUZZ_EXAMPLES = int(os.environ.get("VPLAYGROUND_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=FUZZ_EXAMPLES, deadline=None, database=None,
                derandomize="VPLAYGROUND_FUZZ_EXAMPLES" not in os.environ,
                suppress_health_check=list(HealthCheck))
CODES = ("RESULT_OK:", "RESULT_NOT_FOUND:", "RESULT_INCORRECT_STATE:", "RESULT_OPERATION_FAILED:",
         "NAME_NOT_UNIQUE:", "NAME_INVALID:", "INVALID_POSE:", "ALREADY_IN_TARGET_STATE:", "MISSING_ASSETS:",
         "UNSUPPORTED_ASSETS:", "UNSUPPORTED_ELEMENTS:")
MAX_MESSAGE = 4000  # characters: an error names the problem, it does not echo a 1 MiB request
TRIED = collections.Counter()     # handler -> requests tried
ACCEPTED = collections.Counter()  # handler -> requests that (legitimately) succeeded


# ------------------------------------------------------------------------ the running world
class Harness:
    def __init__(self, directory):
        self.directory = directory
        world = load_world(str(find_shared("config/default_scene.yaml")))
        world.step(1)  # compiles the step now if the JIT cache is cold, not inside a 10 s request
        self.sim = Simulation(world, start_paused=True)
        self.sim.start()
        self.requests = Requests(self.sim, scene_directories=[directory])
        self.escapes = make_escapes(directory)

    def fingerprint(self):
        """Everything a request could change, as bytes and plain data (taken between batches)."""
        def take(world):
            names = world.body_names()
            state = {key: np.ascontiguousarray(value).tobytes() for key, value in world.state().items()}
            return (names, world.vehicle_names(), state, [world.body(n) for n in names],
                    [world.vehicle(n) for n in world.vehicle_names()], repr(world.settings),
                    repr(world.ground), repr(world.playground_spec), world.time, world.step_count,
                    world.layout_version, world.sensor_specs, id(world))
        return self.sim.call(take)

    def steps_on(self):
        """The simulation still steps: one ~/step is run by the loop."""
        # The world itself, not the snapshot: a reset swaps the world before the next snapshot.
        world, before = self.sim.call(lambda w: (w, w.step_count))
        ok, message = self.requests.step(1)
        assert ok, message
        deadline = time.monotonic() + 10.0
        while world.step_count <= before:
            assert time.monotonic() < deadline, "the simulation stopped stepping"
            time.sleep(0.0005)

    def answers(self):
        """Every entity service still answers: the list whole (a nameless half-made body once
        made it raise for good), and each entity by name."""
        entities = self.requests.entities()
        assert all(isinstance(name, str) for name, _ in entities), [name for name, _ in entities]
        for name, _ in entities[:3] + entities[-3:]:
            ok, message = self.requests.get_entity(json.dumps({"entity": name}))
            assert ok, message

    def check(self, handler, call, must_fail=True):
        """Runs one request; checks the reply and, when refused, that nothing changed."""
        TRIED[handler] += 1
        before = self.fingerprint()
        ok, message = call(self.requests)
        assert isinstance(ok, bool) and isinstance(message, str)
        assert message.startswith(CODES), message[:300]
        code, _, text = message.partition(": ")
        assert "internal error" not in message, message[:500]
        if ok:
            assert not must_fail, f"accepted: {message[:300]}"
            ACCEPTED[handler] += 1
            self.requests.reset(api.SCOPE_ALL)  # back to the loaded scene for the next example
        else:
            assert text.strip() and len(message) <= MAX_MESSAGE, message[:300]
            assert self.fingerprint() == before, f"{handler} changed the world: {message[:300]}"
        self.steps_on()
        self.answers()
        return ok, message


@pytest.fixture(scope="module")
def harness(tmp_path_factory, pytestconfig):
    harness = Harness(tmp_path_factory.mktemp("scenes"))
    yield harness
    harness.sim.stop()
    reporter = pytestconfig.pluginmanager.get_plugin("terminalreporter")
    capture = pytestconfig.pluginmanager.get_plugin("capturemanager")
    if reporter is not None and capture is not None and TRIED:
        with capture.global_and_fixture_disabled():  # teardown output is captured otherwise
            reporter.write_line("")
            reporter.write_line(f"fuzz: {sum(TRIED.values())} hostile inputs tried (shrinking included), "
                                f"{sum(ACCEPTED.values())} taken as valid, every other one refused unchanged")
            for handler in sorted(TRIED):
                reporter.write_line(f"  {handler:<14} {TRIED[handler]:6d} tried  {ACCEPTED[handler]:4d} taken")


# ------------------------------------------------------------------------------ strategies
BAD_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 1e308 * 10, 10 ** 400, -10 ** 400])
# Sizes and masses at the edges of floating point: subnormals, values whose volume or inertia
# underflows to 0 (1e-300 m: mass 0 kg, once a half-made body) or overflows, and the largest.
EDGE_FLOATS = [5e-324, 1e-320, 2.2250738585072014e-308 / 4, 1e-300, 1e-30, 1e-12, 1e30, 1e300, 1.7976931348623157e308]
NOT_NUMBERS = st.one_of(st.none(), st.booleans(), st.text(max_size=20),
                        # Lists no vector (3) or quaternion (4) takes:
                        st.lists(st.integers(), max_size=2), st.lists(st.integers(), min_size=5, max_size=6),
                        # Not {} nor {x: 1}: a geometry_msgs-style point with defaults is a fine vector.
                        st.dictionaries(st.text(min_size=2, max_size=5), st.integers(), min_size=1, max_size=2))
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(min_value=-10 ** 30, max_value=10 ** 30),
                    st.floats(), BAD_FLOATS, st.text(max_size=40))
JUNK = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=6) |
                    st.dictionaries(st.text(max_size=12), inner, max_size=6), max_leaves=25)
BAD_NAMES = st.one_of(
    st.sampled_from(["", " ", "a b", "1abc", "-x", ".x", "a\n", "a\x00b", "ä", "🚗", "../x", "a/b",
                     "x" * 65, "名前", "a" * 64 + "\n"]),
    st.text(min_size=65, max_size=3000),
    st.text(alphabet=st.characters(blacklist_categories=["Lu", "Ll", "Nd"]), min_size=1, max_size=30),
    NOT_NUMBERS.filter(lambda v: not isinstance(v, str)))


def bad_number(low, high, low_open=False):
    """Values specs.number(low, high) must refuse."""
    outside = [st.floats(min_value=high, exclude_min=True, allow_infinity=False)]
    if low_open:
        outside.append(st.floats(max_value=low, allow_infinity=False))
    else:
        outside.append(st.floats(max_value=low, exclude_max=True, allow_infinity=False))
    edges = [v for v in EDGE_FLOATS + [-v for v in EDGE_FLOATS] if v > high or v < low or (low_open and v == low)]
    return st.one_of(BAD_FLOATS, NOT_NUMBERS, st.sampled_from(edges), *outside)


def bad_vector(length, low, high, low_open=False):
    good = st.floats(min_value=max(low, -1e3), max_value=min(high, 1e3), allow_nan=False).filter(
        lambda v: v > low or not low_open)

    @st.composite
    def one_bad_element(draw):
        values = draw(st.lists(good, min_size=length, max_size=length))
        values[draw(st.integers(0, length - 1))] = draw(bad_number(low, high, low_open))
        return values
    return st.one_of(one_bad_element(), NOT_NUMBERS,
                     st.lists(good, max_size=8).filter(lambda v: len(v) != length))


BODY_BAD = {
    "name": BAD_NAMES,
    "shape": st.one_of(st.text(max_size=20).filter(lambda s: s not in SHAPES), NOT_NUMBERS),
    "size": bad_vector(3, specs.MIN_SIZE, specs.MAX_SIZE),
    "radius": bad_number(0.5 * specs.MIN_SIZE, 0.5 * specs.MAX_SIZE),
    "length": bad_number(0.0, specs.MAX_SIZE),
    "position": st.one_of(bad_vector(3, -specs.MAX_COORDINATE, specs.MAX_COORDINATE),
                          st.tuples(st.floats(5e3, 1e6), st.floats(-1e3, 1e3), st.floats(0, 10)).map(list)),
    "rpy": bad_vector(3, -1e3, 1e3),
    "quaternion": st.one_of(bad_vector(4, -1e3, 1e3), st.just([0, 0, 0, 0])),
    "linear_velocity": bad_vector(3, -specs.MAX_SPEED, specs.MAX_SPEED),
    "angular_velocity": bad_vector(3, -specs.MAX_SPEED, specs.MAX_SPEED),
    "density": bad_number(0.0, 1e12, low_open=True),
    "mass": bad_number(specs.MIN_MASS, specs.MAX_MASS),
    "elasticity": bad_number(0.0, 1.0),
    "static_friction": bad_number(0.0, specs.MAX_FRICTION),
    "dynamic_friction": bad_number(0.0, specs.MAX_FRICTION),
    "immovable": NOT_NUMBERS.filter(lambda v: not isinstance(v, bool)) | st.integers(),
    "allow_freezing": st.sampled_from([0, 1, "true", "yes", None, []]),
    "frozen": st.sampled_from([0, 1, "false", None, {}]),
    "allow_renaming": st.sampled_from([0, 1, "true", None, [True]]),
    "initial_pose": st.one_of(
        NOT_NUMBERS.filter(lambda v: not isinstance(v, dict)),
        st.fixed_dictionaries({"position": bad_vector(3, -specs.MAX_COORDINATE, specs.MAX_COORDINATE)}),
        st.fixed_dictionaries({"orientation": st.one_of(bad_vector(4, -specs.MAX_COORDINATE, specs.MAX_COORDINATE),
                                                        st.just({"x": 0, "y": 0, "z": 0, "w": 0}))}),
        st.fixed_dictionaries({"position": st.fixed_dictionaries({"x": st.floats(3e3, 1e5)})}),
        st.dictionaries(st.text(min_size=1, max_size=8).filter(
            lambda k: k not in {"position", "orientation", "pose", "header"}), JUNK, min_size=1, max_size=3)),
}
# Keys no handler or scene level knows (so a request carrying one is always wrong).
KNOWN_KEYS = (specs.BODY_KEYS | specs.VEHICLE_KEYS | {"allow_renaming", "initial_pose", "state", "set_pose",
              "set_twist", "vehicle", "entity", "filter", "all", "path", "overwrite", "version",
              "settings", "ground", "playground", "bodies", "vehicles"})
UNKNOWN_KEYS = st.text(min_size=1, max_size=30).filter(lambda k: k not in KNOWN_KEYS)
GOOD_BODY = st.fixed_dictionaries({}, optional={
    "size": st.lists(st.floats(0.1, 3), min_size=3, max_size=3),
    "position": st.lists(st.floats(-20, 20), min_size=3, max_size=3),
    "mass": st.floats(0.1, 100), "elasticity": st.floats(0, 1), "immovable": st.booleans()})


@st.composite
def bad_body(draw):
    """A body spec with exactly one fault."""
    body = draw(GOOD_BODY)
    kind = draw(st.sampled_from(["key", "key", "key", "unknown", "both_rotations", "not_a_mapping"]))
    if kind == "unknown":
        body[draw(UNKNOWN_KEYS)] = draw(JUNK)
    elif kind == "both_rotations":
        body.update(rpy=[0, 0, 0], quaternion=[0, 0, 0, 1])
    elif kind == "not_a_mapping":
        return draw(st.one_of(SCALARS, st.lists(SCALARS, max_size=3)))
    else:
        key = draw(st.sampled_from(sorted(BODY_BAD)))
        body[key] = draw(BODY_BAD[key])
    return body


WHEEL = {"mount": [1.0, 0.8, -0.3], "radius": 0.35}
GOOD_VEHICLE = {"chassis": {"size": [4.0, 1.8, 0.6], "mass": 1200}, "position": [5.0, 5.0, 1.0],
                "wheels": [dict(WHEEL) for _ in range(4)]}


@st.composite
def bad_vehicle(draw):
    vehicle = json.loads(json.dumps(GOOD_VEHICLE))
    fault = draw(st.sampled_from(["wheels", "wheel", "chassis", "power", "steer", "missing"]))
    if fault == "wheels":
        vehicle["wheels"] = draw(st.one_of(st.lists(st.just(WHEEL), max_size=8).filter(lambda w: len(w) != 4),
                                           NOT_NUMBERS))
    elif fault == "wheel":
        key = draw(st.sampled_from(["mount", "radius", "mass", "spring_stiffness", "damper", "steered", "bogus"]))
        value = draw(bad_vector(3, -specs.MAX_SIZE, specs.MAX_SIZE) if key == "mount" else
                     st.sampled_from([0, 1]) if key == "steered" else
                     JUNK if key == "bogus" else bad_number(0.0, 1e9, low_open=key != "damper"))
        vehicle["wheels"][draw(st.integers(0, 3))][key] = value
    elif fault == "chassis":
        vehicle["chassis"] = draw(st.one_of(
            st.fixed_dictionaries({"size": bad_vector(3, specs.MIN_SIZE, specs.MAX_SIZE), "mass": st.just(1.0)}),
            st.fixed_dictionaries({"size": st.just([1, 1, 1]), "mass": bad_number(specs.MIN_MASS, specs.MAX_MASS)}),
            st.just({"size": [1, 1, 1]}), NOT_NUMBERS))
    elif fault == "power":
        vehicle[draw(st.sampled_from(["engine_power", "brake_power"]))] = draw(bad_number(0.0, 1e9))
    elif fault == "steer":
        vehicle["max_steer"] = draw(bad_number(0.0, 1.5))
    else:
        del vehicle[draw(st.sampled_from(["chassis", "wheels"]))]
    return vehicle


def encode(value, style):
    """JSON, block YAML or flow YAML text of a request."""
    if style == "json":
        return json.dumps(value, allow_nan=True)
    return yaml.safe_dump(value, default_flow_style=style == "flow", allow_unicode=True)


def alias_bomb(key):
    """A ~300-byte YAML mapping whose `key` holds 10**8 leaves through aliases (its full repr
    is hundreds of MB)."""
    levels = ["&l0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    levels += [f"&l{k} [" + ", ".join([f"*l{k - 1}"] * 10) + "]" for k in range(1, 8)]
    return f"{{{key}: [{', '.join(levels)}]}}"


BROKEN_TEXT = st.one_of(
    st.text(max_size=300),
    st.binary(max_size=300).map(lambda b: b.decode("latin-1")),
    st.sampled_from([
        "{name: a", "[{}, {]", "{a: b: c}", "- a\n b: [", "!!python/object/apply:os.system ['true']",
        "!!binary ~~~", "{? [1, 2]: 3}", "&a [*a]", "*undefined", "%YAML 9.9\n---\n{}", "\t{}",
        "{\"name\": \"a\", }", "[" * 5000 + "]" * 5000, "{a: " * 3000 + "1" + "}" * 3000,
        "mass: " + "9" * 5000, "{\"mass\": " + "9" * 5000 + "}", "\ud800", "{\"x\": \"\\ud800\"}",
        "x" * (api.MAX_PAYLOAD + 1)]),
    st.text(max_size=200).map(lambda t: "{" + t),
)


@st.composite
def deep(draw):
    """Nested lists/mappings 10-900 levels deep around a junk leaf."""
    value = draw(SCALARS)
    for _ in range(draw(st.integers(10, 900))):
        value = [value] if draw(st.booleans()) else {"k": value}
    return value


# --------------------------------------------------------------------------------- spawn
@st.composite
def spawn_request(draw):
    """(payload, must it be refused): random text can happen to be a valid spawn ("{}")."""
    kind = draw(st.sampled_from(["body", "body", "vehicle", "list", "many", "too_many", "text",
                                 "deep", "bomb", "junk"]))
    if kind == "text":
        return draw(BROKEN_TEXT), False
    return spawn_payload(draw, kind), True


def spawn_payload(draw, kind):
    style = draw(st.sampled_from(["json", "block", "flow"]))
    if kind == "body":
        return encode(draw(bad_body()), style)
    if kind == "vehicle":
        return encode(draw(bad_vehicle()), style)
    if kind == "list":  # all or nothing: one bad entry among good ones
        items = [{"size": [0.5, 0.5, 0.5], "position": [k, 0.0, 5.0]} for k in range(draw(st.integers(1, 30)))]
        items.insert(draw(st.integers(0, len(items))), draw(bad_body() | bad_vehicle()))
        return encode(items, style)
    if kind == "many":  # thousands of bodies, one of them bad (or a duplicated name)
        n = draw(st.integers(1000, 5000))
        items = [{"name": f"fz{k}", "position": [k % 40 - 20.0, k // 40 % 40 - 20.0, 2.0 + k // 1600]} for k in range(n)]
        bad = draw(st.integers(0, n - 1))
        items[bad] = draw(st.one_of(bad_body(), st.just({"name": f"fz{(bad + 1) % n}"}), st.just({"name": "car"})))
        return json.dumps(items, allow_nan=True)
    if kind == "too_many":
        return "[" + ",".join(["{}"] * draw(st.integers(10_001, 250_000))) + "]"
    if kind == "deep":
        return json.dumps({"size": draw(deep())})
    if kind == "bomb":
        return alias_bomb(draw(st.sampled_from(sorted(BODY_BAD))))
    return encode({"mass": draw(JUNK), draw(UNKNOWN_KEYS): 1}, style)


@FUZZ
@given(request=spawn_request())
@example(request=(alias_bomb("mass"), True))
@example(request=("{name: tower_1}", True))
def test_spawn_refuses_malformed_requests(harness, request):
    payload, must_fail = request
    harness.check("spawn", lambda r: r.spawn(payload), must_fail)


def test_a_million_boxes_are_refused_at_once(harness):
    payload = "[" + ",".join(["{}"] * 300_000) + "]"  # ~1 MiB, within MAX_PAYLOAD: the cap refuses it
    started = time.perf_counter()
    ok, message = harness.check("spawn", lambda r: r.spawn(payload))
    assert not ok and "max_bodies" in message
    assert time.perf_counter() - started < 2.0


def test_max_bodies_caps_what_the_world_holds(harness):
    requests = harness.requests
    count = len(harness.sim.call(lambda w: w.body_names()))
    requests.max_bodies = count + 2  # the parameter layer may change it at any time
    try:
        ok, message = harness.check("spawn", lambda r: r.spawn("[{}, {}, {}]"))
        assert not ok and message.startswith("RESULT_OPERATION_FAILED:") and "max_bodies" in message
        ok, message = requests.spawn("[{name: cap_1}, {name: cap_2}]")
        assert ok, message
        ok, message = harness.check("spawn", lambda r: r.spawn("{name: cap_3}"))
        assert "max_bodies" in message
    finally:
        requests.max_bodies = api.DEFAULT_MAX_BODIES
        requests.reset(api.SCOPE_ALL)


# ---------------------------------------------------------------------------------- edit
@st.composite
def edit_request(draw):
    kind = draw(st.sampled_from(["field", "pose", "twist", "flags", "vehicle", "entity", "text", "junk"]))
    entity = draw(st.sampled_from(["tower_1", "car", "plank"]))
    style = draw(st.sampled_from(["json", "block", "flow"]))
    if kind == "field":
        key = draw(st.sampled_from(sorted(set(BODY_BAD) - {"name", "shape", "allow_renaming", "initial_pose"})))
        request = {"entity": entity, key: draw(BODY_BAD[key])}
        if draw(st.booleans()):
            request[draw(st.sampled_from(["name", "shape", "colour", "entity_name"]))] = "x"
    elif kind == "pose":
        request = {"entity": entity, "state": {"pose": draw(st.one_of(
            NOT_NUMBERS.filter(lambda v: not isinstance(v, dict)),
            st.fixed_dictionaries({"position": BODY_BAD["position"]}),
            st.fixed_dictionaries({"orientation": st.one_of(bad_vector(4, -1e6, 1e6), st.just([0, 0, 0, 0]))}),
            st.dictionaries(st.sampled_from(["where", "rotation"]), JUNK, min_size=1)))}}
    elif kind == "twist":
        request = {"entity": entity, "state": {"twist": draw(st.one_of(
            st.fixed_dictionaries({"linear": bad_vector(3, -specs.MAX_SPEED, specs.MAX_SPEED)}),
            st.fixed_dictionaries({"angular": bad_vector(3, -specs.MAX_SPEED, specs.MAX_SPEED)}),
            st.dictionaries(st.sampled_from(["lin", "x"]), JUNK, min_size=1)))}}
    elif kind == "flags":
        request = {"entity": entity, "state": {"pose": {"position": [0, 0, 1]}},
                   draw(st.sampled_from(["set_pose", "set_twist"])): draw(st.sampled_from([0, 1, "yes", None]))}
    elif kind == "vehicle":
        request = {"entity": draw(st.sampled_from(["car", "car", "tower_1"])), "vehicle": draw(st.one_of(
            st.fixed_dictionaries({"engine_power": bad_number(0.0, 1e9)}),
            st.fixed_dictionaries({"max_steer": bad_number(0.0, 1.5)}),
            st.fixed_dictionaries({"wheels": st.one_of(
                st.dictionaries(st.integers(4, 100) | st.integers(-100, -1) | st.sampled_from(["0", "x", None]),
                                st.just({"radius": 1.0}), min_size=1),
                st.fixed_dictionaries({0: st.fixed_dictionaries({"radius": bad_number(0.0, 1e9, True)})}),
                st.fixed_dictionaries({1: st.dictionaries(st.sampled_from(["tyre", "colour"]), JUNK, min_size=1)}),
                NOT_NUMBERS)}),
            st.fixed_dictionaries({"chassis": JUNK}), NOT_NUMBERS.filter(lambda v: v is not None)))}  # null: no edit
        if request["entity"] == "tower_1":
            request["vehicle"] = {"engine_power": 10.0}  # not a vehicle
        style = "block" if style == "json" else style  # wheel indices are integers: YAML only
    elif kind == "entity":
        request = {"entity": draw(st.one_of(BAD_NAMES, st.just("nobody"))), "mass": 1.0}
        if draw(st.booleans()):
            del request["entity"]
    elif kind == "text":
        return draw(BROKEN_TEXT)
    else:
        return encode({"entity": entity, draw(UNKNOWN_KEYS): draw(JUNK)}, style)
    return encode(request, style)


@FUZZ
@given(payload=edit_request())
def test_edit_refuses_malformed_requests(harness, payload):
    ok, message = harness.check("edit", lambda r: r.edit(payload))
    assert not ok


# ------------------------------------------------- sizes and masses at the edges of floating point
# Every shape, every key that sizes it or weighs it, each edge value: spawned, and edited onto a
# body of that shape. Each is refused naming its key with a coded reply, the world untouched and
# every service answering after (Harness.check), or, where the value is a fine one (a mass of
# 1e-9 kg is the least allowed), taken.
CUBE = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
SHAPE_KEYS = {"box": {"size": lambda v: [v, v, v]}, "sphere": {"radius": lambda v: v},
              "capsule": {"radius": lambda v: v, "length": lambda v: v},
              "cylinder": {"radius": lambda v: v, "length": lambda v: v},
              "convex": {"points": lambda v: [[v * c for c in p] for p in CUBE]},
              # a part sized by the value beside one placed and weighed by it
              "compound": {"parts": lambda v: [{"size": [v, v, v]},
                                               {"shape": "sphere", "radius": 0.5, "position": [v, 0.0, 0.0], "mass": v}]}}
EDGE_CASES = [(shape, key, value) for shape, keys in SHAPE_KEYS.items()
              for key in [*keys, "mass", "density"] for value in EDGE_FLOATS]
# What a body of the shape needs besides the value tried (the shapes whose size has no default).
REQUIRED_KEYS = {"convex": {"points": CUBE}, "compound": {"parts": [{"size": [1.0, 1.0, 1.0]}]}}


def edge_fields(shape, key, value):
    if key in SHAPE_KEYS[shape]:
        return {key: SHAPE_KEYS[shape][key](value)}
    return {key: value, **REQUIRED_KEYS.get(shape, {})}


def check_edge_reply(ok, message, key):
    assert ok or key in message, message  # the key is named
    assert "Singular" not in message and "division" not in message, message  # never a library's words


@pytest.mark.parametrize("shape,key,value", EDGE_CASES)
def test_spawn_at_the_edges_of_floating_point(harness, shape, key, value):
    body = {"name": "edge", "shape": shape, "position": [30.0, 30.0, 5.0], **edge_fields(shape, key, value)}
    ok, message = harness.check("spawn", lambda r: r.spawn(json.dumps(body)), must_fail=False)
    check_edge_reply(ok, message, key)


@pytest.mark.parametrize("shape,key,value", EDGE_CASES)
def test_edit_at_the_edges_of_floating_point(harness, shape, key, value):
    name = f"edge_{shape}"
    if not harness.sim.call(lambda world: name in world.body_names()):  # an accepted edit resets the scene
        ok, message = harness.requests.spawn(json.dumps({"name": name, "shape": shape, **REQUIRED_KEYS.get(shape, {}),
                                                         "position": [30.0, -30.0 + 6 * len(name), 1.0]}))
        assert ok, message
    request = {"entity": name, **edge_fields(shape, key, value)}
    ok, message = harness.check("edit", lambda r: r.edit(json.dumps(request)), must_fail=False)
    check_edge_reply(ok, message, key)


@pytest.mark.parametrize("key,value", [(key, value) for key in ("radius", "mass") for value in EDGE_FLOATS])
def test_wheels_at_the_edges_of_floating_point(harness, key, value):
    vehicle = json.loads(json.dumps(GOOD_VEHICLE))
    vehicle["wheels"][1][key] = value
    ok, message = harness.check("spawn", lambda r: r.spawn(json.dumps(vehicle)), must_fail=False)
    check_edge_reply(ok, message, key)
    edit = {"entity": "car", "vehicle": {"wheels": {1: {key: value}}}}
    ok, message = harness.check("edit", lambda r: r.edit(yaml.safe_dump(edit)), must_fail=False)
    check_edge_reply(ok, message, key)


# -------------------------------------------------------------------------------- remove
# Backtracking patterns anchored so that no body of the scene matches them.
def not_a_name(value):
    """Junk that cannot be the name of a body of the scene."""
    return not (isinstance(value, str) and specs.NAME_PATTERN.fullmatch(value))


REDOS = st.sampled_from(["^(a+)+$", "^(a|a)*$", "^(a|aa)*b$", "^(.*a){20}$", "^(\\w+\\s?)*!$", "(x+x+)+y",
                         "^((a*)*)*c$"])


@st.composite
def remove_request(draw):
    kind = draw(st.sampled_from(["entity", "filter", "redos", "all", "keys", "text", "junk"]))
    if kind == "entity":
        return encode({"entity": draw(st.one_of(BAD_NAMES, st.just("nobody"), JUNK.filter(not_a_name)))}, "json")
    if kind == "filter":
        return encode({"filter": draw(st.one_of(
            st.sampled_from(["(", "[", "a{99999999999}", "*", "(?P<", "\\", "(?<=a+)zq", "x" * 1001, ""]),
            st.text(max_size=30).map(lambda t: "^zz_nomatch_" + t.replace("|", "") + "$"),
            NOT_NUMBERS.filter(lambda v: not isinstance(v, str))))}, "json")
    if kind == "redos":  # no body matches, after as much backtracking as the pattern can do
        return encode({"filter": draw(REDOS)}, "json")
    if kind == "all":
        return encode({"all": draw(st.sampled_from([False, 1, "true", None, [True], {"x": 1}]))}, "json")
    if kind == "keys":
        keys = draw(st.lists(st.sampled_from(["entity", "filter", "all", "name", "regex"]), min_size=0,
                             max_size=3, unique=True).filter(lambda k: len(k) != 1 or k[0] in ("name", "regex")))
        return encode({k: "nobody" for k in keys}, draw(st.sampled_from(["json", "flow"])))
    if kind == "text":
        return draw(BROKEN_TEXT)
    return encode(draw(JUNK.filter(lambda v: not (isinstance(v, dict) and {"entity", "filter", "all"} & set(v)))), "json")


@FUZZ
@given(payload=remove_request())
@example(payload='{"filter": "^(a+)+$"}')
def test_remove_refuses_malformed_requests(harness, payload):
    ok, message = harness.check("remove", lambda r: r.remove(payload))
    assert not ok


def test_a_backtracking_filter_is_cut_off_not_run_to_the_end(harness):
    # 64-character names (the longest allowed) make (a+)+$ backtrack 2**63 times per name.
    names = ["a" * 63 + c for c in "xyz"]
    ok, message = harness.requests.spawn(json.dumps([{"name": n, "position": [k, 9.0, 1.0]}
                                                     for k, n in enumerate(names)]))
    assert ok, message
    try:
        started = time.perf_counter()
        ok, message = harness.check("remove", lambda r: r.remove('{"filter": "^(a|aa)+$"}'))
        assert not ok and time.perf_counter() - started < 5.0
    finally:
        harness.requests.reset(api.SCOPE_ALL)


@pytest.mark.parametrize("pattern", ["a{99999999}", "((a{100}){100}){100}", "x{0,4294967296}", "(?:ab|c){20000,}"])
def test_a_counted_repetition_bomb_is_refused_before_compiling(harness, pattern):
    """The regex module unrolls counted repetitions when it compiles: a{99999999} took minutes
    and gigabytes before any time bound applied (found by test_fuzz_standard's filters)."""
    started = time.perf_counter()
    ok, message = harness.check("remove", lambda r: r.remove(json.dumps({"filter": pattern})))
    assert not ok and "counted repetitions" in message and time.perf_counter() - started < 5.0


# ---------------------------------------------------------------------------- get_entity
@FUZZ
@given(payload=st.one_of(
    st.builds(lambda e: json.dumps({"entity": e}, allow_nan=True), st.one_of(BAD_NAMES, st.just("nobody"), JUNK.filter(not_a_name))),
    st.builds(lambda k, v: json.dumps({"entity": "car", k: v}, allow_nan=True), UNKNOWN_KEYS, JUNK),
    BROKEN_TEXT, JUNK.map(json.dumps)))
def test_get_entity_refuses_malformed_requests(harness, payload):
    ok, message = harness.check("get_entity", lambda r: r.get_entity(payload))
    assert not ok


# ------------------------------------------------------------- pause, step, reset, freezing
NOT_BOOLS = JUNK.filter(lambda v: not isinstance(v, bool))


@FUZZ
@given(value=NOT_BOOLS)
def test_pause_refuses_what_is_not_a_bool(harness, value):
    ok, message = harness.check("pause", lambda r: r.pause(value))
    assert not ok and harness.sim.paused is True


@FUZZ
@given(value=st.one_of(JUNK, st.integers(max_value=0), st.integers(min_value=api.MAX_STEPS + 1), st.floats(),
                       st.just(True)).filter(lambda v: not whole(v, range(1, api.MAX_STEPS + 1))))
def test_step_refuses_bad_counts(harness, value):
    ok, message = harness.check("step", lambda r: r.step(value))
    assert not ok


def whole(value, valid):
    """Whether specs.integer would take `value` (3 or 3.0, not True) and it is in `valid`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return (isinstance(value, int) or (math.isfinite(value) and value.is_integer())) and int(value) in valid


VALID_SCOPES = set(range(0, 8)) | {255}  # 0: simulation_interfaces' SCOPE_DEFAULT, ALL


@FUZZ
@given(value=st.one_of(JUNK, st.integers(-300, 300), st.just(True)).filter(lambda v: not whole(v, VALID_SCOPES)))
def test_reset_refuses_bad_scopes(harness, value):
    ok, message = harness.check("reset", lambda r: r.reset(value))
    assert not ok


@FUZZ
@given(value=NOT_BOOLS)
def test_set_freezing_refuses_what_is_not_a_bool(harness, value):
    ok, message = harness.check("set_freezing", lambda r: r.set_freezing(value))
    assert not ok


# --------------------------------------------------------------------- save and load scene
def make_escapes(directory):
    """Paths that must not be written or read: outside, through `..`, through symlinks."""
    outside = directory.parent / "outside"
    outside.mkdir(exist_ok=True)
    (directory / "link_out").symlink_to(outside, target_is_directory=True)
    (directory / "file_link.yaml").symlink_to(outside / "target.yaml")
    (directory / "loop.yaml").symlink_to(directory / "loop.yaml")
    return [str(outside / "x.yaml"), f"{directory}/../outside/x.yaml", f"{directory}/link_out/x.yaml",
            str(directory / "file_link.yaml"), str(directory / "loop.yaml"), "/etc/passwd", "/etc/x.yaml",
            "/dev/full", "/proc/self/environ", "../../../../../../etc/x.yaml", "~/x.yaml",
            str(directory / "scene.txt"), str(directory / ".bashrc"), str(directory), "/"]


@st.composite
def save_request(draw, directory, escapes):
    existing = directory / "existing.yaml"
    kind = draw(st.sampled_from(["escape", "exists", "keys", "overwrite", "path", "text"]))
    if kind == "escape":
        path = draw(st.sampled_from(escapes))
        return draw(st.sampled_from([path, json.dumps({"path": path, "overwrite": True})]))
    if kind == "exists":
        return draw(st.sampled_from([str(existing), json.dumps({"path": str(existing)}),
                                     json.dumps({"path": str(existing), "overwrite": False})]))
    if kind == "keys":
        return json.dumps({"path": str(directory / "new.yaml"), draw(UNKNOWN_KEYS): draw(JUNK)}, allow_nan=True)
    if kind == "overwrite":
        return json.dumps({"path": str(existing), "overwrite": draw(NOT_BOOLS)}, allow_nan=True)
    if kind == "path":
        return json.dumps({"path": draw(st.one_of(
            NOT_NUMBERS.filter(lambda v: not isinstance(v, str)), st.just(""), st.just("a\x00.yaml"),
            st.text(min_size=4097, max_size=5000), st.just("\ud800.yaml"),
            st.text(max_size=40).map(lambda t: str(directory / "missing_dir" / (t.replace("/", "") + "x.yaml")))))})
    return "{" + draw(st.text(max_size=100))


@FUZZ
@given(data=st.data())
def test_save_scene_writes_nothing_it_is_not_asked_to(harness, data):
    directory = harness.directory
    existing = directory / "existing.yaml"
    if not existing.exists():
        existing.write_text("precious\n")
    payload = data.draw(save_request(directory, harness.escapes))
    listing = sorted(p.name for p in directory.parent.rglob("*"))
    ok, message = harness.check("save_scene", lambda r: r.save_scene(payload))
    assert not ok
    assert existing.read_text() == "precious\n"
    assert sorted(p.name for p in directory.parent.rglob("*")) == listing  # no file made anywhere


def scene_dict_with_one_fault(draw):
    scene = {"version": 1, "bodies": [{"name": "a", "position": [0, 0, 1]}], "vehicles": [GOOD_VEHICLE]}
    fault = draw(st.sampled_from(["version", "settings", "ground", "body", "vehicle", "duplicate",
                                  "top", "list", "playground"]))
    if fault == "version":
        scene["version"] = draw(st.one_of(st.integers().filter(lambda v: v != 1), st.just("1"), st.just(1.5), st.none()))
    elif fault == "settings":
        key = draw(st.sampled_from(["gravity", "steps_per_second", "resolve_iterations", "octree_depth", "freezing", "dt"]))
        value = draw(bad_vector(3, -1e3, 1e3) if key == "gravity" else
                     st.one_of(st.integers(-5, 0), st.integers(20_000), NOT_NUMBERS, BAD_FLOATS) if key != "freezing" else
                     st.one_of(st.fixed_dictionaries({"time": bad_number(0, 1e6)}), st.just({"enabled": "on"}), NOT_NUMBERS))
        scene["settings"] = {key: value}
    elif fault == "ground":
        scene["ground"] = draw(st.one_of(st.fixed_dictionaries({"height": bad_number(-1e6, 1e6)}),
                                         st.fixed_dictionaries({"elasticity": bad_number(0, 1)}),
                                         st.just({"slope": 1}), st.sampled_from([1, "flat", [0]])))
    elif fault == "body":
        scene["bodies"].append(draw(bad_body()))
    elif fault == "vehicle":
        scene["vehicles"] = [draw(bad_vehicle())]
    elif fault == "duplicate":
        scene["bodies"].append({"name": draw(st.sampled_from(["a", "car"]))})
        scene["vehicles"][0] = {**GOOD_VEHICLE, "name": "car"}
    elif fault == "top":
        scene[draw(UNKNOWN_KEYS)] = draw(JUNK)
    elif fault == "list":
        scene[draw(st.sampled_from(["bodies", "vehicles"]))] = draw(st.one_of(st.text(min_size=1), st.integers(1), st.just({"a": 1})))
    else:
        scene["playground"] = draw(st.one_of(
            st.just({"position": [0, 0, 0]}), st.fixed_dictionaries({"mesh": NOT_NUMBERS}),
            st.just({"mesh": "does_not_exist.obj"}), st.just({"mesh": "/etc/passwd"}),
            st.just({"mesh": "/dev/zero"}), st.just({"mesh": "playground.gltf"}),
            st.fixed_dictionaries({"mesh": st.just("playground.obj"), "scale": bad_number(0, 1e4, True)}),
            st.fixed_dictionaries({"mesh": st.just("playground.obj"), "position": bad_vector(3, -1e6, 1e6)})))
    return scene


@st.composite
def scene_text(draw):
    kind = draw(st.sampled_from(["dict", "dict", "text", "deep", "bomb"]))
    if kind == "dict":
        return encode(scene_dict_with_one_fault(draw), draw(st.sampled_from(["json", "block", "flow"])))
    if kind == "text":
        return draw(BROKEN_TEXT)
    if kind == "deep":
        return json.dumps({"version": 1, "bodies": [{"size": draw(deep())}]})
    return "version: 1\nbodies:\n- " + alias_bomb(draw(st.sampled_from(["mass", "size", "name"])))


@FUZZ
@given(data=st.data())
def test_load_scene_refuses_malformed_and_escaping_files(harness, data):
    directory = harness.directory
    if data.draw(st.booleans()):
        path = data.draw(st.sampled_from(harness.escapes + [str(directory / "nothing_here.yaml")]))
    else:
        text = data.draw(scene_text())
        path = str(directory / "fuzzed.yaml")
        Path(path).write_bytes(text.encode("utf-8", "surrogatepass"))

    def call(requests):
        result, message = requests.load_scene(path)
        assert result in (api.MAP_DOES_NOT_EXIST, api.INVALID_MAP_DATA), message[:300]
        return False, message
    harness.check("load_scene", call)


def test_oversized_scene_files_are_refused_before_reading(harness):
    path = harness.directory / "huge.yaml"
    with open(path, "wb") as stream:  # sparse: 17 MiB that cost no disk
        stream.truncate(17 << 20)
    replies = []

    def call(requests):
        replies.append(requests.load_scene(str(path)))
        return False, replies[-1][1]
    harness.check("load_scene", call)
    assert replies[0][0] == api.INVALID_MAP_DATA and "bytes" in replies[0][1], replies
    path.unlink()


def test_a_scene_with_more_bodies_than_max_bodies_is_refused(harness):
    path = harness.directory / "crowded.yaml"
    path.write_text(json.dumps({"version": 1, "bodies": [{"position": [k % 50 - 25, k // 50 - 25, 1]}
                                                         for k in range(2500)]}))
    harness.requests.max_bodies = 2000
    try:
        result, message = harness.requests.load_scene(str(path))
        assert result == api.INVALID_MAP_DATA and "max_bodies" in message, message
    finally:
        harness.requests.max_bodies = api.DEFAULT_MAX_BODIES


# -------------------------------------------------------------------- scene files directly
@FUZZ
@given(data=st.data())
def test_load_world_refuses_malformed_scene_dicts_and_files(tmp_path_factory, data):
    TRIED["load_world"] += 1
    if data.draw(st.booleans()):
        scene = scene_dict_with_one_fault(data.draw)
    else:
        scene = tmp_path_factory.getbasetemp() / "direct.yaml"
        scene.write_bytes(data.draw(scene_text()).encode("utf-8", "surrogatepass"))
    with pytest.raises(SceneError) as error:
        load_world(scene)
    assert str(error.value) and len(str(error.value)) <= MAX_MESSAGE


# -------------------------------------------------------------------------- corrupt meshes
# Legal .obj variations that must load, and faults that must be refused with these words, on
# the line they are on (1-based) where a line is meant.
OBJ_BAD_NUMBERS = ["1,5", "1.2.3", "0x1p3", "1d3", "--1", "1e", ".", "1/2", "\u00bd", "\u0661", "1\u00a0"]
OBJ_GOOD_NUMBERS = ["1e-3", "+1.5", ".5", "5.", "-0", "1E2", "0000.25", "-7e+0"]
OBJ_NAMES = [("latin-1", "Büro"), ("cp1252", "naïve “quotes”"), ("shift_jis", "名前"), ("utf-8", "🚗 ä"),
             ("koi8-r", "Привет")]
OBJ_SKIPPED_LINES = [b"vt 0.5 0.5", b"vn 0 0 1", b"vp 0.1", b"o thing", b"g a b", b"s off", b"usemtl steel",
                     b"mtllib /etc/passwd", b"l 1 2", b"p 1", b"# a comment", b"", b"   \t"]


OBJ_CASES = ["nan_vertex", "far_vertex", "vertex_dimension", "bad_number", "good_number", "extra_numbers",
             "index_high", "index_negative_beyond", "index_zero", "negative_ok", "faces_first", "corner_forms",
             "polygon", "short_face", "bad_corner", "unknown_statement", "skipped", "inline_comment",
             "name_encoding", "utf16_bom", "utf16_no_bom", "utf8_bom", "line_ends", "no_faces", "junk"]
ANY = object()  # random bytes: refused, or by chance a mesh


@st.composite
def obj_text(draw, fault):
    """(.obj bytes, what loading it must give: None = a world, ANY = either, else a piece of
    the error): a Wavefront .obj with the fault or legal variation named (OBJ_CASES), or
    binary junk. A proper triangle comes first, so no legal variation leaves only degenerate
    ones."""
    vertices = [(0, 0, 0), (1, 0, 0), (0, 1, 0)] + draw(st.lists(
        st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-5, 5)), max_size=30))
    count = len(vertices)
    faces = [(1, 2, 3)] + draw(st.lists(st.tuples(*[st.integers(1, count)] * 3), max_size=30))
    lines = [f"v {x} {y} {z}".encode() for x, y, z in vertices]
    k = draw(st.integers(0, count - 1))  # the vertex a vertex fault is put on
    expected = None
    face_lines = [f"f {a} {b} {c}".encode() for a, b, c in faces]
    last = count + len(faces) + 1  # the line a face appended at the end is on
    if fault == "nan_vertex":
        token = draw(st.sampled_from(["nan", "inf", "-inf", "NaN", "infinity", "1e400", "-1e309"]))
        lines[k] = f"v 0 {token} 0".encode()
        expected = f"line {k + 1}: {token!r} is not a finite number"
    elif fault == "far_vertex":
        lines[k] = f"v {draw(st.sampled_from(['1e308', '-2e6', '1e7']))} 0 0".encode()
        expected = f"vertex {k} is at"  # finite, but beyond the world's bounds
    elif fault == "vertex_dimension":
        numbers = draw(st.sampled_from([0, 1, 2, 5, 7, 9]))
        lines[k] = b" ".join([b"v"] + [b"0.5"] * numbers)
        expected = f"line {k + 1}: a vertex has {numbers} numbers"
    elif fault == "bad_number":
        token = draw(st.sampled_from(OBJ_BAD_NUMBERS))
        lines[k] = f"v 0 {token} 0".encode()
        expected = f"line {k + 1}: {token!r} is not a number"
    elif fault == "good_number":
        lines[k] = f"v {draw(st.sampled_from(OBJ_GOOD_NUMBERS))} {vertices[k][1]} {vertices[k][2]}".encode()
    elif fault == "extra_numbers":  # w, or an r g b colour
        lines[k] += draw(st.sampled_from([b" 1.0", b" 0.2 0.4 0.6"]))
    elif fault == "index_high":
        index = count + draw(st.integers(1, 10 ** 9))
        face_lines.append(f"f 1 2 {index}".encode())
        expected = f"line {last}: the face refers to vertex {index}, but the file has only {count} vertices"
    elif fault == "index_negative_beyond":
        index = -count - draw(st.integers(1, 10 ** 9))
        face_lines.append(f"f 1 2 {index}".encode())
        expected = f"line {last}: the face refers to vertex {index}, but only {count} vertices come before it"
    elif fault == "index_zero":
        face_lines.append(b"f 0 1 2")
        expected = f"line {last}: face corner '0': vertex numbers start at 1"
    elif fault == "negative_ok":
        face_lines.append(b"f -3 -2 -1")
    elif fault == "faces_first":  # positive numbers may refer to vertices further down
        lines, face_lines = face_lines, lines
    elif fault == "corner_forms":
        form = draw(st.sampled_from(["{}/{}", "{}//{}", "{}/{}/{}", "{}/{}/"]))
        face_lines = [b"f " + " ".join(form.format(*[i] * form.count("{}")) for i in face).encode()
                      for face in faces]
    elif fault == "polygon":
        corners = draw(st.lists(st.integers(1, count), min_size=4, max_size=12))
        face_lines.append(("f " + " ".join(map(str, corners))).encode())
    elif fault == "short_face":
        corners = draw(st.sampled_from(["", "1", "1 2"]))
        face_lines.append(f"f {corners}".encode())
        expected = f"line {last}: a face needs at least 3 corners, this one has {len(corners.split())}"
    elif fault == "bad_corner":
        corner = draw(st.sampled_from(["a", "/1", "1.5", "x/1/1", "--2", "1e3"]))
        face_lines.append(f"f 1 2 {corner}".encode())
        expected = f"line {last}: face corner {corner!r} does not start with a vertex number"
    elif fault == "unknown_statement":
        keyword = draw(st.sampled_from(["curv", "surf", "vertex", "F", "V", "x"]))
        face_lines.append(f"{keyword} 1 2 3".encode())
        expected = f"line {last}: unknown statement {keyword!r}"
    elif fault == "skipped":
        face_lines.insert(draw(st.integers(0, len(face_lines))), draw(st.sampled_from(OBJ_SKIPPED_LINES)))
    elif fault == "inline_comment":
        lines[k] += b" # a remark: 1,5 nan f 0"
    elif fault == "name_encoding":  # bytes of any encoding in names and comments
        encoding, name = draw(st.sampled_from(OBJ_NAMES))
        lines.insert(0, b"o " + name.encode(encoding))
        face_lines.append(b"# " + name.encode(encoding))
    if fault == "no_faces":
        face_lines = []
        expected = "has no triangles"
    text = b"\n".join(lines + face_lines) + b"\n"
    if fault == "utf16_bom":
        text = text.decode().encode("utf-16")
    elif fault == "utf16_no_bom":
        text = text.decode().encode("utf-16-le")
        expected = "line 1: a NUL byte"
    elif fault == "utf8_bom":
        text = b"\xef\xbb\xbf" + text
    elif fault == "line_ends":
        text = text.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r"])))
    elif fault == "junk":
        text, expected = draw(st.binary(max_size=2000)), ANY
    return text, expected


@pytest.mark.parametrize("fault", OBJ_CASES)
@settings(FUZZ, max_examples=max(4, FUZZ_EXAMPLES // 20))  # each case, so none is left to chance
@given(draw=st.data())
def test_meshes_load_or_are_refused_naming_the_file_and_the_problem(tmp_path_factory, fault, draw):
    data, expected = draw.draw(obj_text(fault))
    TRIED["mesh"] += 1
    mesh = tmp_path_factory.getbasetemp() / "fuzzed.obj"
    mesh.write_bytes(data)
    try:
        world = load_world({"version": 1, "playground": {"mesh": str(mesh)}})
    except SceneError as error:
        message = str(error)
        assert expected is not None, f"a legal .obj was refused: {message}"
        assert message.startswith(f"<scene>: playground.mesh: mesh {mesh}") and len(message) <= MAX_MESSAGE, message
        assert expected is ANY or expected in message, message
        return
    assert expected is None or expected is ANY, f"taken, but should be refused with {expected!r}"
    ACCEPTED["mesh"] += 1
    triangles = world.playground_triangles
    assert len(triangles) and np.all(np.abs(triangles) <= specs.MAX_COORDINATE)
    world.add_body({"position": [0, 0, 3]})
    world.step(8)  # and it steps


def test_a_mesh_of_millions_of_triangles_is_refused_before_parsing(tmp_path):
    TRIED["mesh"] += 1
    mesh = tmp_path / "huge.obj"
    count = 2 * MAX_PLAYGROUND_TRIANGLES
    mesh.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + b"f 1 2 3\n" * count)
    started = time.perf_counter()
    with pytest.raises(SceneError, match="triangles"):
        load_world({"version": 1, "playground": {"mesh": str(mesh)}})
    assert time.perf_counter() - started < 2.0
    # One polygon fanned into a million triangles counts the same.
    mesh.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf " + b" ".join([b"1", b"2", b"3"] * (count // 3 + 1)) + b"\n")
    with pytest.raises(SceneError, match="triangles"):
        load_world({"version": 1, "playground": {"mesh": str(mesh)}})
    # So do faces indented, or on classic Mac OS line ends: counted in the text too (they had
    # been parsed, then refused by their number: "has 1000000 triangles, more than").
    for faces in (b" f 1 2 3\n", b"\tf\t1 2 3\n", b"f 1 2 3\r"):
        line_end = faces[-1:]
        mesh.write_bytes(line_end.join([b"v 0 0 0", b"v 1 0 0", b"v 0 1 0", b""]) + faces * count)
        with pytest.raises(SceneError, match=f"has more than the {MAX_PLAYGROUND_TRIANGLES} triangles allowed"):
            load_world({"version": 1, "playground": {"mesh": str(mesh)}})


def test_a_mesh_outside_the_scene_directories_is_refused(harness, tmp_path_factory):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    mesh = find_shared("meshes/playground.obj")
    (elsewhere / "copy.obj").write_bytes(mesh.read_bytes())
    scene = harness.directory / "mesh_out.yaml"
    scene.write_text(yaml.safe_dump({"version": 1, "playground": {"mesh": str(elsewhere / "copy.obj")}}))
    result, message = harness.requests.load_scene(str(scene))
    assert result == api.INVALID_MAP_DATA and "outside" in message, message
    # The package's own meshes stay usable by name, and by their absolute path (as README says).
    for name in ("playground.obj", str(mesh)):
        scene.write_text(yaml.safe_dump({"version": 1, "playground": {"mesh": name}}))
        result, message = harness.requests.load_scene(str(scene))
        assert result == api.MAP_SUCCESS, message
    default = find_shared("config/default_scene.yaml")
    result, message = harness.requests.load_scene(str(default))  # config/ is not listed here
    assert result == api.MAP_DOES_NOT_EXIST and "outside the scene directories" in message, message
    harness.requests.scene_directories = [harness.directory, default.parent]
    try:
        assert harness.requests.load_scene(str(default))[0] == api.MAP_SUCCESS
    finally:
        harness.requests.scene_directories = [harness.directory]


# ---------------------------------------------------------------------------- parameters
PARAMETER_VALUES = st.one_of(  # what a ROS or Foxglove parameter can carry
    st.booleans(), st.integers(-2 ** 63, 2 ** 63 - 1), st.floats(), BAD_FLOATS.filter(lambda v: isinstance(v, float)),
    st.text(max_size=60), st.binary(max_size=20), st.lists(st.booleans(), max_size=4),
    st.lists(st.integers(-2 ** 63, 2 ** 63 - 1), max_size=4), st.lists(st.floats(), max_size=4),
    st.lists(st.text(max_size=10), max_size=4))


@pytest.fixture(scope="module")
def runtime(harness):
    import argparse
    import logging

    from vplayground_ros.runtime import Runtime
    options = argparse.Namespace(scene="default_scene.yaml", real_time_factor=1.0, start_paused=True, duration=None,
                                 record=None, record_split_size=0, foxglove=None)
    return Runtime(harness.sim, options, logging.getLogger("test_fuzz"))


def parameter_names():
    import argparse

    from vplayground_ros.parameters import parameter_table
    world = load_world({"version": 1})
    options = argparse.Namespace(scene="", real_time_factor=1.0, start_paused=False, duration=None, record=None,
                                 record_split_size=0, foxglove=None)
    return ([spec.name for spec in parameter_table(world.settings, options, [], api.DEFAULT_MAX_BODIES)]
            + ["no_such.parameter"])


@pytest.mark.parametrize("name", parameter_names())
@settings(FUZZ, max_examples=max(20, FUZZ_EXAMPLES // 4))
@given(value=PARAMETER_VALUES)
def test_parameter_sets_refuse_bad_values_and_change_nothing(harness, runtime, name, value):
    store = runtime.parameters
    TRIED["parameters"] += 1
    values, before = dict(store.values), harness.fingerprint()
    ok, reason = store.set({name: value})
    if ok:  # a valid value of the right type: put the old one back for the next example
        ACCEPTED["parameters"] += 1
        assert store.set({name: values[name]})[0]
    else:
        assert name in reason and len(reason) <= MAX_MESSAGE, reason
        assert store.values == values
        assert harness.fingerprint() == before
    harness.steps_on()
