"""The Python API of SPEC 4: names, slots, bad input, scene files."""
import math
import os

import numpy as np
import pytest

from vplayground_ros.physics import World, pipeline
from vplayground_ros.scene import SceneError, load_world, save_world


def snapshot(world):
    return (world.body_names(), {k: v.copy() for k, v in world.state().items()}, world.layout_version,
            [world.body(name) for name in world.body_names()])


def assert_unchanged(world, before):
    names, state, layout, bodies = snapshot(world)
    assert names == before[0] and layout == before[2]
    for key in state:
        assert np.array_equal(state[key], before[1][key]), key
    assert repr(bodies) == repr(before[3])


@pytest.fixture
def world():
    w = World()
    w.add_body({"name": "a", "position": [0, 0, 0.5]})
    w.add_body({"name": "b", "position": [3, 0, 0.5]})
    w.step(10)
    return w


@pytest.mark.parametrize("spec, fragment", [
    ({"colour": "red"}, "body.colour: unknown key"),
    ({"size": [1, 0, 1]}, "body.size[1]: must be >= 0.001"),
    ({"size": [1e-300, 1e-300, 1e-300]}, "body.size[0]: must be >= 0.001"),
    ({"size": [1, 1]}, "body.size: expected 3 numbers"),
    ({"mass": -2}, "body.mass: must be >= 1e-09"),
    ({"mass": 5e-324}, "body.mass: must be >= 1e-09"),
    ({"density": 0}, "body.density: must be > 0"),
    ({"density": 1e-300}, "body.density: the body's mass 1e-300 kg is below 1e-09 kg"),
    # A mass that density gives is a mass too: saved as `mass`, 8e12 kg had made a scene unloadable.
    ({"size": [2, 2, 2], "density": 1e12}, "body.density: the body's mass 8e+12 kg is more than 1e+12 kg"),
    ({"shape": "sphere", "radius": 1e-300}, "body.radius: must be >= 0.0005"),
    ({"shape": "cylinder", "length": 1e-30}, "body.length: must be >= 0.001 for a cylinder"),
    ({"shape": "convex", "points": [[0, 0, 0], [1e-30, 0, 0], [0, 1e-30, 0], [0, 0, 1e-30]]},
     "body.points: the points span 1e-30 m, less than the smallest body size 0.001 m"),
    ({"position": [0, math.nan, 1]}, "body.position[1]: must be finite"),
    ({"linear_velocity": [math.inf, 0, 0]}, "body.linear_velocity[0]: must be finite"),
    ({"elasticity": 1.5}, "body.elasticity: must be <= 1"),
    ({"static_friction": -0.1}, "body.static_friction: must be >= 0"),
    ({"immovable": "yes"}, "body.immovable: expected true or false"),
    ({"shape": "cone"}, "body.shape: unsupported shape"),
    ({"name": "a"}, "already exists"),
    ({"name": "bad name!"}, "body.name: invalid name"),
    ({"rpy": [0, 0, 0], "quaternion": [0, 0, 0, 1]}, "either rpy or quaternion"),
])
def test_bad_spawn_raises_and_changes_nothing(world, spec, fragment):
    before = snapshot(world)
    with pytest.raises(ValueError, match=None) as error:
        world.add_body(spec)
    assert fragment in str(error.value)
    assert_unchanged(world, before)


@pytest.mark.parametrize("fields, fragment", [
    ({"size": [1, -1, 1]}, "a.size[1]: must be >= 0.001"),
    ({"mass": 0}, "a.mass: must be >= 1e-09"),
    ({"density": 1e-300}, "a.density: the body's mass 1e-300 kg is below 1e-09 kg"),
    ({"size": [100, 100, 100], "density": 2e6}, "a.density: the body's mass 2e+12 kg is more than"),
    ({"name": "c"}, "a.name: unknown key"),
    ({"position": [0, 0, float("nan")]}, "a.position[2]: must be finite"),
])
def test_bad_edit_raises_and_changes_nothing(world, fields, fragment):
    before = snapshot(world)
    with pytest.raises(ValueError) as error:
        world.edit_body("a", **fields)
    assert fragment in str(error.value)
    assert_unchanged(world, before)


def test_a_refused_body_takes_no_slot_and_no_name(world):
    """Issue 35: a body refused after its slot was taken stayed there, nameless, and every later
    layout held None. The next body gets the slot and the name it would have had anyway."""
    with pytest.raises(ValueError, match="density: the body's mass"):
        world.add_body({"density": 1e-300})
    fresh = World()
    for name in ("a", "b"):
        fresh.add_body({"name": name})
    assert world.add_body({}) == fresh.add_body({})
    assert world._slots == fresh._slots and world._free == fresh._free  # the layout, reached past the API
    assert None not in world.body_names()


