"""Simultaneous autoregressive (SAR) trend-surface model by maximum likelihood (seed 002, eq. 1-4).

``z - rho W z = A theta + eps``, ``eps ~ N(0, sigma^2 I)``: written as
``z = rho W z + A theta + eps`` this is the *spatial lag* model of Anselin (1988), the
model PySAL fits with ``spreg.ML_Lag`` (not the spatial error model
``z = A theta + u, u = rho W u + eps``). The fit maximises the profile (concentrated)
log-likelihood of eq. 2 over rho, first on a grid (Pace, Barry and Sirmans 1998), then by a
bounded scalar refinement around the best grid value; theta and sigma^2 follow in closed
form (eq. 3.1, 3.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import linalg as sla
from scipy import stats as _st
from scipy.optimize import minimize_scalar
from scipy.sparse.linalg import splu

from ..errors import InvalidParameterError
from ._sar_logdet import LogDet

#: Largest n for which the information-matrix traces use a dense inverse.
DENSE_TRACE_MAX = 150


@dataclass(frozen=True)
class SARFit:
    """Maximum-likelihood fit of the SAR (spatial lag) trend model.

    Attributes
    ----------
    theta : (r,) ndarray
        Trend coefficients (eq. 3.1).
    rho : float
        Spatial interaction parameter.
    sigma2 : float
        ML noise variance (eq. 3.2, divisor n, as in the paper and spreg).
    cov : (r + 2, r + 2) ndarray
        Asymptotic covariance of (theta, rho, sigma^2) from the information matrix
        (Anselin 1988, eq. 12.x; the matrix spreg inverts).
    loglik : float
        Full log-likelihood at the optimum.
    residuals : (n,) ndarray
        ``(I - rho W) z - A theta``.
    n : int
        Observations.
    logdet_method : str
        How log|I - rho W| was computed.
    profile : (2, f) ndarray
        Grid of rho and the profile log-likelihood on it (for plots).
    """

    theta: np.ndarray
    rho: float
    sigma2: float
    cov: np.ndarray
    loglik: float
    residuals: np.ndarray
    n: int
    logdet_method: str
    profile: np.ndarray

    @property
    def se_theta(self) -> np.ndarray:
        """Standard errors of theta."""
        r = self.theta.size
        return np.sqrt(np.diag(self.cov)[:r])

    @property
    def se_rho(self) -> float:
        """Standard error of rho."""
        return float(np.sqrt(self.cov[self.theta.size, self.theta.size]))

    @property
    def se_sigma2(self) -> float:
        """Standard error of sigma^2."""
        return float(np.sqrt(self.cov[-1, -1]))

    @property
    def std_residuals(self) -> np.ndarray:
        """Standardised residuals e of eq. 4."""
        return self.residuals / np.sqrt(self.sigma2)

    def t_test(self, alpha=0.05):
        """Two-sided t tests of ``theta_i = 0`` with n - r - 1 degrees of freedom."""
        from ._results import TestResult

        t = self.theta / self.se_theta
        df = self.n - self.theta.size - 1
        p = 2.0 * _st.t.sf(np.abs(t), df)
        return TestResult(t, p, float(df), p < alpha, float(alpha))


def sar_fit(z, A, W, *, logdet="auto", grid=11, bounds=None, xatol=1e-8, covariance=True,
            rng=0):
    """Fit ``z = rho W z + A theta + eps`` by maximum likelihood (profile likelihood in rho).

    Parameters
    ----------
    z : (n,) array_like
        Heights.
    A : (n, r) array_like
        Trend design matrix (e.g. :func:`polynomial_basis`).
    W : (n, n) sparse matrix
        Spatial weights (row-standardised: see :func:`weights_matrix`).
    logdet : {'auto', 'eig', 'lu', 'series'} or LogDet
        How ``log|I - rho W|`` is computed (see :class:`LogDet`).
    grid : int
        Grid size over the admissible rho interval before the bounded refinement.
    bounds : (float, float), optional
        Search interval of rho; default (-1, 1) cut to the eigenvalue bounds when known
        (the paper's grid over [0, 1] assumes non-negative interaction).
    xatol : float
        Absolute tolerance of the refinement.
    covariance : bool
        Compute the information-matrix covariance (traces of ``W (I - rho W)^-1``:
        dense for n <= :data:`DENSE_TRACE_MAX`, stochastic (Hutchinson, 32 probes) above).
    rng : Generator or int, optional
        Seed of stochastic traces.

    Returns
    -------
    SARFit

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.stats import sar_fit, weights_matrix
    >>> from lidarstat.neighbors import radius_neighbors
    >>> rng = np.random.default_rng(1)
    >>> xy = rng.uniform(0, 10, (300, 2))
    >>> nb = radius_neighbors(np.c_[xy, np.zeros(300)], 1.0, dim=2)
    >>> W = weights_matrix(nb.indptr, nb.indices, 300)
    >>> A = np.c_[np.ones(300), xy]
    >>> z = A @ [1.0, 0.3, -0.2] + rng.normal(0, 0.1, 300)
    >>> fit = sar_fit(z, A, W)
    >>> abs(fit.rho) < 0.3
    True
    """
    z = np.asarray(z, dtype=np.float64).ravel()
    A = np.asarray(A, dtype=np.float64)
    n = z.size
    if A.ndim != 2 or A.shape[0] != n:
        raise InvalidParameterError(f"sar_fit: `A` must have shape ({n}, r); got {A.shape}")
    r = A.shape[1]
    if n <= r + 1:
        raise InvalidParameterError(f"sar_fit: {n} observations are too few for {r} trend "
                                    f"parameters and rho")
    W = sp.csr_matrix(W)
    if W.shape != (n, n):
        raise InvalidParameterError(f"sar_fit: `W` must be ({n}, {n}); got {W.shape}")
    ld = logdet if isinstance(logdet, LogDet) else LogDet(W, logdet, rng=rng)
    wz = W @ z
    q, rr = np.linalg.qr(A)
    e0 = z - q @ (q.T @ z)
    e1 = wz - q @ (q.T @ wz)
    a00, a01, a11 = e0 @ e0, e0 @ e1, e1 @ e1

    def negll(rho):
        ss = a00 - 2 * rho * a01 + rho * rho * a11
        return 0.5 * n * np.log(max(ss, 1e-300) / n) - ld(rho)

    lo, hi = bounds if bounds is not None else ld.bounds()
    eps = 1e-6 * (hi - lo)
    rhos = np.linspace(lo + eps, hi - eps, int(grid))
    vals = np.array([negll(x) for x in rhos])
    k = int(np.argmin(vals))
    a, b = rhos[max(k - 1, 0)], rhos[min(k + 1, rhos.size - 1)]
    res = minimize_scalar(negll, bounds=(a, b), method="bounded", options={"xatol": xatol})
    rho = float(res.x)
    if vals[k] < res.fun:
        rho = float(rhos[k])
    ystar = z - rho * wz
    theta = sla.solve_triangular(rr, q.T @ ystar)
    resid = ystar - A @ theta
    sigma2 = float(resid @ resid / n)
    loglik = float(-negll(rho) - 0.5 * n * (np.log(2 * np.pi) + 1.0))
    # an exact fit (noise-free plane, sigma2 = 0) has no information matrix: NaN, as
    # without `covariance`
    cov = _information_cov(A, W, theta, rho, sigma2, ld, rng) if covariance and sigma2 > 0 \
        else np.full((r + 2, r + 2), np.nan)
    return SARFit(theta, rho, sigma2, cov, loglik, resid, n, ld.method,
                  np.vstack([rhos, -vals - 0.5 * n * (np.log(2 * np.pi) + 1.0)]))


def _information_cov(A, W, theta, rho, sigma2, ld, rng, probes=32):
    n, r = A.shape
    I = sp.identity(n, format="csc")
    M = sp.csc_matrix(I - rho * W)
    if n <= DENSE_TRACE_MAX:
        wai = W @ np.linalg.inv(M.toarray())
        wai = np.asarray(wai)
        tr1 = np.trace(wai)
        tr2 = np.sum(wai * wai.T)
        tr3 = np.sum(wai * wai)
    else:
        lu = splu(M)
        gen = np.random.default_rng(rng)
        x = gen.choice([-1.0, 1.0], size=(n, probes))
        y = W @ lu.solve(x)  # W A^-1 x
        if ld.evals is not None:
            lam = ld.evals.real
            tr1 = float(np.sum(lam / (1 - rho * lam)))
            tr2 = float(np.sum((lam / (1 - rho * lam)) ** 2))
        else:
            tr1 = float(np.mean(np.sum(x * y, axis=0)))
            y2 = W @ lu.solve(y)
            tr2 = float(np.mean(np.sum(x * y2, axis=0)))
        tr3 = float(np.mean(np.sum(y * y, axis=0)))
    lu = splu(M)
    predy = lu.solve(A @ theta)
    wpy = W @ predy
    v = np.zeros((r + 2, r + 2))
    v[:r, :r] = A.T @ A / sigma2
    v[:r, r] = v[r, :r] = A.T @ wpy / sigma2
    v[r, r] = tr2 + tr3 + wpy @ wpy / sigma2
    v[r, r + 1] = v[r + 1, r] = tr1 / sigma2
    v[r + 1, r + 1] = n / (2.0 * sigma2 ** 2)
    try:
        return np.linalg.inv(v)
    except np.linalg.LinAlgError:
        return np.full((r + 2, r + 2), np.nan)


def _solve_lag(W, rho, b, tol=1e-12, max_terms=200):
    """``(I - rho W)^-1 b`` by the power series ``sum (rho W)^k b`` (row-standardised W,
    |rho| < 1), with a sparse LU when the series would converge slowly."""
    W = sp.csr_matrix(W)
    if abs(rho) <= 0.9:
        x = b.copy()
        term = b.copy()
        scale = max(float(np.abs(b).max()), 1e-300)
        for _ in range(max_terms):
            term = rho * (W @ term)
            x += term
            if float(np.abs(term).max()) <= tol * scale:
                return x
    n = W.shape[0]
    return splu(sp.csc_matrix(sp.identity(n, format="csc") - rho * W)).solve(b)


def sar_mean_surface(fit, A, W):
    """Coefficients of the polynomial closest to the SAR mean ``(I - rho W)^-1 A theta``.

    In the lag model the expected heights are ``(I - rho W)^-1 A theta``, not
    ``A theta``: inside a surface ``W A ~ A`` so ``A theta ~ (1 - rho) E[z]``. The
    surface itself (for normals, intersections) is the least-squares projection of the
    model mean on the trend basis, ``(A'A)^-1 A' (I - rho W)^-1 A theta``.
    """
    mean = _solve_lag(W, fit.rho, A @ fit.theta)
    return np.linalg.lstsq(A, mean, rcond=None)[0]


def sar_trend(z, A, W, rho, sigma2, *, covariance=True):
    """Least-squares trend of the heights with its covariance under the SAR model.

    The surface of a unit is the polynomial closest to the expected heights. In the lag
    model those are ``(I - rho W)^-1 A theta``; :func:`sar_mean_surface` projects the
    *model* mean, whereas the ordinary least-squares fit ``c = (A'A)^-1 A'z`` estimates
    the same projection directly from the data, without relying on theta and rho
    (``E[c] = (A'A)^-1 A' E[z]`` under any zero-mean noise). It is the estimator used for
    the reported surfaces: on planes with independent noise the lag model is misspecified
    (rho picks up edge effects of the row-standardised W and points of neighbouring faces),
    and the model-based projection then tilts small planes by up to 0.5 degrees where the
    least-squares plane does not (docs/methods/sar.md).

    The covariance accounts for the spatial dependence the SAR fit found: with
    ``Cov(z) = sigma2 (I - rho W)^-1 (I - rho W)^-T``,
    ``Cov(c) = (A'A)^-1 A' Cov(z) A (A'A)^-1`` (a sandwich; ``rho = 0`` gives the usual
    ``sigma2 (A'A)^-1``).

    Parameters
    ----------
    z : (n,) array_like
        Heights.
    A : (n, r) array_like
        Trend design.
    W : (n, n) sparse matrix
        Spatial weights of the SAR model.
    rho, sigma2 : float
        SAR interaction and innovation variance.
    covariance : bool
        False: `cov` is NaN (not computed).

    Returns
    -------
    coef : (r,) ndarray
    cov : (r, r) ndarray

    Examples
    --------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> from lidarstat.stats import sar_trend
    >>> A = np.c_[np.ones(5), np.arange(5.0)]
    >>> coef, cov = sar_trend(A @ [1.0, 0.5], A, sp.csr_matrix((5, 5)), 0.0, 0.01)
    >>> np.allclose(coef, [1.0, 0.5]), np.allclose(cov, 0.01 * np.linalg.inv(A.T @ A))
    (True, True)
    """
    z = np.asarray(z, dtype=np.float64).ravel()
    A = np.asarray(A, dtype=np.float64)
    q, rr = np.linalg.qr(A)
    coef = sla.solve_triangular(rr, q.T @ z)
    if not covariance:
        return coef, np.full((coef.size, coef.size), np.nan)
    ainv = sla.solve_triangular(rr, np.eye(rr.shape[0]))  # R^-1
    if rho == 0.0:
        bread = ainv @ ainv.T
        return coef, sigma2 * bread
    # Y = (I - rho W)^-T A ; A' Cov(z) A = sigma2 Y'Y
    Y = _solve_lag(sp.csr_matrix(W).T, rho, A)
    meat = sigma2 * (Y.T @ Y)
    bread = ainv @ ainv.T  # (A'A)^-1
    return coef, bread @ meat @ bread
