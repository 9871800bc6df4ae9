"""Unsupervised classification by sequential skewness and kurtosis (Crosilla et al., seed 004).

:func:`moments` runs named steps, each in a module of its own:

1. low noise: isolated points far below their neighbourhood are class 7 and leave every
   analysis (:func:`~._outliers.low_outliers`);
2. analysis windows: a regular grid of root windows, worked in window order
   (:mod:`._moments_windows`);
3. the per-window moment analysis: the elevation cut, the progressive split, the
   paper's clustering steps (:mod:`._moments_analysis`);
4. the ground: lower envelope, interpolated window cuts, one TIN refitted to the ground
   of all windows, raised patches (:mod:`._moments_ground`);
   then the terrain step: the ground grown over smooth continuations and every point
   tested against it with a slope-dependent tolerance (:mod:`._terrain`);
5. roads: the darker intensity sub-cluster of the whole ground (:mod:`._roads`);
6. objects: buildings by tested local planes (:mod:`._buildings`), vegetation and the
   ASPRS codes (:mod:`._moments_objects`).

Elevation is analysed as the height above a ground model (the paper uses raw elevations,
which on a slope mixes the terrain trend with the objects; see docs/methods/moments.md).
"""

from __future__ import annotations

import warnings

import numpy as np

from .._shared._columns import column_min
from .._shared._deprecate import renamed_parameters
from .._shared._memory import release_freed
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError, LidarstatDeprecationWarning, LidarstatWarning
from ._continuity import raised_patches
from ._cycle import ElevationRule
from ._moments_ground import drop_raised_patches, ground_cut, heights
from ._moments_kernels import canonical_order, compact_rows
from ._moments_objects import asprs_classes, building_step
from ._moments_options import MomentsMethod, MomentsOptions, unit_factors
from ._moments_result import ASPRS, MomentsClassification
from ._moments_windows import root_windows
from ._outliers import low_outliers
from ._roads import RoadRule, road_points
from ._terrain import terrain_step

__all__ = ["classify_moments", "moments"]

_FUNC = "moments"


