"""Unsupervised classification by sequential skewness and kurtosis (Crosilla et al., seed 004).

The procedure of the paper, per tile:

1. density estimates and dip tests of elevation and intensity; the category with the more
   clearly multimodal distribution (smaller dip-test p-value) is analysed first;
2. the sequential skewness/kurtosis analysis of that category gives a separating cycle:
   the values left form the first cluster, the removed ones stay unclassified;
3. the cluster is analysed by the complementary category and split again when that is
   multimodal;
4. steps 2-3 are repeated on the unclassified values until nothing separates.

Elevation is analysed as the residual from a plane fitted to the tile's ground cluster (the
paper uses raw elevations, which on a slope mixes terrain trend with objects; removing the
trend is what makes the method usable on the ISPRS samples, see docs/methods/moments.md).
Tiles are the progressive method of the paper's section 4: regular tiles split into four
while the ground cluster stays multimodal. Classes come from one ground surface built over
all tiles, so tile borders leave no seams.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError, LidarstatWarning
from ..stats import (DensityEstimate, SequentialMoments, density_estimate, dip_test,
                     sequential_moments)
from ._cycle import CycleChoice, choose_cycle, skewness_balance_cycle
from ._continuity import raised_patches
from ._outliers import low_outliers
from ._roads import cell_median, road_cut
from ._seams import interpolate_cuts
from ._surface import cell_keys, ground_surface

logger = logging.getLogger(__name__)

__all__ = ["MomentsStep", "MomentsClassification", "classify_moments", "ASPRS"]

#: ASPRS LAS classification codes written by ``moments``.
ASPRS = {"unclassified": 1, "ground": 2, "low_vegetation": 3, "medium_vegetation": 4,
         "high_vegetation": 5, "building": 6, "low_noise": 7, "road": 11}

_CURVE_SAMPLES = 600  # samples of each curve kept for the report


@dataclass(frozen=True)
class MomentsStep:
    """One analysed population: what was tested, the curves and the cycle chosen.

    Attributes
    ----------
    tile : int
        Tile index (-1 for the reconciliation pass over all tiles).
    step : int
        Step number inside the tile (1 = first category).
    population : str
        What was analysed (``'tile'``, ``'cluster 1'``, ``'unclassified'`` ...).
    category : str
        ``'elevation'`` (residual from the tile trend) or ``'intensity'``.
    n : int
        Values analysed.
    dip : dict
        Dip statistic and p-value per category tested at this step.
    choice : CycleChoice
        The separating cycle and its evidence.
    curves : dict
        Thinned ``cycle``, ``skewness``, ``kurtosis``, ``threshold`` arrays.
    density : DensityEstimate or None
        Density of the analysed category.
    """

    tile: int
    step: int
    population: str
    category: str
    n: int
    dip: dict
    choice: CycleChoice
    curves: dict
    density: DensityEstimate | None = None

    def to_dict(self) -> dict:
        """JSON-ready summary (curves excluded)."""
        return {"tile": self.tile, "step": self.step, "population": self.population,
                "category": self.category, "n": self.n, "dip": self.dip,
                "choice": self.choice.to_dict()}


@dataclass(frozen=True)
class MomentsClassification:
    """Result of :func:`classify_moments`.

    Attributes
    ----------
    classification : (N,) ndarray of uint8
        ASPRS codes (see :data:`ASPRS`).
    cluster_id : (N,) ndarray of int32
        Cluster each point was assigned to by the moment procedure (unique over tiles;
        0 = none).
    height : (N,) ndarray of float64
        Height above the ground surface model.
    ground : (N,) ndarray of bool
        Ground (classes 2 and 11).
    steps : list of MomentsStep
        Every analysis, in order, for the report.
    tiles : list of dict
        Tile boxes, sizes, split decisions and ground thresholds.
    params : dict
        Parameters used.
    cut : (N,) ndarray of float64
        Height cut of the last pass at each point (ground when ``height <= cut``): its
        tile's cut, interpolated between tiles unless ``cut_interpolation=False``; inf
        where a root tile found no cut, NaN for low noise.
    """

    classification: np.ndarray
    cluster_id: np.ndarray
    height: np.ndarray
    ground: np.ndarray
    steps: list = field(default_factory=list)
    tiles: list = field(default_factory=list)
    params: dict = field(default_factory=dict)
    cut: np.ndarray | None = None

    def to_fields(self) -> dict:
        """Per-point output fields: ``classification`` and ``cluster_id``."""
        return {"classification": self.classification, "cluster_id": self.cluster_id}

    def counts(self) -> dict:
        """Points per ASPRS class name."""
        names = {v: k for k, v in ASPRS.items()}
        codes, n = np.unique(self.classification, return_counts=True)
        return {names.get(int(c), str(int(c))): int(k) for c, k in zip(codes, n)}

    def summary(self) -> str:
        """A few lines for the terminal."""
        tot = max(1, self.classification.size)
        lines = [f"{self.classification.size} points, {len(self.tiles)} tiles, "
                 f"{len(self.steps)} moment analyses"]
        for name, k in self.counts().items():
            lines.append(f"  {name:<18}{k:>10}  {100 * k / tot:5.1f} %")
        return "\n".join(lines)


# --------------------------------------------------------------------------- helpers
def _thin(sm: SequentialMoments) -> dict:
    """About `_CURVE_SAMPLES` samples of each curve, as copies: a strided view would keep
    the whole curve (one value per point analysed) alive in the report records."""
    step = max(1, sm.cycle.size // _CURVE_SAMPLES)
    s = slice(None, None, step)
    return {name: getattr(sm, name)[s].copy()
            for name in ("cycle", "skewness", "kurtosis", "threshold", "remaining")}


@dataclass
class _Params:
    alpha: float
    min_cluster: int
    smoothing: float
    cycle: int | None
    bandwidth: object
    method: str
    max_steps: int
    elevation_rule: str = "symmetry"
    tile_size: float = 64.0
    min_tile_size: float = 16.0
    min_tile_points: int = 40
    ground_spread: float = 3.0


def _analyse(values, category, p: _Params, *, tile, step, population, dips, record=True):
    """Sequential moments of one population + the cycle choice; returns (choice, step)."""
    sm = sequential_moments(values, min_points=max(2, min(4, values.size)))
    if p.method == "skewness-balancing":
        ch = skewness_balance_cycle(sm)
    else:
        ch = choose_cycle(sm, category, min_cluster=p.min_cluster, smoothing=p.smoothing,
                          cycle=p.cycle if step == 1 else None,
                          elevation_rule=p.elevation_rule)
    rec = None
    if record:
        de = density_estimate(values, bandwidth=p.bandwidth, gridsize=256)
        rec = MomentsStep(tile=tile, step=step, population=population, category=category,
                          n=int(values.size), dip=dips, choice=ch, curves=_thin(sm),
                          density=de)
    return ch, rec


def _dips(cats: dict, alpha: float) -> dict:
    out = {}
    for name, v in cats.items():
        t = dip_test(v, alpha=alpha)
        out[name] = {"dip": float(t.statistic), "pvalue": float(t.pvalue),
                     "multimodal": bool(t.reject)}
    return out


# --------------------------------------------------------------------------- ground
def opening_surface(xy, z, *, window: float, cell: float = 1.0) -> np.ndarray:
    """Lower envelope of the cloud: grey opening of the lowest-point grid (per point).

    The opening (erosion then dilation with a ``window x window`` square) removes every
    object narrower than the window and keeps planar slopes exactly (the opening of a
    linear function is itself), so ``z - opening`` is a height above ground that is not
    biased by the terrain trend. Empty cells take the value of the nearest filled cell.
    """
    from scipy import ndimage as ndi

    ij = np.floor((xy - column_min(xy)) / cell).astype(np.int64)
    shape = tuple(column_max(ij) + 1)
    _check_raster(shape, cell)
    g = np.full(shape, np.inf)
    np.minimum.at(g, (ij[:, 0], ij[:, 1]), z)
    empty = ~np.isfinite(g)
    if empty.any():
        ind = ndi.distance_transform_edt(empty, return_distances=False, return_indices=True)
        g = g[tuple(ind)]
    k = max(3, int(round(window / cell)) | 1)
    op = ndi.grey_opening(g, size=(k, k))
    return op[ij[:, 0], ij[:, 1]]


#: Bytes a cell of the opening's raster costs at its peak (grid, nearest-filled indices,
#: opening and masks).
_RASTER_CELL_BYTES = 48


def _check_raster(shape, cell):
    """Refuse a ground raster larger than a quarter of the physical memory.

    The raster covers the cloud's bounding box, so its size follows the extent, not the
    points: two small areas 100 km apart made a 100,000 x 100,000 raster (75 GB).
    """
    from ..errors import InvalidPointsError
    from .._shared._memory import physical_memory

    cells = int(shape[0]) * int(shape[1])
    limit = (physical_memory() or 8 << 30) // 4
    if cells * _RASTER_CELL_BYTES > limit:
        raise InvalidPointsError(
            f"the cloud spans {shape[0] * cell:,.0f} x {shape[1] * cell:,.0f} coordinate "
            f"units: its ground raster of {cell:g}-unit cells would hold {cells:,} cells "
            f"({cells * _RASTER_CELL_BYTES / 1e9:,.1f} GB), more than a quarter of the "
            "memory; split the cloud into its separate areas, or check its units "
            "(--units, --scale)")


def _heights(z, surface):
    """Heights above a surface, rounded to 1e-6 of the coordinate unit.

    A cut often falls inside a mass of tied heights: the TIN vertices themselves (height
    exactly 0 in exact arithmetic) and points on flat ground. Without rounding, which of
    them fall below the cut would depend on the last bits of the interpolation (1e-15),
    i.e. on how the TIN is evaluated, not on the data.
    """
    return np.round(z - surface, 6)


def _tiles(xy, size, origin=None):
    key = cell_keys(xy, size, origin=origin)
    o = np.argsort(key, kind="stable")
    ks = key[o]
    b = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True])
    return [o[a:e] for a, e in zip(b[:-1], b[1:])]


def _progressive(xy, h, idx, size, parent_thr, p, tile_id, steps, tiles, record):
    """Cut of one tile on heights; split into four while its ground stays multimodal.

    Returns ``[(indices, threshold), ...]``. A tile whose heights do not separate keeps
    its parent's threshold (a tile lying on one large roof is unimodal too, so "nothing
    separates" must not mean "everything is ground").
    """
    v = h[idx]
    thr = parent_thr
    rec = None
    if idx.size >= 2 * p.min_cluster + 4:
        dips = _dips({"elevation": v}, p.alpha) if record else {}
        ch, rec = _analyse(v, "elevation", p, tile=tile_id, step=1,
                           population="heights above the ground model", dips=dips,
                           record=record)
        if ch.cycle is not None:
            thr = min(ch.threshold, parent_thr)
            if p.ground_spread > 0 and p.method == "moments":
                thr = max(thr, _cluster_bound(v[v <= thr], p.ground_spread))
    info = {"tile": tile_id, "size": size, "n": int(idx.size),
            "x0": float(xy[idx, 0].min()) if idx.size else None,
            "y0": float(xy[idx, 1].min()) if idx.size else None,
            "threshold": float(thr) if np.isfinite(thr) else None, "split": False}
    kept = v <= thr
    if (size / 2 >= p.min_tile_size and idx.size >= 4 * p.min_tile_points
            and kept.sum() >= 8):
        d = dip_test(v[kept], alpha=p.alpha)
        info["ground_dip_pvalue"] = float(d.pvalue)
        if d.reject:
            info["split"] = True
            tiles.append(info)
            if rec is not None:
                steps.append(rec)
            out = []
            origin = (xy[idx, 0].min(), xy[idx, 1].min())
            for j, child in enumerate(_tiles(xy[idx], size / 2, origin)):
                out.extend(_progressive(xy, h, idx[child], size / 2, thr, p,
                                        f"{tile_id}.{j}", steps, tiles, record))
            return out
    tiles.append(info)
    if rec is not None:
        steps.append(rec)
    return [(idx, thr)]


def _cluster_bound(kept, z):
    """``median + z x 1.4826 MAD`` of the kept heights (-inf for fewer than 8 values).

    The sequential cut stops where what is left is symmetric; on ground that the surface
    follows only roughly (sparse or steep terrain) that stop lies inside the ground's own
    upper tail. The cut is never placed closer to the ground cluster's centre than `z`
    robust standard deviations of that cluster.
    """
    if kept.size < 8:
        return -np.inf
    med = np.median(kept)
    return float(med + z * 1.4826 * np.median(np.abs(kept - med)))


class _TileOut:
    """What one root tile gives back: per-point fields plus its report records."""

    def __init__(self, fields, ground_steps, infos, steps=(), n_ids=0):
        self.fields = fields
        self.ground_steps = ground_steps
        self.infos = infos
        self.steps = list(steps)
        self.n_ids = n_ids

    def to_fields(self):
        return self.fields


def _cut_tile(xyh, p, record):
    """Progressive cuts of one root tile on heights (column 2 of `xyh`): ground mask and
    each point's (sub-)tile cut (inf where the root tile found none)."""
    xy, h = xyh[:, :2], xyh[:, 2]
    steps, infos = [], []
    parts = _progressive(xy, h, np.arange(h.size), p.tile_size, np.inf, p, "", steps, infos,
                         record)
    ground = np.zeros(h.size, bool)
    cut = np.empty(h.size)
    for idx, thr in parts:
        ground[idx] = h[idx] <= thr
        cut[idx] = thr
    return ground, cut, steps, infos


