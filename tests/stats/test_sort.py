"""``sort_values``: the array ``np.sort`` gives, by a radix sort of the values' bits."""

import numpy as np
import pytest

from lidarstat.stats import sort_values
from lidarstat.stats._sort import RADIX_MIN


def _clouds(rng, n):
    """Values of the kinds the moment analyses sort: heights rounded to 1e-6 and to the
    centimetre (long runs of ties), one-sided tails, integer intensities, and the edges
    of the doubles (infinities, subnormals, both zeros)."""
    yield rng.normal(0.0, 3.0, n)
    yield np.round(rng.normal(0.0, 3.0, n), 6)
    yield np.round(np.r_[rng.normal(0.0, 0.1, n - n // 4), rng.uniform(2, 30, n // 4)], 2)
    yield -rng.exponential(1.0, n) * 1e5
    yield rng.integers(0, 300, n).astype(np.float64)
    yield rng.choice([np.inf, -np.inf, 0.0, 1e-310, -1e-310, 5e-324, -2.5, 4.0e300], n)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n", [0, 1, 7, RADIX_MIN - 1, RADIX_MIN, 5_000, 40_000])
def test_equals_numpy_sort(seed, n):
    rng = np.random.default_rng(seed)
    for x in _clouds(rng, n):
        rng.shuffle(x)
        got = sort_values(x)
        assert got.dtype == np.float64 and got.shape == x.shape
        np.testing.assert_array_equal(got, np.sort(x))
        assert got is not x


def test_zeros_of_both_signs_negative_first():
    x = np.r_[np.zeros(3000), -np.zeros(3000), np.arange(1.0, 100.0), -np.arange(1.0, 100.0)]
    np.random.default_rng(0).shuffle(x)
    got = sort_values(x)
    np.testing.assert_array_equal(got, np.sort(x))
    zeros = got[got == 0]
    assert np.signbit(zeros[:3000]).all() and not np.signbit(zeros[3000:]).any()


def test_nan_sorted_as_numpy_does():
    x = np.random.default_rng(1).normal(size=4000)
    x[[5, 900]] = np.nan
    np.testing.assert_array_equal(sort_values(x), np.sort(x))  # NaNs last


def test_input_kept_and_read_only_or_other_dtypes_accepted():
    rng = np.random.default_rng(2)
    x = rng.normal(size=3000)
    before = x.copy()
    ro = x[::-1]
    ro.flags.writeable = False
    np.testing.assert_array_equal(sort_values(ro), np.sort(x))
    np.testing.assert_array_equal(x, before)
    ints = rng.integers(0, 65535, 3000).astype(np.uint16)
    np.testing.assert_array_equal(sort_values(ints), np.sort(ints.astype(np.float64)))
