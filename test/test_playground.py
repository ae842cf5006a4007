"""The triangle-mesh playground: boxes on the shipped ramp, on mesh floors and across seams."""
import math

import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.playground import CONCAVE, make_playground
from vplayground_ros.resources import find_shared
from vplayground_ros.scene import load_world

G = 9.81
# The shipped ramp rises from (8, y, 0) to (16, y, 2), for |y| <= 3: slope 1:4.
RAMP_NORMAL = np.array([-2.0, 0.0, 8.0]) / math.hypot(2.0, 8.0)
RAMP_POINT = np.array([8.0, 0.0, 0.0])


def playground_world(**settings):
    return load_world({"version": 1, "settings": settings, "playground": {"mesh": "playground.obj"}})


def lowest_corner_above_ramp(world, name):
    """Signed distance of the box's lowest corner to the ramp plane."""
    s, row = world.state(), world.body_names().index(name)
    x, y, z, w = s["quaternions"][row]
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    half = s["sizes"][row] / 2
    corners = s["positions"][row] + (np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                               for sz in (-1, 1)]) * half) @ r.T
    return float(np.min((corners - RAMP_POINT) @ RAMP_NORMAL))


def over_ramp(world, name):
    p = world.state()["positions"][world.body_names().index(name)]
    return 8.5 < p[0] < 15.5 and abs(p[1]) < 2.5


def test_box_slides_down_the_ramp_without_tunnelling():
    world = playground_world()
    slope = math.atan(0.25)
    world.add_body({"name": "b", "size": [0.5] * 3, "position": [14.0, 0.0, 1.5 + 0.25 / math.cos(slope)],
                    "rpy": [0, -slope, 0], "static_friction": 0.0, "dynamic_friction": 0.0})
    lowest = []
    for _ in range(3 * 128):
        world.step(1)
        if over_ramp(world, "b"):
            lowest.append(lowest_corner_above_ramp(world, "b"))
    assert world.state()["positions"][0, 0] < 8.0  # reached the bottom
    assert min(lowest) > -0.01  # never more than 1 cm into the ramp


def test_box_dropped_from_ten_metres_onto_the_ramp_does_not_pass_through():
    world = playground_world()
    world.add_body({"name": "b", "size": [0.5] * 3, "position": [12.0, 0.5, 12.0], "rpy": [0.3, 0.2, 0.1]})
    lowest = []
    for _ in range(4 * 128):
        world.step(1)
        if over_ramp(world, "b"):
            lowest.append(lowest_corner_above_ramp(world, "b"))
    assert min(lowest) > -0.05
    p = world.state()["positions"][0]
    assert np.all(np.isfinite(p)) and p[2] > 0.2  # on the ramp or the ground, never below


def mesh_floor(cells=10, cell=2.0):
    """A floor of cells x cells squares, each two triangles: seams every `cell` metres both
    ways and along every diagonal."""
    n = cells + 1
    xs = (np.arange(n) - cells / 2) * cell
    vertices = np.array([[x, y, 0.0] for y in xs for x in xs])
    faces = []
    for j in range(cells):
        for i in range(cells):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i
            faces += [[a, b, c], [a, c, d]]
    return vertices, np.array(faces)


def test_box_on_a_mesh_floor_rests_like_on_the_ground_plane():
    heights = []
    for use_mesh in (False, True):
        world = World(ground=None if use_mesh else {"height": 0.0})
        if use_mesh:
            world.set_playground(*mesh_floor())
        world.add_body({"name": "b", "size": [1.0, 0.8, 0.6], "position": [0.3, -0.7, 1.0], "rpy": [0, 0, 0.4]})
        touched = set()
        for _ in range(3 * 128):
            world.step(1)
            touched |= set(world.contacts()["body_b"].tolist())
        assert touched == ({-2} if use_mesh else {-1})  # contacts() names the playground -2
        heights.append(world.state()["positions"][0, 2])
        assert world.state()["frozen"][0]
    assert heights[1] == pytest.approx(heights[0], abs=1e-3)
    assert heights[1] == pytest.approx(0.3, abs=6e-3)


