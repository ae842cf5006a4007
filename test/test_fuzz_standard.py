"""Hostile input through the simulation_interfaces types (issue 37): test_fuzz.py's corpus as a
client of the standard services would send it, in their real request messages (rclpy's
classes, so only what the types can carry), to the same running Simulation. For every request
refused: a standard result code with a message naming the problem, no internal error, the world
byte-identical to before, and the simulation still stepping. Queries change nothing either way.
"""
import json
import math
import time
from types import SimpleNamespace

import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st

pytest.importorskip("simulation_interfaces")

from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Twist, Vector3  # noqa: E402
from simulation_interfaces.msg import Bounds, EntityCategory, EntityFilters, EntityState, SimulationState  # noqa: E402
from simulation_interfaces.srv import (DeleteEntity, GetEntities, GetEntityBounds, GetEntityInfo,  # noqa: E402
                                       GetEntityState, LoadWorld, ResetSimulation, SetEntityState,
                                       SetSimulationState, SpawnEntity, StepSimulation)

from test_fuzz import (ACCEPTED, BAD_FLOATS, BAD_NAMES, FUZZ, GOOD_VEHICLE, MAX_MESSAGE, TRIED, harness,  # noqa: E402,F401
                       scene_text, spawn_request)
from vplayground_ros import api  # noqa: E402
from vplayground_ros.standard_services import StandardServices, valid_namespace  # noqa: E402

# Result.result and the numbers above 100 the services define.
CODES = {0, 1, 2, 3, 4} | set(range(101, 110)) | {150}
QUERIES = {"get_entities", "get_entity_state", "get_entity_info", "get_entity_bounds"}
FLOATS = st.one_of(BAD_FLOATS.filter(lambda v: isinstance(v, float)), st.floats(allow_nan=True, allow_infinity=True))
NAMES = BAD_NAMES.filter(lambda v: isinstance(v, str))
BOX = "{shape: box, size: [0.5, 0.5, 0.5]}"


@pytest.fixture(scope="module")
def standard(harness):
    runtime = SimpleNamespace(requests=harness.requests, sim=harness.sim, parameters={"world_frame": "world"},
                              broadcaster=SimpleNamespace(scene_changed=lambda: None))
    return StandardServices(runtime)


def check(harness, standard, service, request, must_fail=True):
    """One standard request; its Result checked, and when refused (or a query) nothing changed."""
    TRIED[f"si {service}"] += 1
    before = harness.fingerprint()
    result = getattr(standard, service)(request)["result"]
    code, message = result["result"], result["error_message"]
    assert code in CODES, (code, message[:300])
    assert "internal error" not in message, message[:500]
    if code == 1 and service not in QUERIES:
        assert not must_fail, f"accepted: {request}"
        ACCEPTED[f"si {service}"] += 1
        harness.requests.reset(api.SCOPE_ALL)
    else:
        if code != 1:
            assert message.strip() and len(message) <= MAX_MESSAGE, message[:300]
        assert harness.fingerprint() == before, f"{service} changed the world: {message[:300]}"
    harness.steps_on()
    harness.answers()
    return code, message


def stamped(x=0.0, y=0.0, z=2.0, q=(0.0, 0.0, 0.0, 1.0), frame=""):
    pose = PoseStamped(pose=Pose(position=Point(x=x, y=y, z=z),
                                 orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])))
    pose.header.frame_id = frame
    return pose


@st.composite
def bad_pose(draw):
    """A pose with one fault: a coordinate not finite or outside the world, a quaternion of
    no rotation, or a frame the node does not publish."""
    fault = draw(st.sampled_from(["position", "quaternion", "frame"]))
    if fault == "position":
        value = draw(st.one_of(BAD_FLOATS.filter(lambda v: isinstance(v, float)), st.floats(1e6, 1e300),
                               st.floats(-1e300, -1e6)))
        return stamped(**{draw(st.sampled_from("xyz")): value})
    if fault == "quaternion":
        q = draw(st.one_of(st.just((0.0, 0.0, 0.0, 0.0)),
                           st.tuples(FLOATS, FLOATS, FLOATS, FLOATS).filter(lambda q: not all(map(math.isfinite, q)))))
        return stamped(q=q)
    return stamped(frame="no_" + draw(st.text(max_size=40)))  # no frame the node publishes starts so