@renamed_parameters(tile_size="window", min_tile_size="min_window", min_cluster="min_points")
def moments(xyz, intensity=None, *, number_of_returns=None, return_number=None,
            method: MomentsMethod | str = "moments", window: float = 64.0,
            min_window: float = 16.0, alpha: float = 0.05, min_points: int = 10,
            smoothing: float = 0.01, cycle: int | None = None, bandwidth="silverman",
            surface_cell: float = 4.0, opening_window: float = 20.0, iterations: int = 4,
            vegetation_heights=(0.5, 2.0), min_object_height: float = 0.5,
            elevation_rule: ElevationRule | str = "symmetry", low_noise: bool = True,
            road_rule: RoadRule | str = "antimode", road_cell_points: float = 8.0,
            ground_spread: float = 3.0, continuity: bool = True, rng=0,
            workers: int | None = None, scheduler: str = "threads", units=1.0,
            source: str | None = None,
            road_threshold: float | None = None,
            terrain: bool = True, building_alpha: float = 0.01,
            sigma: float | None = None,
            overwrite_xyz: bool = False, evidence: bool = True) -> MomentsClassification:
    """Classify points as ground, road, building, vegetation or unclassified without training.

    Parameters
    ----------
    xyz : (N, 3) array_like
        Coordinates (UTM-sized values are fine: every window works in a local frame).
    intensity : (N,) array_like, optional
        Return intensity. Without it only elevation is analysed (a LidarstatWarning says
        so) and no road class is produced.
    number_of_returns, return_number : (N,) array_like, optional
        Return structure; points that are not the last of several returns are vegetation
        candidates.
    method : MomentsMethod or {'moments', 'skewness-balancing'}
        The sequential moments procedure, or the skewness-balancing baseline (Bartels &
        Wei 2006: remove the highest points until the skewness is <= 0) in the same windows.
    window, min_window : float
        Side of the regular analysis windows (the paper's tiles) and the smallest side the
        progressive split may reach (metres).
    alpha : float
        Level of the dip tests.
    min_points : int
        Smallest cluster a cut may leave on either side.
    smoothing : float
        Moving-average width of the curves as a fraction of the values analysed.
    cycle : int, optional
        Override the separating cycle of the first analysis of every window.
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
    elevation_rule : ElevationRule or {'symmetry', 'plateau'}
        Rule choosing an elevation cut (:func:`~lidarstat.classify.choose_cycle`).
    low_noise : bool
        First flag isolated points far below their neighbourhood's lowest points
        (:func:`~lidarstat.classify.low_outliers`) as low noise (class 7) and leave them
        out of every analysis: one multipath echo metres under the terrain otherwise
        pulls the lower envelope and the ground surface down around it.
    road_rule : RoadRule or {'antimode', 'kurtosis-peak'}
        Cut of the ground's intensity into road and the rest: the antimode of the
        density between its two main modes or the paper's kurtosis peak; either only
        when the dip test finds the ground's intensity multimodal.
    road_cell_points : float
        The ground intensity is first replaced by its median over cells of about this
        many ground points (one echo's intensity is too noisy to split; roads are areas).
    ground_spread : float
        The cut of a window is never closer to the centre of the ground cluster it leaves
        than this many robust standard deviations (median + z 1.4826 MAD) of that cluster
        (0 switches it off; the skewness-balancing baseline never uses it).
    continuity : bool
        After the last cut, ground points in a patch of the lowest-point grid that stands
        above its surroundings on (almost) every side (a roof the surface ran over) become
        objects.
    road_threshold : float, optional
        Cut the ground's cell-median intensity at this value instead of deciding the cut
        from this cloud's ground (the road is the darker side); ``-inf``: no road. A cut
        decided once for a whole area, given to each tile of a catalogue
        (``params["road_threshold"]`` holds the cut a run used, None when it found no
        road).
    rng : int or numpy.random.Generator
        Seed of the dip tests' subsample (samples above 20,000 values) and dequantisation
        (tied values); a Generator gives one seed for every test.
    workers : int, optional
        Threads for the windows (default: CPU count). Above 1 the raised patches' graph
        is also built beside the window passes and the roads found beside the building
        tests; 1 runs every step in turn. The result is the same.
    scheduler : {'threads', 'sync', 'dask'}
        How root windows run (:func:`lidarstat.pipeline.map_tiles`); every scheduler gives
        the same result.
    units : float, (float, float) or LinearUnits
        Metres per coordinate unit (horizontal, vertical), e.g. from
        :func:`lidarstat.io.linear_units` of the file's CRS. Every length parameter
        (`window`, `min_window`, `surface_cell`, `opening_window`, `vegetation_heights`,
        `min_object_height`) is in metres and converted with it, so a file in feet gets
        the same physical windows as one in metres.
    source : str, optional
        File name used in messages.
    terrain : bool
        After the moments cut, grow the ground over smooth continuations (embankments,
        ramps, steep banks the cut left out), take back grown regions walled on most of
        their border (bridges, roofs), and test every point against the grown surface
        with a slope-dependent tolerance and a fence on the local ground's noise
        (:func:`~._terrain.refine_terrain`; the skewness-balancing baseline never uses
        it).
    building_alpha : float
        Level of the building tests: the chi-square test of each object point's local
        plane, the normal test of its distance to a neighbour's accepted plane, the
        binomial test of a roof patch's share of non-last returns.
    sigma : float, optional
        Noise std (metres) of the building tests; estimated from the local planes of the
        ground when not given.
    overwrite_xyz : bool
        Allow the classification to use the memory of `xyz` (a C-contiguous float64
        array) for its own work arrays: `xyz` holds no coordinates afterwards. A caller
        that does not need the coordinates again (a file read only to classify it)
        saves a copy of them, 24 bytes a point, for the whole run.
    evidence : bool
        Keep in `steps` what only the report reads: the density estimate of every
        analysed population (``steps[i].density``) and the dip test of every window's
        heights before its cut. False leaves them out (None, an empty ``dip``) and
        changes no class, cut or test that decides one.

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
    The separating cycles are chosen by :func:`~lidarstat.classify.choose_cycle`; ground
    is what lies under the window cuts on heights above one TIN of all windows' ground,
    the cuts interpolated between windows so that neighbouring windows agree; the ground
    is then split by intensity (road = the darker cluster when intensity is multimodal on
    the ground) and the objects by their return structure and height. See
    ``docs/methods/moments.md``.

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
    >>> res = moments(np.c_[xy, z], intensity, window=60)
    >>> bool((res.classification[roof] == 6).mean() > 0.9)
    True
    >>> bool((res.classification[~roof] == 2).mean() > 0.95)
    True
    """
    pts = check_points(xyz, min_points=8, source=source)
    n = len(pts)
    # the work arrays take the coordinates' memory when it is this call's own copy or the
    # caller gives it up
    reuse = bool(overwrite_xyz) or (pts is not xyz and pts.base is None)
    method = MomentsMethod(check_option(method, "method", [m.value for m in MomentsMethod],
                                        func=_FUNC))
    elevation_rule = ElevationRule(check_option(
        elevation_rule, "elevation_rule", [r.value for r in ElevationRule], func=_FUNC))
    road_rule = RoadRule(check_option(road_rule, "road_rule", [r.value for r in RoadRule],
                                      func=_FUNC))
    check_option(scheduler, "scheduler", ("threads", "sync", "dask"), func=_FUNC)
    window = check_scalar(window, "window", func=_FUNC, low=0)
    min_window = check_scalar(min_window, "min_window", func=_FUNC, low=0)
    alpha = check_scalar(alpha, "alpha", func=_FUNC, low=0, high=1)
    min_points = check_scalar(min_points, "min_points", func=_FUNC, low=1, closed="left",
                              integer=True)
    smoothing = check_scalar(smoothing, "smoothing", func=_FUNC, low=0, high=0.5,
                             closed="left")
    surface_cell = check_scalar(surface_cell, "surface_cell", func=_FUNC, low=0)
    opening_window = check_scalar(opening_window, "opening_window", func=_FUNC, low=0)
    iterations = check_scalar(iterations, "iterations", func=_FUNC, low=0, closed="left",
                              integer=True)
    if workers is not None:
        workers = check_scalar(workers, "workers", func=_FUNC, low=1, closed="left",
                               integer=True)
    ground_spread = check_scalar(ground_spread, "ground_spread", func=_FUNC, low=0,
                                 closed="left")
    road_cell_points = check_scalar(road_cell_points, "road_cell_points", func=_FUNC, low=1,
                                    closed="left")
    if cycle is not None:
        cycle = check_scalar(cycle, "cycle", func=_FUNC, low=0, closed="left", integer=True)
    seed = _seed(rng)
    building_alpha = check_scalar(building_alpha, "building_alpha", func=_FUNC, low=0, high=1)
    if sigma is not None:
        sigma = check_scalar(sigma, "sigma", func=_FUNC, low=0)
    inten, nret, rnum = (_attribute(a, name, n, source) for a, name in (
        (intensity, "intensity"), (number_of_returns, "number_of_returns"),
        (return_number, "return_number")))
    inten = _usable_intensity(inten, source)
    # the vegetation candidates (non-last returns of multi-return pulses): one mask
    # put in window order below, not the two return attributes
    multi = _multiple_returns(nret, rnum)
    has_returns = multi is not None
    del nret, rnum
    ux, uz = unit_factors(units, source)
    # The classes must not depend on the order of the points (the tiles of a catalogue
    # bring them in another order than the whole file): every step runs on the points
    # sorted by x, y, z and intensity, and the results go back to the caller's order.
    canon = canonical_order(pts[:, 0], pts[:, 1], pts[:, 2], inten)
    if reuse:
        _permute_columns(pts, canon)
    else:
        pts = np.take(pts, canon, axis=0)  # rows by np.take: a third of fancy indexing's time

    # 1. low noise, out of every analysis
    noise = (low_outliers(pts, pts[:, 2], min_depth=0.5 / uz) if low_noise
             else np.zeros(n, bool))
    pts_noise = pts[noise]  # for their heights under the final surface
    pts = _without_low_noise(noise, pts, source, in_place=reuse)
    release_freed()  # between steps: what a step freed goes back to the system

    # 2. analysis windows; the points in root-window order, local coordinates. Ties are
    # broken by the index in the sorted order above, not by the caller's order.
    p = MomentsOptions(alpha=alpha, min_points=min_points, smoothing=smoothing, cycle=cycle,
                       bandwidth=bandwidth, method=method, elevation_rule=elevation_rule,
                       window=window / ux, min_window=min_window / ux,
                       ground_spread=float(ground_spread), seed=seed,
                       building_alpha=building_alpha, sigma=sigma,
                       evidence=bool(evidence))
    # the windows and rasters lie on multiples of the window side in the file's own
    # coordinates, so that the tiles of a catalogue share the whole area's windows
    origin = column_min(pts)
    origin[:2] = np.floor(origin[:2] / p.window) * p.window
    perm, roots = root_windows(pts[:, :2] - origin[:2], p.window)
    # the input position of every point in window order (and of the low noise): the
    # fields go back to the caller's order through these alone
    kept = np.flatnonzero(~noise) if noise.any() else None
    dest = canon[perm] if kept is None else canon[kept[perm]]
    # intensity and the candidates straight from the caller's order to window order
    inten = None if inten is None else np.take(inten, dest)
    multi = np.zeros(len(dest), bool) if multi is None else np.take(multi, dest)
    if n < 2**31:  # the positions are only scattered through: half the memory
        dest = dest.astype(np.int32)
    low = canon[np.flatnonzero(noise)]
    del canon, kept
    xy, z = _window_frame(pts, perm, origin, in_place=reuse)
    del pts  # the caller's array (or its copy without the low noise): not needed again
    release_freed()

    # 3-4. window analyses and the ground; the raised patches' graph reads only the
    # coordinates, so it is built beside them, on the core the surface fits leave idle
    continuous = continuity and method is MomentsMethod.MOMENTS
    patches = _beside(continuous and workers != 1, raised_patches, xy, z, step=0.3 / uz,
                      rank=perm)
    try:
        ground, height, cut, surf, fields, steps, windows = ground_cut(
            xy, z, perm, roots, p, inten, opening_window=opening_window / ux,
            opening_cell=1.0 / ux, surface_cell=surface_cell / ux, iterations=iterations,
            scheduler=scheduler, workers=workers)
    except BaseException:
        if patches is not None:
            patches.cancel()
        raise
    cluster_id = fields["cluster_id"]
    del fields, roots  # the last pass's own ground and cuts: `ground` and `cut` hold them
    refine = terrain and method is MomentsMethod.MOMENTS
    if refine:
        height = surf = None  # replaced by the terrain's: freed before it allocates
    if continuous:  # the surface without the patches only where no terrain replaces it
        ground, height, surf = drop_raised_patches(
            xy, z, perm, ground, height, surf, surface_cell=surface_cell / ux, step=0.3 / uz,
            raised=None if patches is None else patches.result(), refit=not refine)
        del patches
    del perm  # the ranks of the ground steps' ties
    release_freed()
    if refine:
        ground, height, surf, tolerance = terrain_step(xy, z, ground, ux=ux, uz=uz)
        release_freed()
    else:
        tolerance = np.full(len(z), np.inf)
    low_height = None  # heights of the low noise under the final surface
    if low.size and surf is not None:
        q = pts_noise - origin
        low_height = heights(q[:, 2], surf(q[:, :2]))
    del pts_noise, surf  # the surface's TIN: not needed again
    # 5-6. roads, and buildings (tested roof planes): both read the ground and nothing of
    # each other, so the roads (one core) run beside the building tests
    road_options = dict(road_rule=road_rule, road_cell_points=road_cell_points,
                        threshold=_road_threshold(road_threshold), first_step=len(steps) + 1)
    roads = _beside(workers != 1, road_points, xy, inten, ground, p, **road_options)
    try:
        blds, brows = building_step(xy, z, height, ground, multi, (ux, uz),
                                    min_object_height=min_object_height / uz,
                                    min_height=vegetation_heights[1], options=p)
    except BaseException:
        if roads is not None:
            roads.cancel()
        raise
    road, road_step = (road_points(xy, inten, ground, p, **road_options) if roads is None
                       else roads.result())
    del roads
    if road_step is not None:
        steps.append(road_step)
    has_intensity = inten is not None
    del inten
    release_freed()
    # objects and classes
    building = np.zeros(len(z), bool)
    building[brows] = blds.building
    cls = asprs_classes(xy, height, ground, road, multi, buildings=building,
                        min_object_height=min_object_height / uz,
                        vegetation_heights=tuple(v / uz for v in vegetation_heights),
                        surface_cell=surface_cell / ux, height_spread=4 * surface_cell / uz)
    del xy, z, multi, road, building  # the window-order inputs: the fields are made next
    params = dict(method=method.value, window=window, min_window=min_window, alpha=alpha,
                  min_points=min_points, smoothing=smoothing, cycle=cycle,
                  bandwidth=bandwidth, surface_cell=surface_cell,
                  opening_window=opening_window, iterations=iterations,
                  vegetation_heights=list(vegetation_heights),
                  min_object_height=min_object_height, elevation_rule=elevation_rule.value,
                  intensity=has_intensity, returns=has_returns, low_noise=low_noise,
                  road_rule=road_rule.value, road_cell_points=road_cell_points,
                  ground_spread=ground_spread, continuity=continuity, rng=seed,
                  road_threshold=(road_threshold if road_threshold is not None else
                                  None if road_step is None or road_step.choice.cycle is None
                                  else float(road_step.choice.threshold)),
                  n_low_noise=int(noise.sum()), units={"horizontal_m": ux, "vertical_m": uz},
                  terrain=terrain, buildings=blds.params)
    # back to the input order, low noise included: one scatter per field through the
    # composed order `dest` (window order -> without low noise -> sorted -> input)
    # one field at a time, each window-order array released as its copy is made
    cls = _expand(dest, low, n, cls, fill=(ASPRS["low_noise"],))[0]
    cluster_id = _expand(dest, low, n, cluster_id, fill=(0,))[0]
    height = _expand(dest, low, n, height, fill=(np.nan,))[0]
    ground = _expand(dest, low, n, ground, fill=(False,))[0]
    cut = _expand(dest, low, n, cut, fill=(np.nan,))[0]
    tolerance = _expand(dest, low, n, tolerance, fill=(np.nan,))[0]
    if low_height is not None:
        height[low] = low_height
    building_fields = {}  # per candidate: the other points (low noise too) get NaN or 0
    brows = dest[brows]
    for name in list(blds.fields):
        a = blds.fields.pop(name)
        building_fields[name] = np.full(n, np.nan if a.dtype.kind == "f" else 0, a.dtype)
        building_fields[name][brows] = a
    return MomentsClassification(classification=cls, cluster_id=cluster_id, height=height,
                                 ground=ground, steps=steps, windows=windows, params=params,
                                 cut=cut, tolerance=tolerance, building_fields=building_fields)


