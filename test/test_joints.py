"""Joints against analytic answers (issue 38's accuracy targets), and the World's joint API."""
import math
import re

import numpy as np
import pytest

from vplayground_ros.physics import World
from vplayground_ros.physics.specs import SpecError

G = 9.81
RATE = 128
UNFROZEN = {"gravity": [0, 0, -G], "steps_per_second": RATE, "freezing": {"enabled": False}}


def rod_pendulum(amplitude, length=1.0, mass=1.0, width=0.05):
    """A rod hanging from a revolute joint to the world at its top end, swung out by
    `amplitude` about x. Returns the world, the pivot and the moment of inertia about it."""
    world = World(UNFROZEN, ground=None)
    pivot = np.array([0.0, 0.0, 3.0])
    centre = pivot + 0.5 * length * np.array([0.0, math.sin(amplitude), -math.cos(amplitude)])
    world.add_body({"name": "rod", "size": [width, width, length], "mass": mass,
                    "position": centre.tolist(), "rpy": [amplitude, 0, 0]})
    world.add_joint({"name": "hinge", "type": "revolute", "child": "rod", "anchor": pivot.tolist(),
                     "axis": [1, 0, 0]})
    inertia = mass / 12 * (width ** 2 + length ** 2) + mass * (0.5 * length) ** 2
    return world, pivot, inertia


def record_swing(world, pivot, seconds):
    """The rod's angle from the vertical and its energy (kinetic + potential) after each step."""
    angles, energies = [], []
    for _ in range(int(seconds * RATE)):
        world.step(1)
        body = world.body("rod")
        p, v, w = (np.array(body[key]) for key in ("position", "linear_velocity", "angular_velocity"))
        r = p - pivot
        angles.append(math.atan2(r[1], -r[2]))
        inertia_centre = body["mass"] / 12 * (0.05 ** 2 + 1.0)
        energies.append(0.5 * body["mass"] * v @ v + 0.5 * inertia_centre * w[0] ** 2 + body["mass"] * G * p[2])
    return np.array(angles), np.array(energies)


def upward_crossings(angles):
    """Times (s) at which the angle crosses zero upwards, interpolated between steps."""
    k = np.nonzero((angles[:-1] < 0) & (angles[1:] >= 0))[0]
    return (k + angles[k] / (angles[k] - angles[k + 1])) / RATE


def test_pendulum_period_and_energy():
    amplitude = 0.1
    world, pivot, inertia = rod_pendulum(amplitude)
    angles, energies = record_swing(world, pivot, 60.0)
    # Compound pendulum, with the first finite-amplitude term.
    period = 2 * math.pi * math.sqrt(inertia / (G * 0.5)) * (1 + amplitude ** 2 / 16)
    measured = np.diff(upward_crossings(angles)[:11])  # 10 swings
    assert len(measured) == 10
    assert measured.mean() == pytest.approx(period, rel=0.005)
    # Drift of the mean energy, first swing against last, in parts of the swing's energy (the
    # energy above the rest position; its share of the total depends only on where z = 0 is).
    swing_energy = 1.0 * G * 0.5 * (1 - math.cos(amplitude))
    n = int(period * RATE)
    drift = (energies[-n:].mean() - energies[:n].mean()) / swing_energy
    assert abs(drift) < 0.01
    assert abs(angles).max() == pytest.approx(amplitude, rel=0.01)  # it still swings as far


def test_pendulum_energy_at_a_wide_swing():
    world, pivot, _ = rod_pendulum(0.8)
    _, energies = record_swing(world, pivot, 60.0)
    swing_energy = 1.0 * G * 0.5 * (1 - math.cos(0.8))
    n = 2 * RATE
    assert abs(energies[-n:].mean() - energies[:n].mean()) / swing_energy < 0.01


def test_joint_reports_the_hinge_angle():
    world, pivot, _ = rod_pendulum(0.3)
    world.step(37)
    body = world.body("rod")
    r = np.array(body["position"]) - pivot
    angle_now = math.atan2(r[1], -r[2])
    joint = world.joint("hinge")
    # 0 where it was made; about +x, positive turning the rod's bottom towards -y... or +y:
    # either way the hinge angle is the change of the rod's angle, up to the axis' sign.
    assert abs(joint["position"]) == pytest.approx(abs(angle_now - 0.3), abs=1e-6)
    assert joint["velocity"] == pytest.approx(np.sign(joint["position"] * (angle_now - 0.3))
                                              * body["angular_velocity"][0], abs=1e-9)