@FUZZ
@given(request=spawn_request())
def test_spawn_entity_refuses_the_spawn_corpus_as_resource_string(harness, standard, request):
    payload, must_fail = request
    # The request's name and allow_renaming override the resource's: where the corpus may have
    # put its fault in the name, the resource's own is used (name empty); a fault in
    # allow_renaming is one the standard's request cannot carry.
    assume("allow_renaming" not in payload)
    name = "" if "name" in payload else "fuzzed"
    check(harness, standard, "spawn_entity", SpawnEntity.Request(name=name, resource_string=payload), must_fail)


@FUZZ
@given(name=NAMES, pose=bad_pose(), fault=st.sampled_from(["name", "pose", "namespace"]),
       namespace=st.text(min_size=1, max_size=30))
@example(name="car", pose=stamped(), fault="name", namespace="x")
def test_spawn_entity_refuses_bad_names_poses_and_namespaces(harness, standard, name, pose, fault, namespace):
    if fault == "name":
        request = SpawnEntity.Request(name=name, resource_string=BOX, initial_pose=stamped(y=8.0))
        must_fail = True
    elif fault == "pose":
        request = SpawnEntity.Request(name="posed", resource_string=BOX, initial_pose=pose)
        must_fail = True
    else:
        request = SpawnEntity.Request(name="spaced", resource_string=json.dumps(GOOD_VEHICLE), entity_namespace=namespace)
        must_fail = not valid_namespace(namespace)
    check(harness, standard, "spawn_entity", request, must_fail)


@FUZZ
@given(entity=st.one_of(NAMES, st.sampled_from(["car", "tower_1"])), pose=bad_pose(),
       twist=st.tuples(FLOATS, FLOATS), accelerate=st.booleans())
def test_set_entity_state_refuses_bad_states(harness, standard, entity, pose, twist, accelerate):
    state = EntityState(pose=pose.pose, twist=Twist(linear=Vector3(x=twist[0]), angular=Vector3(z=twist[1])))
    state.header.frame_id = pose.header.frame_id
    if accelerate:
        state.acceleration.linear.x = 1.0
    # Refused whatever else is drawn: the pose always has its fault.
    check(harness, standard, "set_entity_state", SetEntityState.Request(entity=entity, state=state))


@FUZZ
@given(entity=NAMES, service=st.sampled_from(["delete_entity", "get_entity_state", "get_entity_info",
                                              "get_entity_bounds"]))
def test_entity_services_refuse_names_of_no_entity(harness, standard, entity, service):
    kind = {"delete_entity": DeleteEntity, "get_entity_state": GetEntityState, "get_entity_info": GetEntityInfo,
            "get_entity_bounds": GetEntityBounds}[service]
    code, _ = check(harness, standard, service, kind.Request(entity=entity))
    assert code == 2  # RESULT_NOT_FOUND


@FUZZ
@given(pattern=st.one_of(st.text(max_size=60), st.sampled_from(["(a+)+$", "(", "[", "\\", "a{99999999}", "(?<", ".*" * 500])),
       categories=st.lists(st.integers(0, 255), max_size=4), bounds_type=st.integers(0, 255),
       points=st.lists(st.tuples(FLOATS, FLOATS, FLOATS), max_size=5))
def test_entity_filters_answer_any_filter_and_change_nothing(harness, standard, pattern, categories, bounds_type,
                                                             points):
    filters = EntityFilters(filter=pattern, categories=[EntityCategory(category=c) for c in categories],
                            bounds=Bounds(type=bounds_type, points=[Vector3(x=x, y=y, z=z) for x, y, z in points]))
    check(harness, standard, "get_entities", GetEntities.Request(filters=filters), must_fail=False)


