"""Tests of SAR trend surfaces and of their residuals (seed 002).

* :func:`sar_variance_test`: goodness of fit, the residual scale of a surface against
  the survey noise, with the SAR correlation of the noise (Satterthwaite).
* :func:`moran_test`: Moran's I of least-squares residuals with its exact moments under
  independent normal errors (is there spatial correlation to model at all?).
* :func:`likelihood_ratio_test`: twice the log-likelihood gain of a model against the
  model it nests, referred to chi-square (e.g. rho = 0 in a SAR fit).
* :func:`chow_test`: the F test that two point sets lie on one regression surface.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidParameterError
from ._critical import chi2_test, f_test, z_test_statistic
from ._results import TestResult
from ._sar import _solve_lag

__all__ = ["sar_variance_test", "moran_test", "likelihood_ratio_test", "chow_test"]


def sar_variance_test(z, A, W, rho, sigma2, *, alpha=0.001, probes=40, rng=0):
    """Goodness of fit of a trend surface: its residual scale against the survey noise.

    The chi-square test of the a posteriori against the a priori variance factor (seed
    000, eq. 7), written for heights whose noise may be spatially correlated by the SAR
    process ``u = rho W u + eps``, ``Cov(u) = s^2 (I - rho W)^-1 (I - rho W)^-T``. The
    a priori noise `sigma2` is the *marginal* variance of a height about its surface
    (what a survey's noise figure, or the scatter about local planes, measures), so the
    covariance is normalised to mean diagonal 1, ``Sigma = sigma2 * C`` with
    ``tr(C) = n``. With ``M = I - A (A'A)^-1 A'`` the least-squares residual form is
    ``RSS = z'Mz``, ``E[RSS] = sigma2 tr(MC)``, ``Var[RSS] = 2 sigma2^2 tr((MC)^2)``,
    and Satterthwaite's approximation refers ``RSS / (c sigma2)`` to chi-square(nu),
    ``c = tr((MC)^2) / tr(MC)``, ``nu = tr(MC)^2 / tr((MC)^2)``. With ``rho = 0`` this
    is the textbook test, ``RSS / sigma2 ~ chi2(n - r)``. Positive correlation both
    raises the marginal variance above the innovation variance and widens the spread of
    RSS (fewer effective degrees of freedom): ignoring it over-rejects true surfaces
    (tested). The traces use Rademacher probes (Hutchinson) through the sparse lag
    solves of :func:`sar_trend`.

    The test is one-sided (upper tail): a scatter larger than the noise is the lack of
    fit (another surface, clutter) it looks for.

    Parameters
    ----------
    z : (n,) array_like
        Heights.
    A : (n, r) array_like
        Trend design.
    W : (n, n) sparse matrix
        Row-standardised spatial weights.
    rho : float
        SAR interaction (0: independent noise).
    sigma2 : float
        A priori marginal noise variance.
    alpha : float
        Level.
    probes : int
        Rademacher probes of the stochastic traces (only with ``rho != 0``).
    rng : int or Generator
        Seed of the probes.

    Returns
    -------
    TestResult
        Scalar ``statistic`` (``RSS / (c sigma2)``), ``pvalue``, ``df`` (nu), ``reject``.

    Examples
    --------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> from lidarstat.stats import sar_variance_test
    >>> rng = np.random.default_rng(0)
    >>> A = np.c_[np.ones(200), rng.uniform(0, 10, (200, 2))]
    >>> z = A @ [1.0, 0.2, 0.1] + rng.normal(0, 0.03, 200)
    >>> W = sp.csr_matrix((200, 200))
    >>> t = sar_variance_test(z, A, W, 0.0, 0.03 ** 2)
    >>> float(t.df), bool(t.reject)
    (197.0, False)
    >>> bool(sar_variance_test(z + 0.2 * (A[:, 1] > 5), A, W, 0.0, 0.03 ** 2).reject)
    True
    """
    z = np.asarray(z, dtype=np.float64).ravel()
    A = np.asarray(A, dtype=np.float64)
    n, r = A.shape
    if n <= r:
        raise InvalidParameterError(f"sar_variance_test: {n} heights are too few for {r} "
                                    f"trend parameters")
    if not sigma2 > 0:
        raise InvalidParameterError(f"sar_variance_test: the noise variance must be "
                                    f"positive; got {sigma2}")
    q, _ = np.linalg.qr(A)
    e = z - q @ (q.T @ z)
    rss = float(e @ e)
    if rho == 0.0:
        t1 = t2 = float(n - r)
    else:
        W = sp.csr_matrix(W)
        gen = np.random.default_rng(rng)
        V = gen.choice([-1.0, 1.0], size=(n, int(probes)))
        a = _solve_lag(W, rho, V)  # S V, S = (I - rho W)^-1
        b = a - q @ (q.T @ a)  # M S V
        c = _solve_lag(W.T, rho, b)  # S' M S V
        norm = n / float(np.sum(a * a) / probes)  # n / tr(S S')
        t1 = float(np.sum(b * b) / probes) * norm  # tr(M C)
        t2 = float(np.sum(c * c) / probes) * norm * norm  # tr((M C)^2)
    scale, nu = t2 / t1, t1 * t1 / t2
    stat = rss / (scale * sigma2)
    p = float(chi2_test(stat, nu, alpha=alpha).pvalue)
    return TestResult(np.float64(stat), np.float64(p), np.float64(nu),
                      np.bool_(p < alpha), float(alpha))


def moran_test(e, q, W, *, alpha=0.05) -> TestResult:
    """Moran's I test of least-squares residuals, two-sided normal reference.

    ``I = e'We / e'e`` of the residuals `e` of a design whose columns span the
    orthonormal `q`, against its exact mean and variance under independent normal errors
    (Cliff and Ord 1981), with ``M = I - qq'`` and W of zero diagonal:
    ``E[I] = tr(MW) / (n - r)``,
    ``Var[I] = (tr(MWMW') + tr((MW)^2) + tr(MW)^2) / ((n - r)(n - r + 2)) - E[I]^2``;
    the traces are expanded through ``qq'`` (one sparse product per column of q). The
    statistic is ``z = (I - E[I]) / sqrt(Var[I])``; where the variance or ``e'e`` is
    zero it is 0 (nothing to test).

    Parameters
    ----------
    e : (n,) array_like
        Least-squares residuals.
    q : (n, r) array_like
        Orthonormal basis of the design's column space.
    W : (n, n) sparse matrix
        Spatial weights (zero diagonal; row-standardised in the SAR units).
    alpha : float
        Level of the two-sided test.

    Returns
    -------
    TestResult
        Scalar z ``statistic``, two-sided ``pvalue``, ``df`` NaN.

    Examples
    --------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> rng = np.random.default_rng(0)
    >>> n = 400
    >>> W = sp.diags([np.full(n - 1, 0.5), np.full(n - 1, 0.5)], [-1, 1], format="csr")
    >>> q = np.full((n, 1), 1 / np.sqrt(n))
    >>> e = rng.normal(size=n); e -= e.mean()
    >>> bool(moran_test(e, q, W).reject)
    False
    >>> s = np.cumsum(rng.normal(size=n)); s -= s.mean()   # a random walk: correlated
    >>> bool(moran_test(s, q, W).reject)
    True
    """
    e = np.asarray(e, dtype=np.float64).ravel()
    q = np.asarray(q, dtype=np.float64)
    W = sp.csr_matrix(W)
    n, r = q.shape
    Wq, Wtq = W @ q, W.T @ q
    qWq = q.T @ Wq
    t1 = -np.trace(qWq)  # tr(MW)
    WW = W.multiply(W).sum()  # tr(WW')
    WWt = W.multiply(W.T).sum()  # tr(WW)
    tr_mwmwt = WW - np.sum(Wtq * Wtq) - np.sum(Wq * Wq) + np.sum(qWq * qWq)
    tr_mw2 = WWt - 2.0 * np.sum(Wtq * Wq) + np.sum(qWq * qWq.T)
    d = n - r
    mean = t1 / d
    var = (tr_mwmwt + tr_mw2 + t1 * t1) / (d * (d + 2)) - mean * mean
    ee = float(e @ e)
    z = 0.0
    if var > 0 and ee > 0:
        z = (float(e @ (W @ e)) / ee - mean) / np.sqrt(var)
    return z_test_statistic(np.float64(z), alpha=alpha)


def likelihood_ratio_test(loglik, loglik0, df, *, alpha=0.05) -> TestResult:
    """Likelihood-ratio test of a model against the model it nests.

    ``LR = 2 (loglik - loglik0)`` is referred to chi-square(`df`) (Wilks), upper tail;
    `df` is the number of parameters the null fixes (1 for rho = 0 in a SAR fit, whose
    null value lies inside the admissible interval, so the chi-square(1) reference holds).

    Examples
    --------
    >>> r = likelihood_ratio_test(-100.0, -104.0, 1)
    >>> float(r.statistic), bool(r.reject)
    (8.0, True)
    """
    stat = 2.0 * (float(loglik) - float(loglik0))
    return chi2_test(np.float64(stat), df, alpha=alpha)


def chow_test(rss_pooled, rss_a, rss_b, n_terms, n_a, n_b, *, alpha=0.05) -> TestResult:
    """Chow's F test that two point sets lie on one regression surface of `n_terms` terms.

    ``F = ((RSS_ab - RSS_a - RSS_b) / r) / ((RSS_a + RSS_b) / (n_a + n_b - 2r))`` with
    F(r, n_a + n_b - 2r) reference, upper tail (`RSS_ab`: the pooled fit). When the
    separate fits leave no residual or no degrees of freedom the test cannot reject: the
    statistic is 0 and the p-value 1.

    Examples
    --------
    >>> r = chow_test(12.0, 4.0, 4.0, 3, 50, 50, alpha=0.01)
    >>> round(float(r.statistic), 2), bool(r.reject)
    (15.67, True)
    """
    r = int(n_terms)
    df2 = n_a + n_b - 2 * r
    if df2 <= 0 or rss_a + rss_b <= 0:
        return TestResult(np.float64(0.0), np.float64(1.0), np.float64(max(df2, 0)),
                          np.bool_(False), float(alpha))
    f = ((rss_pooled - rss_a - rss_b) / r) / ((rss_a + rss_b) / df2)
    return f_test(np.float64(f), r, df2, alpha=alpha)
