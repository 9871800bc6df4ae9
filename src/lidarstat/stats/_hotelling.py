"""Hotelling's T^2 test of a bivariate mean (the covariance method's boundary test).

For ``n`` points of a bivariate normal sample with mean ``mu``, sample mean ``c`` and
sample covariance ``S``, ``T2 = n (c - mu)' S^-1 (c - mu)`` and

    T2 (n - 2) / (2 (n - 1)) ~ F(2, n - 2)

under ``H0: mu = mu0`` (Johnson and Wichern 2002, the confidence region of a mean).

>>> r = hotelling_test(12.0, 50, alpha=0.01)
>>> bool(r.reject), round(float(r.pvalue), 5)
(True, 0.00521)
"""

from __future__ import annotations

import numpy as np

from ._critical import f_pvalue
from ._results import TestResult
from ._tests import _finish

__all__ = ["hotelling_pvalue", "hotelling_test"]


def hotelling_pvalue(t2, n):
    """Upper-tail p-value of a bivariate Hotelling T^2 of a mean of `n` points (vectorised;
    NaN where n <= 2)."""
    n = np.asarray(n, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.asarray(t2, dtype=np.float64) * (n - 2) / (2 * (n - 1))
        return f_pvalue(f, 2.0, np.where(n > 2, n - 2, np.nan))


def hotelling_test(t2, n, *, alpha) -> TestResult:
    """Hotelling's T^2 test of a bivariate mean at level `alpha`.

    Parameters
    ----------
    t2 : float or ndarray
        ``n (c - mu0)' S^-1 (c - mu0)``.
    n : int or ndarray
        Points behind each mean.
    alpha : float

    Returns
    -------
    TestResult
        ``df`` is the denominator degrees of freedom ``n - 2``.
    """
    n = np.asarray(n, dtype=np.float64)
    return _finish(t2, hotelling_pvalue(t2, n), n - 2, alpha)
