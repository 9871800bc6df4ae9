"""Sequential skewness and kurtosis, Gaussian density estimates and Hartigan's dip test (seed 004).

The sequential analysis of Crosilla et al. removes the largest value at every *cycle* and
recomputes skewness and kurtosis of what is left. After one sort the values left at cycle
``k`` are the ``n - k`` smallest, i.e. a prefix of the sorted array, so all cycles come from
one pass that adds the sorted values one at a time with the one-pass central-moment
updates of Terriberry (2007) / Pébay (2008). The values are first shifted by their median
and scaled by a robust spread, so UTM-sized elevations (4.5e6 m) lose no precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._shared._jit import njit
from .._shared.validation import check_scalar
from ..errors import InvalidParameterError, InvalidPointsError
from ._results import TestResult
from ._sort import sort_values

__all__ = ["SequentialMoments", "sequential_moments", "standard_moments", "DensityEstimate",
           "density_estimate", "dip_test", "moment_push", "moment_shape", "robust_frame"]


# --------------------------------------------------------------------------- kernels
@njit
def moment_push(y, i, mu, s2, s3, s4):  # pragma: no cover - compiled
    """Mean and central sums ``mu, s2, s3, s4`` after adding `y` as value number `i`
    (from 0): the one-pass updates of Pébay (2008), eq. 1.4-1.6."""
    n1 = float(i)
    cnt = n1 + 1.0
    delta = y - mu
    dn = delta / cnt
    dn2 = dn * dn
    term1 = delta * dn * n1
    mu += dn
    s4 += term1 * dn2 * (cnt * cnt - 3.0 * cnt + 3.0) + 6.0 * dn2 * s2 - 4.0 * dn * s3
    s3 += term1 * dn * (cnt - 2.0) - 3.0 * dn * s2
    s2 += term1
    return mu, s2, s3, s4


@njit
def moment_shape(cnt, mu, s2, s3, s4):  # pragma: no cover - compiled
    """Standard skewness and kurtosis of `cnt` values from their mean and central sums;
    NaN where ``var <= (1e-12 (|mean| + 1))^2`` (the values all equal)."""
    var = s2 / cnt
    t = 1e-12 * (abs(mu) + 1.0)
    if var > t * t:
        return np.sqrt(cnt) * s3 / s2 ** 1.5, cnt * s4 / (s2 * s2)
    return np.nan, np.nan


@njit
def _sequential_stats(xs, y, c, s, m, mean, std, skew, kurt, thr):  # pragma: no cover
    """Every cycle's mean, std, skewness, kurtosis and threshold, in one pass.

    ``y`` are the sorted values `xs` in the robust frame ``(xs - c) / s``; output row
    ``k`` (``k < m``) is the prefix of length ``n - k``. The arithmetic is that of the
    NumPy expressions it replaces (``var = m2 / cnt``, ``sqrt(cnt) m3 / m2^1.5``,
    ``cnt m4 / m2^2``, NaN where ``var <= (1e-12 (|mean| + 1))^2``), value for value.
    """
    n = y.shape[0]
    mu = 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    for i in range(n):
        mu, s2, s3, s4 = moment_push(y[i], i, mu, s2, s3, s4)
        k = n - 1 - i
        if k >= m:
            continue
        cnt = float(i) + 1.0
        mean[k] = mu * s + c
        std[k] = np.sqrt(s2 / cnt) * s
        thr[k] = xs[i]
        skew[k], kurt[k] = moment_shape(cnt, mu, s2, s3, s4)


def _as_values(values, name: str, func: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise InvalidParameterError(f"`{name}` of {func} must be one-dimensional; got shape "
                                    f"{arr.shape}")
    if arr.size == 0:
        raise InvalidPointsError(f"`{name}` of {func} is empty (0 values)")
    if not np.isfinite(arr.sum()):
        raise InvalidPointsError(f"`{name}` of {func} holds "
                                 f"{int((~np.isfinite(arr)).sum())} NaN or infinite values")
    return arr


def _presorted(sorted_values, n, func):
    """A caller's ``np.sort(values)`` as float64 (its length checked against `n`)."""
    xs = np.asarray(sorted_values, dtype=np.float64)
    if xs.shape != (n,):
        raise InvalidParameterError(f"`sorted_values` of {func} has shape {xs.shape}; "
                                    f"expected ({n},)")
    return xs


