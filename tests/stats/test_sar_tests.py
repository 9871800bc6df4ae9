"""The SAR-side hypothesis tests of ``stats``: Moran's I, the likelihood-ratio test of rho,
Chow's F test and the Forward Search envelopes, each checked for its size under the null
(Monte Carlo, binomial bounds) and its power or its exact value."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy import stats as st

from lidarstat.neighbors import radius_neighbors
from lidarstat.stats import (chow_test, deletion_residual_envelope, likelihood_ratio_test,
                             moran_test, sar_fit, truncated_normal_variance, weights_matrix)


def _binomial_bounds(n, p, level=1e-3):
    lo, hi = st.binom.interval(1 - level, n, p)
    return lo / n, hi / n


def _design(rng, n=150):
    """Random planimetric positions, a plane design and its row-standardised W."""
    xy = rng.uniform(0, np.sqrt(n / 4.0), (n, 2))
    nb = radius_neighbors(np.c_[xy, np.zeros(n)], 0.9, dim=2)
    W = weights_matrix(nb.indptr, nb.indices, n)
    A = np.c_[np.ones(n), xy]
    q, _ = np.linalg.qr(A)
    return A, q, W


@pytest.mark.parametrize("seed", [0, 1])
def test_moran_test_has_its_size_under_independent_errors(seed):
    rng = np.random.default_rng(seed)
    A, q, W = _design(rng)
    reps, alpha = 600, 0.05
    rej = 0
    for _ in range(reps):
        z = A @ [1.0, 0.3, -0.2] + rng.normal(0, 0.05, A.shape[0])
        e = z - q @ (q.T @ z)
        rej += bool(moran_test(e, q, W, alpha=alpha).reject)
    lo, hi = _binomial_bounds(reps, alpha)
    assert lo <= rej / reps <= hi


def test_moran_test_detects_sar_errors():
    rng = np.random.default_rng(3)
    A, q, W = _design(rng)
    n = A.shape[0]
    lag = sp.csc_matrix(sp.identity(n) - 0.6 * W)
    rej = 0
    for _ in range(100):
        u = sp.linalg.spsolve(lag, rng.normal(0, 0.05, n))
        e = u - q @ (q.T @ u)
        rej += bool(moran_test(e, q, W, alpha=0.05).reject)
    assert rej >= 90


def test_moran_test_of_zero_residuals_is_zero():
    rng = np.random.default_rng(0)
    A, q, W = _design(rng, 50)
    r = moran_test(np.zeros(50), q, W)
    assert float(r.statistic) == 0.0 and not r.reject


def test_likelihood_ratio_test_of_rho_has_its_size():
    rng = np.random.default_rng(11)
    n, reps, alpha = 120, 300, 0.05
    _, _, W = _design(rng, n)
    rej = 0
    for _ in range(reps):
        e = rng.normal(0, 1.0, n)
        fit = sar_fit(e, np.ones((n, 1)), W, covariance=False)
        d = e - e.mean()
        ll0 = -0.5 * n * (np.log(float(d @ d) / n) + np.log(2 * np.pi) + 1.0)
        rej += bool(likelihood_ratio_test(fit.loglik, ll0, 1, alpha=alpha).reject)
    lo, hi = _binomial_bounds(reps, alpha)
    assert lo <= rej / reps <= hi


def test_likelihood_ratio_test_matches_chi_square():
    r = likelihood_ratio_test(-10.0, -12.5, 2, alpha=0.01)
    assert float(r.statistic) == 5.0
    assert float(r.pvalue) == pytest.approx(st.chi2.sf(5.0, 2))
    assert not r.reject


def _rss(A, z):
    c = np.linalg.lstsq(A, z, rcond=None)[0]
    e = z - A @ c
    return float(e @ e)


@pytest.mark.parametrize("seed", [0, 1])
def test_chow_test_has_its_size_and_power(seed):
    rng = np.random.default_rng(seed)
    reps, alpha, na, nb = 800, 0.05, 40, 60
    rej = power = 0
    for _ in range(reps):
        A = np.c_[np.ones(na + nb), rng.uniform(0, 10, (na + nb, 2))]
        z = A @ [2.0, 0.4, -0.1] + rng.normal(0, 0.05, na + nb)
        a, b = slice(0, na), slice(na, na + nb)
        args = (_rss(A, z), _rss(A[a], z[a]), _rss(A[b], z[b]), 3, na, nb)
        rej += bool(chow_test(*args, alpha=alpha).reject)
        z2 = z.copy()
        z2[b] += 0.05 * A[b, 1]  # the second set on a plane 3 degrees steeper
        args = (_rss(A, z2), _rss(A[a], z2[a]), _rss(A[b], z2[b]), 3, na, nb)
        power += bool(chow_test(*args, alpha=alpha).reject)
    lo, hi = _binomial_bounds(reps, alpha)
    assert lo <= rej / reps <= hi
    assert power / reps > 0.99


def test_chow_test_without_residual_cannot_reject():
    r = chow_test(1.0, 0.0, 0.0, 3, 3, 3)
    assert float(r.pvalue) == 1.0 and not r.reject


@pytest.mark.parametrize("m, n", [(20, 60), (45, 60), (150, 200)])
def test_envelope_is_the_order_statistic_quantile(m, n):
    rng = np.random.default_rng(m)
    alpha = 0.05
    env = float(deletion_residual_envelope(m, n, alpha))
    draws = np.sort(np.abs(rng.normal(size=(20000, n))), axis=1)[:, m]
    lo, hi = _binomial_bounds(draws.size, alpha)
    assert lo <= np.mean(draws > env) <= hi
    assert np.isnan(deletion_residual_envelope(n, n, alpha))


@pytest.mark.parametrize("p", [0.3, 0.7, 0.95])
def test_truncated_normal_variance_matches_monte_carlo(p):
    x = np.random.default_rng(1).normal(size=400000)
    keep = np.abs(x) <= np.quantile(np.abs(x), p)
    assert float(truncated_normal_variance(p)) == pytest.approx(np.var(x[keep]), rel=0.01)
