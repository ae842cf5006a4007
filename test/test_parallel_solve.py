"""The contact solve on two threads (issue 20): the serial solve's result bit for bit, whatever
the thread count and however many threads actually run (physics, not timing)."""
import numba
import numpy as np
import pytest
from numba import njit

from helpers import pile, pyramid, tower
from vplayground_ros.physics import World
from vplayground_ros.physics.contact_solver import (MAX_WAITING_SHARE, MIN_GROUPS_PER_LEVEL, PARALLEL_MIN_POINTS,
                                                   SHOCK_ROW_SIZE, reads_body, shock_group, shock_propagation)
from vplayground_ros.physics.contact import allocate_contacts
from vplayground_ros.physics.narrow_phase import PARALLEL_MIN_PAIRS, collide, collide_shared
from vplayground_ros.physics.pipeline import list_colliding, list_live_bodies
from vplayground_ros.physics.solve_schedule import NO_WAIT, shock_levels, split_chains, support_groups
from vplayground_ros.physics.step_context import newest_contacts

NO_FREEZING = {"freezing": {"enabled": False}}


def last_split(world):
    """The two chains of the last step's contact points (the contact pass's velocity sweeps
    solve them all), split at the bodies' current positions: (points, chain lengths, how many
    points wait for the other chain in an upward sweep)."""
    contacts = newest_contacts(world._contacts)
    count = contacts.count[0]
    items, need_up, need_down = (np.empty(count, np.int64) for _ in range(3))
    chain_start = np.empty(3, np.int64)
    publish_up, publish_down = np.empty(count, np.bool_), np.empty(count, np.bool_)
    split_chains(contacts.solve_order[:count].copy(), count, contacts, world._bodies.position,
                 np.asarray(world.settings["gravity"], dtype=float), items, chain_start, need_up,
                 need_down, publish_up, publish_down)
    return count, np.diff(chain_start), int(np.sum(need_up != NO_WAIT))


def last_levels(world):
    """Shock propagation's levels for the last step's support points: (support points, groups,
    groups per level)."""
    contacts = newest_contacts(world._contacts)
    supports = contacts.support_count[0]
    group_start, by_level, level_start = (np.empty(supports + 1, np.int64) for _ in range(3))
    groups = support_groups(contacts.support_order, supports, contacts.support_body, group_start)
    levels = shock_levels(contacts.support_order, contacts.support_body, contacts.velocity_a,
                          contacts.velocity_b, len(world._bodies.active) + 1, group_start, groups,
                          by_level, level_start)
    assert sorted(by_level[:groups]) == list(range(groups))
    return supports, groups, np.diff(level_start[:levels + 1]).tolist()


def two_layers(side=16):
    """side x side cubes on the ground, as many on top of them: every box held up by one
    support, the upper layer's by a lower box."""
    world = World(NO_FREEZING)
    for layer in range(2):
        for i in range(side):
            for j in range(side):
                world.add_body({"size": [1, 1, 1], "position": [1.5 * i, 1.5 * j, 0.5 + layer]})
    return world


def snapshot(world):
    state = world.state()
    contacts = world.contacts()
    return {**state, "impulses": contacts["impulses"], "points": contacts["points"]}


def assert_same_bytes(first, second):
    for key in first:
        assert np.array_equal(first[key], second[key]), key


def stepped(build, threads, steps, numba_threads=None):
    """A world from `build` with `threads` solver threads, after `steps` steps; with
    `numba_threads`, Numba runs that many threads meanwhile (set_num_threads)."""
    world = build()
    world.solver_threads = threads
    world.measure_threads = False  # every call on `threads`, whatever they measure
    if numba_threads is None:
        world.step(steps)
        return world
    before = numba.get_num_threads()
    numba.set_num_threads(numba_threads)
    try:
        world.step(steps)
    finally:
        numba.set_num_threads(before)
    return world


