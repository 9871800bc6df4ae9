"""Hotelling's T^2 test of a bivariate mean: size under the null, power off it."""

import numpy as np
import pytest

from lidarstat.stats import chi2_pvalue, hotelling_pvalue, hotelling_test, normal_pvalue


def _t2(x, mu=(0.0, 0.0)):
    """``n (c - mu)' S^-1 (c - mu)`` of every sample in `x` (R, n, 2)."""
    n = x.shape[1]
    c = x.mean(axis=1) - mu
    d = x - x.mean(axis=1, keepdims=True)
    s = np.einsum("rni,rnj->rij", d, d) / (n - 1)
    return n * np.einsum("ri,rij,rj->r", c, np.linalg.inv(s), c)


@pytest.mark.parametrize("n, alpha", [(10, 0.05), (50, 0.01)])
def test_size_is_alpha_on_correlated_normal_samples(n, alpha):
    """Under H0 (bivariate normal, correlation 0.6, unequal variances) the rejection rate
    is within the 99.9 % binomial interval of alpha, over seeds."""
    reps = 20000
    for seed in range(3):
        rng = np.random.default_rng(seed)
        cov = np.array([[4.0, 1.2], [1.2, 1.0]])
        x = rng.multivariate_normal((0.0, 0.0), cov, size=(reps, n))
        rate = hotelling_test(_t2(x), n, alpha=alpha).reject.mean()
        assert abs(rate - alpha) < 3.3 * np.sqrt(alpha * (1 - alpha) / reps), (seed, rate)


def test_power_grows_with_the_offset_and_pvalues_are_vectorised():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(4000, 30, 2))
    p0 = hotelling_pvalue(_t2(x), 30)
    p1 = hotelling_pvalue(_t2(x + [0.8, 0.0]), np.full(4000, 30))
    assert np.mean(p1 < 0.05) > 0.9 > 0.1 > np.mean(p0 < 0.05)
    assert np.isnan(hotelling_pvalue(1.0, 2))


def test_chi2_and_normal_pvalues():
    assert chi2_pvalue(0.0, 3) == 1.0
    assert abs(chi2_pvalue(5.991464547107979, 2) - 0.05) < 1e-12
    assert abs(normal_pvalue(1.959963984540054) - 0.05) < 1e-12
    assert abs(normal_pvalue(1.6448536269514722, sides=1) - 0.05) < 1e-12
    assert np.isnan(chi2_pvalue(1.0, np.nan))
