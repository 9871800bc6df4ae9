"""Automatic scale of the jets: per point, the smallest radius of a ladder at which the
test that matters detects its quantity at the noise (the bandwidth reasoning of eq. 19-20).

A ladder of radii ``r_j = r_0 sqrt(2)^j`` (each rung doubles the expected number of
neighbours; ``r_0`` holds about :data:`BASE_NEIGHBORS` points at the cloud's density). On
seed points (one per cube of side ``r_0``) the jets are fitted rung by rung, smallest
first; a seed keeps the first rung at which its test statistic exceeds its null quantile
at ``alpha / J`` (normal, Bonferroni over the criterion's tails too, or simulated for a
calibrated criterion: :func:`null_quantile`) plus a power term, so that a seed with
nothing to detect picks a rung by chance with probability at most ``alpha``. The climb
stops at the first rung whose jet the chi-square test rejects (eq. 7: a wider
neighbourhood only adds model bias) or whose neighbourhood is one-sided (a border); a
seed where no rung detects anything takes the smallest rung (nothing to gain by
smoothing). A seed's detection counts only when a neighbouring seed's confirms it
(:func:`confirmed_detections`). Every point takes the smallest rung of the detecting
seeds within ``r_0``, else its nearest seed's, and the jets are fitted once more at
every point's radius.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..neighbors import CellIndex, knn_neighbors
from ..stats import normal_quantile, z_critical
from . import _jet_kernels as _jk
from ._jet_fit import MONGE_NAMES, _allocate, _fit_cells, _fit_into, _outs, _sensor, _to_fit
from ._jet_kernels import SKIPPED

#: Expected neighbours of the smallest rung: three times the 16 a degree-4 jet needs.
BASE_NEIGHBORS = 48
#: Rungs of the ladder (the largest holds 2^(J-1) times the smallest's neighbours).
SCALE_RUNGS = 7
#: Ratio of consecutive radii (twice the points per rung on a surface).
RUNG_FACTOR = math.sqrt(2.0)
#: Power at which the estimate must be detectable at the chosen rung.
SCALE_POWER = 0.8
#: Largest distance from a point to its neighbours' centroid, over the radius, of a
#: neighbourhood the scale may grow from: a half disc (a straight border) has 0.42, a
#: whole disc of 48 random points exceeds 0.25 with probability about 0.002.
ONE_SIDED = 0.35
#: Distance, in smallest radii, within which a seed's detection must be confirmed by
#: another's (:func:`confirmed_detections`): the seeds of the neighbouring cubes.
CONFIRM_REACH = 2.0
#: Rungs above its own at which a neighbouring seed's detection confirms a seed's: a
#: seed up to two smallest radii from a feature sees it once its radius has grown by
#: about that distance, a factor 2 (two rungs).
CONFIRM_RUNGS = 2


@dataclass(frozen=True)
class JetScaleCriterion:
    """What the automatic scale must detect.

    ``statistic(fit, fields)`` returns, per fitted point, a statistic that is one-sided
    standard normal under the null (nothing to detect) for each of ``tails`` tails; a rung
    is chosen when it exceeds ``z_{1 - alpha / (J tails)}``. With ``calibrate`` the
    statistic's null distribution is not taken as normal but simulated
    (:func:`null_quantile`): the rung is chosen when it exceeds the simulated
    ``1 - alpha / J`` quantile.
    """

    name: str
    statistic: object
    tails: int
    calibrate: bool = False


def _curvature_statistic(fit, fields):
    with np.errstate(invalid="ignore", divide="ignore"):
        z1 = np.abs(fields["k1"]) / fields["k1_sd"]
        z2 = np.abs(fields["k2"]) / fields["k2_sd"]
    return np.fmax(np.nan_to_num(z1, nan=0.0), np.nan_to_num(z2, nan=0.0))


#: Default criterion of :func:`lidarstat.features.jets`: a principal curvature is
#: significant (two two-sided tests: four tails).
CURVATURE_SCALE = JetScaleCriterion("curvature", _curvature_statistic, 4)


def radius_ladder(points, rungs=SCALE_RUNGS, base=BASE_NEIGHBORS, *, sample=None, rng=0):
    """Radii of the ladder: ``r_0 sqrt(2)^j``, ``r_0`` holding about `base` points.

    The density is read from the median distance ``d_8`` to the 8th nearest point (the
    point itself included) as ``8 / (pi d_8^2)`` points per unit area of surface; over
    every point, or over a seeded random subset of `sample` points (their neighbours
    among all the points).
    """
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[0]
    k = min(8, n)
    query = None
    if sample is not None and sample < n:
        query = np.sort(np.random.default_rng(rng).choice(n, size=int(sample), replace=False))
    nb = knn_neighbors(points, k, query=query)
    d = float(np.median(nb.distances[nb.indptr[1:] - 1]))
    r0 = d * math.sqrt(base / k)
    return r0 * RUNG_FACTOR ** np.arange(rungs)


def scale_seeds(points, cell):
    """One seed per occupied cube of side `cell` (cubes on multiples of `cell`): the
    point nearest the cube's centre (ties: the smallest x, then y, then z).

    Neither the cubes nor the seed depend on the order of the points or on which other
    points the cloud holds, so a tile with a buffer of neighbouring points has the whole
    area's seeds over its extent.
    """
    keys = np.floor(points / cell).astype(np.int64)
    d2 = (((points / cell) - keys - 0.5) ** 2).sum(axis=1)
    order = np.lexsort((points[:, 2], points[:, 1], points[:, 0], d2, keys[:, 2],
                        keys[:, 1], keys[:, 0]))
    k = keys[order]
    first = np.r_[True, np.any(k[1:] != k[:-1], axis=1)]
    return np.sort(order[first])


def fit_rungs(points, radii, rung, kw, block_size=131072, progress=None):
    """Jets of every point at radius ``radii[rung[i]]`` (rung -1: not fitted, SKIPPED).

    One fused radius pass per rung that has points, over the whole cloud; each block's
    fits go straight to their points' rows, so the memory is that of the result and one
    block.
    """
    n = points.shape[0]
    merged = _allocate(n)
    unfitted = rung < 0
    if unfitted.any():  # as the kernels mark a skipped point
        merged["status"][unfitted] = SKIPPED
        for key in ("jet", "monge", "frames", "stats", "mcof"):
            merged[key][unfitted] = np.nan
    slot = np.arange(n)
    todo = [j for j in range(len(radii)) if np.any(rung == j)]
    for j in todo:
        _fit_into(points, float(radii[j]), rung == j, kw, block_size, merged, slot)
        if progress is not None:
            progress(int(np.count_nonzero((rung >= 0) & (rung <= j))), n)
    return merged


def choose_rungs(points, radii, criterion, alpha, tests, kw, block_size=131072):
    """The rung of every point (see the module docstring).

    `tests(fit, rows)` returns the per-point fields of the fitted rows (Monge coefficients
    and their standard deviations at the cloud's noise) for `criterion`.

    Returns
    -------
    rung : (N,) ndarray of int
    seeds : (M,) ndarray of int
        The seed points.
    seed_stat : (M, J) ndarray
        The criterion's statistic of every seed at every rung it was fitted at (NaN
        above its chosen rung).
    """
    n = points.shape[0]
    seeds = scale_seeds(points, float(radii[0]))
    nr = len(radii)
    z = [null_quantile(criterion, j, alpha / nr, kw) + normal_quantile(SCALE_POWER)
         if criterion.calibrate else
         z_critical(alpha / (nr * criterion.tails), sides=1) + normal_quantile(SCALE_POWER)
         for j in range(nr)]
    chosen = np.full(seeds.size, -1, np.int64)
    stopped = np.zeros(seeds.size, bool)
    stat = np.full((seeds.size, nr), np.nan)
    for j in range(nr):
        open_ = (chosen < 0) & ~stopped
        if not open_.any():
            break
        rows = seeds[open_]
        mask = np.zeros(n, bool)
        mask[rows] = True
        slot = np.full(n, -1, np.int64)
        slot[rows] = np.arange(rows.size)
        out = _allocate(rows.size)
        _fit_into(points, float(radii[j]), mask, kw, block_size, out, slot)
        sub = _to_fit(out, kw["degree"], kw["monge_degree"], kw["weight"])
        fields = tests(sub, rows)
        s = np.asarray(criterion.statistic(sub, fields), dtype=np.float64)
        s = np.where(sub.status == 0, s, np.nan)
        stat[open_, j] = s
        # the jet must fit at the chosen radius (eq. 7): a rejected jet stops the climb
        # (a wider neighbourhood only adds model bias: a crease, the far side of a
        # feature); a seed whose jet is rejected before anything is detected keeps r_0
        # One-sided neighbourhoods (a border, an occlusion) stop it too: their jets
        # extrapolate, and the statistic's null distribution is that of whole ones.
        whole = sub.centroid <= ONE_SIDED
        fits = np.asarray(fields["chi2_pass"], dtype=bool) & whole
        hit = np.flatnonzero(open_)[(s > z[j]) & whole]
        chosen[hit] = j
        stopped[np.flatnonzero(open_)[~fits]] = True
    detected = confirmed_detections(points[seeds], chosen, CONFIRM_REACH * float(radii[0]))
    chosen[~detected] = 0
    return spread_rungs(points, seeds, chosen, detected, float(radii[0]), nr), seeds, stat


def confirmed_detections(seed_points, chosen, reach):
    """Seeds whose detection (``chosen >= 0``) another detecting seed within `reach`
    confirms by a rung at most :data:`CONFIRM_RUNGS` above its own.

    Each seed's test errs with probability up to ``alpha`` over the ladder, and a
    cloud has many seeds: a few detect by chance, most often at a small rung where the
    feature around them (if any) is detected at a larger one; as the smallest rung
    within reach wins (:func:`spread_rungs`), such a lone rung would cut a hole of two
    smallest radii into a line traced at the larger one. A feature the scale serves
    (a ridge line, longer than two radii) is seen by the seeds of neighbouring cubes
    at about the same rung; two neighbouring chance detections at about the same rung
    are rare (the square of a small probability).
    """
    from scipy.spatial import cKDTree

    det = np.flatnonzero(chosen >= 0)
    ok = np.zeros(chosen.size, bool)
    if det.size < 2:
        return ok
    pairs = cKDTree(seed_points[det]).query_pairs(reach, output_type="ndarray")
    if pairs.size:
        a, b = det[pairs[:, 0]], det[pairs[:, 1]]
        ok[a[chosen[b] <= chosen[a] + CONFIRM_RUNGS]] = True
        ok[b[chosen[a] <= chosen[b] + CONFIRM_RUNGS]] = True
    return ok


def spread_rungs(points, seeds, chosen, detected, reach, nr):
    """Every point's rung: the smallest rung of the detecting seeds within `reach` (the
    smallest radius: the point's own smallest neighbourhood), else its nearest seed's.

    The smallest rung wins so that the scale is homogeneous across a feature (a crest's
    axis detected at a small rung is not flanked by points at larger rungs whose
    crossings with it would be mixed-scale).
    """
    from scipy.spatial import cKDTree

    n = points.shape[0]
    rung = np.full(n, -1, np.int64)
    for j in range(nr):
        sel = seeds[detected & (chosen == j)]
        if sel.size == 0:
            continue
        open_ = np.flatnonzero(rung < 0)
        if open_.size == 0:
            break
        d, _ = cKDTree(points[sel]).query(points[open_], distance_upper_bound=reach)
        rung[open_[np.isfinite(d)]] = j
    rest = np.flatnonzero(rung < 0)
    if rest.size:
        _, near = cKDTree(points[seeds]).query(points[rest])
        rung[rest] = chosen[near]
    return rung


#: Null samples of a calibrated criterion per simulated rung, and the simulated rungs
#: (the smallest: the null of a ratio statistic depends on the neighbourhood's pattern,
#: which is the same at every rung up to scale and count; ``benchmarks/ridge_scale_null.py``
#: measures its quantiles at all seven).
NULL_SAMPLES = 6000
NULL_RUNGS = 2


def _unit_fields(fit, sigma):
    """Monge coefficients and their standard deviations at height noise `sigma`."""
    sd = sigma * np.sqrt(np.maximum(fit.monge_cofactor, 0.0))
    out = {}
    for j, name in enumerate(MONGE_NAMES):
        out[name] = fit.monge[:, j]
        out[f"{name}_sd"] = sd[:, j]
    return out


@functools.lru_cache(maxsize=64)
def _null_sample(criterion, rung, degree, weight, min_neighbors, samples=NULL_SAMPLES,
                 seed=20250):
    """Sorted simulated null values of ``criterion.statistic`` at rung `rung` of the ladder.

    The null is a plane with normal noise along its normal. The statistics the scale
    tests (ratios of a coefficient to its standard deviation) do not depend on the noise
    level or the plane's orientation there, only on the pattern of the neighbourhood: a
    jittered unit grid (each node moved uniformly within its cell) with the ladder of the
    data (:func:`radius_ladder` of the pattern itself). The statistic is read at
    `samples` query points on a square grid of step ``1.25 r`` (neighbourhoods that share
    few points), one patch of the pattern with one noise draw.
    """
    rng = np.random.default_rng(seed + rung)
    r = float(radius_ladder(_pattern(rng, 48))[rung])
    sigma = 1e-3
    m = int(math.ceil(math.sqrt(samples)))
    step = 1.25 * r
    side = int(math.ceil(m * step + 2 * r)) + 2
    pts = _pattern(rng, side)
    pts[:, 2] = rng.normal(0.0, sigma, pts.shape[0])
    grid = r + 1.0 + step * (np.arange(m) + 0.5)
    gx, gy = [a.ravel()[:samples] for a in np.meshgrid(grid, grid)]
    from scipy.spatial import cKDTree

    _, q = cKDTree(pts[:, :2]).query(np.c_[gx, gy])
    q = np.unique(q)
    mask = np.zeros(pts.shape[0], bool)
    mask[q] = True
    kw = dict(degree=degree, monge_degree=4, weight=weight, sensor=None,
              min_neighbors=min_neighbors, standard_errors=True)
    out = _fit_cells(CellIndex(pts, r), active=mask, block_size=131072, progress=None, **kw)
    fit = _to_fit({key: val[q] for key, val in out.items()}, degree, 4, weight)
    stat = np.asarray(criterion.statistic(fit, _unit_fields(fit, sigma)), dtype=np.float64)
    return np.sort(stat[fit.status == 0])


def _pattern(rng, side):
    """A jittered unit grid of `side` x `side` nodes from the origin (z = 0)."""
    g = np.arange(side, dtype=np.float64)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    return np.c_[x + rng.uniform(-0.5, 0.5, x.size), y + rng.uniform(-0.5, 0.5, y.size),
                 np.zeros(x.size)]


def null_quantile(criterion, rung, prob, kw):
    """The upper `prob` quantile of a criterion's statistic under the null at a rung.

    Empirical from the pooled :func:`_null_sample` of the ``NULL_RUNGS`` smallest rungs
    down to ``prob = 20 / samples``; below that the
    excesses over that quantile are taken as exponential (their mean fitted on the top
    20 samples), which is conservative for a statistic with a normal-like tail.
    """
    del rung  # the null does not depend on the rung (module docstring)
    s = np.sort(np.concatenate([
        _null_sample(criterion, j, int(kw["degree"]), str(kw["weight"]),
                     int(kw["min_neighbors"])) for j in range(NULL_RUNGS)]))
    m = s.size
    p0 = 20.0 / m
    if prob >= p0:
        return float(np.quantile(s, 1.0 - prob))
    t0 = float(s[m - 21])
    excess = float(np.mean(s[m - 20:] - t0))
    return t0 + excess * math.log(p0 / prob)