def _classify_tile(xyh, attrs, p, record, final):
    """One root tile: its ground cut, and on the final pass also the paper's five steps
    (cluster ids local, from 1)."""
    ground, cut, gsteps, infos = _cut_tile(xyh, p, record)
    if not final:
        return _TileOut({"ground": ground, "cut": cut}, gsteps, infos)
    h = xyh[:, 2]
    inten = attrs.get("intensity")
    n = h.size
    steps = []
    if n < 2 * p.min_cluster:
        return _TileOut({"ground": ground, "cut": cut, "cluster_id": np.ones(n, np.int32)},
                        gsteps, infos, steps, 1)
    cats = {"elevation": h}
    if inten is not None:
        cats["intensity"] = inten
    lab, next_id = _five_step(cats, p, -1, steps, 1)
    return _TileOut({"ground": ground, "cut": cut, "cluster_id": lab}, gsteps, infos, steps,
                    next_id - 1)


def _tile_order(roots):
    """Order of the points tile by tile (input order inside a tile), and the root tiles
    of the cloud in that order: each tile's points become the block of positions it
    occupies (core points only: no halo)."""
    perm = np.concatenate([t.points for t in roots])
    out, start = [], 0
    for t in roots:
        m = t.points.size
        out.append(replace(t, points=np.arange(start, start + m)))
        start += m
    return perm, out


