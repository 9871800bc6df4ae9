"""Automatic choice of the separating cycle of a sequential skewness/kurtosis analysis.

Crosilla et al. pick the cycle by eye: for intensity "the maximum value of kurtosis, where a
peak value of skewness is also present" (their Figs. 5 and 14), for elevation "a local
flatness of the kurtosis" (Figs. 7, 11, 17). Both rules are made reproducible here on
curves smoothed over a window that grows with the sample, with a minimum cluster size on
each side of the cut; the evidence (candidates, tolerances, the rule that fired) is kept so
the report can show why a cycle was chosen.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared._jit import njit
from .._shared.validation import check_option
from ..errors import InvalidParameterError
from ..stats import SequentialMoments, moment_push, moment_shape, robust_frame

__all__ = ["CycleChoice", "ElevationRule", "choose_cycle", "skewness_balance_cycle",
           "symmetry_cycle"]


class ElevationRule(str, enum.Enum):
    """Rule choosing the cut of an elevation analysis (:func:`choose_cycle`).

    ``symmetry``: the fewest removals after which what is left is symmetric (skewness not
    significantly positive) and not platykurtic; ``plateau``: the paper's start of the
    kurtosis plateau.
    """

    SYMMETRY = "symmetry"
    PLATEAU = "plateau"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class CycleChoice:
    """The separating cycle and why it was chosen.

    Attributes
    ----------
    cycle : int or None
        Values removed before the cut (the removed ``cycle`` largest values form the upper
        cluster); None when no cycle separates two clusters.
    threshold : float
        Largest value kept: the lower cluster is ``x <= threshold``.
    rule : str
        ``'kurtosis-peak'``, ``'kurtosis-plateau'``, ``'skewness-balance'``, ``'given'`` or
        ``'none'``.
    evidence : dict
        Numbers behind the decision (smoothing window, candidates, tolerance).
    """

    cycle: int | None
    threshold: float
    rule: str
    evidence: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {"cycle": self.cycle, "threshold": self.threshold, "rule": self.rule,
                **{k: v for k, v in self.evidence.items()}}


@njit
def _add(s, comp, x):  # pragma: no cover - compiled
    """Neumaier-compensated ``s + x``: the new sum and the new running compensation."""
    t = s + x
    if abs(s) >= abs(x):
        comp += (s - t) + x
    else:
        comp += (x - t) + s
    return t, comp


@njit
def _window_sums(v, ok, h, num, den):  # pragma: no cover - compiled
    """Sums of `v` and counts of `ok` over ``[i - h, i + h]`` (clipped), for every i.

    Running sums with Neumaier compensation: O(n) instead of the O(n w) of a direct
    convolution, and as accurate (the error does not grow with n).
    """
    n = v.size
    s = 0.0
    comp = 0.0
    cnt = 0
    hi = -1  # last index added
    lo = 0  # first index still in the window
    for i in range(n):
        while hi < min(n - 1, i + h):
            hi += 1
            s, comp = _add(s, comp, v[hi])
            cnt += ok[hi]
        while lo < i - h:
            s, comp = _add(s, comp, -v[lo])
            cnt -= ok[lo]
            lo += 1
        num[i] = s + comp
        den[i] = cnt


def _smooth(y: np.ndarray, w: int) -> np.ndarray:
    """Centred moving average of odd width `w` (NaNs treated as missing), in O(n)."""
    if w <= 1:
        return y.copy()
    ok = np.isfinite(y)
    v = np.where(ok, y, 0.0)
    num = np.empty(y.size)
    den = np.empty(y.size, np.int64)
    _window_sums(v, ok.astype(np.int64), w // 2, num, den)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def _local_maxima(y: np.ndarray, w: int) -> np.ndarray:
    """Indices that are the maximum of their ``+-w`` window (plateaus give their first index)."""
    from scipy.ndimage import maximum_filter1d

    yy = np.where(np.isfinite(y), y, -np.inf)
    mx = maximum_filter1d(yy, size=2 * w + 1, mode="nearest")
    idx = np.flatnonzero((yy == mx) & np.isfinite(y))
    if idx.size:
        keep = np.r_[True, np.diff(idx) > 1]
        idx = idx[keep]
    return idx


def skewness_balance_cycle(sm: SequentialMoments) -> CycleChoice:
    """First cycle at which the skewness of what is left is <= 0 (Bartels & Wei 2006).

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.stats import sequential_moments
    >>> x = np.r_[np.linspace(-1, 1, 200), np.linspace(8, 9, 20)]
    >>> skewness_balance_cycle(sequential_moments(x)).cycle >= 20
    True
    """
    ok = np.flatnonzero(sm.skewness <= 0)
    k = int(ok[0]) if ok.size else int(sm.cycle[-1])
    return CycleChoice(cycle=k, threshold=float(sm.threshold[k]), rule="skewness-balance",
                       evidence={"skewness": float(sm.skewness[k])})


@renamed_parameters(min_cluster="min_points")
def choose_cycle(sm: SequentialMoments, category: str, *, min_points: int = 10,
                 smoothing: float = 0.01, cycle: int | None = None,
                 elevation_rule: ElevationRule | str = "plateau") -> CycleChoice:
    """Choose the separating cycle of a sequential moment analysis.

    Parameters
    ----------
    sm : SequentialMoments
        Curves of the category analysed.
    category : {'elevation', 'intensity'}
        Which of the paper's two rules to apply.
    min_points : int, optional
        Smallest cluster on either side of the cut.
    smoothing : float, optional
        Width of the moving average as a fraction of the number of values (at least 3
        cycles), so sampling noise of the curves does not create peaks or plateaus.
    cycle : int, optional
        Use this cycle (the ``--cycle`` override).
    elevation_rule : ElevationRule or {'plateau', 'symmetry'}, optional
        The paper's plateau rule, or the first cycle at which the skewness of what is left
        is no longer significantly positive (``sk <= 1.645 sqrt(6 / n_k)``, a one-sided
        test of symmetry at 5 %): the fewest removals leaving a symmetric ground cluster.

    Returns
    -------
    CycleChoice

    Notes
    -----
    *Intensity* (kurtosis peak): candidates are local maxima of the smoothed kurtosis over
    cycles that leave at least `min_points` values on each side; a candidate is accepted
    when the smoothed skewness also has a local maximum within the smoothing window, and
    the most prominent accepted candidate (kurtosis above the curve's median) is chosen.

    *Elevation* (start of the kurtosis plateau): the first cycle ``k`` after which the
    smoothed kurtosis stays within ``tol`` of ``ku[k]`` while the next half of the values
    left are removed, with ``tol = max(3 sqrt(24 / n_k), 0.05 range(ku))`` (``sqrt(24/n)``
    is the standard error of the kurtosis of a normal sample of size ``n``) and the
    skewness not significantly positive (``sk <= 1.645 sqrt(6 / n_k)``) or already flat.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.stats import sequential_moments
    >>> g = np.random.default_rng(0)
    >>> z = np.r_[g.normal(0, 0.2, 3000), g.normal(8, 0.5, 600)]
    >>> ch = choose_cycle(sequential_moments(z), "elevation")
    >>> 550 <= ch.cycle <= 700
    True
    """
    if category not in ("elevation", "intensity"):
        raise InvalidParameterError("The 'category' parameter of choose_cycle must be "
                                    f"'elevation' or 'intensity'. Got {category!r} instead.")
    check_option(elevation_rule, "elevation_rule", [r.value for r in ElevationRule],
                 func="choose_cycle")
    m = sm.cycle.size
    if cycle is not None:
        k = int(np.clip(int(cycle), 0, m - 1))
        return CycleChoice(cycle=k, threshold=float(sm.threshold[k]), rule="given",
                           evidence={"requested": int(cycle)})
    n = sm.n
    w = max(3, int(smoothing * n) | 1)
    lo, hi = max(min_points, 1), m - 1 - min_points
    if hi <= lo:
        return CycleChoice(None, float(sm.threshold[0]), "none", {"reason": "too few values"})
    ev = {"window": w, "min_points": min_points}
    if category == "intensity":
        ku = _smooth(sm.kurtosis, w)
        sk = _smooth(sm.skewness, w)
        cand = _local_maxima(ku, w)
        cand = cand[(cand >= lo) & (cand <= hi)]
        sk_max = _local_maxima(sk, w)
        base = float(np.nanmedian(ku))
        good = [int(c) for c in cand
                if sk_max.size and np.min(np.abs(sk_max - c)) <= w and ku[c] > base]
        ev.update(candidates=[int(c) for c in cand[:20]], accepted=good[:20])
        if not good:
            return CycleChoice(None, float(sm.threshold[0]), "none",
                               {**ev, "reason": "no kurtosis peak with a skewness peak"})
        k = max(good, key=lambda c: ku[c])
        return CycleChoice(k, float(sm.threshold[k]), "kurtosis-peak",
                           {**ev, "kurtosis": float(sm.kurtosis[k]),
                            "skewness": float(sm.skewness[k])})
    if elevation_rule == "symmetry":
        good = _symmetric(sm.skewness, sm.kurtosis, sm.remaining.astype(float))
        if good[0]:
            return CycleChoice(None, float(sm.threshold[0]), "none",
                               {**ev, "reason": "symmetric and not platykurtic at cycle 0",
                                "skewness": float(sm.skewness[0]),
                                "kurtosis": float(sm.kurtosis[0])})
        ok = np.flatnonzero(good[lo:hi + 1])
        k = int(ok[0]) + lo if ok.size else hi
        return CycleChoice(k, float(sm.threshold[k]), "symmetry",
                           {**ev, "skewness": float(sm.skewness[k]),
                            "kurtosis": float(sm.kurtosis[k])})
    # elevation: plateau start
    ku = _smooth(sm.kurtosis, w)
    rng = float(np.nanmax(ku[lo:hi + 1]) - np.nanmin(ku[lo:hi + 1]))
    rem = sm.remaining.astype(float)
    tol = np.maximum(3.0 * np.sqrt(24.0 / rem), 0.05 * rng)
    sk_ok = sm.skewness <= 1.645 * np.sqrt(6.0 / rem)
    # for each candidate k: range of ku over [k, k + rem_k / 2]
    kk = np.where(np.isfinite(ku), ku, np.nanmedian(ku))
    chosen = None
    # test candidates on a coarse grid first, then refine linearly inside the first hit
    for k in range(lo, hi + 1, max(1, w // 2)):
        end = min(hi, k + int(rem[k] // 2))
        seg = kk[k:end + 1]
        if seg.size < 2:
            break
        if seg.max() - seg.min() <= tol[k] and sk_ok[k]:
            chosen = k
            break
    if chosen is None:
        return CycleChoice(None, float(sm.threshold[0]), "none",
                           {**ev, "reason": "kurtosis never flattens",
                            "kurtosis_range": rng})
    start = max(lo, chosen - max(1, w // 2) + 1)
    for k in range(start, chosen + 1):
        end = min(hi, k + int(rem[k] // 2))
        seg = kk[k:end + 1]
        if seg.max() - seg.min() <= tol[k] and sk_ok[k]:
            chosen = k
            break
    return CycleChoice(chosen, float(sm.threshold[chosen]), "kurtosis-plateau",
                       {**ev, "tolerance": float(tol[chosen]), "kurtosis_range": rng,
                        "kurtosis": float(sm.kurtosis[chosen]),
                        "skewness": float(sm.skewness[chosen])})


#: One-sided 5 % normal quantile of the symmetry rule's tests of skewness and kurtosis.
_Z_SYMMETRY = 1.645


def _symmetric(sk, ku, rem):
    """The symmetry rule's test of the values left (`rem` of them, float): skewness not
    significantly positive, kurtosis not significantly below 3 (False where NaN)."""
    return ((sk <= _Z_SYMMETRY * np.sqrt(6.0 / rem))
            & (ku >= 3.0 - _Z_SYMMETRY * np.sqrt(24.0 / rem)))


@njit
def _symmetric_scan(xs, c, s, lo, hi, z, at, sk_at, ku_at):  # pragma: no cover - compiled
    """``(k, skewness, kurtosis)`` of the symmetry rule on sorted `xs` (robust frame `c`,
    `s`): ``k = -1`` when cycle 0 passes, else the first cycle of ``[lo, hi]`` that passes
    (``hi`` when none does). The running sums of every prefix are kept in one forward
    pass (:func:`~lidarstat.stats.moment_push`, as the sequential moments add
    them), and the cycles are tested from ``lo`` on until one passes: the skewness and
    kurtosis of the cycles past the cut are never formed. The test is
    :func:`_symmetric`'s, operation for operation. The skewness and kurtosis of the
    cycles `at` go to `sk_at`, `ku_at` (the curves a record keeps)."""
    n = xs.shape[0]
    sums = np.empty((n, 4))
    mu = 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    for i in range(n):
        mu, s2, s3, s4 = moment_push((xs[i] - c) / s, i, mu, s2, s3, s4)
        sums[i, 0] = mu
        sums[i, 1] = s2
        sums[i, 2] = s3
        sums[i, 3] = s4
    for j in range(at.size):
        i = n - 1 - at[j]
        sk_at[j], ku_at[j] = moment_shape(float(i) + 1.0, sums[i, 0], sums[i, 1],
                                          sums[i, 2], sums[i, 3])
    k = 0
    while True:
        i = n - 1 - k
        sk, ku = moment_shape(float(i) + 1.0, sums[i, 0], sums[i, 1], sums[i, 2],
                              sums[i, 3])
        rem = float(n - k)
        if sk <= z * np.sqrt(6.0 / rem) and ku >= 3.0 - z * np.sqrt(24.0 / rem):
            return (-1 if k == 0 else k), sk, ku
        if k >= hi:
            return k, sk, ku
        k = lo if k < lo else k + 1


def symmetry_cycle(sorted_values, *, min_points: int = 10, smoothing: float = 0.01,
                   curve_step: int = 0) -> tuple[CycleChoice, dict | None]:
    """The symmetry rule's choice on values sorted ascending, without the whole curves.

    The same :class:`CycleChoice` as ``choose_cycle(sequential_moments(values,
    min_points=max(2, min(4, n))), "elevation", min_points=min_points,
    smoothing=smoothing, elevation_rule="symmetry")``, for a caller that needs the cut
    and not the curves of every cycle: the moments are formed only for the cycles up to
    the one chosen, and with ``curve_step > 0`` for every `curve_step`-th cycle, whose
    ``cycle``, ``skewness``, ``kurtosis``, ``threshold`` and ``remaining`` are returned
    as the second item (the curves sliced ``[::curve_step]``; None without).

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.stats import sequential_moments
    >>> g = np.random.default_rng(0)
    >>> z = np.sort(np.r_[g.normal(0, 0.2, 3000), g.normal(8, 0.5, 600)])
    >>> a, _ = symmetry_cycle(z)
    >>> b = choose_cycle(sequential_moments(z), "elevation", elevation_rule="symmetry")
    >>> a == b
    True
    """
    xs = sorted_values
    n = xs.size
    m = n - max(2, min(4, n)) + 1
    at = np.arange(0, m, curve_step) if curve_step > 0 else np.empty(0, np.int64)
    sk_at, ku_at = np.empty(at.size), np.empty(at.size)
    w = max(3, int(smoothing * n) | 1)
    lo, hi = max(min_points, 1), m - 1 - min_points
    c, s = robust_frame(xs)
    k, sk, ku = _symmetric_scan(xs, float(c), float(s), lo, hi, _Z_SYMMETRY, at, sk_at,
                                ku_at)
    curves = None if curve_step <= 0 else {
        "cycle": at, "skewness": sk_at, "kurtosis": ku_at, "threshold": xs[n - 1 - at],
        "remaining": n - at}
    if hi <= lo:
        return CycleChoice(None, float(xs[n - 1]), "none", {"reason": "too few values"}), curves
    ev = {"window": w, "min_points": min_points}
    if k < 0:
        return CycleChoice(None, float(xs[n - 1]), "none",
                           {**ev, "reason": "symmetric and not platykurtic at cycle 0",
                            "skewness": float(sk), "kurtosis": float(ku)}), curves
    return CycleChoice(int(k), float(xs[n - 1 - k]), "symmetry",
                       {**ev, "skewness": float(sk), "kurtosis": float(ku)}), curves
