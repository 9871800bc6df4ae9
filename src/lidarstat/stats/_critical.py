"""Critical values and the generic tests every method shares.

The local models and segmentations decide with a statistic against a reference
distribution; the quantiles and tail probabilities they need come from here, so that one
module holds every distributional choice of the package:

>>> round(z_critical(0.05), 4)             # two-sided normal test at 5 %
1.96
>>> round(chi2_critical(0.05, 2), 4)       # upper tail of chi2(2)
5.9915
>>> r = f_test(4.0, 2, 30, alpha=0.05)     # one F test, a TestResult
>>> bool(r.reject), round(float(r.pvalue), 4)
(True, 0.0288)
"""

from __future__ import annotations

import numpy as np

from . import _distributions as _d
from ._results import TestResult
from ._tests import _finish

__all__ = ["z_critical", "t_critical", "chi2_critical", "chi2_quantile", "normal_quantile",
           "f_pvalue", "chi2_pvalue", "normal_pvalue", "f_test", "chi2_test",
           "z_test_statistic"]


def _level(alpha, name="alpha"):
    a = np.asarray(alpha, dtype=np.float64)
    if np.any(~(a > 0)) or np.any(~(a < 1)):
        raise ValueError(f"{name} must lie in (0, 1); got {alpha!r}")
    return a


def z_critical(alpha, *, sides: int = 2):
    """Critical value of a normal test at level `alpha`.

    Parameters
    ----------
    alpha : float or ndarray
        Significance level, in (0, 1).
    sides : {1, 2}
        2 for ``|z| > c`` (``c = Phi^-1(1 - alpha/2)``), 1 for ``z > c``.

    Returns
    -------
    float or ndarray
    """
    a = _level(alpha)
    c = _d.norm_isf(a / sides)
    return float(c) if np.ndim(c) == 0 else c


def t_critical(alpha, df, *, sides: int = 2):
    """Critical value of Student's t test with `df` degrees of freedom at level `alpha`."""
    a = _level(alpha)
    from scipy import stats as _st

    c = _st.t.isf(a / sides, df)
    return float(c) if np.ndim(c) == 0 else c


def chi2_critical(alpha, df):
    """Upper critical value of chi2(`df`) at level `alpha` (reject when the statistic exceeds it)."""
    a = _level(alpha)
    c = _d.chi2_isf(a, df)
    return float(c) if np.ndim(c) == 0 else c


def chi2_quantile(q, df):
    """The `q` quantile of chi2(`df`) (robust scale estimates divide by it)."""
    c = _d.chi2_ppf(q, df)
    return float(c) if np.ndim(c) == 0 else c


def normal_quantile(q):
    """The `q` quantile of the standard normal (robust scale factors, power calculations)."""
    c = _d.norm_ppf(q)
    return float(c) if np.ndim(c) == 0 else c


def f_pvalue(statistic, df1, df2):
    """Upper-tail p-value of F(`df1`, `df2`) at `statistic` (vectorised)."""
    from scipy import stats as _st

    p = _st.f.sf(statistic, df1, df2)
    return float(p) if np.ndim(p) == 0 else p


def chi2_pvalue(statistic, df):
    """Upper-tail p-value of chi2(`df`) at `statistic` (vectorised; NaN where df is NaN)."""
    with np.errstate(invalid="ignore"):
        p = _d.chi2_sf(statistic, df)
    return float(p) if np.ndim(p) == 0 else p


def normal_pvalue(statistic, *, sides: int = 2):
    """p-value of a standard normal statistic: ``P(|Z| > |z|)`` (``sides=2``) or
    ``P(Z > z)`` (``sides=1``), vectorised."""
    z = np.asarray(statistic, dtype=np.float64)
    p = np.minimum(2.0 * _d.norm_sf(np.abs(z)), 1.0) if sides == 2 else _d.norm_sf(z)
    return float(p) if np.ndim(p) == 0 else p


def f_test(statistic, df1, df2, *, alpha) -> TestResult:
    """F test: reject where ``P(F(df1, df2) > statistic) < alpha``.

    Parameters
    ----------
    statistic : float or ndarray
        The F statistic (NaN where it could not be computed).
    df1, df2 : float or ndarray
        Numerator and denominator degrees of freedom.
    alpha : float
        Significance level.

    Returns
    -------
    TestResult
    """
    from scipy import stats as _st

    _level(alpha)
    stat = np.asarray(statistic, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        p = _st.f.sf(stat, df1, df2)
    return _finish(stat, p, np.asarray(df2, dtype=np.float64), alpha)


def chi2_test(statistic, df, *, alpha) -> TestResult:
    """Upper-tail chi-square test: reject where ``P(chi2(df) > statistic) < alpha``."""
    _level(alpha)
    stat = np.asarray(statistic, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        p = _d.chi2_sf(stat, df)
    return _finish(stat, p, np.asarray(df, dtype=np.float64), alpha)


def z_test_statistic(statistic, *, alpha, sides: int = 2) -> TestResult:
    """Normal test of a standardised statistic (two-sided by default)."""
    _level(alpha)
    stat = np.asarray(statistic, dtype=np.float64)
    tail = _d.norm_sf(np.abs(stat)) if sides == 2 else _d.norm_sf(stat)
    return _finish(stat, np.minimum(sides * tail, 1.0), np.nan, alpha)