def test_a_refused_wheel_edit_changes_nothing():
    world = load_world("config/default_scene.yaml")
    before = snapshot(world)
    with pytest.raises(ValueError, match=r"car.wheels\[1\].mass: must be >= 1e-09"):
        world.edit_vehicle("car", wheels={1: {"mass": 1e-300}})
    assert_unchanged(world, before)
    assert world.vehicle("car")["wheels"][1]["mass"] == 20.0


def test_numpy_numbers_are_numbers():
    """What numpy hands a caller (float32, int64, bool_ scalars, 1-D arrays) is taken as the
    numbers and flags it holds: np.float32 speeds and array positions had been refused
    ("expected a number, got float32")."""
    world = World()
    world.add_body({"name": "crate", "shape": "box", "size": np.array([0.5, 0.5, 0.5], np.float32),
                    "position": np.array([0.0, 0.0, 2.0]), "mass": np.float32(3.0),
                    "immovable": np.bool_(False)})
    body = world.body("crate")
    assert body["size"] == [0.5, 0.5, 0.5] and body["position"] == [0.0, 0.0, 2.0] and body["mass"] == 3.0
    assert world.body("crate")["immovable"] is False
    world.step(np.int64(3))
    from vplayground_ros.resources import find_shared
    car = load_world(find_shared("config/default_scene.yaml"))
    name = car.vehicle_names()[0]
    car.drive(name, np.float32(1.5), np.int64(0), timeout=np.float64(2.0))
    assert car.vehicle_state(name)["command_speed"] == 1.5
    with pytest.raises(ValueError, match="expected a number"):
        car.drive(name, np.bool_(True), 0.0)
    with pytest.raises(ValueError, match="expected a list of 3 numbers"):
        world.edit_body("crate", position=np.zeros((1, 3)))


def test_unknown_names_raise_key_error(world):
    before = snapshot(world)
    for call in (lambda: world.edit_body("nobody", mass=1.0), lambda: world.remove_body("nobody"),
                 lambda: world.apply_impulse("nobody", [1, 0, 0])):
        with pytest.raises(KeyError, match="nobody"):
            call()
    assert_unchanged(world, before)


def test_step_rejects_bad_counts(world):
    for n in (-1, 1.5, "3", True):
        with pytest.raises(ValueError):
            world.step(n)


def test_names_are_unique_and_slots_are_reused_without_disturbing_others(world):
    generated = world.add_body({"position": [6, 0, 0.5]})
    assert generated not in ("a", "b") and generated in world.body_names()
    b_before = world.state()["positions"][world.body_names().index("b")].copy()
    world.remove_body("a")
    assert world.body_names() == ["b", generated] or world.body_names() == [generated, "b"] or "a" not in world.body_names()
    assert np.array_equal(world.state()["positions"][world.body_names().index("b")], b_before)
    world.add_body({"name": "c", "position": [-4, 0, 0.5]})
    assert sorted(world.body_names()) == sorted(["b", "c", generated])
    assert len(world._bodies.active) == 64  # the freed slot was reused, nothing grew


def test_a_body_in_a_removed_bodys_slot_starts_its_freezing_time_afresh():
    """A body at rest freezes after freezing.time whichever slot it takes: the slot of one
    removed 0.44 s into its rest had handed the newcomer that time, and it froze after 0.06 s."""
    scene = {"version": 1, "bodies": [{"name": "a", "position": [0, 0, 0.5]}]}
    reused = load_world(scene)
    reused.step(56)
    reused.remove_body("a")
    reused.add_body(scene["bodies"][0])
    fresh = load_world(scene)
    for world in (reused, fresh):
        world.step(16)
        assert not world.body("a")["frozen"]
        world.step(52)
        assert world.body("a")["frozen"]


def respawned_on_stack(first, second):
    """A box resting on another for 40 steps beside an inert placeholder, the three added in
    the order given; then the upper box and the placeholder removed and the upper box added
    again as it started, into the lower of the two slots freed."""
    world = World({"freezing": {"enabled": False}})
    for spec in ({"name": "base", "position": [0, 0, 0.5]}, first, second):
        world.add_body(spec)
    world.step(40)
    world.remove_bodies(["top", "spare"])
    world.add_body(STACKED)
    return world