def test_ten_link_chain_hangs_still():
    world = World(UNFROZEN, ground=None)
    length = 0.3
    for k in range(10):
        world.add_body({"name": f"link{k}", "size": [0.05, 0.05, length], "mass": 1.0,
                        "position": [0, 0, 5 - length / 2 - k * length]})
        world.add_joint({"type": "revolute", "parent": f"link{k - 1}" if k else None,
                         "child": f"link{k}", "anchor": [0, 0, 5 - k * length], "axis": [1, 0, 0]})
    start = world.state()["positions"].copy()
    world.step(20 * RATE)
    creep = np.linalg.norm(world.state()["positions"] - start, axis=1)
    assert creep.max() < 1e-3


@pytest.mark.parametrize("ratio", [1.0, 100.0])
def test_revolute_limit_holds_a_heavy_load(ratio):
    """A 1 kg arm hinged to the world carries a weight `ratio` times heavier on a fixed joint at
    its end; the upper limit stops it 0.5 rad below horizontal."""
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "arm", "size": [1.0, 0.05, 0.05], "mass": 1.0, "position": [0.5, 0, 2]})
    world.add_body({"name": "weight", "size": [0.2, 0.2, 0.2], "mass": ratio, "position": [1.1, 0, 2]})
    world.add_joint({"name": "shoulder", "type": "revolute", "child": "arm", "anchor": [0, 0, 2],
                     "axis": [0, 1, 0], "lower": 0.0, "upper": 0.5})
    world.add_joint({"type": "fixed", "parent": "arm", "child": "weight"})
    world.step(5 * RATE)
    limit = 0.5
    expected = np.array([1.1 * math.cos(limit), 0.0, 2 - 1.1 * math.sin(limit)])
    assert np.linalg.norm(np.array(world.body("weight")["position"]) - expected) < 2e-3
    joint = world.joint("shoulder")
    assert joint["position"] == pytest.approx(limit, abs=2e-3)
    torque = G * (1.0 * 0.5 + ratio * 1.1) * math.cos(limit)
    assert -joint["effort"] == pytest.approx(torque, rel=0.01)


def motored_slider(mass, axis, speed, max_effort):
    """A box on a prismatic joint `rail` to the world whose motor drives it at `speed`."""
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "slider", "size": [0.2, 0.2, 0.2], "mass": mass, "position": [0, 0, 2]})
    world.add_joint({"name": "rail", "type": "prismatic", "child": "slider", "axis": axis,
                     "motor": {"mode": "velocity", "target": speed, "max_effort": max_effort}})
    world.step(RATE)
    return world


def test_prismatic_velocity_motor_tracks_its_speed():
    world = motored_slider(5.0, [1, 0, 1], 0.5, 500.0)
    start = world.joint("rail")["position"]
    world.step(2 * RATE)
    joint = world.joint("rail")
    assert (joint["position"] - start) / 2.0 == pytest.approx(0.5, rel=0.01)
    assert joint["velocity"] == pytest.approx(0.5, rel=0.01)
    # Holding 5 kg on a 45-degree rail: the gravity along it.
    assert joint["effort"] == pytest.approx(5.0 * G / math.sqrt(2), rel=0.01)
    # It slides along the axis only.
    p = world.body("slider")["position"]
    assert p[0] == pytest.approx(p[2] - 2, abs=1e-6) and abs(p[1]) < 1e-9


def test_motor_effort_bound():
    """A velocity motor too weak to lift its load slides back at the rate its effort allows."""
    world = motored_slider(2.0, [0, 0, 1], 1.0, 10.0)
    v0 = world.joint("rail")["velocity"]
    world.step(RATE)
    joint = world.joint("rail")
    # Net force 10 - 2 g down: a = (10 - 19.62) / 2 m/s^2.
    assert joint["velocity"] - v0 == pytest.approx((10.0 - 2.0 * G) / 2.0, rel=1e-3)
    assert joint["effort"] == pytest.approx(10.0, rel=1e-9)


def test_position_motor_holds_an_arm_level():
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "arm", "size": [1.0, 0.05, 0.05], "mass": 2.0, "position": [0.5, 0, 2]})
    world.add_joint({"name": "shoulder", "type": "revolute", "child": "arm", "anchor": [0, 0, 2],
                     "axis": [0, -1, 0], "motor": {"mode": "position", "target": 0.3, "max_effort": 100.0}})
    world.step(3 * RATE)
    joint = world.joint("shoulder")
    assert joint["position"] == pytest.approx(0.3, abs=1e-3)
    # Raised 0.3 rad about -y: the end is up; the motor holds the arm's weight moment.
    assert world.body("arm")["position"][2] == pytest.approx(2 + 0.5 * math.sin(0.3), abs=1e-3)
    assert joint["effort"] == pytest.approx(2.0 * G * 0.5 * math.cos(0.3), rel=0.01)


