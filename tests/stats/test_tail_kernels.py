"""The scalar chi-square tail and quantile kernels agree with SciPy's ``chdtrc``/``chdtri``."""

import numpy as np
import pytest
from scipy import special as sc

from lidarstat.stats import chi2_isf_many, chi2_isf_scalar, chi2_sf_scalar
from lidarstat._shared._jit import njit


@njit
def _sf_many(x, df, out):
    for i in range(x.size):
        out[i] = chi2_sf_scalar(x[i], df[i])


def test_tail_matches_scipy_over_the_fits_degrees_of_freedom():
    # Satterthwaite degrees of freedom of the local fits (about 1 to a few thousand), the
    # statistic around them and far in both tails
    rng = np.random.default_rng(3)
    df = np.exp(rng.uniform(np.log(0.3), np.log(3000), 200_000))
    x = df * np.exp(rng.normal(0, 0.7, df.size))
    got = np.empty_like(x)
    _sf_many(x, df, got)
    want = sc.chdtrc(df, x)
    usable = want > 1e-280
    np.testing.assert_allclose(got[usable], want[usable], rtol=1e-11, atol=0)
    np.testing.assert_array_less(got[~usable], 1e-270)


def test_tail_edges_as_the_vectorised_test():
    from lidarstat.stats._distributions import chi2_sf

    x = np.array([0.0, -0.0, -3.0, 1e-300, np.inf, np.nan, 2.0, 2.0, 2.0, 5.0])
    df = np.array([2.0, 2.0, 4.0, 3.0, 5.0, 4.0, 0.0, -1.0, np.nan, np.inf])
    got = np.empty_like(x)
    _sf_many(x, df, got)
    want = chi2_sf(x, df)
    np.testing.assert_array_equal(got, want)


def test_uniform_pvalues_under_the_null():
    # statistical: p-values of chi2(df) draws are uniform (Kolmogorov-Smirnov at 1e-3)
    from scipy import stats

    rng = np.random.default_rng(11)
    for df in (1.7, 23.4, 310.0):
        x = rng.chisquare(df, 20_000)
        p = np.empty_like(x)
        _sf_many(x, np.full_like(x, df), p)
        assert stats.kstest(p, "uniform").pvalue > 1e-3, df


@pytest.mark.parametrize("q", [0.5, 0.05, 0.999, 1e-8])
def test_quantile_matches_scipy(q):
    rng = np.random.default_rng(5)
    df = np.exp(rng.uniform(np.log(0.2), np.log(3000), 20_000))
    got = np.empty_like(df)
    chi2_isf_many(q, df, got)
    np.testing.assert_allclose(got, sc.chdtri(df, q), rtol=1e-12, atol=0)


def test_quantile_refuses_outside_its_domain():
    for q, df in ((0.0, 3.0), (1.0, 3.0), (np.nan, 3.0), (0.5, 0.0), (0.5, -2.0),
                  (0.5, np.nan), (0.5, np.inf)):
        assert np.isnan(chi2_isf_scalar(q, df)), (q, df)
