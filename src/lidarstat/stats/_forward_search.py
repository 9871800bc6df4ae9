"""Reference distributions of the Forward Search's deletion residuals (Atkinson and Riani 2000).

At step m the Forward Search monitors the smallest absolute deletion residual among the
points outside its subset of m. Under the model that is the (m+1)-th order statistic of n
absolute standard normals, once the residual scale, estimated on the m points nearest the
fit (a truncated sample), is corrected by the variance of the normal truncated to its
central fraction m/n (Riani, Atkinson and Cerioli 2009).
"""

from __future__ import annotations

import numpy as np
from scipy import special
from scipy import stats as _st

__all__ = ["deletion_residual_envelope", "truncated_normal_variance"]


def truncated_normal_variance(p):
    """Variance of a standard normal truncated to its central fraction `p` (vectorised).

    ``1 - 2 q phi(q) / p`` with ``q = Phi^-1((1 + p) / 2)``; the scale of a subset holding
    the fraction p of the points nearest the fit is divided by its square root.

    >>> round(float(truncated_normal_variance(0.5)), 4)
    0.1427
    """
    p = np.clip(np.asarray(p, dtype=np.float64), 1e-9, 1 - 1e-12)
    q = _st.norm.ppf((1 + p) / 2)
    return 1.0 - 2.0 * q * _st.norm.pdf(q) / p


def deletion_residual_envelope(m, n, alpha):
    """``1 - alpha`` quantile of the (m+1)-th smallest of n absolute standard normals.

    The order statistic's probability integral transform is Beta(m + 1, n - m); its
    quantile mapped through the half-normal quantile is the envelope of the minimum
    deletion residual at subset size `m` (vectorised over m; NaN where m >= n).

    >>> env = deletion_residual_envelope(np.array([50, 90]), 100, 0.01)
    >>> bool(env[0] < env[1])
    True
    """
    m = np.asarray(m, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bq = special.betaincinv(m + 1, np.maximum(n - m, 1e-9), 1 - alpha)
    env = _st.norm.ppf((1 + bq) / 2)
    return np.where(m < n, env, np.nan)
