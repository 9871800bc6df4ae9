"""Roads: the intensity sub-cluster of the ground cluster (the paper's step 4, Figs. 13-15).

Crosilla et al. split the ground cluster by its intensity: the ground's intensity density
is bimodal where asphalt is darker than the land around it, and the sequential moments of
the intensity give the cut (their cycle 153, "a local maximum of kurtosis").  Three things
make that work on real ground clusters (measured on AHN3 tiles):

1. **Speckle.** One echo's intensity scatters about as much as road and land differ (AHN3
   Amsterdam: carriageway quartiles 18-34, the rest 40-76 per point).  Roads are areas, so
   each ground point takes the median intensity of its ground cell (cells of about
   ``points_per_cell`` ground points): quartiles 26-32 against 49-73 on the same area.
2. **One population.** The sub-cluster is analysed on the ground of the whole cloud, not per
   64 m window: a window holding a street and its pavements is often not significantly bimodal
   by the dip test (AHN3 Delft: p = 0.24-0.74 on windows that are 25-53 % street), while the
   whole ground cluster is.
3. **The cut.** The kurtosis peaks of the smoothed curve are coarse and, with the skewness
   peak the paper asks for, rarely coincide on real data (Delft: the kurtosis maximum at
   cycle 26,859 of 35,177, the skewness extremum 1,272 cycles away).  The default cut is
   the antimode of the paper's own density estimate (eq. 5) between its two most prominent
   modes, taken only when the dip test rejects unimodality; the sequential moments are
   still computed and reported, and ``rule='kurtosis-peak'`` gives the paper's rule.

The darker cluster is the road when it holds between ``min_fraction`` and ``max_fraction``
of the ground.
"""

from __future__ import annotations

import enum

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared._deprecate import renamed_parameters
from .._shared.validation import check_option
from ..stats import density_estimate, dip_test, sequential_moments
from . import _roads_kernels as _rk
from . import _surface_kernels as _sk
from ._cycle import CycleChoice, choose_cycle
from ._moments_result import MomentsStep, thin_curves
from ._surface import cell_keys, cell_median_values

__all__ = ["RoadRule", "cell_median", "road_cut", "road_points"]


class RoadRule(str, enum.Enum):
    """Cut of the ground's intensity into road and the rest (:func:`road_cut`).

    ``antimode``: the density minimum between its two main modes; ``kurtosis-peak``: the
    paper's kurtosis peak of the sequential moments.
    """

    ANTIMODE = "antimode"
    KURTOSIS_PEAK = "kurtosis-peak"

    def __str__(self) -> str:
        return self.value