@pytest.mark.parametrize("heading", [0.0, 0.3, math.pi / 4])
def test_box_slides_across_seams_without_a_jump(heading):
    mu = 0.3
    # No ground plane: the mesh floor alone carries the box (with the default ground material).
    world = World(ground=None, settings={"freezing": {"enabled": False}})
    world.set_playground(*mesh_floor())
    speed = 4.0
    world.add_body({"name": "b", "size": [0.6, 0.6, 0.4], "position": [-5.0, -3.0, 0.2],
                    "rpy": [0, 0, heading], "static_friction": mu, "dynamic_friction": mu,
                    "linear_velocity": [speed, 0.8, 0.0]})
    world.step(8)
    previous = world.state()["linear_velocities"][0].copy()
    # Coulomb deceleration per step, pair coefficient the geometric mean with the material's 0.6.
    expected_drop = math.sqrt(mu * 0.6) * G / 128
    for _ in range(100):
        world.step(1)
        v = world.state()["linear_velocities"][0]
        if np.linalg.norm(previous[:2]) < 0.2:
            break
        drop = np.linalg.norm(previous[:2]) - np.linalg.norm(v[:2])
        assert drop == pytest.approx(expected_drop, rel=0.15), (world.time, previous, v)
        assert abs(v[2]) < 0.02  # no hop at a seam
        heading_change = abs(math.atan2(v[1], v[0]) - math.atan2(previous[1], previous[0]))
        assert heading_change < 0.01
        previous = v.copy()


def test_default_scene_runs_ten_seconds_finite_and_above_the_ground():
    world = load_world(find_shared("config/default_scene.yaml"))
    assert len(world.playground_triangles) > 200
    world.step(10 * 128)
    s = world.state()
    for key in ("positions", "quaternions", "linear_velocities", "angular_velocities"):
        assert np.all(np.isfinite(s[key])), key
    # Nothing below the ground: the lowest point of each box's bounds stays above z = 0.
    half_diagonal = 0.5 * np.linalg.norm(s["sizes"], axis=1)
    assert np.all(s["positions"][:, 2] > -0.01)
    assert np.all(s["positions"][:, 2] + half_diagonal > 0.0)
    # The octree keeps the triangle tests a small fraction of the mesh.
    per_step = world.stats["triangles"] / world.step_count
    assert per_step < 0.1 * len(world.playground_triangles)


def test_box_pushed_against_a_step_stops_at_its_riser():
    world = playground_world()
    world.add_body({"name": "b", "size": [0.5] * 3, "position": [0.0, 9.0, 0.25],
                    "linear_velocity": [0.0, 3.0, 0.0], "elasticity": 0.0})
    world.step(2 * 128)
    p = world.state()["positions"][0]
    assert p[1] == pytest.approx(10.0 - 0.25, abs=0.02)  # against the first riser at y = 10
    assert p[2] == pytest.approx(0.25, abs=0.01)  # still on the ground, not lifted onto the step


def ramp_onto_floor():
    """One mesh: a floor (z = 0, x from -10 to 0, |y| <= 3) and a ramp rising from it at x = 0
    to 2 m at x = 8 (1:4), meeting at a concave crease; no ground plane under them."""
    world = World(ground=None)
    world.set_playground(np.array([[-10, -3, 0], [0, -3, 0], [0, 3, 0], [-10, 3, 0], [8, -3, 2], [8, 3, 2]], float),
                         np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]))
    return world