def classify_moments(*args, **kwargs) -> MomentsClassification:
    """Deprecated name of :func:`moments`."""
    warnings.warn("classify_moments is deprecated; use moments", LidarstatDeprecationWarning,
                  stacklevel=2)
    return moments(*args, **kwargs)


def _beside(run, func, *args, **kwargs):
    """``func(*args, **kwargs)`` started in a thread of its own (a Future), or None when
    not `run` (the caller then calls it in turn)."""
    if not run:
        return None
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(1, thread_name_prefix="lidarstat-moments")
    future = pool.submit(func, *args, **kwargs)
    pool.shutdown(wait=False)  # the thread ends with its one task
    return future


def _road_threshold(value):
    """A given road cut: a finite number, -inf (no road), or None (decided here)."""
    if value is None or (isinstance(value, float) and value == -np.inf):
        return value
    return check_scalar(value, "road_threshold", func=_FUNC)


def _seed(rng) -> int:
    """The dip tests' seed: an integer >= 0 as given, or one drawn from a Generator."""
    if isinstance(rng, np.random.Generator):
        return int(rng.integers(2**32))
    return check_scalar(rng, "rng", func=_FUNC, low=0, closed="left", integer=True)


def _multiple_returns(nret, rnum):
    """The vegetation candidates, non-last returns of multi-return pulses (a mask), or
    None without the return attributes."""
    if nret is None or rnum is None:
        return None
    same = nret.dtype == rnum.dtype and nret.dtype.kind in "ui"
    if same and nret.dtype.itemsize < 8:  # compared as they are: no int64 copies
        return (nret > 1) & (rnum < nret)
    return (nret.astype(int) > 1) & (rnum.astype(int) < nret.astype(int))


