"""The regular-expression sandbox of ~/remove filters: any pattern, bounded in length and in
wall time, matched off the simulation thread with the GIL released.
"""
import time

import regex

from .results import FAILED, RequestError

MAX_FILTER = 1000  # characters of a ~/remove filter
# Wall time a ~/remove filter may spend matching names: a backtracking pattern such as (a+)+$
# would otherwise take longer than the age of the universe on a 64-character name.
FILTER_SECONDS = 0.5


# Product of a pattern's counted repetitions ({n}, {n,m}, {n,}): the regex module unrolls them
# when compiling, unbounded in time and memory (a{99999999} took minutes and gigabytes; a
# product of 10,000 compiles in ~25 ms).
MAX_REPEATS = 10_000
COUNTED = regex.compile(r"\{(\d*)(?:,(\d*))?\}")


def match_names(pattern, names, seconds=FILTER_SECONDS, what="remove.filter"):
    """The names `pattern` (a POSIX ERE, Python syntax) finds, with the compiling and the
    matching bounded; FAILED naming the problem (as `what`) for a bad or too costly pattern."""
    repeats = 1
    for low, high in COUNTED.findall(pattern):
        repeats *= max(1, int(high or low or 0))
        if repeats > MAX_REPEATS:
            raise RequestError(FAILED, f"{what}: counted repetitions ({{n}}, {{n,m}}) multiply to more than "
                                       f"{MAX_REPEATS} (they are unrolled)")
    try:
        compiled = regex.compile(pattern)
    except (regex.error, ValueError, OverflowError, RecursionError) as error:
        raise RequestError(FAILED, f"{what}: not a valid regular expression: {error}") from None
    deadline = time.monotonic() + seconds
    matched = []
    try:
        for name in names:
            # concurrent: the GIL is released while matching, so the physics keeps stepping.
            if compiled.search(name, timeout=max(deadline - time.monotonic(), 1e-3), concurrent=True):
                matched.append(name)
    except TimeoutError:
        raise RequestError(FAILED, f"{what}: matching took longer than {seconds:g} s "
                                   "(nested repetition such as (a+)+ backtracks without end)") from None
    return matched