def test_position_motor_target_moves_at_its_velocity():
    """A position motor's `velocity` moves its target between commands: an arm follows a ramp
    of 0.4 rad/s given once, in batches of steps, without the lag a fixed target would give."""
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "arm", "size": [1.0, 0.05, 0.05], "mass": 2.0, "position": [0.5, 0, 2]})
    world.add_joint({"name": "shoulder", "type": "revolute", "child": "arm", "anchor": [0, 0, 2],
                     "axis": [0, -1, 0], "motor": {"mode": "position", "target": 0.0, "velocity": 0.4,
                                                   "max_effort": 100.0}})
    for _ in range(RATE // 4):
        world.step(4)
    joint = world.joint("shoulder")
    assert joint["motor"]["target"] == pytest.approx(0.4, abs=1e-9)
    assert joint["position"] == pytest.approx(0.4, abs=2e-3)
    assert joint["velocity"] == pytest.approx(0.4, abs=1e-2)
    world.edit_joint("shoulder", motor={"velocity": 0.0})  # an edit keeps the target where it moved to
    world.step(RATE)
    assert world.joint("shoulder")["position"] == pytest.approx(0.4, abs=1e-3)


def test_coupled_motors_reach_their_speeds_in_the_first_step():
    """Velocity motors along a chain whose links differ 100:1 in mass are coupled through it
    (turning the first hinge swings the links beyond it): solved together with the chain's
    equalities, each reaches its speed exactly in the first step (sweeping row by row, 10
    sweeps left the first two 1e-3 rad/s off, then swinging about the answer)."""
    world = World(UNFROZEN, ground=None)
    targets = [1.0, -2.0, 3.0]
    for k, (mass, target) in enumerate(zip([10.0, 1.0, 0.1], targets)):
        world.add_body({"name": f"link{k}", "size": [0.5, 0.05, 0.05], "mass": mass,
                        "position": [0.25 + 0.5 * k, 0, 2]})
        world.add_joint({"name": f"hinge{k}", "type": "revolute", "child": f"link{k}",
                         **({"parent": f"link{k - 1}"} if k else {}), "anchor": [0.5 * k, 0, 2],
                         "axis": [0, 0, 1], "motor": {"mode": "velocity", "target": target}})
    for _ in range(3):
        world.step(1)
        for k, target in enumerate(targets):
            assert world.joint(f"hinge{k}")["velocity"] == pytest.approx(target, abs=1e-12)


@pytest.mark.parametrize("mass", [0.01253, 0.02531, 0.0813, 0.5])
def test_a_motor_driving_into_its_limit_stays_bounded(mass):
    """A light link whose motor drives it into its joint's lower limit: the motor's and the
    limit's rows share the axis. The limit holds the link there whatever the motor's effort
    bound: a bound far above what the link needs (300 N m, the KUKA's) had let the motor, solved
    after the limit, drive it 0.2 rad past at full speed; an unbounded motor, which won before,
    never by impulses of 1e15 N s (a whole-matrix inverse of their coupling once gave that, and
    the link spun at hundreds of rad/s)."""
    for effort in (0.01, 300.0, np.inf):
        world = World(UNFROZEN, ground=None)
        world.add_body({"name": "link", "size": [0.5, 0.05, 0.05], "mass": mass, "position": [0.25, 0, 2]})
        world.add_joint({"name": "hinge", "type": "revolute", "child": "link", "anchor": [0, 0, 2],
                         "axis": [0, 0, 1], "lower": -0.02, "upper": 1.0,
                         "motor": {"mode": "velocity", "target": -1.0, "max_effort": effort}})
        for _ in range(RATE):
            world.step(1)
            joint = world.joint("hinge")
            assert joint["position"] >= -0.02 - 1e-6 and abs(joint["velocity"]) <= 1.0 + 1e-6
            assert abs(joint["effort"]) < 1e3
        assert joint["position"] == pytest.approx(-0.02, abs=1e-6) and abs(joint["velocity"]) < 1e-6


def test_a_chain_of_limited_joints_never_gains_energy():
    """Five 1 kg links hinged end to end, each joint limited to +-0.3 rad, released level: the
    limits can only take energy out. Their bounded rows, solved together from the answer
    without bounds clipped onto them, kept the pushes that had balanced the clipped pulls: the
    chain gained 92 times its drop energy and its joints spun at 188 rad/s."""
    world = World(UNFROZEN, ground=None)
    names = [f"l{k}" for k in range(5)]
    for k, name in enumerate(names):
        world.add_body({"name": name, "size": [0.5, 0.05, 0.05], "mass": 1.0, "position": [0.25 + 0.5 * k, 0, 5]})
        world.add_joint({"name": f"j{k}", "type": "revolute", **({"parent": names[k - 1]} if k else {}),
                         "child": name, "anchor": [0.5 * k, 0, 5], "axis": [0, 1, 0], "lower": -0.3, "upper": 0.3})
    world.disable_collisions(names)
    inertia = np.diag([1.0 / 12 * 0.05 ** 2 * 2, 1.0 / 12 * (0.5 ** 2 + 0.05 ** 2), 1.0 / 12 * (0.5 ** 2 + 0.05 ** 2)])

    def energy():
        total = 0.0
        for name in names:
            body = world.body(name)
            x, y, z, w = body["quaternion"]
            r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                          [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                          [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            v, omega = np.array(body["linear_velocity"]), np.array(body["angular_velocity"])
            total += 0.5 * v @ v + 0.5 * omega @ (r @ inertia @ r.T) @ omega + G * body["position"][2]
        return total
    start, drop = energy(), G * (0.25 + 0.75 + 1.25 + 1.75 + 2.25)
    for _ in range(4 * RATE):
        world.step(1)
        assert energy() <= start + 1e-3 * drop
        positions, _, _ = world.joint_states([f"j{k}" for k in range(5)])
        assert np.abs(positions).max() <= 0.3 + 1e-3


def test_continuous_joint_counts_turns():
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "wheel", "shape": "cylinder", "radius": 0.3, "length": 0.1,
                    "mass": 1.0, "position": [0, 0, 1]})
    world.add_joint({"name": "axle", "type": "continuous", "child": "wheel", "axis": [0, 0, 1],
                     "motor": {"mode": "velocity", "target": 2 * math.pi}})
    world.step(2 * RATE)
    joint = world.joint("axle")
    assert joint["velocity"] == pytest.approx(2 * math.pi, rel=1e-6)
    # 2 s at one turn a second, less the first step's spin-up (none: the motor is not bounded).
    assert joint["position"] == pytest.approx(4 * math.pi, rel=1e-3)


def test_jointed_group_freezes_and_wakes_together():
    world = World({"gravity": [0, 0, -G], "freezing": {"enabled": True, "time": 0.5}}, ground=None)
    world.add_body({"name": "upper", "size": [0.05, 0.05, 0.5], "mass": 1.0, "position": [0, 0, 2.75]})
    world.add_body({"name": "lower", "size": [0.05, 0.05, 0.5], "mass": 1.0, "position": [0, 0, 2.25]})
    world.add_joint({"type": "revolute", "child": "upper", "anchor": [0, 0, 3], "axis": [1, 0, 0]})
    world.add_joint({"type": "revolute", "parent": "upper", "child": "lower", "anchor": [0, 0, 2.5],
                     "axis": [1, 0, 0]})
    world.step(RATE)
    assert world.body("upper")["frozen"] and world.body("lower")["frozen"]
    world.apply_impulse("lower", [0, 0.5, 0])  # wakes the lower link, and with it the upper
    world.step(1)
    assert not world.body("upper")["frozen"] and not world.body("lower")["frozen"]
    assert world.body("upper")["angular_velocity"][0] != 0.0


def test_a_moving_link_keeps_its_group_awake():
    world = World({"gravity": [0, 0, -G], "freezing": {"enabled": True, "time": 0.5}}, ground=None)
    world.add_body({"name": "base", "size": [0.4, 0.4, 0.4], "mass": 10.0, "position": [0, 0, 2]})
    world.add_body({"name": "spinner", "shape": "cylinder", "radius": 0.2, "length": 0.05,
                    "mass": 1.0, "position": [0, 0, 2.3]})
    world.add_joint({"type": "fixed", "child": "base"})
    world.add_joint({"type": "continuous", "parent": "base", "child": "spinner",
                     "motor": {"mode": "velocity", "target": 3.0}})
    world.step(2 * RATE)
    assert not world.body("base")["frozen"] and not world.body("spinner")["frozen"]


def test_jointed_bodies_do_not_collide_unless_asked():
    def overlap_after(collide):
        world = World(UNFROZEN, ground=None)
        world.add_body({"name": "a", "size": [1, 1, 1], "position": [0, 0, 2], "immovable": True})
        world.add_body({"name": "b", "size": [1, 1, 1], "position": [0.5, 0, 2]})
        world.add_joint({"type": "prismatic", "parent": "a", "child": "b", "axis": [1, 0, 0],
                         "collide_connected": collide})
        world.update_settings({"gravity": [0, 0, 0]})
        world.step(RATE)
        return 1.0 - (world.body("b")["position"][0] - world.body("a")["position"][0])

    assert overlap_after(False) == pytest.approx(0.5, abs=1e-9)  # left where it was
    assert overlap_after(True) < 0.01  # pushed out along the rail


def test_removing_a_body_removes_its_joints():
    world, _, _ = rod_pendulum(0.2)
    world.add_body({"name": "other", "position": [5, 0, 1]})
    world.remove_body("rod")
    assert world.joint_names() == []
    # Its slot goes to the next body, which no joint holds.
    world.add_body({"name": "newcomer", "position": [0, 0, 2.5]})
    world.step(RATE)
    assert world.body("newcomer")["linear_velocity"][2] == pytest.approx(-G, rel=0.01)


def test_a_body_id_names_that_body_and_no_other():
    """Ids outlive their bodies: once a body is removed its id names nothing, even when another
    body takes its slot or its name (or both), and ids survive the arrays growing."""
    world = World(capacity=2)
    first = world.body_id(world.add_body({"name": "a", "position": [0, 0, 1]}))
    world.remove_body("a")
    world.add_body({"name": "a", "position": [0, 0, 1]})  # its slot and its name again
    assert world.body_name(first) is None and world.body_id("a") != first
    second = world.body_id("a")
    ids = {world.body_id(world.add_body({"position": [k, 3, 1]})): k for k in range(5)}  # grows twice
    assert world.body_name(second) == "a" and len(ids) == 5
    assert [world.body_name(i) for i in ids] == [f"box_{k + 1}" for k in range(5)]
    assert world.body_name(-1) is None and world.body_name(1 << 40) is None
    with pytest.raises(KeyError, match="no body named 'b'"):
        world.body_id("b")


def test_edit_and_remove_joint():
    world, _, _ = rod_pendulum(0.0)
    world.edit_joint("hinge", motor={"mode": "velocity", "target": 1.0, "max_effort": 1000.0})
    world.step(RATE)
    assert world.joint("hinge")["velocity"] == pytest.approx(1.0, rel=1e-6)
    world.edit_joint("hinge", motor={"mode": "none"})
    world.remove_joint("hinge")
    world.step(RATE)
    assert world.body("rod")["linear_velocity"][2] < -5.0  # falls free
    with pytest.raises(KeyError, match="no joint named 'hinge'"):
        world.joint("hinge")


@pytest.mark.parametrize("spec, message", [
    ({"type": "revolute"}, "joint.child: missing"),
    ({"type": "hinge", "child": "a"}, "joint.type: unsupported joint type 'hinge'"),
    ({"type": "revolute", "child": "nobody"}, "joint.child: no body named 'nobody'"),
    ({"type": "revolute", "child": "a", "parent": "a"}, "joint.parent: 'a' is the child too"),
    ({"type": "continuous", "child": "a", "lower": -1}, "joint.lower: a continuous joint has no limits"),
    ({"type": "revolute", "child": "a", "lower": 1, "upper": 0}, "lower limit 1 is above the upper limit 0"),
    ({"type": "fixed", "child": "a", "motor": {"mode": "velocity"}}, "joint.motor.mode: a fixed joint has no motor"),
    ({"type": "revolute", "child": "a", "motor": {"mode": "torque"}}, "unsupported motor mode 'torque'"),
    ({"type": "revolute", "child": "a", "motor": {"max_effort": 0}}, "joint.motor.max_effort: must be > 0"),
    ({"type": "revolute", "child": "a", "axis": [0, 0, 0]}, "joint.axis: has zero length"),
    ({"type": "revolute", "child": "a", "spring": 3}, "joint.spring: unknown key"),
    # Made past a limit, the joint's correction launched it across its range.
    ({"type": "revolute", "child": "a", "lower": 0.5, "upper": 1.0},
     r"joint.position: 0 .where the joint is made. is outside its limits \[0.5, 1\]"),
    ({"type": "prismatic", "child": "a", "position": 2.0, "upper": 1.0}, r"joint.position: 2 .* \[-inf, 1\]"),
])
def test_bad_joint_specs_are_refused_whole(spec, message):
    world = World(UNFROZEN)
    world.add_body({"name": "a", "position": [0, 0, 1]})
    with pytest.raises(SpecError, match=message.replace("(", r"\(")):
        world.add_joint(spec)
    assert world.joint_names() == []
    world.add_joint({"name": "ok", "type": "revolute", "child": "a"})
    with pytest.raises(ValueError, match="a joint named 'ok' already exists"):
        world.add_joint({"name": "ok", "type": "fixed", "child": "a"})


def test_joints_are_deterministic():
    def run():
        world = World(UNFROZEN)
        for k in range(4):
            world.add_body({"name": f"l{k}", "size": [0.1, 0.1, 0.4], "position": [0.3 * k, 0, 2 - 0.4 * k]})
            world.add_joint({"type": "revolute", "parent": f"l{k - 1}" if k else None, "child": f"l{k}",
                             "anchor": [0.3 * k, 0, 2.2 - 0.4 * k], "axis": [1, 1, 0]})
        world.step(3 * RATE)  # falls onto the ground, swinging
        return world.state()["positions"].tobytes()

    assert run() == run()


def test_differential_drive_robot_drives_its_circle():
    """A robot built from joints: a chassis, two wheels on continuous joints with velocity
    motors, a frictionless caster fixed under its tail. Wheel speeds for a 5 m circle (2.5 m
    radius at the axle's middle) must drive one within 2 %."""
    world = World({"gravity": [0, 0, -G], "freezing": {"enabled": False}})
    track, wheel, axle_x = 0.5, 0.15, 0.15
    world.add_body({"name": "chassis", "size": [0.6, 0.4, 0.1], "mass": 10.0, "position": [0, 0, 0.2]})
    for side, y in (("left", track / 2), ("right", -track / 2)):
        world.add_body({"name": side, "shape": "cylinder", "radius": wheel, "length": 0.05,
                        "mass": 1.0, "position": [axle_x, y, wheel], "rpy": [math.pi / 2, 0, 0],
                        "static_friction": 1.0, "dynamic_friction": 0.9})
        world.add_joint({"name": f"{side}_axle", "type": "continuous", "parent": "chassis",
                         "child": side, "anchor": [axle_x, y, wheel], "axis": [0, 1, 0]})
    world.add_body({"name": "caster", "shape": "sphere", "radius": 0.05, "mass": 0.2,
                    "position": [-0.25, 0, 0.05], "static_friction": 0.0, "dynamic_friction": 0.0})
    world.add_joint({"type": "fixed", "parent": "chassis", "child": "caster"})
    radius, speed = 2.5, 0.5
    world.step(RATE // 2)  # settles on its wheels
    for side, sign in (("left", -1), ("right", 1)):
        world.edit_joint(f"{side}_axle", motor={"mode": "velocity", "max_effort": 20.0,
                                                 "target": speed * (1 + sign * track / (2 * radius)) / wheel})
    world.step(2 * RATE)
    track_points = []
    for _ in range(int(2 * math.pi * radius / speed * RATE / 8)):  # one lap
        world.step(8)
        track_points.append(world.body("chassis")["position"][:2])
    points = np.array(track_points)
    # The circle through the chassis' centre (least squares), which runs axle_x behind the axle.
    a = np.c_[2 * points, np.ones(len(points))]
    cx, cy, c = np.linalg.lstsq(a, (points ** 2).sum(axis=1), rcond=None)[0]
    fitted = math.sqrt(c + cx * cx + cy * cy)
    assert fitted == pytest.approx(math.hypot(radius, axle_x), rel=0.02)
    assert np.ptp(np.linalg.norm(points - [cx, cy], axis=1)) < 0.01 * radius  # a circle, not a spiral


CHAIN_SCENE = {
    "version": 1,
    "settings": {"freezing": {"enabled": False}},
    "bodies": [{"name": "upper", "size": [0.1, 0.1, 0.6], "mass": 1.0, "position": [0, 0, 2.7]},
               {"name": "lower", "size": [0.1, 0.1, 0.6], "mass": 2.0, "position": [0, 0, 2.1]},
               {"name": "slider", "size": [0.2, 0.2, 0.2], "position": [1, 0, 1]}],
    "joints": [{"name": "shoulder", "type": "revolute", "child": "upper", "anchor": [0, 0, 3],
                "axis": [1, 0, 0], "lower": -1.0, "upper": 1.0},
               {"name": "elbow", "type": "continuous", "parent": "upper", "child": "lower",
                "anchor": [0, 0, 2.4], "axis": [1, 0, 0],
                "motor": {"mode": "velocity", "target": 2.0, "max_effort": 5.0}},
               {"name": "rail", "type": "prismatic", "child": "slider", "axis": [0, 1, 0],
                "lower": -0.5, "upper": 0.5, "motor": {"mode": "position", "target": 0.3}}],
}


def test_scene_joints_load_and_save_whole(tmp_path):
    from vplayground_ros.scene import load_world, save_world
    world = load_world(CHAIN_SCENE)
    world.step(100)  # swinging, the elbow turning, the slider on its way
    saved = {name: world.joint(name) for name in world.joint_names()}
    assert saved["shoulder"]["position"] != 0.0 and saved["elbow"]["position"] > 0.5
    save_world(world, tmp_path / "saved.yaml")
    again = load_world(tmp_path / "saved.yaml")
    assert again.joint_names() == ["shoulder", "elbow", "rail"]
    for name, joint in saved.items():
        reloaded = again.joint(name)
        for key in ("type", "lower", "upper", "motor", "collide_connected"):
            assert reloaded[key] == joint[key]
        for key in ("position", "velocity"):  # where they were, not back at 0
            assert reloaded[key] == pytest.approx(joint[key], abs=1e-9)
        np.testing.assert_allclose(reloaded["anchor"], joint["anchor"], atol=1e-12)
        np.testing.assert_allclose(reloaded["axis"], joint["axis"], atol=1e-12)
    # And they go on as the original does (the warm start aside).
    world.step(64)
    again.step(64)
    for name in saved:
        assert again.joint(name)["position"] == pytest.approx(world.joint(name)["position"], abs=1e-3)


@pytest.mark.parametrize("joints, message", [
    ([{"type": "fixed", "child": "ghost"}], "joints[0].child: no body or vehicle named 'ghost' in the scene"),
    ([{"name": "j", "type": "fixed", "child": "upper"}, {"name": "j", "type": "fixed", "child": "lower"}],
     "joints[1].name: duplicate joint name 'j'"),
    ([{"type": "fixed", "child": "upper", "position": 1.0}], "joints[0].position: a fixed joint has no position"),
    ("elbow", "joints: expected a list"),
])
def test_scene_joint_errors_name_the_key(joints, message):
    from vplayground_ros.scene import SceneError, load_world
    with pytest.raises(SceneError, match=re.escape(message)):
        load_world({**CHAIN_SCENE, "joints": joints})


def test_a_door_on_two_hinges_swings():
    """Two hinges on one axis: five of their ten rows repeat the others (a redundant K)."""
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "door", "size": [0.05, 0.9, 2.0], "mass": 20.0, "position": [0, 0.45, 2.0]})
    for z in (1.2, 2.8):
        world.add_joint({"type": "revolute", "child": "door", "anchor": [0, 0, z], "axis": [0, 0, 1]})
    world.apply_impulse("door", [10.0, 0, 0])
    world.step(2 * RATE)
    door = world.body("door")
    assert np.all(np.isfinite(door["position"]))
    assert door["position"][2] == pytest.approx(2.0, abs=1e-3)  # held up by its hinges
    assert math.hypot(door["position"][0], door["position"][1]) == pytest.approx(0.45, abs=1e-3)
    assert abs(door["angular_velocity"][2]) > 0.1  # and swinging about them


