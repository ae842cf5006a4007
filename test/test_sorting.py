"""The step's stable sort against numpy's (physics/sorting.py)."""
import numpy as np
import pytest
from numba import njit

from vplayground_ros.physics.sorting import ARGSORT_RADIX_MIN, SORT_RADIX_MIN, sorted_keys, stable_argsort


@njit
def argsort(values):  # Python entries to the compiled-only kernels
    return stable_argsort(values)


@njit
def sort_head(keys, n):  # as the octree sorts its keys: the used part of a larger array
    return sorted_keys(keys[:n]).copy()


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


@pytest.mark.parametrize("n", [0, 5, SORT_RADIX_MIN - 1, SORT_RADIX_MIN, 6000])
def test_sorted_keys_is_numpys_sort(n):
    """Octree keys: a cell's key above an object id (some cells shared), the array longer than
    the part sorted."""
    rng = np.random.default_rng(n)
    cells = rng.integers(0, 1 << 24, n) // 16 * 16
    keys = np.concatenate([(cells << 20) | rng.integers(0, 1 << 20, n), np.full(7, -1)]).astype(np.int64)
    assert np.array_equal(sort_head(keys.copy(), n), np.sort(keys[:n]))
