"""Sequential moments against direct recomputation; density; dip-test size and power."""

import numpy as np
import pytest
from scipy import stats as ss

from lidarstat.errors import InvalidPointsError
from lidarstat.stats import density_estimate, dip_test, sequential_moments, standard_moments


def _direct(x):
    # exact reference in extended precision on values shifted by an exactly representable centre
    d = (x - np.float64(4.5e6)).astype(np.longdouble)
    d = d - d.mean()
    m2 = np.mean(d ** 2)
    return float(np.mean(d ** 3) / m2 ** 1.5), float(np.mean(d ** 4) / m2 ** 2), float(np.sqrt(m2))


def test_sequential_matches_direct_on_utm_elevations(rng):
    x = 4.5e6 + np.r_[rng.normal(0, 0.05, 4000), rng.gamma(2.0, 3.0, 800)]
    sm = sequential_moments(x, return_order=True)
    assert sm.cycle.size == x.size - 3
    for k in rng.integers(0, x.size - 10, 40):
        left = x[sm.kept(k)]
        sk, ku, sd = _direct(left)
        assert sm.remaining[k] == left.size
        assert sm.skewness[k] == pytest.approx(sk, rel=1e-9, abs=1e-9)
        assert sm.kurtosis[k] == pytest.approx(ku, rel=1e-9)
        assert sm.std[k] == pytest.approx(sd, rel=1e-9)
        assert sm.threshold[k] == left.max()


def test_standard_moments_match_scipy(rng):
    x = rng.gamma(3.0, size=500)
    sk, ku = standard_moments(x)
    assert sk == pytest.approx(ss.skew(x), rel=1e-10)
    assert ku == pytest.approx(ss.kurtosis(x, fisher=False), rel=1e-10)


@pytest.mark.parametrize("bad", [[], [1.0, np.nan, 2.0, 3.0]])
def test_bad_values(bad):
    with pytest.raises(InvalidPointsError):
        sequential_moments(bad)


def test_density_recovers_gaussian(rng):
    x = rng.normal(3.0, 2.0, 20000)
    de = density_estimate(x)
    true = ss.norm.pdf(de.grid, 3.0, 2.0)
    assert np.max(np.abs(de.density - true)) < 0.02
    assert de.bandwidth == pytest.approx(0.9 * 2.0 * 20000 ** -0.2, rel=0.1)
    assert density_estimate(x, bandwidth=0.5).bandwidth == 0.5


def test_dip_size_under_unimodal_null():
    """Rejection rate on unimodal samples must not exceed alpha (binomial bound)."""
    g = np.random.default_rng(7)
    trials, alpha = 300, 0.05
    rej = sum(bool(dip_test(g.normal(size=300), rng=i).reject) for i in range(trials))
    # the uniform is the least favourable null: the test is conservative on a normal
    upper = ss.binom.ppf(0.999, trials, alpha)
    assert rej <= upper


def test_dip_power_on_bimodal():
    g = np.random.default_rng(8)
    rej = sum(bool(dip_test(np.r_[g.normal(0, 1, 150), g.normal(5, 1, 150)], rng=i).reject)
              for i in range(50))
    assert rej >= 48


def test_dip_dequantizes_integer_intensities():
    g = np.random.default_rng(9)
    x = np.round(g.normal(100, 3, 5000))  # integers: heavy ties
    assert not dip_test(x).reject


@pytest.mark.parametrize("seed", range(5))
def test_dip_dequantisation_step_from_the_distinct_values(seed):
    # the jitter's width is the smallest gap between distinct values, and no jitter is
    # drawn without ties or with one distinct value: as np.unique gives them
    import diptest

    g = np.random.default_rng(seed)
    x = [np.round(g.normal(100, 3, 3000)), g.normal(size=3000), np.full(50, 2.0),
         np.round(g.uniform(0, 5, 400), 2) * 1e-3 + 4.5e6, np.r_[np.zeros(30), 1.0]][seed]
    gen = np.random.default_rng(seed)
    u = np.unique(x)
    y = x
    if u.size < x.size and u.size > 1:
        q = float(np.min(np.diff(u)))
        y = x + gen.uniform(-0.5 * q, 0.5 * q, size=x.size)
    dip, p = diptest.diptest(y)
    got = dip_test(x, rng=seed)
    assert (float(got.statistic), float(got.pvalue)) == (dip, p)


@pytest.mark.parametrize("seed", range(5))
def test_sorted_values_given_change_nothing(seed):
    # a caller's np.sort(values) replaces the sorts of the dip test and the sequential
    # moments: bit-identical results with ties (spread), without, one value, and a sample
    # drawn from more than max_points values (the given sort cannot serve it)
    g = np.random.default_rng(seed)
    x = [np.round(g.normal(100, 3, 3000)), g.normal(size=3000), np.full(50, 2.0),
         np.round(g.uniform(0, 5, 400), 2) * 1e-3 + 4.5e6,
         np.r_[g.normal(0, 1, 15000), g.normal(4, 1, 10000)]][seed]
    xs = np.sort(x)
    for kw in ({}, {"dequantize": False}):
        a, b = dip_test(x, rng=seed, **kw), dip_test(x, rng=seed, sorted_values=xs, **kw)
        assert (float(a.statistic), float(a.pvalue)) == (float(b.statistic), float(b.pvalue))
    a, b = sequential_moments(x), sequential_moments(x, sorted_values=xs)
    for name in ("mean", "std", "skewness", "kurtosis", "threshold", "sorted_values"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    with pytest.raises(ValueError, match="sorted_values"):
        sequential_moments(x, sorted_values=xs[:-1])


@pytest.mark.parametrize("seed", range(3))
def test_density_from_sorted_values_is_the_same(seed):
    g = np.random.default_rng(seed)
    x = np.round(np.r_[g.normal(0, 0.2, 3000), g.uniform(3, 20, 700)], 3)
    g.shuffle(x)
    for bw in ("silverman", "scott", 0.3):
        a = density_estimate(x, bandwidth=bw, gridsize=256)
        b = density_estimate(x, bandwidth=bw, gridsize=256, sorted_values=np.sort(x))
        assert a.bandwidth == b.bandwidth
        np.testing.assert_array_equal(a.grid, b.grid)
        np.testing.assert_array_equal(a.density, b.density)
