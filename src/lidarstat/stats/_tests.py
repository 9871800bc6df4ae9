"""Vectorised hypothesis tests used by the local models.

All functions take per-point arrays and return a :class:`TestResult`; NaN inputs give NaN
statistics and ``reject=False`` (the caller records *why* a point was not tested).
"""

from __future__ import annotations

import numpy as np

from ._distributions import chi2_sf, norm_sf
from ._results import TestResult


def _finish(stat, pval, df, alpha):
    stat = np.asarray(stat, dtype=np.float64)
    pval = np.asarray(pval, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        reject = np.where(np.isfinite(pval), pval < alpha, False)
    return TestResult(stat, pval, df, reject, float(alpha))


def variance_test_paper(q, n_used, sigma2, alpha):
    """Chi-square test of the variance factor as printed in Crosilla et al. (2009), eq. 7.

    ``T = sigma0^2 (p - 6) / sigma_ls^2 = v'Wv / sigma_ls^2`` against chi2(p - 6), upper
    tail. With tricube weights that are not inverse variances this reference
    distribution is wrong (see :func:`variance_test_satterthwaite`).

    Parameters
    ----------
    q : ndarray
        Weighted residual sums of squares v'Wv.
    n_used : ndarray
        Number of neighbours with positive weight, p.
    sigma2 : float
        A-priori measurement variance sigma_ls^2.
    alpha : float
        Significance level.
    """
    df = np.asarray(n_used, dtype=np.float64) - 6.0
    stat = np.asarray(q, dtype=np.float64) / sigma2
    with np.errstate(invalid="ignore"):
        df_ok = np.where(df > 0, df, np.nan)
        pval = chi2_sf(stat, df_ok)
    return _finish(stat, pval, df, alpha)


def variance_test_satterthwaite(q, trace_b, trace_b2, sigma2, alpha):
    """Chi-square test of the weighted residual form with Satterthwaite's approximation.

    Under H0 (the quadric holds, independent noise of variance sigma^2) the weighted
    residual form is ``Q = e'We = eps' B eps`` with ``B = W - W X N^-1 X' W``, so
    ``E[Q] = sigma^2 tr(B)`` and ``Var[Q] = 2 sigma^4 tr(B^2)``. Matching the first two
    moments with ``c chi2(nu)`` gives ``c = tr(B^2)/tr(B)`` and
    ``nu = tr(B)^2 / tr(B^2)``; the statistic ``Q / (c sigma^2)`` is referred to
    chi2(nu), upper tail.

    Parameters
    ----------
    q, trace_b, trace_b2 : ndarray
        Q, tr(B) and tr(B^2) per point.
    sigma2 : float
        A-priori measurement variance.
    alpha : float
        Significance level.
    """
    q = np.asarray(q, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = trace_b2 / trace_b
        nu = trace_b * trace_b / trace_b2
        stat = q / (c * sigma2)
        nu_ok = np.where(nu > 0, nu, np.nan)
        pval = chi2_sf(stat, nu_ok)
    return _finish(stat, pval, nu, alpha)


def wald_test(estimate, covariance, alpha, *, pinv=False):
    """Wald (chi-square) test of ``E[estimate] = 0`` with a known covariance.

    ``T = x' C^-1 x`` against chi2(r), r = dimension; exact for Gaussian linear estimates
    with known covariance. With ``pinv=True`` a singular C is inverted by its
    pseudo-inverse and r is its numerical rank.

    Parameters
    ----------
    estimate : (M, r) ndarray
    covariance : (M, r, r) ndarray
    alpha : float
    """
    x = np.asarray(estimate, dtype=np.float64)
    c = np.asarray(covariance, dtype=np.float64)
    r = x.shape[1]
    good = np.isfinite(x).all(axis=1) & np.isfinite(c).all(axis=(1, 2))
    stat = np.full(x.shape[0], np.nan)
    df = np.full(x.shape[0], float(r))
    if good.any():
        xg, cg = x[good], c[good]
        if pinv:
            ci = np.linalg.pinv(cg, rcond=1e-10, hermitian=True)
            df[good] = np.linalg.matrix_rank(cg, rtol=1e-10, hermitian=True)
        else:
            with np.errstate(all="ignore"):
                ci = _safe_inv(cg)
        stat[good] = np.einsum("mi,mij,mj->m", xg, ci, xg)
    with np.errstate(invalid="ignore"):
        pval = chi2_sf(stat, np.where(df > 0, df, np.nan))
    return _finish(stat, pval, df, alpha)


def _safe_inv(c):
    out = np.full_like(c, np.nan)
    det_ok = np.abs(np.linalg.det(c)) > 0
    if det_ok.any():
        out[det_ok] = np.linalg.inv(c[det_ok])
    return out


def z_test(estimate, std, alpha):
    """Two-sided z test of ``E[estimate] = 0`` with known standard deviation `std`."""
    est = np.asarray(estimate, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = est / std
        pval = 2.0 * norm_sf(np.abs(z))
        pval = np.where(std > 0, pval, np.nan)
    return _finish(z, pval, np.inf, alpha)


def f_test_paper(estimate, cofactor, sigma0_sq, alpha):
    """Crosilla et al. (2009) eq. 17: ``x' Q^-1 x / (r sigma0^2)`` against F(r, inf).

    Uses the pseudo-inverse where Q is singular (it is, to first order, on a plane: the
    Gaussian curvature's gradient vanishes there), with r the numerical rank.
    """
    x = np.asarray(estimate, dtype=np.float64)
    res = wald_test(x, np.asarray(cofactor) * np.asarray(sigma0_sq)[:, None, None], 1.0,
                    pinv=True)
    df = np.asarray(res.df, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        stat = res.statistic / df
        pval = chi2_sf(res.statistic, np.where(df > 0, df, np.nan))  # F(r, inf) = chi2(r)/r
    return _finish(stat, pval, df, alpha)
