"""The step's sorts: the sweep orders' stable argsort (np.argsort(kind="mergesort")'s result)
and the octree indexes' entries by cell, faster for the thousands of items of a landing pile.

Numba's merge sort took ~255 us for a landing's 4,000 point heights (35 us at 1,000, superlinear
past a few hundred), a tenth of the step at its peak, and its np.sort ~100 us for 3,000 index
keys. An LSD radix sort, a byte a pass, skipping the passes in which every key has the same byte
(the high bytes of heights within a few metres, of cells near each other), takes ~72 us for the
4,000 heights and ~14 for 3,840 entries' cells (two bytes vary); below ARGSORT_RADIX_MIN heights
the merge sort is faster (its setup is small). Both keep equal keys in their order (stable).
A float is sorted by its bits ordered as the numbers are: negatives flipped whole, positives
with the sign bit set.
"""
import numpy as np
from numba import njit

ARGSORT_RADIX_MIN = 512   # heights: merge 4.2 / radix 5.6 us at 300, 35 / 16 at 1,000
DIGIT_BITS = 8
SIGN_BIT = np.uint64(1 << 63)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def radix_sort(keys, order):
    """keys (uint64) sorted ascending, stably, with `order` (int64) carried along: returns both
    (either may be the arrays given, overwritten)."""
    n = len(keys)
    spare_keys = np.empty(n, np.uint64)
    spare_order = np.empty(n, np.int64)
    buckets = 1 << DIGIT_BITS
    mask = np.uint64(buckets - 1)
    counts = np.empty(buckets + 1, np.int64)
    for shift in range(0, 64, DIGIT_BITS):
        s = np.uint64(shift)
        counts[:] = 0
        for k in range(n):
            counts[((keys[k] >> s) & mask) + 1] += 1
        if n == 0 or counts[((keys[0] >> s) & mask) + 1] == n:
            continue  # every key has this digit: the order stands
        for d in range(buckets):
            counts[d + 1] += counts[d]
        for k in range(n):
            d = (keys[k] >> s) & mask
            at = counts[d]
            spare_keys[at] = keys[k]
            spare_order[at] = order[k]
            counts[d] = at + 1
        keys, spare_keys = spare_keys, keys
        order, spare_order = spare_order, order
    return keys, order


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def stable_argsort(values):
    """The indices that sort `values` (float64, no NaN), equal values in index order: what
    np.argsort(values, kind="mergesort") gives, -0.0 and 0.0 being equal too."""
    n = len(values)
    if n < ARGSORT_RADIX_MIN:
        return np.argsort(values, kind="mergesort")
    clean = np.empty(n)
    for k in range(n):
        clean[k] = values[k] if values[k] != 0.0 else 0.0  # -0.0 sorts as 0.0
    bits = clean.view(np.int64)
    keys = np.empty(n, np.uint64)
    for k in range(n):
        x = bits[k]
        keys[k] = np.uint64(~x) if x < 0 else np.uint64(x) | SIGN_BIT
    return radix_sort(keys, np.arange(n))[1]
