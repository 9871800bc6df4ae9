"""Tails and quantiles of the normal and chi-square distributions, from ``scipy.special``.

These are the functions ``scipy.stats.norm`` and ``scipy.stats.chi2`` evaluate (``ndtr``,
``ndtri``, ``chdtrc``, ``chdtri``, ``gammaincinv``), with the same answers outside the
distributions' domains (NaN for a degree of freedom that is not positive or a probability
outside [0, 1], the tail probability 1 below the support), without importing
``scipy.stats``: the commands that only need these start in a fraction of the time.
``scipy.special`` itself is imported at the first call, so a command whose tests run in
kernels (``lidarstat curvature`` at a fixed radius) does not load it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["chi2_isf", "chi2_ppf", "chi2_sf", "norm_isf", "norm_ppf", "norm_sf"]


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