def cell_median(xy, values, *, points_per_cell: float = 8.0, return_cells: bool = False):
    """Median of `values` over square cells holding about `points_per_cell` points each.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates.
    values : (N,) ndarray
        Per-point values (intensity).
    points_per_cell : float, optional
        Mean points per cell; the side is ``sqrt(points_per_cell * area / N)`` over the
        bounding box.

    return_cells : bool, optional
        Also return the median of every occupied cell (one value per cell).

    Returns
    -------
    (N,) ndarray of float64
        Each point's cell median.
    (C,) ndarray of float64
        With `return_cells`: one median per occupied cell. Test and cut these, not the
        per-point copies: the copies are ties, and the dip test reads a staircase of
        ties as many modes.

    Examples
    --------
    >>> import numpy as np
    >>> xy = np.array([[0.1, 0.1], [0.2, 0.3], [0.3, 0.2], [5.0, 5.0]])
    >>> cell_median(xy, np.array([1.0, 5.0, 3.0, 9.0]), points_per_cell=1).tolist()
    [3.0, 3.0, 3.0, 9.0]
    """
    xy = np.asarray(xy, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    n = v.size
    span = np.maximum(column_max(xy) - column_min(xy), 1e-9) if n else np.ones(2)
    cell = float(np.sqrt(points_per_cell * span[0] * span[1] / max(n, 1)))
    key = cell_keys(xy, cell)
    return cell_median_values(key, v, return_cells=return_cells)


def _cell_median_at(xy, rows, values, points_per_cell):
    """``cell_median(xy[rows], values, points_per_cell=..., return_cells=True)`` without
    the (M, 2) copy of the rows: their bounds and cell keys read in place."""
    key = np.empty(rows.size, np.int64)
    if rows.size:
        from numba import get_num_threads

        xy = np.ascontiguousarray(xy, dtype=np.float64)
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        blocks = min(get_num_threads(), 8)
        bounds = np.empty(4)
        _rk.row_bounds(xy, rows, blocks, bounds)
        span = np.maximum(bounds[2:] - bounds[:2], 1e-9)
        cell = float(np.sqrt(points_per_cell * span[0] * span[1] / rows.size))
        _sk.cell_keys_where(xy, rows, cell, blocks, key)
    return cell_median_values(key, values, return_cells=True)


def _peaks(x):
    """Local maxima of `x` and their prominences, as ``scipy.signal.find_peaks(x,
    prominence=0)`` gives them (a flat top's middle sample, rounded down; neither end).

    On the density's few hundred samples; ``scipy.signal`` would add half a second of
    imports (it loads ``scipy.stats``) to every ``moments`` process for this one call.
    """
    n = x.size
    start = np.flatnonzero(np.r_[True, x[1:] != x[:-1]])  # runs of equal samples
    end = np.r_[start[1:], n] - 1
    inner = (start > 0) & (end < n - 1)
    start, end = start[inner], end[inner]
    top = (x[start - 1] < x[start]) & (x[end + 1] < x[start])
    peaks = (start[top] + end[top]) // 2
    prominences = np.empty(peaks.size)
    for i, p in enumerate(peaks):  # the bases: lowest sample before a higher one each side
        higher = np.flatnonzero(x[:p] > x[p])
        left = x[(higher[-1] + 1 if higher.size else 0):p + 1].min()
        higher = np.flatnonzero(x[p + 1:] > x[p])
        right = x[p:(p + 1 + higher[0] if higher.size else n)].min()
        prominences[i] = x[p] - max(left, right)
    return peaks, prominences


def _antimode(de):
    """Grid value of the density minimum between its two most prominent modes, or None."""
    f = de.density
    peaks, prominences = _peaks(np.r_[0.0, f, 0.0])
    peaks = peaks - 1
    if peaks.size < 2:
        return None, {}
    top = np.sort(peaks[np.argsort(prominences)[-2:]])
    a, b = int(top[0]), int(top[1])
    j = a + int(np.argmin(f[a:b + 1]))
    return float(de.grid[j]), {"modes": [float(de.grid[a]), float(de.grid[b])],
                               "antimode": float(de.grid[j]),
                               "valley_ratio": float(f[j] / min(f[a], f[b]))}


@renamed_parameters(min_cluster="min_points")
def road_cut(values, *, alpha: float = 0.05, rule: RoadRule | str = "antimode",
             min_fraction: float = 0.02, max_fraction: float = 0.8, min_points: int = 10,
             smoothing: float = 0.01, bandwidth="silverman", rng=0):
    """Cut of the ground's (smoothed) intensity into a darker road cluster and the rest.

    Parameters
    ----------
    values : (N,) ndarray
        Smoothed intensity of the ground, one value per cell (:func:`cell_median` with
        ``return_cells=True``).
    alpha : float, optional
        Level of the dip test; without a rejection there is no sub-cluster.
    rule : RoadRule or {'antimode', 'kurtosis-peak'}, optional
        Cut at the density's antimode, or at the paper's kurtosis peak.
    min_fraction, max_fraction : float, optional
        Admissible share of the darker cluster in the ground.
    min_points, smoothing, bandwidth
        As in :func:`~lidarstat.classify.moments`.
    rng : int, optional
        Seed of the dip test's subsample and dequantisation.

    Returns
    -------
    choice : CycleChoice
        ``cycle`` = values above the cut (None when there is no road cluster),
        ``threshold`` = largest road value, evidence (dip, modes, kurtosis, skewness).
    sm : SequentialMoments
        The curves, for the report.
    de : DensityEstimate
        The density, for the report.
    dip : dict
        Dip statistic, p-value and decision.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(0)
    >>> v = np.r_[g.normal(30, 3, 3000), g.normal(60, 6, 7000)]
    >>> ch, *_ = road_cut(v)
    >>> bool(40 < ch.threshold < 50)
    True
    """
    rule = RoadRule(check_option(rule, "rule", [r.value for r in RoadRule], func="road_cut"))
    v = np.asarray(values, dtype=np.float64)
    t = dip_test(v, alpha=alpha, rng=rng)
    dip = {"dip": float(t.statistic), "pvalue": float(t.pvalue), "multimodal": bool(t.reject)}
    sm = sequential_moments(v, min_points=max(2, min(4, v.size)))
    de = density_estimate(v, bandwidth=bandwidth, gridsize=512)
    ev = {"dip_pvalue": dip["pvalue"], "rule_asked": rule.value}
    if not t.reject:
        return CycleChoice(None, float(sm.threshold[0]), "none",
                           {**ev, "reason": "ground intensity unimodal (dip test)"}), sm, de, dip
    n = v.size
    if rule is RoadRule.KURTOSIS_PEAK:
        ch = choose_cycle(sm, "intensity", min_points=min_points, smoothing=smoothing)
        if ch.cycle is None:
            return ch, sm, de, dip
        k, thr = int(ch.cycle), float(ch.threshold)
        ev.update(ch.evidence)
    else:
        thr, info = _antimode(de)
        ev.update(info)
        if thr is None:
            return CycleChoice(None, float(sm.threshold[0]), "none",
                               {**ev, "reason": "density has a single mode"}), sm, de, dip
        left = int(np.searchsorted(sm.sorted_values, thr, side="right"))
        k = min(n - left, sm.cycle.size - 1)
        thr = float(sm.threshold[k])
    frac = (n - k) / n
    ev.update(fraction=float(frac), kurtosis=float(sm.kurtosis[k]),
              skewness=float(sm.skewness[k]))
    if not min_fraction <= frac <= max_fraction:
        return CycleChoice(None, float(sm.threshold[0]), "none",
                           {**ev, "reason": f"darker cluster holds {100 * frac:.1f} % of "
                                            "the ground"}), sm, de, dip
    return CycleChoice(k, thr, rule.value, ev), sm, de, dip


def road_points(xy, intensity, ground, opts, *, road_rule, road_cell_points: float,
                first_step: int, threshold: float | None = None):
    """Roads: the darker intensity sub-cluster of the whole ground cluster.

    Each ground point takes the median intensity of its cell (about `road_cell_points`
    ground points per cell); one value per cell is tested and cut (:func:`road_cut`).

    Returns
    -------
    road : (N,) ndarray of bool
    step : MomentsStep or None
        The analysis, for the report (None without intensity or enough ground, or with a
        given `threshold`).
    """
    road = np.zeros(ground.size, bool)
    gi = np.flatnonzero(ground)
    if intensity is None or gi.size < 2 * opts.min_points:
        return road, None
    smoothed, cells = _cell_median_at(xy, gi, intensity[gi], road_cell_points)
    if threshold is not None:  # a cut decided for a whole area (a catalogue's tiles)
        road[gi[smoothed <= threshold]] = True
        return road, None
    ch, sm, de, dips = road_cut(cells, alpha=opts.alpha, rule=road_rule,
                                min_points=opts.min_points, smoothing=opts.smoothing,
                                bandwidth=opts.bandwidth, rng=opts.seed)
    step = MomentsStep(window=-1, step=first_step, population="ground cluster (cell medians)",
                       category="intensity", n=int(cells.size), dip={"intensity": dips},
                       choice=ch, curves=thin_curves(sm), density=de)
    if ch.cycle is not None:
        road[gi[smoothed <= ch.threshold]] = True
    return road, step
