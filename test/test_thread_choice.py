"""The second solver thread is used while it pays (thread_choice): a World allowed two threads
tries one and two on its calls that share work and keeps the faster, which changes only the
time (the bytes are the serial ones either way). Timed by a stand-in clock: behaviour, not the
machine's speed."""
import numpy as np
import pytest

from helpers import pile
from vplayground_ros.physics.contact_solver import PARALLEL_MIN_POINTS
from vplayground_ros.physics.narrow_phase import PARALLEL_MIN_PAIRS
from vplayground_ros.physics.thread_choice import (HOLD_CALLS, KEEP_SHARE, TRIAL_CALLS, TRIAL_PATTERN,
                                                  SecondThreadChoice, would_share)


def run_trial(choice, ns_per_unit):
    """Calls that share work, each taking ns_per_unit[threads] per unit of work: the thread
    counts the trial asked for."""
    asked = []
    for _ in range(TRIAL_CALLS):
        threads = choice.threads(2, sharing=True)
        asked.append(threads)
        choice.record(threads, ns_per_unit[threads] * 1000, 1000)
    return asked


@pytest.mark.parametrize("two_over_one, keeps_two", [(0.6, True), (KEEP_SHARE * 0.99, True),
                                                     (KEEP_SHARE * 1.01, False), (1.2, False)])
def test_a_trial_keeps_the_second_thread_only_where_it_pays(two_over_one, keeps_two):
    choice = SecondThreadChoice()
    asked = run_trial(choice, {1: 100.0, 2: 100.0 * two_over_one})
    assert asked == list(TRIAL_PATTERN) * (TRIAL_CALLS // len(TRIAL_PATTERN))
    assert choice.speedup == pytest.approx(1 / two_over_one)
    assert choice.use_second is keeps_two
    assert choice.threads(2, sharing=True) == (2 if keeps_two else 1)


def test_a_trial_judges_by_the_median_not_one_slow_call():
    """One call preempted for 50 ms does not decide the trial."""
    choice = SecondThreadChoice()
    for k in range(TRIAL_CALLS):
        threads = choice.threads(2, sharing=True)
        ns = 50e6 if k == 1 else (700.0 if threads == 2 else 1000.0) * 1000
        choice.record(threads, ns, 1000)
    assert choice.use_second


def test_the_choice_is_tried_again_after_a_while():
    """The machine's state changes: after HOLD_CALLS calls that share work, a new trial, which
    can turn the second thread back on."""
    choice = SecondThreadChoice()
    run_trial(choice, {1: 100.0, 2: 130.0})
    assert not choice.use_second
    for _ in range(HOLD_CALLS):
        assert choice.threads(2, sharing=True) == 1
        choice.record(1, 100_000, 1000)
    assert not choice.trial_done()  # the next trial begins
    asked = run_trial(choice, {1: 100.0, 2: 60.0})
    assert 2 in asked and 1 in asked
    assert choice.use_second and choice.threads(2, sharing=True) == 2


def test_calls_that_share_no_work_neither_count_nor_take_part():
    """A call too small to share runs on the current choice, whatever a trial would ask."""
    choice = SecondThreadChoice()
    run_trial(choice, {1: 100.0, 2: 130.0})
    assert choice.threads(2, sharing=False) == 1
    fresh = SecondThreadChoice()
    assert [fresh.threads(2, sharing=False) for _ in range(5)] == [2] * 5
    assert fresh.threads(1, sharing=True) == 1  # one thread allowed: nothing to choose


def test_what_would_share():
    assert not would_share(0, 0, 0)
    assert would_share(2, 2 * PARALLEL_MIN_POINTS, 0) and not would_share(2, 2 * PARALLEL_MIN_POINTS - 1, 0)
    assert would_share(3, 0, 3 * PARALLEL_MIN_PAIRS) and not would_share(3, 0, 3 * PARALLEL_MIN_PAIRS - 1)


def stepped_on_a_clock(two_over_one, steps=130):
    """A landing pile stepped call by call, on a clock by which each call takes 1 ms on one
    thread and `two_over_one` ms on two: (the world, the thread count of each call)."""
    world = pile(300, seed=3)
    world.solver_threads = 2
    now = [0]

    def clock():  # each read moves it on by what the call in progress costs: so does end - start
        now[0] += int(1e6 * (two_over_one if world.threads_in_use == 2 else 1.0))
        return now[0]
    world._clock = clock
    used = []
    for _ in range(steps):
        world.step(1)
        used.append(world.threads_in_use)
    return world, used


@pytest.mark.parametrize("two_over_one", [0.7, 1.3])
def test_a_world_keeps_the_faster_count_and_the_serial_bytes(two_over_one):
    world, used = stepped_on_a_clock(two_over_one)
    choice = world._thread_choice
    assert choice.trial_done() and choice.speedup == pytest.approx(1 / two_over_one, rel=0.05)
    last = used[-20:]
    assert last == ([2] * 20 if two_over_one < KEEP_SHARE else [1] * 20)
    serial = pile(300, seed=3)
    serial.solver_threads, serial.measure_threads = 1, False
    for _ in range(len(used)):
        serial.step(1)
    for key, value in serial.state().items():
        assert np.array_equal(value, world.state()[key]), key


def test_one_thread_allowed_runs_no_trial_and_a_new_count_a_new_one():
    """With solver_threads 1 there is nothing to choose: no trial (one had filled with
    one-thread calls alone and found a NaN speed-up); set to 2, the world tries both afresh."""
    world = pile(300, seed=3)
    world.solver_threads = 1
    for _ in range(100):
        world.step(1)
        assert world.threads_in_use == 1
    assert world.second_thread_speedup is None and not world._thread_choice.trial
    world.solver_threads = 2
    used = []
    for _ in range(40):
        world.step(1)
        used.append(world.threads_in_use)
    assert 1 in used and 2 in used and world.second_thread_speedup is not None


def test_measure_threads_is_a_checked_setting():
    world = pile(4)
    for bad in (1, "yes", None):
        with pytest.raises(ValueError, match="measure_threads"):
            world.measure_threads = bad
    world.measure_threads = False
    assert world.measure_threads is False
