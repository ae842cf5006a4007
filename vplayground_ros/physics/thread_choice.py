"""Whether the contact solve's second thread pays on this machine now, measured on the world's
own steps.

Two threads give the serial result bit for bit (solve_schedule), so the thread count a step runs
with changes only how long it takes. How long depends on the machine at the moment more than on
the world: on the 2-core VM of this project the loose pile's falling phase took 0.82 of one
thread's time with two, and a quarter of an hour earlier 1.16 of it (a cache line's round trip
between the two cores 0.4-0.5 us then, 41-48 ns after: the data the threads share crosses
between them at every shared pass), and the parallel builds of Rapier and Jolt lost their
speed-up with it. So a World allowed two
threads tries both, now and then, on the calls that would share work, and keeps the faster.

A trial is TRIAL_CALLS such calls, one thread and two in the order 1, 2, 2, 1 (a pile's calls
grow or shrink in cost as it lands; the pattern cancels a steady trend), each call's wall time
per unit of work (contact points and candidate pairs). Two threads are kept when their median is
at most KEEP_SHARE of one thread's (the second core's CPU must buy some time), for the next
HOLD_CALLS such calls; then a trial again, since the machine's state changes.
"""
import numpy as np

from .contact_solver import PARALLEL_MIN_POINTS
from .narrow_phase import PARALLEL_MIN_PAIRS

TRIAL_PATTERN = (1, 2, 2, 1)
TRIAL_CALLS = 16
KEEP_SHARE = 0.95
HOLD_CALLS = 1024


def would_share(steps, points, pairs):
    """Whether a call of `steps` steps with these counters (summed over them: contact points,
    candidate pairs with bodies and with playground triangles) had steps large enough for the
    shared passes: the next call is then likely to share too."""
    return steps > 0 and (points >= PARALLEL_MIN_POINTS * steps or pairs >= PARALLEL_MIN_PAIRS * steps)


class SecondThreadChoice:
    """The thread count each call of a World should use, out of at most `solver_threads`, from
    what its earlier calls measured (`threads`, then `record`)."""

    def __init__(self):
        self.use_second = True  # until a trial says otherwise
        self.trial = []  # (threads, wall ns per unit of work) of the last trial's calls
        self.held = 0  # calls that shared work since the last trial ended
        self.speedup = None  # the last trial's: one thread's median over two threads'

    def threads(self, solver_threads, sharing):
        """Threads for the next call; `sharing`: whether the last call's steps shared work."""
        if solver_threads < 2:
            return 1
        if not sharing or self.trial_done():
            return 2 if self.use_second else 1
        return TRIAL_PATTERN[len(self.trial) % len(TRIAL_PATTERN)]

    def trial_done(self):
        return len(self.trial) >= TRIAL_CALLS

    def record(self, threads, wall_ns, work):
        """What a call that shared work (and was expected to) took on `threads`, which
        `threads()` chose out of two: its wall time and its work (contact points and candidate
        pairs over its steps)."""
        if work <= 0:
            return
        if self.trial_done():
            self.held += 1
            if self.held >= HOLD_CALLS:
                self.held = 0
                self.trial = []
            return
        self.trial.append((threads, wall_ns / work))
        if self.trial_done():
            per_unit = np.array(self.trial)
            one = np.median(per_unit[per_unit[:, 0] == 1, 1])
            two = np.median(per_unit[per_unit[:, 0] == 2, 1])
            self.speedup = float(one / two)
            self.use_second = bool(two <= KEEP_SHARE * one)