def test_two_fixed_joints_between_the_same_bodies_hold():
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "a", "position": [0, 0, 3], "immovable": True})
    world.add_body({"name": "b", "position": [1, 0, 3]})
    world.add_joint({"type": "fixed", "parent": "a", "child": "b"})
    world.add_joint({"type": "fixed", "parent": "a", "child": "b", "anchor": [0.5, 0, 3]})
    world.step(RATE)
    assert world.body("b")["position"] == pytest.approx([1, 0, 3], abs=1e-6)


@pytest.mark.parametrize("links", [24, 48])  # 48: beyond the 32 joints islands were solved whole up to before
def test_a_long_chain_solved_whole_hangs_still(links):
    world = World(UNFROZEN, ground=None)
    for k in range(links):
        world.add_body({"name": f"l{k}", "size": [0.05, 0.05, 0.2], "mass": 1.0, "position": [0, 0, 10 - 0.1 - 0.2 * k]})
        world.add_joint({"type": "revolute", "parent": f"l{k - 1}" if k else None, "child": f"l{k}",
                         "anchor": [0, 0, 10 - 0.2 * k], "axis": [1, 0, 0]})
    start = world.state()["positions"].copy()
    world.step(2 * RATE)
    assert np.abs(world.state()["positions"] - start).max() < 1e-3