STACKED = {"name": "top", "position": [0.1, 0, 1.5], "rpy": [0, 0, 0.4]}
SPARE = {"name": "spare", "position": [30, 30, 30], "immovable": True, "collides": False}


def test_a_body_in_a_removed_bodys_slot_is_warm_started_by_nothing_of_it():
    """The removed body's contacts leave none of their impulses to the newcomer in its slot: it
    moves as one added where no contact was (the placeholder's slot). The shock propagation's
    impulses had stayed, and the newcomer started from its predecessor's."""
    again = respawned_on_stack(STACKED, SPARE)      # back in the slot its predecessor held
    elsewhere = respawned_on_stack(SPARE, STACKED)  # in the placeholder's
    for _ in range(5):
        again.step(1)
        elsewhere.step(1)
        assert np.array_equal(again.state()["positions"], elsewhere.state()["positions"])


def test_contacts_are_not_handed_to_a_body_in_a_removed_bodys_slot():
    """contacts() after a removal leaves the removed body's contacts out, also once another
    body has taken its slot: they had been listed as the newcomer's, touching where it is not."""
    world = load_world({"version": 1, "bodies": [{"name": "base", "position": [0, 0, 0.5]}, STACKED]})
    world.step(20)
    world.remove_body("top")
    world.add_body({"name": "far", "position": [5, 5, 5]})
    far = world.body_names().index("far")
    contacts = world.contacts()
    assert far not in contacts["body_a"] and far not in contacts["body_b"]
    assert len(contacts["points"]) > 0  # the base still stands on the ground


def test_edit_changes_only_given_keys(world):
    before = world.body("b")
    world.edit_body("b", mass=10.0, linear_velocity=[1, 0, 0])
    after = world.body("b")
    assert after["mass"] == 10.0 and after["linear_velocity"] == [1.0, 0.0, 0.0]
    for key in ("size", "position", "quaternion", "elasticity", "static_friction"):
        assert after[key] == before[key]


def test_state_and_contacts_shapes():
    world = World({"freezing": {"enabled": False}})  # frozen bodies make no contacts
    world.add_body({"name": "a", "position": [0, 0, 0.5]})
    world.add_body({"name": "b", "position": [3, 0, 0.5]})
    world.step(64)
    s = world.state()
    assert s["positions"].shape == (2, 3) and s["quaternions"].shape == (2, 4)
    c = world.contacts()
    assert len(c["points"]) >= 8  # two boxes on the ground, four corners each
    assert set(np.unique(c["body_b"])) == {-1}
    assert np.allclose(c["normals"], [0, 0, -1])
    assert np.all(c["impulses"] >= 0)


def test_growing_beyond_capacity_keeps_bodies():
    world = World(capacity=4)
    names = [world.add_body({"position": [2.0 * k, 0, 0.5]}) for k in range(10)]
    world.step(5)
    assert world.body_names() == names
    assert np.allclose(world.state()["positions"][:, 0], 2.0 * np.arange(10), atol=1e-5)


SCENE = {
    "version": 1,
    "settings": {"steps_per_second": 100, "resolve_iterations": 4, "octree_depth": 4,
                 "gravity": [0, 0, -9.0], "freezing": {"enabled": False}},
    "ground": {"height": -1.0, "elasticity": 0.3},
    "bodies": [
        {"name": "crate", "size": [1, 2, 0.5], "position": [0, 0, 2], "rpy": [0.1, 0.2, 0.3],
         "linear_velocity": [1, 0, 0], "mass": 12.5, "elasticity": 0.4},
        {"name": "wall", "size": [5, 0.2, 2], "position": [0, 4, 0], "immovable": True},
        {"size": [0.3, 0.3, 0.3], "position": [2, 2, 5], "density": 800},
    ],
}


def test_scene_round_trip(tmp_path):
    world = load_world(SCENE)
    world.step(30)
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    assert again.body_names() == world.body_names()
    assert again.settings == world.settings and again.ground == world.ground
    for name in world.body_names():
        assert again.body(name) == world.body(name)
    world.step(20)
    again.step(20)
    assert np.allclose(again.state()["positions"], world.state()["positions"], atol=1e-9)