def _without_low_noise(noise, pts, source, in_place=False):
    """The points left out of the low noise. `in_place`: they are moved to the front
    of `pts` (no copy)."""
    if noise.any():
        keep = ~noise
        if keep.sum() < 8:
            raise InvalidParameterError(f"{source or 'points'}: fewer than 8 points left "
                                        "after removing low outliers")
        pts = pts[:compact_rows(pts, keep)] if in_place else pts[keep]
    return pts


def _permute_columns(pts, order):
    """``pts[:] = pts[order]`` one column at a time: a gather into a column-sized
    temporary, then copied back (independent loads, against a cycle walk's chain of
    dependent ones; a third of the rows' size in memory)."""
    for j in range(pts.shape[1]):
        pts[:, j] = np.take(pts[:, j], order)


def _window_frame(pts, perm, origin, *, in_place):
    """Planimetric and vertical coordinates of the rows `perm` of `pts` minus `origin`:
    ``(xy, z)``, C-contiguous. `in_place`: written over the memory of `pts` (a
    C-contiguous block of rows), the (N, 2) block first and z after it."""
    m = perm.size
    if in_place and pts.flags.c_contiguous:
        cols = [np.subtract(np.take(pts[:, j], perm), origin[j]) for j in range(2)]
        z = np.take(pts[:, 2], perm)
        z -= origin[2]
        flat = pts.reshape(-1)  # a view: the rows are contiguous
        xy = flat[:2 * m].reshape(m, 2)
        for j in range(2):
            xy[:, j] = cols[j]
        del cols
        flat[2 * m:] = z
        return xy, flat[2 * m:]
    xy = np.empty((m, 2))  # column by column: no (N, 2) temporaries
    for j in range(2):
        np.subtract(np.take(pts[:, j], perm), origin[j], out=xy[:, j])
    z = np.take(pts[:, 2], perm)
    z -= origin[2]
    return xy, z