@FUZZ
@given(steps=st.one_of(st.just(0), st.integers(api.MAX_STEPS + 1, 2 ** 64 - 1)),
       scope=st.integers(8, 254), state=st.integers(4, 255))
def test_stepping_resetting_and_states_refuse_what_the_standard_does_not_define(harness, standard, steps, scope, state):
    check(harness, standard, "step_simulation", StepSimulation.Request(steps=steps))
    check(harness, standard, "reset_simulation", ResetSimulation.Request(scope=scope))
    check(harness, standard, "set_simulation_state",
          SetSimulationState.Request(state=SimulationState(state=state)))


@FUZZ
@given(data=st.data())
def test_load_world_refuses_the_scene_corpus_and_escaping_uris(harness, standard, data):
    if data.draw(st.booleans()):
        request = LoadWorld.Request(uri=data.draw(st.sampled_from(harness.escapes)))
    else:
        request = LoadWorld.Request(resource_string=data.draw(scene_text()))
    check(harness, standard, "load_world", request)


def test_spawn_entities_beyond_max_bodies_fail_at_once(harness, standard):
    from simulation_interfaces.msg import SpawnEntity as Entry
    from simulation_interfaces.srv import SpawnEntities

    entries = [Entry() for _ in range(int(harness.requests.max_bodies) + 1)]
    started = time.perf_counter()
    code, message = check(harness, standard, "spawn_entities", SpawnEntities.Request(spawn_requests=entries))
    assert code == 4 and "max_bodies" in message and time.perf_counter() - started < 5.0


def test_the_2x_field_layout_is_read_too(harness, standard):
    """simulation_interfaces 2.x (Rolling) moved SpawnEntity's and LoadWorld's uri and
    resource_string into a Resource and gave SetEntityState set_pose/set_twist/set_acceleration:
    the handlers read either layout (here 2.x-shaped requests, as its types would carry them)."""
    def vector3(x=0.0, y=0.0, z=0.0):
        return SimpleNamespace(x=x, y=y, z=z)

    pose = SimpleNamespace(position=vector3(0.0, 9.0, 3.0), orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0))
    spawn = SimpleNamespace(name="rolling_box", allow_renaming=False, entity_namespace="",
                            entity_resource=SimpleNamespace(uri="", resource_string=BOX),
                            initial_pose=SimpleNamespace(header=SimpleNamespace(frame_id=""), pose=pose))
    try:
        reply = standard.spawn_entity(spawn)
        assert reply["result"]["result"] == 1 and reply["entity_name"] == "rolling_box", reply
        before = harness.requests.entity("rolling_box")
        # set_pose false, set_twist true: the pose given (far away) is left, the twist is set.
        state = SimpleNamespace(header=SimpleNamespace(frame_id=""),
                                pose=SimpleNamespace(position=vector3(50.0, 50.0, 50.0), orientation=pose.orientation),
                                twist=SimpleNamespace(linear=vector3(z=2.0), angular=vector3()),
                                acceleration=SimpleNamespace(linear=vector3(), angular=vector3()))
        edit = SimpleNamespace(entity="rolling_box", state=state, set_pose=False, set_twist=True, set_acceleration=False)
        assert standard.set_entity_state(edit)["result"]["result"] == 1
        after = harness.requests.entity("rolling_box")
        assert after["pose"]["position"] == before["pose"]["position"] and after["twist"]["linear"] == [0.0, 0.0, 2.0]
        refused = standard.set_entity_state(SimpleNamespace(**{**vars(edit), "set_acceleration": True}))
        assert refused["result"]["result"] == 4
        world = SimpleNamespace(world_resource=SimpleNamespace(uri="", resource_string="<sdf/>"))
        assert standard.load_world(world)["result"]["result"] == LoadWorld.Response.UNSUPPORTED_FORMAT
    finally:
        harness.requests.reset(api.SCOPE_ALL)
