"""What the machine gives a second thread at the moment: the round trip of a cache line between
two threads (on a VM it moves with the host's placement of the virtual cores: 41-48 ns when they
share a cache, 0.4-0.5 us when they do not, on this project's VM within one hour). A shared
solver pass hands lines across at every wait and its data after it, so a slow round trip is
what turns a second thread into a loss (thread_choice). Printed beside the thread benches'
figures so they can be read."""
import threading
import time

import numpy as np
from numba import njit

from vplayground_ros.physics.atomics import atomic_load, atomic_store
from vplayground_ros.physics.jit_cache import usable_cores


# A volley stops after this many waits for a turn (~0.1 s at 40 ns, however long a wait takes:
# with one core between the threads each turn waits for the other's time slice).
MAX_SPINS = 2_000_000


@njit(nogil=True, cache=True)
def volley(sync, player, rounds):
    """Waits for its turn on sync[0] and passes it on, `rounds` times, or until it has waited
    MAX_SPINS times; sync[1 + player] gets the rounds it played."""
    spins = 0
    for r in range(rounds):
        turn = 2 * r + player
        while atomic_load(sync, 0) < turn:
            spins += 1
            if spins >= MAX_SPINS:
                atomic_store(sync, 0, 2 * rounds)  # the other one stops too
                return
        if atomic_load(sync, 0) != turn:
            return  # stopped by the other
        atomic_store(sync, 0, turn + 1)
        sync[1 + player] = r + 1


def core_round_trip_ns(rounds=100_000, trials=3):
    """The fastest of `trials` means of a line's round trip between two threads (ns); None
    where the process may run on one core only."""
    if usable_cores() < 2:
        return None
    sync = np.zeros(8, np.int64)
    volley(sync, 0, 0)  # compile before timing
    best = np.inf
    for _ in range(trials):
        sync[:] = 0
        threads = [threading.Thread(target=volley, args=(sync, player, rounds)) for player in (0, 1)]
        started = time.perf_counter()
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        played = min(sync[1], sync[2])
        if played > 0:
            best = min(best, (time.perf_counter() - started) / played * 1e9)
    return best


def round_trip_text(ns):
    return "one core only" if ns is None else f"{ns:.0f} ns"


if __name__ == "__main__":
    print(f"cache line round trip between two threads: {round_trip_text(core_round_trip_ns())}")