def _attribute(a, name, n, source):
    """A per-point attribute as an array of shape (n,), or None."""
    if a is None:
        return None
    arr = np.asarray(a)
    if arr.shape != (n,):
        raise InvalidParameterError(f"{source or 'points'}: `{name}` has shape {arr.shape}; "
                                    f"expected ({n},)")
    return arr


def _usable_intensity(inten, source):
    """Intensity, None when absent or constant (with a warning).

    Integers of up to 32 bits (LAS intensity is 16-bit) keep their type: every step
    that reads them converts its own slice to float64 exactly, so the cloud-sized copy
    is a quarter of a float64 one. Other values become float64.
    """
    if inten is not None:
        if inten.dtype.kind not in "ui" or inten.dtype.itemsize > 4:
            inten = inten.astype(np.float64)
        if inten.dtype.kind == "f" and not np.isfinite(inten).all():
            raise InvalidParameterError(f"{source or 'points'}: `intensity` holds NaN values")
        if np.ptp(inten) == 0:
            inten = None
    if inten is None:
        warnings.warn(f"{source or 'points'}: no usable intensity; classifying by elevation "
                      "alone (no road class)", LidarstatWarning, stacklevel=4)
    return inten


def _expand(dest, low, n, *arrays, fill):
    """Scatter per-point arrays to positions `dest` of ``n`` points; the positions `low`
    (the low noise: every other position is in `dest`) get `fill`."""
    out = []
    for a, f in zip(arrays, fill):
        b = np.empty(n, dtype=a.dtype)
        b[dest] = a
        b[low] = f
        out.append(b)
    return out