def robust_frame(x: np.ndarray) -> tuple[float, float]:
    """Centre (median) and a positive scale (IQR/1.349, else std, else 1) of sorted `x`."""
    n = x.size
    c = float(x[n // 2])
    q1, q3 = float(x[n // 4]), float(x[(3 * n) // 4])
    s = (q3 - q1) / 1.349
    if not s > 0:
        s = float(np.std(x - c))
    if not s > 0:
        s = 1.0
    return c, s


# --------------------------------------------------------------------------- moments
@dataclass(frozen=True)
class SequentialMoments:
    """Moments of the values left after removing the ``k`` largest, for every cycle ``k``.

    Attributes
    ----------
    order : (N,) ndarray of intp or None
        Indices sorting the input ascending (after cycle ``k`` the points ``order[:N - k]``
        are left), when asked for with ``return_order=True``.
    sorted_values : (N,) ndarray of float64
        The input sorted ascending.
    cycle : (M,) ndarray of int64
        Cycles ``0, 1, ..., M - 1`` (``M = N - min_points + 1``).
    remaining : (M,) ndarray of int64
        Values left at each cycle, ``N - cycle``.
    mean, std, skewness, kurtosis : (M,) ndarray of float64
        Mean, population standard deviation (eq. 3), standard skewness
        ``m3 / m2**1.5`` and standard (non-excess) kurtosis ``m4 / m2**2`` of the values
        left; NaN where the values left are all equal.
    threshold : (M,) ndarray of float64
        Largest value left at each cycle: a cut at cycle ``k`` keeps ``x <= threshold[k]``.
    """

    order: np.ndarray | None
    sorted_values: np.ndarray
    cycle: np.ndarray
    remaining: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    skewness: np.ndarray
    kurtosis: np.ndarray
    threshold: np.ndarray

    @property
    def n(self) -> int:
        """Number of input values."""
        return int(self.sorted_values.size)

    def kept(self, cycle: int) -> np.ndarray:
        """Indices of the values left after `cycle` removals (needs ``return_order=True``)."""
        if self.order is None:
            raise InvalidParameterError("kept() needs sequential_moments(..., return_order=True)")
        return self.order[: self.n - int(cycle)]


def sequential_moments(values, *, min_points: int = 4, return_order: bool = False,
                       sorted_values=None) -> SequentialMoments:
    """Skewness and kurtosis after removing the largest value at each cycle, all cycles at once.

    Parameters
    ----------
    values : (N,) array_like of float
        Elevations or intensities.
    min_points : int, optional
        Stop when this many values are left (at least 2).
    return_order : bool, optional
        Also return the argsort (slower than sorting values alone; a cut at cycle ``k`` is
        also ``values <= threshold[k]``, ties kept together).
    sorted_values : (N,) ndarray, optional
        ``np.sort(values)`` when the caller has it (a dip test of the same values sorted
        them): used instead of sorting again. Not with `return_order`.

    Returns
    -------
    SequentialMoments

    Notes
    -----
    Cost O(N log N) for the sort plus O(N) for one pass of the stable one-pass updates of
    the central sums (Pébay 2008, eq. 1.4-1.6) over the values sorted ascending and shifted
    by their median; the prefix of length ``n`` gives cycle ``N - n``. Standard moments
    are returned: the seed paper prints eq. (1) and (4) with a cube and a fourth root but
    states that a normal distribution has kurtosis 3, which holds only without the roots.

    References
    ----------
    Crosilla, F., Macorig, D., Sebastianutti, I., Visintini, D. (2011). Points classification
    by a sequential higher-order moments statistical analysis of LiDAR data. ISPRS Arch.
    XXXVIII-5/W12.
    Pébay, P. (2008). Formulas for robust, one-pass parallel computation of covariances and
    arbitrary-order statistical moments. Sandia report SAND2008-6212.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.r_[np.zeros(90), np.full(10, 5.0)] + np.linspace(0, 1e-3, 100)
    >>> sm = sequential_moments(x)
    >>> bool(sm.skewness[0] > 2), bool(abs(sm.skewness[10]) < 0.1)
    (True, True)
    """
    x = _as_values(values, "values", "sequential_moments")
    min_points = check_scalar(min_points, "min_points", func="sequential_moments", low=2,
                              closed="left", integer=True)
    n = x.size
    if n < min_points:
        raise InvalidPointsError(f"sequential_moments needs at least {min_points} values; got {n}")
    if return_order:
        order = np.argsort(x, kind="stable")
        xs = x[order]
    else:
        order = None
        xs = sort_values(x) if sorted_values is None else _presorted(sorted_values, n,
                                                                      "sequential_moments")
    c, s = robust_frame(xs)
    y = (xs - c) / s
    m = n - min_points + 1  # cycle k leaves the prefix of length n - k, k = 0 .. m - 1
    mean, std, sk, ku, thr = (np.empty(m) for _ in range(5))
    _sequential_stats(xs, y, float(c), float(s), m, mean, std, sk, ku, thr)
    return SequentialMoments(
        order=order, sorted_values=xs, cycle=np.arange(m, dtype=np.int64),
        remaining=np.arange(n, n - m, -1, dtype=np.int64),
        mean=mean, std=std, skewness=sk, kurtosis=ku, threshold=thr)


def standard_moments(values) -> tuple[float, float]:
    """Standard skewness ``m3 / m2**1.5`` and (non-excess) kurtosis ``m4 / m2**2``.

    Examples
    --------
    >>> sk, ku = standard_moments([1.0, 2.0, 3.0, 4.0])
    >>> round(sk, 6), round(ku, 4)
    (0.0, 1.64)
    """
    x = _as_values(values, "values", "standard_moments")
    d = x - np.median(x)
    d = d - d.mean()
    m2 = np.mean(d * d)
    if not m2 > 0:
        return float("nan"), float("nan")
    return float(np.mean(d ** 3) / m2 ** 1.5), float(np.mean(d ** 4) / m2 ** 2)


# --------------------------------------------------------------------------- density
@dataclass(frozen=True)
class DensityEstimate:
    """Gaussian kernel density estimate on a regular grid (eq. 5 of the seed paper).

    Attributes
    ----------
    grid : (G,) ndarray of float64
        Evaluation points.
    density : (G,) ndarray of float64
        Estimated density (integrates to 1 over the grid).
    bandwidth : float
        Kernel standard deviation ``h``.
    method : str
        How ``h`` was chosen (``'silverman'``, ``'scott'`` or ``'given'``).
    """

    grid: np.ndarray
    density: np.ndarray
    bandwidth: float
    method: str

    def modes(self) -> np.ndarray:
        """Grid values of the local maxima of the density."""
        d = self.density
        i = np.flatnonzero((d[1:-1] > d[:-2]) & (d[1:-1] >= d[2:])) + 1
        return self.grid[i]


def density_estimate(values, *, bandwidth="silverman", gridsize: int = 512,
                     sorted_values=None) -> DensityEstimate:
    """Gaussian kernel density of `values`, binned and convolved by FFT (O(N + G log G)).

    Parameters
    ----------
    values : (N,) array_like
    bandwidth : {'silverman', 'scott'} or float, optional
        Data-driven rule (Silverman's robust rule of thumb, ``0.9 min(sd, IQR/1.34) N^-1/5``,
        by default) or the paper's fixed ``h``.
    gridsize : int, optional
    sorted_values : (N,) ndarray, optional
        ``np.sort(values)`` when the caller has it: the quartiles and the range are read
        from it (the same numbers; the standard deviation and the binning keep the
        order of `values`).

    Returns
    -------
    DensityEstimate

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).normal(size=2000)
    >>> de = density_estimate(x)
    >>> bool(abs(de.grid[np.argmax(de.density)]) < 0.3)
    True
    """
    x = _as_values(values, "values", "density_estimate")
    gridsize = check_scalar(gridsize, "gridsize", func="density_estimate", low=16,
                            closed="left", integer=True)
    n = x.size
    sd = float(np.std(x))
    xs = x if sorted_values is None else _presorted(sorted_values, n, "density_estimate")
    q75, q25 = np.percentile(xs, [75, 25])
    spread = min(sd, (q75 - q25) / 1.349) if q75 > q25 else sd
    if isinstance(bandwidth, str):
        if bandwidth not in ("silverman", "scott"):
            raise InvalidParameterError("The 'bandwidth' parameter of density_estimate must be "
                                        f"'silverman', 'scott' or a float > 0. Got {bandwidth!r}")
        method = bandwidth
        h = (0.9 * spread if method == "silverman" else 1.06 * sd) * n ** -0.2
        if not h > 0:
            h = max(abs(float(x[0])) * 1e-9, 1e-9)
    else:
        method = "given"
        h = check_scalar(bandwidth, "bandwidth", func="density_estimate", low=0)
    lo, hi = ((float(x.min()), float(x.max())) if sorted_values is None
              else (float(xs[0]), float(xs[-1])))
    lo, hi = lo - 4 * h, hi + 4 * h
    grid = np.linspace(lo, hi, gridsize)
    step = grid[1] - grid[0]
    # linear binning
    pos = (x - lo) / step
    i0 = np.clip(np.floor(pos).astype(np.int64), 0, gridsize - 2)
    w1 = pos - i0
    counts = np.bincount(i0, 1 - w1, gridsize) + np.bincount(i0 + 1, w1, gridsize)
    m = 2 * gridsize
    k = np.fft.rfftfreq(m, d=step)
    kern = np.exp(-2.0 * (np.pi * k * h) ** 2)
    dens = np.fft.irfft(np.fft.rfft(counts, m) * kern, m)[:gridsize]
    dens = np.clip(dens, 0.0, None)
    total = dens.sum() * step
    dens = dens / total if total > 0 else dens
    return DensityEstimate(grid=grid, density=dens, bandwidth=float(h), method=method)


# --------------------------------------------------------------------------- dip test
def dip_test(values, *, alpha: float = 0.05, max_points: int = 20000, rng=0,
             dequantize: bool = True, sorted_values=None) -> TestResult:
    """Hartigan and Hartigan's dip test of unimodality (``diptest`` package).

    Parameters
    ----------
    values : (N,) array_like
    alpha : float, optional
        Level of the test; ``reject`` is True when the sample is significantly multimodal.
    max_points : int, optional
        Larger samples are tested on a seeded random subsample of this size (the dip
        statistic converges as ``N^-1/2``, so large samples would reject unimodality for
        differences no density plot shows; the subsample keeps the test about shape).
    rng : int or numpy.random.Generator, optional
        Seed of the subsample and of the dequantisation.
    dequantize : bool, optional
        Spread values tied by quantisation (integer intensities, centimetre elevations)
        uniformly over their quantisation step; ties otherwise make the empirical CDF a
        staircase the dip test reads as many modes.
    sorted_values : (N,) ndarray, optional
        ``np.sort(values)`` when the caller has it: the sort for the ties is skipped
        (samples of up to `max_points` values). The result is the same.

    Returns
    -------
    TestResult
        ``statistic`` is the dip (0 to 0.25), ``pvalue`` from the tabulated null of the
        uniform distribution (the least favourable unimodal one), ``df`` the sample size.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(1)
    >>> bool(dip_test(np.r_[g.normal(0, 1, 500), g.normal(6, 1, 500)]).reject)
    True
    """
    import diptest as _dt

    x = _as_values(values, "values", "dip_test")
    alpha = check_scalar(alpha, "alpha", func="dip_test", low=0, high=1)
    gen = np.random.default_rng(rng)
    xs = None  # x sorted, while it is the sample the statistic is taken of
    if x.size > max_points:
        x = gen.choice(x, size=max_points, replace=False)
    elif sorted_values is not None:
        xs = _presorted(sorted_values, x.size, "dip_test")
    if x.size < 4:
        return TestResult(statistic=np.float64(np.nan), pvalue=np.float64(np.nan), df=x.size,
                          reject=np.bool_(False), alpha=alpha)
    if dequantize:
        # ties and the smallest gap between distinct values from one sort: the gaps of
        # the sorted values are 0 between ties and the distinct values' gaps otherwise
        if xs is None:
            xs = sort_values(x)
        gaps = np.diff(xs)
        steps = gaps[gaps > 0]
        if steps.size < gaps.size and steps.size:
            q = float(np.min(steps))
            x = x + gen.uniform(-0.5 * q, 0.5 * q, size=x.size)
            xs = None  # the spread values: sorted again below
    # the statistic of the sorted sample
    dip, p = _dt.diptest(sort_values(x) if xs is None else xs, sort_x=False)
    return TestResult(statistic=np.float64(dip), pvalue=np.float64(p), df=x.size,
                      reject=np.bool_(p < alpha), alpha=alpha)