@pytest.mark.parametrize("mutate, fragment", [
    (lambda s: s.update(version=2), "version: unsupported version 2"),
    (lambda s: s.pop("version"), "version: missing"),
    (lambda s: s.update(extra=1), "extra: unknown key"),
    (lambda s: s["settings"].update(steps_per_second=0), "settings.steps_per_second: must be between"),
    (lambda s: s["settings"]["freezing"].update(time="long"), "settings.freezing.time: expected a number"),
    (lambda s: s["ground"].update(static_friction=-1), "ground.static_friction: must be >= 0"),
    (lambda s: s["bodies"][0].update(size=[1, 2, 0]), "bodies[0].size[2]: must be >= 0.001"),
    (lambda s: s["bodies"][1].update(name="crate"), "bodies[1].name: duplicate name 'crate'"),
    (lambda s: s["bodies"][2].update(mass=float("inf")), "bodies[2].mass: must be finite"),
    (lambda s: s.update(bodies={"a": 1}), "bodies: expected a list"),
])
def test_scene_errors_name_the_key(mutate, fragment):
    import copy
    scene = copy.deepcopy(SCENE)
    mutate(scene)
    with pytest.raises(SceneError) as error:
        load_world(scene)
    assert fragment in str(error.value)


def test_scene_file_errors_name_the_file(tmp_path):
    broken = tmp_path / "broken.yaml"
    broken.write_text("version: 1\nbodies: [\n")
    with pytest.raises(SceneError, match="broken.yaml: not valid YAML"):
        load_world(broken)
    with pytest.raises(SceneError, match="missing.yaml: cannot read"):
        load_world(tmp_path / "missing.yaml")


def test_default_scene_loads_and_runs():
    from vplayground_ros.resources import find_shared
    world = load_world(find_shared("config/default_scene.yaml"))
    world.step(5 * 128)
    s = world.state()
    assert np.all(np.isfinite(s["positions"]))
    half_height = 0.5 * s["sizes"].min(axis=1)
    assert np.all(s["positions"][:, 2] > half_height * 0.5)


def test_buffer_growth_mid_call_gives_the_same_result():
    """Pair and contact buffers that fill up inside step(n) are grown and the call goes on; the
    result is the same as with buffers that were large enough from the start."""
    from helpers import pile
    roomy, cramped = pile(40, seed=3), pile(40, seed=3)
    broad = cramped._broad
    cramped._broad = broad._replace(pair_a=np.zeros(2, np.int64), pair_b=np.zeros(2, np.int64))
    from vplayground_ros.physics.step_context import allocate_contact_buffers, newest_contacts
    cramped._contacts = allocate_contact_buffers(4, 2)
    roomy.step(200)
    cramped.step(200)
    assert len(cramped._broad.pair_a) > 2 and len(newest_contacts(cramped._contacts).body_a) > 4
    for key, value in roomy.state().items():
        assert np.array_equal(value, cramped.state()[key]), key


def test_settings_change_on_the_running_world():
    world = World()
    world.add_body({"name": "b", "position": [0, 0, 0.5]})
    world.step(128)
    assert world.state()["frozen"][0]
    before = world.settings
    with pytest.raises(ValueError, match="settings.gravity"):
        world.update_settings({"gravity": [0, 0, float("nan")]})
    assert world.settings == before and world.state()["frozen"][0]
    world.update_settings({"gravity": [0, 0, 9.81], "octree_depth": 3, "freezing": {"time": 2.0}})
    assert world.settings["freezing"]["linear_speed"] == before["freezing"]["linear_speed"]
    world.step(64)  # woken, and gravity now points up
    assert world.state()["positions"][0, 2] > 1.0


def test_bodies_that_go_non_finite_or_fly_away_are_removed():
    world = World()
    for k, name in enumerate(("keep", "nan", "away")):
        world.add_body({"name": name, "position": [0, 3.0 * k, 0.5]})
    world.step(1)
    world._bodies.velocity[world._slots["nan"], 0] = float("nan")  # injected fault
    world.edit_body("away", linear_velocity=[0, 0, 5000.0])
    world.step(128)
    assert sorted(world.remove_escaped()) == ["away", "nan"]
    assert world.body_names() == ["keep"]
    world.step(10)
    assert np.all(np.isfinite(world.state()["positions"]))


def test_profiling_times_every_stage():
    from helpers import pile
    world = pile(50)
    world.step(20)
    assert sum(world.stage_seconds().values()) == 0.0  # off by default
    world.profiling = True
    world.step(64)
    seconds = world.stage_seconds()
    assert set(seconds) >= {"detection", "contact pass", "collision pass", "freezing"}
    assert all(v >= 0.0 for v in seconds.values()) and seconds["detection"] > 0.0


