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


def match_names(pattern, names, seconds=FILTER_SECONDS):
    """The names `pattern` (a POSIX ERE, Python syntax) finds, with the matching bounded in
    wall time; FAILED naming the problem for a bad or too slow pattern."""
    try:
        compiled = regex.compile(pattern)
    except (regex.error, ValueError, OverflowError, RecursionError) as error:
        raise RequestError(FAILED, f"remove.filter: not a valid regular expression: {error}") from None
    deadline = time.monotonic() + seconds
    matched = []
    try:
        for name in names:
            # concurrent: the GIL is released while matching, so the physics keeps stepping.
            if compiled.search(name, timeout=max(deadline - time.monotonic(), 1e-3), concurrent=True):
                matched.append(name)
    except TimeoutError:
        raise RequestError(FAILED, f"remove.filter: matching took longer than {seconds:g} s "
                                   "(nested repetition such as (a+)+ backtracks without end)") from None
    return matched