def test_two_threads_give_the_serial_result_bit_for_bit():
    """A pile whose contacts cross the cut between the threads' halves, so the chains wait
    for each other: every state and contact byte as with one thread, and as in a second run."""
    build = lambda: pile(300, seed=3)  # noqa: E731
    serial = stepped(build, 1, 130)
    count, lengths, waiting = last_split(serial)
    assert count >= PARALLEL_MIN_POINTS and lengths.min() > count // 4
    assert 0 < waiting * MAX_WAITING_SHARE <= count  # shared, with waits
    shared = [snapshot(stepped(build, 2, 130)) for _ in range(2)]
    assert_same_bytes(snapshot(serial), shared[0])
    assert_same_bytes(shared[0], shared[1])


def test_a_pile_beside_a_swinging_pendulum_on_two_threads_is_the_serial_one():
    """Joints no contact point touches: the pile's points go to the sweeps worlds without joints
    use, which two threads may share (the pendulum's island is solved on its own). Whoever runs
    them, the bytes are the serial ones (this holds the result, not which path ran)."""
    def build():
        world = pile(300, seed=3)
        world.add_body({"name": "bob", "size": [0.1, 0.1, 1.0], "mass": 1.0, "position": [-20, 0, 9.5],
                        "rpy": [0.4, 0, 0]})
        world.add_joint({"type": "revolute", "child": "bob", "anchor": [-20, 0, 10], "axis": [1, 0, 0],
                         "motor": {"mode": "velocity", "target": 0.5, "max_effort": 2.0}})
        return world
    serial = stepped(build, 1, 130)
    count, lengths, waiting = last_split(serial)
    assert count >= PARALLEL_MIN_POINTS and 0 < waiting * MAX_WAITING_SHARE <= count  # shared
    assert abs(serial.body("bob")["angular_velocity"][0]) > 0.1  # swinging, on its motor
    assert_same_bytes(snapshot(serial), snapshot(stepped(build, 2, 130)))


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two Numba threads")
def test_two_threads_on_one_core_do_all_the_work_alone():
    """Numba with one thread runs the region's two workers one after the other: the first takes
    the other chain too (no wait for a thread that never comes), and the bytes are the same."""
    build = lambda: pile(300, seed=3)  # noqa: E731
    alone = stepped(build, 2, 130, numba_threads=1)
    assert_same_bytes(snapshot(stepped(build, 1, 130)), snapshot(alone))


def test_a_pyramid_on_two_threads_is_the_serial_pyramid():
    """The cut runs down the middle of the 20-row pyramid (every row crosses it): so many points
    would wait that one thread solves it after all, and the bytes are the serial ones."""
    build = lambda: pyramid(20, settings=NO_FREEZING, density=500.0, elasticity=0.0)  # noqa: E731
    two = stepped(build, 2, 256)
    count, lengths, waiting = last_split(two)
    assert count >= PARALLEL_MIN_POINTS and waiting > 0
    assert_same_bytes(snapshot(stepped(build, 1, 256)), snapshot(two))