def test_mesh_edges_find_the_creases():
    """Which edges are concave creases, found by where the corners are: the ramp's foot on both
    sides (each holding the other's plane), not the floor's diagonal (a seam), the outline, a
    ridge (convex), nor a fence wound the other way round; the same for a mesh that repeats its
    vertices per triangle or rounds them."""
    creased = ramp_onto_floor()._playground
    assert creased.edges.tolist() == [CONCAVE << 1, 0, 0, CONCAVE << 2]
    ramp = np.array([-2.0, 0.0, 8.0]) / math.hypot(2.0, 8.0)
    np.testing.assert_allclose(creased.creases[0, 1], [*ramp, 0.0], atol=1e-15)  # the ramp's plane
    np.testing.assert_allclose(creased.creases[3, 2], [0.0, 0.0, 1.0, 0.0])  # the floor's
    faces = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])
    ridge = np.array([[0, -1, 0], [1, -1, 1], [1, 1, 1], [0, 1, 0], [2, -1, 0], [2, 1, 0]], float)
    assert not make_playground(ridge, faces)[0].edges.any()
    repeated = creased.triangles.reshape(-1, 3) + np.random.default_rng(0).uniform(-1e-7, 1e-7, (12, 3))
    assert make_playground(repeated, np.arange(12).reshape(4, 3))[0].edges.tolist() == creased.edges.tolist()
    fence = np.array([[-5, -3, 0], [0, -3, 0], [0, 3, 0], [-5, 3, 0], [0, -3, 1], [0, 3, 1]], float)
    facing_in, facing_out = [[0, 1, 2], [0, 2, 3], [2, 1, 4], [2, 4, 5]], [[0, 1, 2], [0, 2, 3], [1, 2, 5], [1, 5, 4]]
    assert make_playground(fence, facing_in)[0].edges.tolist() == [CONCAVE << 1, 0, CONCAVE, 0]
    assert not make_playground(fence, facing_out)[0].edges.any()


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_a_small_fast_body_coming_down_a_ramp_stays_on_the_floor_below(shape):
    """A 4 cm ball or box at 30 m/s down the ramp crosses the crease in one step: the floor,
    one-sided, gave no contact while the body was beside it and none once it was behind its
    plane, and the body fell through (8.7 m below it a second later). The floor's plane goes
    on past the crease now, so the body meets it."""
    world = ramp_onto_floor()
    slope = math.atan(0.25)
    down, up = np.array([-math.cos(slope), 0, -math.sin(slope)]), np.array([-math.sin(slope), 0, math.cos(slope)])
    spec = {"name": "b", "position": (np.array([6.0, 0, 1.5]) + 0.021 * up).tolist(),
            "linear_velocity": (30.0 * down).tolist()}
    spec.update({"shape": "sphere", "radius": 0.02} if shape == "sphere" else {"size": [0.04] * 3, "rpy": [0, -slope, 0]})
    world.add_body(spec)
    over_floor = []
    for _ in range(128):
        world.step(1)
        x, _, z = world.state()["positions"][0]
        if -9.5 < x < -0.5:
            over_floor.append(z)
    assert len(over_floor) >= 3 and min(over_floor) > 0.02 - 0.005


def test_small_spheres_dropped_into_the_half_pipe_stay_in_it():
    """Spheres of 5 mm dropped 5 m into the shipped half-pipe: 27 of 40 had fallen through its
    curved floor, whose strips meet at concave edges (a point beside both of two such strips,
    seen along each one's normal, got no contact from either)."""
    world = playground_world()
    rng = np.random.default_rng(1)
    for k in range(40):
        world.add_body({"name": f"s{k}", "shape": "sphere", "radius": 0.0025,
                        "position": [float(rng.uniform(-19, -9)), float(rng.uniform(-15.5, -8.5)), 5.0]})
    world.step(3 * 128)
    p = world.state()["positions"]
    # The half-pipe (meshes/make_playground.py): radius 4 m, its lowest line at y = -12 on z = 0.
    surface = 4.0 - np.sqrt(np.maximum(16.0 - (p[:, 1] + 12.0) ** 2, 0.0))
    assert np.all(p[:, 2] > surface - 0.01)


def test_a_ball_rolls_off_the_border_of_a_mesh_floor():
    """The plane goes on past concave edges only: past the floor's border there is nothing."""
    world = ramp_onto_floor()
    world.add_body({"name": "b", "shape": "sphere", "radius": 0.1, "position": [-8.0, 0.0, 0.1],
                    "linear_velocity": [-4.0, 0.0, 0.0]})
    world.step(2 * 128)
    x, _, z = world.state()["positions"][0]
    assert x < -10.0 and z < -2.0  # off the end at ~2.9 m/s (rolling), 1.3 s of falling


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_nothing_holds_a_body_beside_a_crease_or_behind_a_fence(shape):
    """The plane goes on past a crease only across it and only for a body in front of the
    other triangle: a body falling 2 mm clear of the mesh's side where the ramp's foot ends
    (the floor's plane went on past that end, and caught 7 of 20), and a body behind a fence
    rising from a floor's edge (the floor's plane went on under it), fall."""
    body = {"shape": "sphere", "radius": 0.05} if shape == "sphere" else {"size": [0.1] * 3}
    for dx in (-0.04, 0.0, 0.04):
        world = ramp_onto_floor()
        world.add_body({**body, "name": "b", "position": [dx, 3.052, 3.0], "linear_velocity": [0, 0, -20.0]})
        world.step(32)
        assert world.state()["linear_velocities"][0, 2] < -20.0
    fence = World(ground=None)
    fence.set_playground(np.array([[-5, -3, 0], [0, -3, 0], [0, 3, 0], [-5, 3, 0], [0, -3, 1], [0, 3, 1]], float),
                         np.array([[0, 1, 2], [0, 2, 3], [2, 1, 4], [2, 4, 5]]))  # facing the yard, x < 0
    fence.add_body({**body, "name": "b", "position": [0.06, 0.5, 0.3]})
    fence.step(128)
    assert fence.state()["positions"][0, 2] < -3.0