def test_editing_a_jointed_compound_keeps_its_joint_on_its_frame():
    world = World(UNFROZEN, ground=None)
    world.add_body({"name": "c", "shape": "compound", "position": [0, 0, 2], "parts": [{"size": [0.2, 0.2, 0.2]}]})
    world.add_joint({"name": "pin", "type": "revolute", "child": "c", "anchor": [0, 0, 2], "axis": [0, 1, 0]})
    world.edit_body("c", parts=[{"size": [0.2, 0.2, 0.2]}, {"size": [0.2, 0.2, 0.2], "position": [1, 0, 0]}])
    assert world.joint("pin")["anchor"] == pytest.approx([0, 0, 2], abs=1e-12)
    world.step(RATE // 2)
    assert world.body("c")["position"] == pytest.approx([0, 0, 2], abs=1e-3)  # it turns about its pin


def test_infinite_limits_only_where_they_mean_none():
    world = World()
    world.add_body({"name": "a", "position": [0, 0, 1]})
    with pytest.raises(SpecError, match="joint.lower: must be finite"):
        world.add_joint({"type": "revolute", "child": "a", "lower": math.inf})
    with pytest.raises(SpecError, match="joint.upper: a fixed joint has no limits"):
        world.add_joint({"type": "fixed", "child": "a", "upper": -math.inf})
    world.add_joint({"type": "revolute", "child": "a", "lower": -math.inf, "upper": math.inf})


def test_a_saved_fixed_joint_loads_again():
    from vplayground_ros.scene import load_world, world_to_scene
    world = load_world({"version": 1, "bodies": [{"name": "a", "position": [0, 0, 1]},
                                                 {"name": "b", "position": [1, 0, 1]}],
                        "joints": [{"name": "weld", "type": "fixed", "parent": "a", "child": "b"}]})
    scene = world_to_scene(world)
    assert "position" not in scene["joints"][0]
    assert load_world(scene).joint_names() == ["weld"]


@pytest.mark.parametrize("motor", [{"mode": "velocity", "target": 0.03},
                                   {"mode": "position", "target": 0.0, "velocity": 0.03}])
def test_a_slowly_driven_joint_does_not_freeze(motor):
    """A hinge its motor turns at 0.03 rad/s (below the freezing thresholds: a velocity motor,
    or a position target moving on): its group froze after 0.5 s and stopped at 0.015 rad. A
    driven group stays awake; at 0.3 rad after 10 s."""
    world = World({"gravity": [0, 0, -G]}, ground=None)  # the default freezing
    world.add_body({"name": "arm", "size": [0.3, 0.05, 0.05], "mass": 1.0, "position": [0.15, 0, 2]})
    world.add_joint({"name": "hinge", "type": "revolute", "child": "arm", "anchor": [0, 0, 2], "axis": [0, 0, 1],
                     "motor": {**motor, "max_effort": 100.0}})
    world.step(10 * RATE)
    assert world.joint("hinge")["position"] == pytest.approx(0.3, abs=1e-3)
    assert not world.body("arm")["frozen"]


def test_a_frozen_arm_reports_the_effort_that_holds_it():
    """An arm held level by its position motor freezes; its joint's effort stays what holds it
    (m g l / 2 = 9.81 N m) when anything else in the world moves (the step's preparation had
    dropped the impulses of joints whose bodies are all at rest, and it read 0)."""
    world = World({"gravity": [0, 0, -G], "freezing": {"enabled": True, "time": 0.5}}, ground=None)
    world.add_body({"name": "arm", "size": [1.0, 0.05, 0.05], "mass": 2.0, "position": [0.5, 0, 2]})
    world.add_joint({"name": "shoulder", "type": "revolute", "child": "arm", "anchor": [0, 0, 2], "axis": [0, -1, 0],
                     "motor": {"mode": "position", "target": 0.0, "max_effort": 100.0}})
    world.step(RATE)
    assert world.body("arm")["frozen"]
    world.add_body({"name": "faller", "position": [20, 0, 50]})
    for _ in range(3):
        world.step(1)
        assert world.body("arm")["frozen"] and world.joint("shoulder")["effort"] == pytest.approx(G, rel=1e-6)


def test_limits_moved_past_the_joint_are_refused():
    """Limits edited past where the joint is launched it across its range (a 100 kg arm 0.8 rad
    past its new upper limit was driven back at 5 rad/s and on to its lower one): refused, like
    a joint made past them, and the joint keeps its limits."""
    world, _, _ = rod_pendulum(0.0)
    with pytest.raises(SpecError, match=r"upper: the joint is at 0, outside the limits \[-1, -0.5\]"):
        world.edit_joint("hinge", lower=-1.0, upper=-0.5)
    assert world.joint("hinge")["upper"] == math.inf
    world.edit_joint("hinge", lower=0.02, upper=0.5)  # within the slack of where it is: taken
    assert world.joint("hinge")["lower"] == 0.02