def _tile_pass(xyh, roots, p, inten, scheduler, workers, record, final):
    """Every root tile through :func:`lidarstat.pipeline.map_tiles`; fields and records."""
    from .._shared._tiles import map_tiles

    index = {t.key: i for i, t in enumerate(roots)}
    outs = [None] * len(roots)

    def keep(tile, res):
        outs[index[tile.key]] = res

    attrs = {} if inten is None else {"intensity": inten}
    fields = map_tiles(lambda pts, a: _classify_tile(pts, a, p, record, final), xyh,
                       tiles=roots, attributes=attrs, scheduler=scheduler, workers=workers,
                       collect=keep)
    steps, infos = [], []
    for i, o in enumerate(outs):
        o.fields = None  # assembled in `fields`; keep only the ids and records
        steps.extend(replace(s, tile=f"{i}{s.tile}") for s in o.ground_steps)
        infos.extend({**t, "tile": f"{i}{t['tile']}"} for t in o.infos)
    return fields, outs, steps, infos


def _five_step(cats: dict, p: _Params, tile: int, steps: list, first_cluster: int):
    """The paper's steps 1-4 on one tile's 1-D values; returns a cluster label per point."""
    n = next(iter(cats.values())).size
    labels = np.zeros(n, np.int32)
    todo = np.arange(n)
    next_id = first_cluster
    step = 1
    while todo.size >= 2 * p.min_cluster and step <= p.max_steps:
        sub = {k: v[todo] for k, v in cats.items()}
        dips = _dips(sub, p.alpha)
        multi = {k: d for k, d in dips.items() if d["multimodal"]}
        if not multi and step > 1:
            break
        pool = multi or dips
        cat = min(pool, key=lambda k: (pool[k]["pvalue"], -pool[k]["dip"]))
        ch, rec = _analyse(sub[cat], cat, p, tile=tile, step=step,
                           population="tile" if step == 1 else "unclassified", dips=dips)
        steps.append(rec)
        if ch.cycle is None:
            break
        low = sub[cat] <= ch.threshold
        cluster = todo[low]
        rest = todo[~low]
        # step 3: the cluster by the complementary category
        comp = [k for k in cats if k != cat]
        split = False
        if comp and cluster.size >= 2 * p.min_cluster:
            c2 = comp[0]
            v2 = cats[c2][cluster]
            d2 = _dips({c2: v2}, p.alpha)
            if d2[c2]["multimodal"]:
                ch2, rec2 = _analyse(v2, c2, p, tile=tile, step=step,
                                     population=f"cluster {next_id}", dips=d2)
                steps.append(rec2)
                if ch2.cycle is not None:
                    lo2 = v2 <= ch2.threshold
                    labels[cluster[lo2]] = next_id
                    labels[cluster[~lo2]] = next_id + 1
                    next_id += 2
                    split = True
        if not split:
            labels[cluster] = next_id
            next_id += 1
        todo = rest
        step += 1
    if todo.size:
        labels[todo] = next_id
        next_id += 1
    return labels, next_id


