"""The step's stable sorts against numpy's (physics/sorting.py)."""
import numpy as np
import pytest
from numba import njit

from vplayground_ros.physics.sorting import ARGSORT_RADIX_MIN, radix_sort, stable_argsort


@njit
def argsort(values):  # Python entries to the compiled-only kernels
    return stable_argsort(values)


@njit
def sort_head(keys, values, n):  # as the octree sorts its entries: the used part of larger arrays
    sorted_keys, sorted_values = radix_sort(keys[:n].view(np.uint64), values[:n])
    return sorted_keys.view(np.int64).copy(), sorted_values.copy()


def cases():
    rng = np.random.default_rng(7)
    heights = rng.uniform(-0.3, 6.0, 4000)
    return {
        "spread": heights,
        "ties": np.round(heights, 2),                     # many equal values: index order
        "ground": np.where(heights < 1.0, 0.0, heights),  # a floor of exact zeros
        "signed zeros": rng.choice([0.0, -0.0, 1e-300, -1e-300, 2.5], 3000),
        "wide": rng.normal(0, 1, 2000) * 10.0 ** rng.integers(-200, 200, 2000),
        "infinities": np.concatenate([heights[:1000], [np.inf, -np.inf, np.inf]]),
        "few": heights[:ARGSORT_RADIX_MIN - 1],
        "just enough": np.round(heights[:ARGSORT_RADIX_MIN], 1),
        "empty": heights[:0],
    }


@pytest.mark.parametrize("name", list(cases()))
def test_stable_argsort_is_numpys_stable_argsort(name):
    values = cases()[name]
    assert np.array_equal(argsort(values), np.argsort(values, kind="stable"))


@pytest.mark.parametrize("n", [0, 1, 5, 500, 6000])
def test_radix_sort_carries_values_stably(n):
    """Octree entries: cell keys (some shared, a few bytes varying) with the ids in ascending
    order carried along, the arrays longer than the part sorted: numpy's stable order."""
    rng = np.random.default_rng(n)
    cells = np.concatenate([4681 + rng.integers(0, 1 << 15, n) // 4, np.full(7, -1)]).astype(np.int64)
    ids = np.concatenate([np.sort(rng.integers(0, 1000, n)), np.full(7, -1)]).astype(np.int64)
    keys, values = sort_head(cells.copy(), ids.copy(), n)
    order = np.argsort(cells[:n], kind="stable")
    assert np.array_equal(keys, cells[:n][order]) and np.array_equal(values, ids[:n][order])
