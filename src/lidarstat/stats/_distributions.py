"""Tails and quantiles of the normal, chi-square and binomial distributions, from
``scipy.special``.

These are the functions ``scipy.stats.norm``, ``scipy.stats.chi2`` and
``scipy.stats.binom`` evaluate (``ndtr``, ``ndtri``, ``chdtrc``, ``chdtri``,
``gammaincinv``, the binomial tail as the regularised incomplete beta ``betainc``), with
the same answers outside the
distributions' domains (NaN for a degree of freedom that is not positive or a probability
outside [0, 1], the tail probability 1 below the support), without importing
``scipy.stats``: the commands that only need these start in a fraction of the time.
``scipy.special`` itself is imported at the first call, so a command whose tests run in
kernels (``lidarstat curvature`` at a fixed radius) does not load it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["binom_sf", "chi2_isf", "chi2_ppf", "chi2_sf", "norm_isf", "norm_ppf", "norm_sf"]


class _Special:
    """``scipy.special``, imported at the first attribute read."""

    def __getattr__(self, name):
        from scipy import special

        return getattr(special, name)


_sc = _Special()


def _out(v):
    return float(v) if np.ndim(v) == 0 else v


def _df(df):
    df = np.asarray(df, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.where(df > 0, df, np.nan)


def _prob(p):
    p = np.asarray(p, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.where((p >= 0) & (p <= 1), p, np.nan)


def chi2_sf(x, df):
    """``P(chi2(df) > x)``; 1 for ``x <= 0``, NaN where x or df is NaN or ``df <= 0``."""
    x = np.asarray(x, dtype=np.float64)
    df = _df(df)
    with np.errstate(invalid="ignore"):
        p = _sc.chdtrc(df, np.where(x > 0, x, 0.0))
        p = np.where(np.isnan(x) | np.isnan(df), np.nan, np.where(x > 0, p, 1.0))
    return _out(p)


def chi2_isf(q, df):
    """The x with ``P(chi2(df) > x) = q``."""
    with np.errstate(invalid="ignore"):
        return _out(_sc.chdtri(_df(df), _prob(q)))


def chi2_ppf(q, df):
    """The `q` quantile of chi2(`df`)."""
    with np.errstate(invalid="ignore"):
        return _out(2.0 * _sc.gammaincinv(_df(df) / 2.0, _prob(q)))


def norm_sf(x):
    """``P(Z > x)`` of the standard normal."""
    return _out(_sc.ndtr(-np.asarray(x, dtype=np.float64)))


def norm_isf(q):
    """The z with ``P(Z > z) = q``."""
    return _out(-_sc.ndtri(_prob(q)))


def norm_ppf(q):
    """The `q` quantile of the standard normal."""
    return _out(_sc.ndtri(_prob(q)))


def binom_sf(k, n, p):
    """``P(X > k)`` for ``X ~ Binomial(n, p)``: ``k`` is floored; 1 below the support, 0 at
    or above ``n``; NaN where an argument is NaN, ``n`` is not a non-negative integer or
    ``p`` lies outside [0, 1]. Inside the support it is ``I_p(k + 1, n - k)``, the
    regularised incomplete beta function.
    """
    k = np.floor(np.asarray(k, dtype=np.float64))
    n = np.asarray(n, dtype=np.float64)
    p = _prob(p)
    with np.errstate(invalid="ignore"):
        bad = ~((n >= 0) & (n == np.floor(n)) & np.isfinite(n)) | np.isnan(k) | np.isnan(p)
        inside = (k >= 0) & (k < n)
        tail = _sc.betainc(np.where(inside, k + 1.0, 1.0), np.where(inside, n - k, 1.0), p)
        out = np.where(inside, tail, np.where(k < 0, 1.0, 0.0))
    return _out(np.where(bad, np.nan, out))
