"""SAR (spatial lag) model by ML: against PySAL spreg.ML_Lag, log-determinants, the
orthogonal polynomial basis and the order selection."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from lidarstat.errors import InvalidParameterError
from lidarstat.neighbors import radius_neighbors
from lidarstat.stats import LogDet, PolynomialBasis, sar_fit, select_degree, weights_matrix


def _sar_data(rng, n=600, rho=0.4, radius=1.5, extent=25.0):
    xy = rng.uniform(0, extent, (n, 2))
    nb = radius_neighbors(np.c_[xy, np.zeros(n)], radius, dim=2)
    W = weights_matrix(nb.indptr, nb.indices, n)
    A = np.c_[np.ones(n), xy]
    eps = rng.normal(0, 0.1, n)
    z = spl.spsolve(sp.csc_matrix(sp.identity(n) - rho * W), A @ [1.0, 0.3, -0.2] + eps)
    return xy, z, A, W


@pytest.mark.parametrize("logdet", ["eig", "lu", "auto"])
def test_matches_spreg_ml_lag(rng, logdet):
    spreg = pytest.importorskip("spreg", reason="PySAL spreg validates the SAR fit")
    libpysal = pytest.importorskip("libpysal", reason="PySAL weights for spreg")
    xy, z, A, W = _sar_data(rng)
    fit = sar_fit(z, A, W, logdet=logdet)
    w = libpysal.weights.WSP(W.tocsr()).to_W(silence_warnings=True)
    w.transform = "r"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = spreg.ML_Lag(z[:, None], xy, w, method="full")
    assert fit.rho == pytest.approx(float(ref.rho), abs=1e-4)
    np.testing.assert_allclose(fit.theta, ref.betas.ravel()[:3], atol=1e-4)
    np.testing.assert_allclose(fit.se_theta, ref.std_err[:3], rtol=2e-3)
    assert fit.se_rho == pytest.approx(float(ref.std_err[3]), rel=2e-3)
    assert fit.sigma2 == pytest.approx(float(ref.sig2), rel=1e-4)


def test_rho_is_recovered_within_its_standard_error(rng):
    hits = 0
    for k in range(8):
        _, z, A, W = _sar_data(np.random.default_rng(100 + k), n=500, rho=0.5)
        fit = sar_fit(z, A, W)
        hits += abs(fit.rho - 0.5) < 2.5 * fit.se_rho
    assert hits >= 7


def test_logdet_methods_agree(rng):
    _, _, _, W = _sar_data(rng, n=500)
    exact = LogDet(W, "eig")
    lu, series = LogDet(W, "lu"), LogDet(W, "series", order=60)
    for rho in (-0.6, 0.0, 0.3, 0.8):
        assert lu(rho) == pytest.approx(exact(rho), abs=1e-8)
    for rho in (-0.5, 0.3, 0.6):  # Barry-Pace series: stochastic traces, truncated
        assert series(rho) == pytest.approx(exact(rho), rel=0.03, abs=0.5)
    lo, hi = exact.bounds()
    assert -1 <= lo < 0 < hi <= 1


def test_orthogonal_basis(rng):
    xy = rng.uniform(100, 120, (400, 2))
    basis = PolynomialBasis.fit(xy, 3)
    X = basis(xy)
    assert X.shape == (400, 10)
    np.testing.assert_allclose(X.T @ X / 400, np.eye(10), atol=1e-10)
    coef = rng.normal(size=10)
    np.testing.assert_allclose(basis.evaluate(coef, xy), X @ coef, atol=1e-10)
    h = 1e-5
    num = np.c_[(basis.evaluate(coef, xy + [h, 0]) - basis.evaluate(coef, xy - [h, 0])) / (2 * h),
                (basis.evaluate(coef, xy + [0, h]) - basis.evaluate(coef, xy - [0, h])) / (2 * h)]
    np.testing.assert_allclose(basis.gradient(coef, xy), num, rtol=1e-5, atol=1e-7)


def test_degree_selection(rng):
    xy = rng.uniform(0, 20, (500, 2))
    nb = radius_neighbors(np.c_[xy, np.zeros(500)], 1.5, dim=2)
    W = weights_matrix(nb.indptr, nb.indices, 500)
    plane = 2 + 0.5 * xy[:, 0] + rng.normal(0, 0.05, 500)
    bowl = 2 + 0.02 * (xy[:, 0] - 10) ** 2 + rng.normal(0, 0.05, 500)
    assert select_degree(plane, xy, W, max_degree=3)[0] == 1
    assert select_degree(bowl, xy, W, max_degree=3)[0] == 2


def test_bad_input(rng):
    _, z, A, W = _sar_data(rng, n=50)
    with pytest.raises(InvalidParameterError, match="shape"):
        sar_fit(z, A[:10], W)
    with pytest.raises(InvalidParameterError, match="too few"):
        sar_fit(z[:3], A[:3], W[:3, :3])
    with pytest.raises(InvalidParameterError, match="'method'"):
        LogDet(W, "magic")


def test_sar_trend_is_least_squares_with_the_sar_sandwich(rng):
    from lidarstat.stats import sar_trend

    n = 300
    xy = rng.uniform(0, 10, (n, 2))
    nb = radius_neighbors(np.c_[xy, np.zeros(n)], 1.0, dim=2)
    W = weights_matrix(nb.indptr, nb.indices, n)
    A = np.c_[np.ones(n), xy]
    z = A @ [1.0, 0.3, -0.2] + rng.normal(0, 0.05, n)
    for rho in (0.0, 0.4, -0.3):
        coef, cov = sar_trend(z, A, W, rho, 0.0025)
        np.testing.assert_allclose(coef, np.linalg.lstsq(A, z, rcond=None)[0], rtol=1e-10)
        Minv = np.linalg.inv(np.eye(n) - rho * W.toarray())
        bread = np.linalg.inv(A.T @ A)
        ref = bread @ A.T @ (0.0025 * Minv @ Minv.T) @ A @ bread
        np.testing.assert_allclose(cov, ref, rtol=1e-8, atol=1e-14)
    # the sandwich is the actual spread of the least-squares trend under SAR noise
    rho, reps = 0.5, 400
    Minv = np.linalg.inv(np.eye(n) - rho * W.toarray())
    est = np.array([np.linalg.lstsq(A, A @ [1.0, 0.3, -0.2] + Minv @ rng.normal(0, 0.05, n),
                                    rcond=None)[0] for _ in range(reps)])
    _, cov = sar_trend(z, A, W, rho, 0.0025)
    ratio = est.var(axis=0, ddof=1) / np.diag(cov)
    # var ratio ~ chi2(reps - 1) / (reps - 1): 99.9 % interval about [0.79, 1.24]
    assert np.all((ratio > 0.79) & (ratio < 1.24)), ratio