def test_resting_bodies_are_still_checked_for_escaping():
    """remove_escaped looks only at bodies that may have moved, plus every body once a simulated
    second (a state the engine should never write in a frozen body) and when the world's
    bounds move (an immovable body now outside)."""
    world = World()
    world.add_body({"name": "rests", "size": [0.5, 0.5, 0.5], "position": [0, 0, 0.25]})
    world.add_body({"name": "wall", "size": [1, 10, 2], "position": [1500, 0, 1], "immovable": True})
    world.step(256)
    assert world.state()["frozen"].tolist() == [True, False] and world.remove_escaped() == []
    world._bodies.position[world._slots["rests"], 2] = float("nan")  # injected fault
    removed = []
    for _ in range(128):  # a batch at a time, as the node steps
        world.step(1)
        removed += world.remove_escaped()
    assert removed == ["rests"]
    # A playground 1,000 m the other way moves the world's centre: the wall is 2,500 m from it.
    world.set_playground(np.array([[-1001.0, 0, 0], [-999.0, 0, 0], [-1000.0, 1, 0]]), np.array([[0, 1, 2]]))
    assert world.remove_escaped() == ["wall"]


def every_array(world):
    """Each array the step writes (bodies, broad phase, both contact buffers), by name."""
    out = {"newest": world._contacts.newest.copy()}
    groups = {"bodies": world._bodies, "broad": world._broad, "contacts 0": world._contacts.pair[0],
              "contacts 1": world._contacts.pair[1]}
    for group, fields in groups.items():
        for field, value in fields._asdict().items():
            for name, array in (value._asdict().items() if hasattr(value, "_asdict") else [("", value)]):
                out[f"{group}.{field}.{name}"] = np.array(array)
    return out


def test_bodies_that_freeze_last_join_the_static_index_once_the_world_is_at_rest():
    """A frozen body waits outside the static index until enough others do (it is re-indexed
    each step meanwhile); when it is the last to freeze nothing else will come, so the world at
    rest indexes it at once and every later step is the resting one, without a compiled call."""
    world = World()
    for k in range(40):
        world.add_body({"size": [0.5] * 3, "position": [(k % 8) * 0.75, (k // 8) * 0.75, 0.25]})
    world.step(3 * 128)
    assert world.state()["frozen"].all() and world._bodies.static_indexed[world._bodies.active].all()
    world.add_body({"name": "late", "size": [0.5] * 3, "position": [-3.0, 0.0, 0.25]})
    world.step(3 * 128)
    assert world.state()["frozen"].all()
    b = world._bodies
    assert b.static_indexed[b.active].all()
    assert pipeline.resting_steps(b, world._broad, world._vehicles.arrays, world._contacts, 1)


def test_a_world_at_rest_steps_alike_with_and_without_the_resting_shortcut():
    """Calls that find every body asleep in the static index step in Python
    (pipeline.resting_steps); the World they leave, and what comes after a push, must be what the
    compiled step leaves."""
    import copy
    world = World()
    for k in range(40):
        for level in range(2):
            world.add_body({"size": [0.5] * 3, "position": [(k % 8) * 0.75, (k // 8) * 0.75, 0.25 + 0.5 * level]})
    world.step(3 * 128)
    assert world.state()["frozen"].all() and world._bodies.static_indexed[world._bodies.active].all()
    shortcut, compiled = world, copy.deepcopy(world)
    compiled.resting_shortcut = False
    for w in (shortcut, compiled):
        for n in (1, 1, 2, 3, 128):
            w.step(n)
        w.apply_impulse(w.body_names()[1], [0.0, 40.0, 0.0])  # wakes the top of a column
        w.step(64)
    a, b = every_array(shortcut), every_array(compiled)
    assert [k for k in a if not np.array_equal(a[k], b[k])] == []
    assert (shortcut.time, shortcut.step_count, shortcut.stats) == (compiled.time, compiled.step_count, compiled.stats)
    assert not shortcut.state()["frozen"][1]


def test_shared_files_are_found_under_the_user_base_of_pip_install_user(tmp_path):
    """pip install --user puts config/ and meshes/ under the user base's share/, which was not
    searched: the default scene 'is not installed'."""
    import subprocess
    import sys
    shared = tmp_path / "share" / "vplayground_ros" / "config" / "only_here.yaml"
    shared.parent.mkdir(parents=True)
    shared.write_text("version: 1\n")
    found = subprocess.run([sys.executable, "-c", "from vplayground_ros.resources import find_shared; "
                            "print(find_shared('config/only_here.yaml'))"],
                           env={**os.environ, "PYTHONUSERBASE": str(tmp_path)}, capture_output=True, text=True)
    assert found.stdout.strip() == str(shared), found.stderr