@pytest.mark.parametrize("size", [0.1, 0.3])
def test_a_box_slides_up_the_ramp_over_its_ridge_onto_the_platform(size):
    """A frictionless cube sliding up the shipped ramp at 4 m/s crosses its top ridge (a convex
    edge) keeping the horizontal part of its speed: sqrt(v0^2 - 2 g dh) cos(slope). With its
    rear still below the platform's plane, the box's front face had been taken for the
    separating axis, and the platform stopped it like a wall (0.82 m/s of 2.41; a 1 m cube
    never got on)."""
    world = playground_world(freezing={"enabled": False})
    slope = math.atan(0.25)
    up_slope = np.array([math.cos(slope), 0.0, math.sin(slope)])
    start = np.array([14.0, 0.5, 1.5]) + (size / 2 + 0.0005) * RAMP_NORMAL
    world.add_body({"name": "b", "size": [size] * 3, "position": start.tolist(), "rpy": [0, -slope, 0],
                    "linear_velocity": (4.0 * up_slope).tolist(), "static_friction": 0.0,
                    "dynamic_friction": 0.0, "elasticity": 0.0})
    expected = math.sqrt(4.0 ** 2 - 2 * G * 0.5) * math.cos(slope)
    for _ in range(300):
        world.step(1)
        if world.state()["positions"][0, 0] > 16.0 + size:
            break
    assert world.state()["positions"][0, 0] > 16.0 + size  # on the platform
    assert world.state()["linear_velocities"][0, 0] == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("size", [0.01, 0.02])
def test_small_capsules_dropped_onto_a_mesh_floor_stay_on_it(size):
    """Capsules of 1-2 cm (radius size/4) dropped 5 cm at random tilts, sliding at up to 3 m/s:
    on a mesh floor 21 of 24 one-centimetre ones had sunk through (the convex path gave a
    tilted capsule one point, its lower end, and the free end landed unseen); on the ground none.
    Both ends meet the floor's face now, as on the ground."""
    world = World(ground=None, settings={"freezing": {"enabled": False}})
    world.set_playground(*mesh_floor(cells=2, cell=20.0))
    rng = np.random.default_rng(7)
    for i in range(24):
        world.add_body({"name": f"c{i}", "shape": "capsule", "radius": size / 4, "length": size / 2,
                        "position": [-8 + (i % 6) * 3.0, -12 + (i // 6) * 3.0, 0.05],
                        "rpy": rng.uniform(-np.pi, np.pi, 3).tolist(),
                        "linear_velocity": [*rng.uniform(-3, 3, 2).tolist(), 0.0]})
    for _ in range(2 * 128):
        world.step(1)
        assert world.state()["positions"][:, 2].min() > -size / 2


def test_an_elastic_box_bounces_off_a_crease_of_the_half_pipe_without_gaining_energy():
    """A 20 cm box of elasticity 1 dropped 1 m onto a crease between two of the half-pipe's
    strips: the collision pass's 5 sweeps, short of converged over its 24 points, sent it off
    with 1.11 times its energy. A bounce off what does not move gives no energy."""
    world = playground_world(freezing={"enabled": False})
    angle = -math.pi / 2 + 13 * math.pi / 24  # the crease between strips 12 and 13
    world.add_body({"name": "b", "size": [0.2] * 3, "elasticity": 1.0,
                    "position": [-14.0, -12 + 4 * math.sin(angle), 4 - 4 * math.cos(angle) + 1.05]})
    mass = world.body("b")["mass"]

    def energy():
        body = world.body("b")
        v, w = np.array(body["linear_velocity"]), np.array(body["angular_velocity"])
        return 0.5 * mass * v @ v + 0.5 * mass * 0.04 / 6 * w @ w + mass * G * body["position"][2]
    start, bounced = energy(), False
    for _ in range(80):
        world.step(1)
        bounced = bounced or world.body("b")["linear_velocity"][2] > 0.0
        if bounced:
            assert energy() <= start * (1 + 1e-9)
    assert bounced
