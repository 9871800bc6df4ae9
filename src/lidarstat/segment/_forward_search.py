"""Forward Search for a regression model (Atkinson and Riani 2000), unitary or block.

Used by the SAR segmentation (seed 002, section 3) on the transformed heights
``y = (I - rho W) z`` with rho held at its raw-cluster ML value, so that every step is a
rank-one update of an ordinary least-squares fit.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared.validation import check_option, check_scalar
from ..errors import InvalidParameterError
from ..stats import deletion_residual_envelope, f_pvalue, truncated_normal_variance
from . import _forward_search_kernels as _k


class StopRule(str, enum.Enum):
    """When the Forward Search stops (``stop``; CLI ``--fs-stop``)."""

    #: At the smaller of the two sizes below.
    BOTH = "both"
    #: At the first step whose F test of ``theta(m) = theta(m0)`` rejects (the paper's rule).
    F = "f"
    #: At the size m* found by superimposing deletion-residual envelopes.
    RESIDUAL = "residual"

    def __str__(self) -> str:
        return self.value


STOP_RULES = tuple(m.value for m in StopRule)


@dataclass(frozen=True)
class ForwardSearchResult:
    """Outcome of :func:`forward_search`.

    Attributes
    ----------
    accepted : (n,) ndarray of bool
        Initial subset plus the points added before the search stopped.
    m0 : int
        Size of the initial subset (the raw cluster, n_s).
    m : int
        Size of the final subset.
    order : (n - m0,) ndarray of int64
        Points in the order they would enter if the search ran to the end.
    msize : (T,) ndarray
        Subset size after each step.
    rmin : (T,) ndarray
        Smallest deletion residual outside the subset at the start of each step, rescaled
        for the truncation of the subset variance (consistency factor for a subset of m
        of the m* good observations, Riani and Atkinson 2007).
    envelope : (T,) ndarray
        Its ``1 - envelope_alpha`` envelope for m* observations: the quantile of the
        (m+1)-th order statistic of m* absolute normal deviates, ``Phi^-1((1 + B)/2)``,
        ``B ~ Beta(m + 1, m* - m)`` (NaN for m >= m*).
    fstat, fpvalue, frank : (T,) ndarray
        F statistic of ``theta(m) - theta(m0)`` with the covariance of the difference
        (``sigma^2 (P0 - P_m)``, nested least squares) divided by its rank, its p-value
        from F(rank, m0 - r), and the rank.
    fpaper : (T,) ndarray
        The statistic as printed in the paper, ``d' A_m'A_m d / (r s0^2)``.
    stop_step : int
        Step at which the search stopped (-1: ran to the end).
    stop_reason : str
        'f', 'residual' or 'exhausted'.
    theta : (r,) ndarray
        Least-squares coefficients on the accepted subset.
    """

    accepted: np.ndarray
    m0: int
    m: int
    order: np.ndarray
    msize: np.ndarray
    rmin: np.ndarray
    envelope: np.ndarray
    fstat: np.ndarray
    fpvalue: np.ndarray
    frank: np.ndarray
    fpaper: np.ndarray
    stop_step: int
    stop_reason: str
    theta: np.ndarray


def _first_signal(rmin, m_before, n, alpha, persistence):
    """First step whose truncation-corrected deletion residual leaves the envelope for n
    observations for `persistence` consecutive steps (steps with m < n only); -1: none."""
    sel = np.flatnonzero(m_before < n)
    if sel.size == 0:
        return -1
    mb = m_before[sel]
    rc = rmin[sel] * np.sqrt(truncated_normal_variance(mb / n))
    exceed = (rc > deletion_residual_envelope(mb, n, alpha)).astype(int)
    if persistence > 1:
        run = np.convolve(exceed, np.ones(persistence, int), "full")[:exceed.size]
        hits = np.flatnonzero(run >= persistence) - (persistence - 1)
        if exceed[-1]:  # the last entry (m = n - 1) cannot be followed: it alone signals
            hits = np.r_[hits, exceed.size - 1]
    else:
        hits = np.flatnonzero(exceed)
    return int(sel[hits[0]]) if hits.size else -1


def _resuperimpose(rmin, m_before, m0, n, alpha, persistence):
    """Size m* of the subset of good observations (Riani, Atkinson and Cerioli 2009).

    With envelopes for all n observations, find the first signal at m'. Then
    superimpose envelopes for n' = m', m' + 1, ... observations: m* is the largest n'
    for which the monitored curve (for m < n') stays inside the envelope for n'.
    Envelopes for all n assume that the search area is mostly the surface; when most of
    it is other surfaces or clutter, the first signal comes early and the superimposed
    envelopes recover the surface's true size.
    """
    t = _first_signal(rmin, m_before, n, alpha, persistence)
    if t < 0:
        return n
    lo = int(m_before[t])
    ok = lo
    # coarse scan upwards, then a fine scan in the last coarse interval
    stride = max(1, (n - lo) // 16)
    cand = lo
    while cand <= n:
        if _first_signal(rmin, m_before, cand, alpha, persistence) >= 0:
            break
        ok = cand
        cand += stride
    for cand in range(ok + 1, min(ok + stride, n + 1)):
        if _first_signal(rmin, m_before, cand, alpha, persistence) >= 0:
            break
        ok = cand
    return max(ok, m0)


@renamed_parameters(alpha_residual="envelope_alpha")
def forward_search(A, y, initial, *, block=1, alpha=0.01, envelope_alpha=0.001, stop="both",
                   persistence=2, max_steps=None, refresh=256):
    """Forward Search from an initial subset, monitoring the F test and deletion residuals.

    Parameters
    ----------
    A : (n, r) array_like
        Design matrix.
    y : (n,) array_like
        Response.
    initial : (n,) array_like of bool
        Initial subset (at least r + 1 points).
    block : int
        Points added per step (1: unitary Forward Search; >1: block Forward Search).
    alpha : float
        Level of the F test of ``theta(m) = theta(m0)`` (the paper's stopping rule).
    envelope_alpha : float
        Level of the deletion-residual envelope.
    stop : StopRule or {'both', 'f', 'residual'}
        Stop at the first step where the F test rejects, at the size m* found by
        superimposing deletion-residual envelopes (a signal: the curve leaves the
        envelope for `persistence` consecutive steps), or at the smaller of the two.
    persistence : int
        Consecutive exceedances of the envelope needed to stop.
    max_steps : int, optional
        Cap on the number of steps: the block size grows to ``ceil((n - m0) / max_steps)``.
    refresh : int
        Additions between exact re-inversions of the normal equations.

    Returns
    -------
    ForwardSearchResult

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.segment import forward_search
    >>> rng = np.random.default_rng(0)
    >>> x = rng.uniform(0, 10, 300)
    >>> y = 1 + 0.5 * x + rng.normal(0, 0.1, 300)
    >>> y[250:] += 3.0                      # a second population
    >>> init = np.zeros(300, bool); init[:50] = True
    >>> res = forward_search(np.c_[np.ones(300), x], y, init)
    >>> bool(res.accepted[:250].mean() > 0.97 and not res.accepted[250:].any())
    True
    """
    func = "forward_search"
    A = np.ascontiguousarray(A, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64).ravel()
    init = np.ascontiguousarray(initial, dtype=bool).ravel()
    n, r = A.shape
    if y.size != n or init.size != n:
        raise InvalidParameterError(f"{func}: `A` ({A.shape}), `y` ({y.size}) and `initial` "
                                    f"({init.size}) must have the same number of rows")
    stop = StopRule(check_option(stop, "stop", STOP_RULES, func=func)).value
    block = check_scalar(block, "block", func=func, low=1, closed="left", integer=True)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    envelope_alpha = check_scalar(envelope_alpha, "envelope_alpha", func=func, low=0.0,
                                  high=1.0)
    m0 = int(init.sum())
    if m0 < r + 1:
        raise InvalidParameterError(f"{func}: the initial subset has {m0} points; at least "
                                    f"{r + 1} are needed for {r} parameters")
    if max_steps is not None and n > m0:
        block = max(block, int(np.ceil((n - m0) / max_steps)))
    total = n - m0
    steps = int(np.ceil(total / block)) if total else 0
    fstat, fpaper, rmin, s2 = (np.zeros(steps) for _ in range(4))
    frank = np.zeros(steps, dtype=np.int64)
    msize = np.zeros(steps, dtype=np.int64)
    order = np.zeros(total, dtype=np.int64)
    if total:
        _k.forward_search(A, y, init, block, int(refresh), fstat, fpaper, frank, rmin, msize,
                          s2, order)
    m_before = np.concatenate(([m0], msize[:-1])) if steps else msize
    with np.errstate(invalid="ignore"):
        fp = np.asarray(f_pvalue(fstat, np.maximum(frank, 1), m0 - r), dtype=np.float64)
    fp[frank == 0] = 1.0
    f_rej = np.flatnonzero(fp < alpha)
    m_f = int(m_before[f_rej[0]]) if (stop in ("both", "f") and f_rej.size) else n
    m_res = n
    if stop in ("both", "residual") and steps:
        m_res = _resuperimpose(rmin, m_before, m0, n, envelope_alpha, persistence)
    m_star = min(m_f, m_res)
    if m_star >= n:
        stop_step, reason = -1, "exhausted"
    else:
        stop_step = int(np.searchsorted(m_before, m_star, side="left"))
        reason = "f" if m_f <= m_res else "residual"
    added = m_star - m0
    rmin_c = rmin * np.sqrt(truncated_normal_variance(m_before / max(m_star, 1)))
    envelope = deletion_residual_envelope(m_before, max(m_star, m0 + 1), envelope_alpha)
    accepted = init.copy()
    accepted[order[:added]] = True
    theta = np.linalg.lstsq(A[accepted], y[accepted], rcond=None)[0]
    return ForwardSearchResult(accepted, m0, int(accepted.sum()), order, msize, rmin_c,
                               envelope, fstat, fp, frank, fpaper, stop_step, reason, theta)