# --------------------------------------------------------------------------- public
def classify_moments(xyz, intensity=None, *, number_of_returns=None, return_number=None,
                     method: str = "moments", tile_size: float = 64.0,
                     min_tile_size: float = 16.0, alpha: float = 0.05, min_cluster: int = 10,
                     smoothing: float = 0.01, cycle: int | None = None,
                     bandwidth="silverman", surface_cell: float = 4.0,
                     opening_window: float = 20.0, iterations: int = 4,
                     vegetation_heights=(0.5, 2.0), min_object_height: float = 0.5,
                     elevation_rule: str = "symmetry", low_noise: bool = True,
                     road_rule: str = "antimode", road_cell_points: float = 8.0,
                     ground_spread: float = 3.0, continuity: bool = True,
                     cut_interpolation: bool = True,
                     workers: int | None = None, scheduler: str = "threads", units=1.0,
                     source: str | None = None) -> MomentsClassification:
    """Classify points as ground, road, building, vegetation or unclassified without training.

    Parameters
    ----------
    xyz : (N, 3) array_like
        Coordinates (UTM-sized values are fine: every tile works in a local frame).
    intensity : (N,) array_like, optional
        Return intensity. Without it only elevation is analysed (a LidarstatWarning says
        so) and no road class is produced.
    number_of_returns, return_number : (N,) array_like, optional
        Return structure; points that are not the last of several returns are vegetation
        candidates.
    method : {'moments', 'skewness-balancing'}
        The sequential moments procedure, or the skewness-balancing baseline (Bartels &
        Wei 2006: remove the highest points until the skewness is <= 0) in the same tiles.
    tile_size, min_tile_size : float
        Side of the regular tiles and the smallest side the progressive split may reach.
    alpha : float
        Level of the dip tests.
    min_cluster : int
        Smallest cluster a cut may leave on either side.
    smoothing : float
        Moving-average width of the curves as a fraction of the values analysed.
    cycle : int, optional
        Override the separating cycle of the first analysis of every tile.
    bandwidth : {'silverman', 'scott'} or float
        Kernel density bandwidth (the paper's ``h`` as a float).
    surface_cell : float
        Cell of the ground surface model (one TIN vertex, the cell's median ground point,
        per cell; a cell of several points keeps the other points' heights honest).
    opening_window : float
        Window of the grey opening giving the first lower envelope (wider than most
        buildings; planar slopes pass unchanged).
    iterations : int
        Refits of the ground surface to the ground of the previous pass.
    vegetation_heights : (float, float)
        Heights above ground separating low (3), medium (4) and high (5) vegetation.
    min_object_height : float
        Points closer than this to the ground surface and not ground are unclassified (1).
    ground_spread : float
        The cut of a tile is never closer to the centre of the ground cluster it leaves
        than this many robust standard deviations (median + z 1.4826 MAD) of that cluster
        (0 switches it off; the skewness-balancing baseline never uses it).
    continuity : bool
        After the last cut, ground points in a patch of the lowest-point grid that stands
        above its surroundings on (almost) every side (a roof the surface ran over) become
        objects (:func:`~lidarstat.classify._continuity.raised_patches`).
    cut_interpolation : bool
        Interpolate the tile cuts bilinearly between the centres of the finest tiles
        (:func:`~lidarstat.classify._seams.interpolate_cuts`) so the cut is continuous
        and no class step appears at a tile border; False applies each tile's cut as a
        step.
    road_rule : {'antimode', 'kurtosis-peak'}
        Cut of the ground's intensity into road and the rest (:func:`road_cut`): the
        antimode of the density between its two main modes (default) or the paper's
        kurtosis peak; either only when the dip test finds the ground's intensity
        multimodal.
    road_cell_points : float
        The ground intensity is first replaced by its median over cells of about this
        many ground points (one echo's intensity is too noisy to split; roads are areas).
    low_noise : bool
        First flag isolated points far below their neighbourhood's lowest points
        (:func:`~lidarstat.classify.low_outliers`) as low noise (class 7) and leave them
        out of every analysis: one multipath echo metres under the terrain otherwise
        pulls the lower envelope and the ground surface down around it.
    workers : int, optional
        Threads for the tiles (default: CPU count).
    units : float, (float, float) or LinearUnits
        Metres per coordinate unit (horizontal, vertical), e.g. from
        :func:`lidarstat.io.linear_units` of the file's CRS. Every length parameter
        (`tile_size`, `min_tile_size`, `surface_cell`, `opening_window`,
        `vegetation_heights`, `min_object_height`) is in metres and converted with it, so
        a file in feet gets the same physical windows as one in metres.
    scheduler : {'threads', 'sync', 'dask'}
        How root tiles run (:func:`lidarstat.pipeline.map_tiles`); every scheduler gives
        the same result.
    source : str, optional
        File name used in messages.

    Returns
    -------
    MomentsClassification

    Raises
    ------
    InvalidPointsError
        Empty cloud, NaN coordinates, too few points.
    InvalidParameterError
        Bad parameter values, or an attribute of the wrong length.

    Notes
    -----
    See the module docstring and ``docs/methods/moments.md``: the separating cycles are
    chosen by :func:`~lidarstat.classify.choose_cycle`; ground is the cluster left after
    the elevation cut of every tile, re-decided once on heights above the single TIN of
    all tiles' ground clusters so that neighbouring tiles agree; the ground is then split
    by intensity (road = the darker cluster when intensity is multimodal on the ground)
    and the objects are split by their return structure and height.

    References
    ----------
    Crosilla, F., Macorig, D., Sebastianutti, I., Visintini, D. (2011). Points
    classification by a sequential higher-order moments statistical analysis of LiDAR data.
    ISPRS Arch. XXXVIII-5/W12.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(0)
    >>> xy = g.uniform(0, 60, (6000, 2))
    >>> z = 100 + 0.05 * xy[:, 0] + g.normal(0, 0.05, 6000)
    >>> roof = (np.abs(xy - 30) < 8).all(axis=1)
    >>> z[roof] += 6
    >>> intensity = g.normal(120, 10, 6000)
    >>> res = classify_moments(np.c_[xy, z], intensity, tile_size=60)
    >>> bool((res.classification[roof] == 6).mean() > 0.9)
    True
    >>> bool((res.classification[~roof] == 2).mean() > 0.95)
    True
    """
    func = "classify_moments"
    pts = check_points(xyz, min_points=8, source=source)
    n = len(pts)
    if method not in ("moments", "skewness-balancing"):
        raise InvalidParameterError(f"The 'method' parameter of {func} must be 'moments' or "
                                    f"'skewness-balancing'. Got {method!r} instead.")
    tile_size = check_scalar(tile_size, "tile_size", func=func, low=0)
    min_tile_size = check_scalar(min_tile_size, "min_tile_size", func=func, low=0)
    alpha = check_scalar(alpha, "alpha", func=func, low=0, high=1)
    min_cluster = check_scalar(min_cluster, "min_cluster", func=func, low=1, closed="left",
                               integer=True)
    smoothing = check_scalar(smoothing, "smoothing", func=func, low=0, high=0.5,
                             closed="left")
    surface_cell = check_scalar(surface_cell, "surface_cell", func=func, low=0)
    opening_window = check_scalar(opening_window, "opening_window", func=func, low=0)
    iterations = check_scalar(iterations, "iterations", func=func, low=0, closed="left",
                              integer=True)
    if workers is not None:
        workers = check_scalar(workers, "workers", func=func, low=1, closed="left",
                               integer=True)
    check_option(scheduler, "scheduler", ("threads", "sync", "dask"), func=func)
    check_option(road_rule, "road_rule", ("antimode", "kurtosis-peak"), func=func)
    ground_spread = check_scalar(ground_spread, "ground_spread", func=func, low=0,
                                 closed="left")
    road_cell_points = check_scalar(road_cell_points, "road_cell_points", func=func, low=1,
                                    closed="left")
    if cycle is not None:
        cycle = check_scalar(cycle, "cycle", func=func, low=0, closed="left", integer=True)

    def _attr(a, name):
        if a is None:
            return None
        arr = np.asarray(a)
        if arr.shape != (n,):
            raise InvalidParameterError(f"{source or 'points'}: `{name}` has shape {arr.shape}; "
                                        f"expected ({n},)")
        return arr

    inten = _attr(intensity, "intensity")
    nret = _attr(number_of_returns, "number_of_returns")
    rnum = _attr(return_number, "return_number")
    if inten is not None:
        inten = inten.astype(np.float64)
        if not np.isfinite(inten).all():
            raise InvalidParameterError(f"{source or 'points'}: `intensity` holds NaN values")
        if np.ptp(inten) == 0:
            inten = None
    if inten is None:
        warnings.warn(f"{source or 'points'}: no usable intensity; classifying by elevation "
                      "alone (no road class)", LidarstatWarning, stacklevel=2)

    ux, uz = _unit_factors(units, source)
    n_all = n
    noise = (low_outliers(pts[:, :2], pts[:, 2], min_depth=0.5 / uz) if low_noise
             else np.zeros(n, bool))
    if noise.any():
        keep = ~noise
        if keep.sum() < 8:
            raise InvalidParameterError(f"{source or 'points'}: fewer than 8 points left "
                                        "after removing low outliers")
        pts_all = pts
        pts, n = pts[keep], int(keep.sum())
        inten, nret, rnum = (None if a is None else a[keep] for a in (inten, nret, rnum))

    p = _Params(alpha=alpha, min_cluster=min_cluster, smoothing=smoothing, cycle=cycle,
                bandwidth=bandwidth, method=method, max_steps=6,
                elevation_rule=elevation_rule, tile_size=tile_size / ux,
                min_tile_size=min_tile_size / ux, min_tile_points=4 * min_cluster,
                ground_spread=float(ground_spread))
    has_returns = nret is not None and rnum is not None
    multi = np.zeros(n, bool)
    if has_returns:
        multi = (nret.astype(int) > 1) & (rnum.astype(int) < nret.astype(int))
    del nret, rnum
    origin = column_min(pts)

    # ---- work in root-tile order: every tile is a contiguous block of points, so the
    # tile passes copy slices and the grid and TIN kernels touch memory locally. Inside a
    # tile the input order is kept (the dip test's subsample sees the same sequence) and
    # every tie is broken by the input index `perm` (classes do not depend on the order).
    from .._shared._tiles import tile_grid

    xyh = np.empty((n, 3))  # x, y and the current heights, in tile order
    xyh[:, :2] = pts[:, :2] - origin[:2]
    xyh[:, 2] = 0.0
    perm, roots = _tile_order(tile_grid(xyh, p.tile_size))
    xyh = xyh[perm]
    z = pts[:, 2][perm]
    z -= origin[2]
    del pts  # the caller's array (or its copy without the low noise): not needed again
    inten = None if inten is None else inten[perm]
    multi = multi[perm]
    xy = np.ascontiguousarray(xyh[:, :2])

    # ---- ground: lower envelope, then cuts on heights above a surface refitted to the
    # ground of the previous pass (progressive tiles through lidarstat.pipeline)
    height = _heights(z, opening_surface(xy, z, window=opening_window / ux, cell=1.0 / ux))
    surf = None
    finest = p.tile_size
    while finest / 2 >= p.min_tile_size:  # the smallest tile _progressive can make
        finest /= 2
    for it in range(iterations + 1):
        last = it == iterations
        xyh[:, 2] = height
        fields, outs, steps, tiles = _tile_pass(xyh, roots, p, inten, scheduler, workers,
                                                record=last, final=last)
        ground, cut = fields["ground"], fields["cut"]
        if cut_interpolation:  # no class step at tile borders (_seams.py)
            cut = interpolate_cuts(xy, cut, finest)
            ground = height <= cut
        if ground.sum() < 3:
            ground[:] = True
        if not last:
            surf = ground_surface(xy[ground], z[ground], cell=surface_cell / ux,
                                  rank=perm[ground])
            height = _heights(z, surf(xy))
    del xyh

    if continuity and method == "moments":
        raised = ground & raised_patches(xy, z, step=0.3 / uz, rank=perm)
        if raised.any() and (ground & ~raised).sum() >= 3:
            ground &= ~raised
            # heights of the patches above the surface refitted without them
            surf = ground_surface(xy[ground], z[ground], cell=surface_cell / ux,
                                  rank=perm[ground])
            height = _heights(z, surf(xy))

    # ---- the paper's five steps per root tile (clusters), run with the last cut above:
    # cluster ids made unique in tile order, records in tile order
    cluster_id = fields["cluster_id"]
    first = 0
    for t, o in zip(roots, outs):
        cluster_id[t.points] += first
        first += o.n_ids
    for i, o in enumerate(outs):
        steps.extend(replace(rec, tile=i) for rec in o.steps)

    # ---- roads: the intensity sub-cluster of the whole ground cluster (_roads.py)
    road = np.zeros(n, bool)
    gi = np.flatnonzero(ground)
    if inten is not None and gi.size >= 2 * min_cluster:
        smoothed, cells = cell_median(xy[gi], inten[gi], points_per_cell=road_cell_points,
                                      return_cells=True)
        ch, sm, de, dips = road_cut(cells, alpha=alpha, rule=road_rule,
                                    min_cluster=min_cluster, smoothing=smoothing,
                                    bandwidth=bandwidth)
        steps.append(MomentsStep(tile=-1, step=len(steps) + 1,
                                 population="ground cluster (cell medians)",
                                 category="intensity", n=int(cells.size),
                                 dip={"intensity": dips}, choice=ch, curves=_thin(sm),
                                 density=de))
        if ch.cycle is not None:
            road[gi[smoothed <= ch.threshold]] = True

    # ---- classes
    cls = np.full(n, ASPRS["unclassified"], np.uint8)
    cls[ground] = ASPRS["ground"]
    cls[ground & road] = ASPRS["road"]
    obj = ~ground & (height >= min_object_height / uz)
    h0, h1 = (v / uz for v in vegetation_heights)
    veg = obj & _vegetation_like(xy, height, obj, multi, surface_cell / ux,
                                 4 * surface_cell / uz)
    bld = obj & ~veg & (height >= h1)
    cls[bld] = ASPRS["building"]
    vmask = obj & ~bld
    cls[vmask & (height < h0)] = ASPRS["low_vegetation"]
    cls[vmask & (height >= h0) & (height < h1)] = ASPRS["medium_vegetation"]
    cls[vmask & (height >= h1)] = ASPRS["high_vegetation"]
    params = dict(method=method, tile_size=tile_size, min_tile_size=min_tile_size, alpha=alpha,
                  min_cluster=min_cluster, smoothing=smoothing, cycle=cycle,
                  bandwidth=bandwidth, surface_cell=surface_cell,
                  vegetation_heights=list(vegetation_heights),
                  min_object_height=min_object_height, intensity=inten is not None,
                  returns=has_returns, low_noise=low_noise,
                  road_rule=road_rule, road_cell_points=road_cell_points,
                  ground_spread=ground_spread, continuity=continuity,
                  cut_interpolation=cut_interpolation,
                  n_low_noise=int(noise.sum()), units={"horizontal_m": ux, "vertical_m": uz})
    # back to the input order
    cls, cluster_id, height, ground, cut = _expand(perm, n, cls, cluster_id, height, ground,
                                                   cut, fill=(0, 0, 0.0, False, 0.0))
    if noise.any():
        cls, cluster_id, height, ground, cut = _expand(
            keep, n_all, cls, cluster_id, height, ground, cut,
            fill=(ASPRS["low_noise"], 0, np.nan, False, np.nan))
        if surf is not None:  # heights of the low noise under the final ground surface
            q = pts_all[noise] - origin
            height[noise] = _heights(q[:, 2], surf(q[:, :2]))
    return MomentsClassification(classification=cls, cluster_id=cluster_id, height=height,
                                 ground=ground, steps=steps, tiles=tiles, params=params,
                                 cut=cut)


