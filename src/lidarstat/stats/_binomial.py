"""Exact binomial test of a share (e.g. the share of non-last returns in a patch)."""

from __future__ import annotations

import numpy as np

from . import _distributions as _d
from ._critical import _level
from ._results import TestResult
from ._tests import _finish

__all__ = ["binomial_test"]


def binomial_test(successes, trials, p0, *, alpha) -> TestResult:
    """Upper-tail exact binomial test of ``H0: p <= p0`` (vectorised).

    The statistic is the observed share ``successes / trials``; the p-value is
    ``P(X >= successes)`` for ``X ~ Binomial(trials, p0)``; NaN where ``trials == 0``.

    >>> r = binomial_test(9, 10, 0.3, alpha=0.01)
    >>> bool(r.reject), round(float(r.pvalue), 6)
    (True, 0.000144)
    """
    _level(alpha)
    k = np.asarray(successes, dtype=np.float64)
    n = np.asarray(trials, dtype=np.float64)
    if not 0.0 <= float(p0) <= 1.0:
        raise ValueError(f"p0 must lie in [0, 1]; got {p0!r}")
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(n > 0, k / n, np.nan)
        p = np.where(n > 0, _d.binom_sf(k - 1, n, p0), np.nan)
    return _finish(share, p, n, alpha)
