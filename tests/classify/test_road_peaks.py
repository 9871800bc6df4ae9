"""The road cut's peaks and prominences equal ``scipy.signal.find_peaks``' on densities,
noise, plateaus and edge cases (a seed sweep)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks

from lidarstat.classify._roads import _peaks
from lidarstat.stats import density_estimate


def _assert_as_scipy(x):
    peaks, prom = _peaks(x)
    ref, props = find_peaks(x, prominence=0)
    np.testing.assert_array_equal(peaks, ref)
    # the same samples subtracted: equal to the last bit
    np.testing.assert_array_equal(prom, props["prominences"])


@pytest.mark.parametrize("seed", range(40))
def test_densities_of_mixtures(seed):
    rng = np.random.default_rng(seed)
    k = rng.integers(1, 5)
    values = np.concatenate([rng.normal(rng.uniform(0, 1000), rng.uniform(10, 150),
                                        rng.integers(50, 3000)) for _ in range(k)])
    de = density_estimate(values, gridsize=512)
    _assert_as_scipy(np.r_[0.0, de.density, 0.0])


@pytest.mark.parametrize("seed", range(40))
def test_quantised_noise_with_plateaus(seed):
    rng = np.random.default_rng(100 + seed)
    x = rng.integers(0, rng.integers(2, 6), rng.integers(3, 200)).astype(np.float64)
    _assert_as_scipy(x)


@pytest.mark.parametrize("x", [[], [1.0], [1.0, 2.0], [0.0, 1.0, 0.0], [0.0, 2.0, 2.0, 0.0],
                               [0.0, 2.0, 2.0, 2.0, 1.0, 3.0, 3.0], [3.0, 1.0, 2.0, 1.0, 3.0],
                               [0.0, 1.0, 1.0, 2.0, 1.0, 1.0, 0.0], [5.0] * 6])
def test_edge_cases(x):
    _assert_as_scipy(np.asarray(x, dtype=np.float64))
