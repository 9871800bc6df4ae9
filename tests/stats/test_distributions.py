"""The normal and chi-square tails of ``lidarstat.stats`` are SciPy's, without scipy.stats."""

import numpy as np
import pytest
from scipy import stats as st

from lidarstat.stats import _distributions as d

RNG = np.random.default_rng(7)
X = np.r_[RNG.uniform(-2, 80, 500), 0.0, -0.0, 1e-300, 1e300, np.inf, -np.inf, np.nan]
DF = np.r_[RNG.uniform(0.1, 60, 500), 0.0, -1.0, np.nan, 3.0, 1e-10, 2.5, 7.0]
Q = np.r_[RNG.uniform(0, 1, 500), 0.0, 1.0, -0.1, 1.1, np.nan, 1e-300, 0.5]


@pytest.mark.parametrize("ours, scipys, args", [
    (d.chi2_sf, st.chi2.sf, (X, DF)),
    (d.chi2_isf, st.chi2.isf, (Q, DF)),
    (d.chi2_ppf, st.chi2.ppf, (Q, DF)),
    (d.norm_sf, st.norm.sf, (X,)),
    (d.norm_isf, st.norm.isf, (Q,)),
    (d.norm_ppf, st.norm.ppf, (Q,)),
])
def test_same_values_as_scipy_stats_edges_included(ours, scipys, args):
    with np.errstate(all="ignore"):
        want = scipys(*args)
    np.testing.assert_array_equal(ours(*args), want)
    assert ours(*(a[3] for a in args)) == scipys(*(a[3] for a in args))


def test_scalars_give_floats():
    assert isinstance(d.chi2_sf(3.0, 2), float)
    assert d.chi2_sf(3.0, 2) == pytest.approx(np.exp(-1.5), rel=1e-15)


def test_binomial_tail_is_scipy_stats_binom_sf():
    # a seed sweep of counts, trials and shares, with the edges of every argument
    rng = np.random.default_rng(11)
    n = np.r_[rng.integers(0, 3000, 4000), 0, 0, 5, 5, 5, 5, 5, 5, 2.5, -1, np.inf, np.nan, 7, 7]
    k = np.r_[np.floor(rng.uniform(-0.2, 1.2, 4000) * (n[:4000] + 1)) - 1,
              -1, 0, -1, 0, 4, 5, 2.7, np.inf, 1, 1, 1, 1, np.nan, -np.inf]
    p = np.r_[rng.uniform(0, 1, 4000), 0.3, 0.3, 0.0, 1.0, 1.0, 0.0, 0.4, 0.4, 0.4, 0.4,
              0.4, 0.4, 0.4, 0.4]
    p[:40] = np.r_[0.0, 1.0, -0.1, 1.1, np.nan, rng.uniform(0, 1, 35)]
    # half of the counts near the mean (within four standard deviations): mid-range tails
    m = n[2000:4000] * p[2000:4000]
    sd = np.sqrt(m * (1 - p[2000:4000]))
    k[2000:4000] = np.floor(m + 4.0 * sd * rng.uniform(-1, 1, 2000))
    with np.errstate(all="ignore"):
        want = st.binom.sf(k, n, p)
    got = d.binom_sf(k, n, p)
    # NaN, 0 and 1 where SciPy gives them; inside the support within 1e-13 relative
    # (both evaluate Boost's incomplete beta; the tail reaches 1e-300 and below)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    edge = np.isin(want, (0.0, 1.0))
    np.testing.assert_array_equal(got[edge], want[edge])
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)
    assert ((want > 0) & (want < 1)).sum() > 2000  # most of the sweep is inside the support
    assert d.binom_sf(0, 10, 0.5) == pytest.approx(1 - 0.5**10, rel=1e-15)
