"""Choice of the local-plane bandwidth (seed 002, section 4): PRESS and penalised selectors.

The PRESS (leave-one-out error through the hat-matrix diagonal, Allen 1974) and the
penalised resubstitution errors of Haerdle (1990) are computed on the local planes of
:mod:`._plane_regression` over a geometric range of candidate bandwidths.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from .._shared._geometry import mean_spacing as _mean_spacing
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import radius_neighbors
from . import _plane_kernels as _k
from ._plane_regression import _run_kernel

__all__ = ["BandwidthCriterion", "BandwidthSelection", "select_plane_bandwidth"]


class BandwidthCriterion(str, enum.Enum):
    """Selector of :func:`select_plane_bandwidth` (``criterion``; CLI ``--criterion``).

    Each is a penalty Xi(u) applied to the mean resubstitution error (u = mean leverage
    of the points themselves), except 'press', the mean squared leave-one-out residual.
    """

    RICE = "rice"
    GCV = "gcv"
    PRESS = "press"

    def __str__(self) -> str:
        return self.value


#: Values of :class:`BandwidthCriterion`.
CRITERIA = tuple(m.value for m in BandwidthCriterion)


@dataclass(frozen=True)
class BandwidthSelection:
    """Outcome of :func:`select_plane_bandwidth`.

    Attributes
    ----------
    bandwidth : float
        The selected bandwidth (smallest score).
    candidates : (K,) ndarray
        Bandwidths tried.
    scores : (K,) ndarray
        Criterion per candidate (mean squared error scale).
    press : (K,) ndarray
        Plain PRESS / n per candidate (leave-one-out through the hat diagonal).
    criterion : str
        Selector used.
    """

    bandwidth: float
    candidates: np.ndarray
    scores: np.ndarray
    press: np.ndarray
    criterion: str


def select_plane_bandwidth(points, candidates=None, *, criterion="rice", trim=0.25,
                           sample=20000, min_neighbors=6, rng=None):
    """Choose the plane-regression bandwidth by PRESS or a penalised selector.

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates.
    candidates : array_like, optional
        Bandwidths to try. Default: 8 values from 1.5 to 8 times the mean point spacing.
    criterion : BandwidthCriterion or {'rice', 'gcv', 'press'}
        ``press``: ``n^-1 sum ((z_i - z0_i) / (1 - h_ii))^2`` (Allen 1974), the
        leave-one-out error without refitting. It "tends to overfit by selecting a
        bandwidth too small" (Haerdle 1990), so the default penalises the resubstitution
        error ``p = n^-1 sum (z_i - z0_i)^2`` with ``Xi(u)``, ``u`` the mean leverage:
        ``gcv``: ``(1 - u)^-2``; ``rice``: ``(1 - 2u)^-1`` (the strongest; infinite when
        ``u >= 1/2``, i.e. for bandwidths holding about two points or fewer).
    trim : float
        Fraction of the largest squared residuals left out of every mean (a trimmed,
        least-trimmed-squares-like loss): vegetation, walls and wires are not surfaces,
        and without trimming they, not the surfaces, set the bandwidth. 0: the plain
        criteria.
    sample : int
        Points used for the score (a seeded random subset of larger clouds).
    min_neighbors : int
        Fewest neighbours for a fit; candidates fitting under half the points score inf.
    rng : Generator or int, optional
        Seed of the subset.

    Returns
    -------
    BandwidthSelection

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.features import select_plane_bandwidth
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 20, (2000, 2))
    >>> z = np.sin(xy[:, 0] / 3) + rng.normal(0, 0.05, 2000)
    >>> sel = select_plane_bandwidth(np.c_[xy, z], [0.5, 1.0, 2.0, 4.0, 8.0])
    >>> sel.bandwidth in (1.0, 2.0)
    True
    """
    func = "select_plane_bandwidth"
    points = check_points(points, min_points=3)
    criterion = BandwidthCriterion(check_option(criterion, "criterion", CRITERIA,
                                                func=func)).value
    sample = check_scalar(sample, "sample", func=func, low=1, closed="left", integer=True)
    if candidates is None:
        s = _mean_spacing(points)
        candidates = s * np.geomspace(1.5, 8.0, 8)
    cand = np.sort(np.asarray(candidates, dtype=np.float64).ravel())
    if cand.size == 0 or not np.all(np.isfinite(cand)) or cand[0] <= 0:
        raise InvalidParameterError(f"The 'candidates' parameter of {func} must hold "
                                    f"positive bandwidths. Got {candidates!r} instead.")
    n = points.shape[0]
    gen = np.random.default_rng(rng)
    query = np.sort(gen.choice(n, sample, replace=False)) if n > sample else None
    nbh = radius_neighbors(points, float(cand[-1]), dim=2, query=query)
    scores = np.full(cand.size, np.inf)
    press = np.full(cand.size, np.inf)
    for k, b in enumerate(cand):
        _, _, st, status = _run_kernel(points, nbh, np.full(len(nbh), b), min_neighbors)
        ok = status == _k.STATUS_OK
        if ok.sum() < 0.5 * len(nbh):
            continue
        h = st[ok, 3]
        r = st[ok, 4]
        loo = (r / (1.0 - h)) ** 2
        keep = loo <= np.quantile(loo, 1.0 - trim) if trim > 0 else np.ones(loo.size, bool)
        u = float(h[keep].mean())
        p = float(np.mean(r[keep] ** 2))
        press[k] = float(np.mean(loo[keep]))
        if criterion == "press":
            scores[k] = press[k]
        elif criterion == "gcv":
            scores[k] = p / (1.0 - u) ** 2
        else:
            scores[k] = p / (1.0 - 2.0 * u) if u < 0.5 else np.inf
    if not np.isfinite(scores).any():
        raise InvalidParameterError(f"{func}: no candidate bandwidth fits planes at half of "
                                    f"the points (candidates {cand.tolist()})")
    best = int(np.argmin(scores))
    return BandwidthSelection(float(cand[best]), cand, scores, press, criterion)