def _unit_factors(units, source):
    """(horizontal, vertical) metres per coordinate unit from a number, pair or LinearUnits."""
    if hasattr(units, "horizontal"):
        pair = (units.horizontal, units.vertical)
    elif np.ndim(units) == 0:
        pair = (units, units)
    else:
        pair = tuple(units)
    if len(pair) != 2 or not all(np.isfinite(float(u)) and float(u) > 0 for u in pair):
        raise InvalidParameterError(f"{source or 'points'}: `units` must be metres per "
                                    f"coordinate unit > 0 (or a pair); got {units!r}")
    return float(pair[0]), float(pair[1])


def _expand(where, n, *arrays, fill):
    """Scatter per-point arrays to positions `where` (a mask or indices) of ``n`` points;
    the others get `fill`."""
    out = []
    for a, f in zip(arrays, fill):
        b = np.full(n, f, dtype=a.dtype)
        b[where] = a
        out.append(b)
    return out


def _vegetation_like(xy, height, obj, multi, cell, spread):
    """Objects whose cell shows vegetation: several returns, or heights spread like a canopy.

    A building cell holds a roof (heights within a few decimetres of a plane over the
    cell); a tree cell holds points at many heights and pulses with several echoes. Cells
    are ``cell / 2`` wide (2 m by default: small enough that a crown overhanging a roof
    does not turn the roof cells beside it into vegetation, which 8 m cells did on the
    synthetic town, building recall 0.57-0.84 against 0.97-0.98 now). A cell is
    vegetation when more than half of its object points are non-last returns or its
    object heights span more than `spread` (``4 * surface_cell`` in height units); every
    non-last return is vegetation.
    """
    out = np.zeros(height.size, bool)
    idx = np.flatnonzero(obj)
    if idx.size == 0:
        return out
    key = cell_keys(xy[idx], 0.5 * cell)
    _, inv = np.unique(key, return_inverse=True)
    k = inv.max() + 1
    hmax = np.full(k, -np.inf)
    hmin = np.full(k, np.inf)
    np.maximum.at(hmax, inv, height[idx])
    np.minimum.at(hmin, inv, height[idx])
    cnt = np.bincount(inv, minlength=k)
    mfrac = np.bincount(inv, weights=multi[idx].astype(float), minlength=k) / np.maximum(cnt, 1)
    veg_cell = (hmax - hmin > spread) | (mfrac > 0.5)
    out[idx] = veg_cell[inv] | multi[idx]
    return out