def test_stacks_the_cut_does_not_cross_never_wait():
    """Two towers apart: each thread has one, and no point waits for the other thread."""
    world = World(NO_FREEZING)
    for x in (-5.0, 5.0):
        for k in range(10):
            world.add_body({"size": [1, 1, 1], "position": [x, 0, 0.5 + k]})
    world.step(2)
    count, lengths, waiting = last_split(world)
    assert list(lengths) == [count // 2, count // 2] and waiting == 0


def test_solver_threads_is_a_checked_setting():
    assert World().solver_threads in (1, 2)
    assert World(solver_threads=1).solver_threads == 1
    world = tower(2)
    for bad in (0, 3, 1.5, True, "2"):
        with pytest.raises(ValueError, match="solver_threads"):
            world.solver_threads = bad
    with pytest.raises(ValueError, match="solver_threads"):
        World(solver_threads=0)
    assert world.solver_threads in (1, 2)


def test_shock_propagation_runs_a_level_at_a_time():
    """Each upper body's group goes one level above the groups whose bodies it reads or that
    read it: the two layers are two levels of one group per box; a tower a level per box, too
    thin to share."""
    world = two_layers()
    world.step(3)
    supports, groups, per_level = last_levels(world)
    assert groups == 512 and per_level == [256, 256]
    assert supports >= PARALLEL_MIN_POINTS and groups >= MIN_GROUPS_PER_LEVEL * len(per_level)  # shared
    world = tower(10, settings=NO_FREEZING)
    world.step(3)
    assert last_levels(world)[2] == [1] * 10


def test_shared_shock_propagation_gives_the_serial_result_bit_for_bit():
    """The two layers, shaken so the upper boxes lean on their supports: two solver threads,
    and two threads run by one (Numba with one thread), give the serial bytes."""
    def build():
        world = two_layers()
        for name in world.body_names()[256::3]:
            world.apply_impulse(name, [300.0, -200.0, 0.0])
        return world
    serial = snapshot(stepped(build, 1, 96))
    shared = stepped(build, 2, 96)
    supports, groups, per_level = last_levels(shared)
    assert supports >= PARALLEL_MIN_POINTS and groups >= MIN_GROUPS_PER_LEVEL * len(per_level)
    assert_same_bytes(serial, snapshot(shared))
    if numba.config.NUMBA_NUM_THREADS >= 2:
        assert_same_bytes(serial, snapshot(stepped(build, 2, 96, numba_threads=1)))


def shock_in_pairs_and_one_at_a_time(world):
    """The last step's shock propagation run again from its contacts as the pass runs it (in
    pairs where it can) and one group after the other: (whether each group could pair with the
    next, whether the two gave the same bytes)."""
    contacts, bodies = newest_contacts(world._contacts), world._bodies
    order, supports = contacts.support_order, contacts.support_count[0]
    group_start = np.empty(supports + 1, np.int64)
    groups = support_groups(order, supports, contacts.support_body, group_start)
    upper = [contacts.support_body[order[group_start[g]]] for g in range(groups)]
    pairable = [not reads_body(order, contacts.velocity_a, contacts.velocity_b, group_start[g + 1],
                               group_start[g + 2], upper[g]) for g in range(groups - 1)]

    def copy(parts):
        return type(parts)(*(part.copy() for part in parts))
    paired_contacts, paired_bodies = copy(contacts), copy(bodies)
    shock_propagation(paired_contacts, paired_bodies, 1)
    c, b = copy(contacts), copy(bodies)
    view = np.empty((supports, 3, SHOCK_ROW_SIZE))
    for g in range(groups):
        shock_group(b.velocity, c.rows, c.row_inv_mass, c.contact_target, c.friction_coefficient,
                    c.impulse, c.friction, c.support_impulse, c.support_friction, c.support_mass,
                    order, c.velocity_a, c.velocity_b, group_start[g], group_start[g + 1], upper[g],
                    view)
    # The pass did something: it changed velocities, or took back impulses that would have
    # added energy (a resting tower's, run again on top of its own step's).
    assert not (np.array_equal(b.velocity, bodies.velocity)
                and np.array_equal(c.support_impulse, contacts.support_impulse))
    same = (np.array_equal(paired_bodies.velocity, b.velocity)
            and np.array_equal(paired_contacts.support_impulse, c.support_impulse)
            and np.array_equal(paired_contacts.support_friction, c.support_friction))
    return pairable, same


def test_shock_propagation_in_pairs_gives_the_one_at_a_time_result():
    """Shock propagation runs two groups at once (shock_pair) where the second does not stand on
    the first: a falling pile's groups, all in pairs, and a tower's, none (each box stands on the
    one before), leave every velocity and one-sided impulse as one group after the other does."""
    world = pile(300, seed=3, settings=NO_FREEZING)
    world.solver_threads = 1
    world.step(120)
    pairable, same = shock_in_pairs_and_one_at_a_time(world)
    assert len(pairable) >= 100 and all(pairable) and same
    world = tower(6, settings=NO_FREEZING)
    world.step(10)
    pairable, same = shock_in_pairs_and_one_at_a_time(world)
    assert len(pairable) == 5 and not any(pairable) and same


@njit
def narrow_phase(contacts, bodies, hulls, parts, broad, playground, live, threads, shared_only):
    """The narrow phase of the last step's candidate pairs at the bodies' current positions
    (Python entries to the compiled-only kernels): collide, or its two-thread part alone."""
    if shared_only:
        jobs = broad.pair_count[0] + broad.playground_count[0] + len(live)
        return collide_shared(contacts, bodies, hulls, parts, broad, playground, True, 0.0, live, jobs)
    return collide(contacts, bodies, hulls, parts, broad, playground, True, 0.0, live, threads)


@njit
def live_colliding(bodies, broad):
    return list_colliding(bodies, broad, list_live_bodies(bodies, broad, False)).copy()


POINT_FIELDS = ("body_a", "body_b", "point", "normal", "depth", "local_a")
MANIFOLD_FIELDS = ("manifold_start", "manifold_size", "manifold_a", "manifold_b")


def manifolds_of(world, points, manifolds, threads, shared_only=False):
    """(fits, the contact set) of the narrow phase into a fresh set of that capacity."""
    contacts = allocate_contacts(points, manifolds)
    live = live_colliding(world._bodies, world._broad)
    fits = narrow_phase(contacts, world._bodies, world._hulls, world._parts, world._broad,
                        world._playground, live, threads, shared_only)
    return fits, contacts


def assert_same_contacts(first, second):
    count, manifolds = first.count[0], first.manifold_count[0]
    assert (second.count[0], second.manifold_count[0]) == (count, manifolds)
    for field in POINT_FIELDS:
        assert np.array_equal(getattr(second, field)[:count], getattr(first, field)[:count]), field
    for field in MANIFOLD_FIELDS:
        assert np.array_equal(getattr(second, field)[:manifolds], getattr(first, field)[:manifolds]), field


def test_the_narrow_phase_on_two_threads_is_the_serial_one():
    """A landing with more candidate pairs than PARALLEL_MIN_PAIRS: the two threads' parts of
    the narrow phase (the second's manifolds written from the buffers' middle, then moved down
    behind the first's) make the serial contact set, point for point. Buffers that hold the
    points but not in halves (two parts of equal work hold unequal numbers of points): the
    shared part says so, and collide runs the jobs again on one thread instead of growing the
    buffers, so the step grows them exactly when the serial one does. The run's bytes are the
    serial run's."""
    build = lambda: pile(600, seed=5)  # noqa: E731
    serial = stepped(build, 1, 110)
    assert serial._broad.pair_count[0] >= PARALLEL_MIN_PAIRS  # the last step shared its narrow phase
    fits, alone = manifolds_of(serial, 16 * 4096, 4 * 4096, 1)
    count, manifolds = alone.count[0], alone.manifold_count[0]
    assert fits and count > 1000 and manifolds > 300
    for points_capacity, manifold_capacity in ((16 * 4096, 4 * 4096), (2 * count, 2 * manifolds)):
        fits, shared = manifolds_of(serial, points_capacity, manifold_capacity, 2, shared_only=True)
        assert fits
        assert_same_contacts(alone, shared)
    fits, shared = manifolds_of(serial, count, manifolds, 2, shared_only=True)
    assert not fits and shared.count[0] == 0  # unequal halves: the first outgrew its own
    fits, tight = manifolds_of(serial, count, manifolds, 2)
    assert fits
    assert_same_contacts(alone, tight)
    assert not manifolds_of(serial, count - 1, manifolds, 2)[0]  # full: the step grows the buffers
    assert_same_bytes(snapshot(serial), snapshot(stepped(build, 2, 110)))
