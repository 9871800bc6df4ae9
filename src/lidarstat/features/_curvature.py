"""Statistically tested curvature of point clouds (Crosilla et al. 2009), whole pipeline."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from .._shared._choices import Frame, Test
from .._shared._jit import kernel_array
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import CellIndex, copies_degenerate, find_duplicates, run_on_unique

__all__ = ["curvature", "curvature_tests", "estimate_sigma"]
from ..stats import z_critical
from . import _curvature_kernels as _ck
from . import _quadric_kernels as _k
from ._curvature_result import CurvatureResult
from ._curvature_scale import climb_into, scale_ladder, walk_ladder
from ._noise import estimate_sigma, estimate_sigma_index, resolve_noise
from ._quadric import FitStatus, _allocate, _run_cells, check_fit_options

logger = logging.getLogger(__name__)


def curvature_tests(out, *, sigma2, alpha, test, minimal_detectable=False, spread=None):
    """Turn raw kernel outputs of one block into curvature, tests and types.

    Parameters
    ----------
    out : dict
        Kernel outputs (``status``, ``npts``, ``beta``, ``cof``, ``frames``, ``stats``).
    sigma2 : float or (M,) ndarray
        Variance of the heights (see :func:`height_variance`).
    alpha : float
        Significance level.
    test : {'calibrated', 'paper'} or Test
        Which family of tests (see docs/methods/curvature.md).
    minimal_detectable : bool
        Also return ``K_min`` and ``H_min`` (eq. 19).
    spread : float or (M,) ndarray, optional
        Inequality of the height variances across each neighbourhood
        (:func:`fit_factor_spread`, default 1: equal): the chi-square's Satterthwaite
        scale is multiplied by it and its degrees of freedom divided by it.

    Returns
    -------
    dict of per-point arrays named as in ``FIELDS``.
    """
    m = out["status"].size
    given = [kernel_array(np.broadcast_to(np.asarray(v, dtype=np.float64), (m,)))
             for v in (sigma2, 1.0 if spread is None else spread)]
    out = {k: kernel_array(out[k], dtype) for k, dtype in (
        ("status", np.uint8), ("npts", np.int32), ("beta", np.float64), ("cof", np.float64),
        ("stats", np.float64), ("frames", np.float64))}  # the pipeline's array types
    floats, flags, neighbors = _field_arrays(m, minimal_detectable)
    _block_fields(out, _ck.NOISE_GIVEN, *given, None, None,
                  _params(np.nan, np.nan, alpha, minimal_detectable), test,
                  np.arange(m, dtype=np.int64), floats, flags, neighbors)
    return _as_fields(floats, flags, neighbors)  # z0 relative: the caller adds the height


#: ``Noise`` value -> the noise model of ``_curvature_kernels.curvature_fields``.
_NOISE_CODES = {"z": _ck.NOISE_Z, "range": _ck.NOISE_RANGE, "normal": _ck.NOISE_NORMAL}
_NO_POINTS = np.zeros((0, 3))
_NO_VALUES = np.zeros(0)


def _params(sigma, radius, alpha, minimal_detectable, origin_z=0.0):
    zc = z_critical(alpha / 2) if minimal_detectable else np.nan  # eq. 19
    return (float(sigma), float(radius), float(alpha), float(zc), float(origin_z))


def _field_arrays(n, minimal_detectable, spare=False):
    """The float64 rows, uint8 rows and neighbour counts of `n` points' fields (with
    `spare`, one more row ahead of each matrix's)."""
    nf = _ck.NFLOAT + (2 if minimal_detectable else 0) + spare
    return (np.empty((nf, n)), np.empty((_ck.NBYTE + spare, n), dtype=np.uint8),
            np.empty(n, dtype=np.int32))


def _as_fields(floats, flags, neighbors):
    """The fields (views of the rows) in the order of ``FIELDS``."""
    f, b = floats, flags
    res = {"neighbors": neighbors, "z0": f[_ck.F_Z0], "sigma0_sq": f[_ck.F_S0],
           "chi2_pass": b[_ck.B_CHI2PASS], "K": f[_ck.F_K], "H": f[_ck.F_H],
           "kmin": f[_ck.F_KMIN], "kmax": f[_ck.F_KMAX], "K_sig": b[_ck.B_KSIG],
           "H_sig": b[_ck.B_HSIG], "surface_type": b[_ck.B_TYPE], "status": b[_ck.B_STATUS],
           "dz0": f[_ck.F_DZ0], "chi2_p": f[_ck.F_CHI2P], "planar_p": f[_ck.F_PLANP],
           "K_p": f[_ck.F_KP], "H_p": f[_ck.F_HP], "NormalX": f[_ck.F_NX],
           "NormalY": f[_ck.F_NY], "NormalZ": f[_ck.F_NZ]}
    if floats.shape[0] > _ck.NFLOAT:
        res["K_min"] = f[_ck.F_KMIN_DET]
        res["H_min"] = f[_ck.F_HMIN_DET]
    return res


def _block_fields(out, noise, sigma2, spread, points, sensor, params, test, dest, floats,
                  flags, neighbors):
    """One call of the fields kernel on a block of fits (:func:`_ck.curvature_fields`)."""
    test = Test.parse(test, "test", func="curvature_tests")
    mode = _ck.TEST_PAPER if test == Test.PAPER else _ck.TEST_CALIBRATED
    _ck.curvature_fields(out["status"], out["npts"], out["beta"], out["cof"], out["stats"],
                         out["frames"], _NO_POINTS if points is None else points,
                         np.zeros(3) if sensor is None else sensor, noise, sigma2, spread,
                         params, mode, dest, floats, flags, neighbors)


def _single_radius(index, *, sigma, noise, alpha, test, frame, sensor, min_neighbors,
                   minimal_detectable, block_size, progress=None, active=None, into=None):
    """The curvature pipeline at the index's radius, block by block; fields in input order.

    `active` (bool per input point) restricts the work to some points (multi-scale); the
    other rows are NaN / unclassified. With `into`, each block's fields go to
    `into(rows, block_fields)` (`rows`: the block's input positions) and nothing is kept
    or returned: a rung of a ladder writes into the chosen fields without a second set of
    fields for the whole cloud. Otherwise each block's fields are written by the fields
    kernel straight into their input positions.
    """
    radius = index.radius
    active_sorted = None if active is None else active[index.order].astype(np.uint8)
    sensor_local = None if sensor is None else np.asarray(sensor, float) - index.origin
    n = index.n_points
    done = 0
    covariance = "paper" if test == Test.PAPER else "sandwich"
    blocks = index.cell_blocks(block_size)
    # one set of kernel outputs for every block: each block's fields are copied out of it
    largest = max(int(index.cell_start[c1] - index.cell_start[c0]) for c0, c1 in blocks)
    buffers = _allocate(largest)
    params = _params(sigma, radius, alpha, minimal_detectable, index.origin[2])
    code = _NOISE_CODES[str(noise)]
    if into is None:  # the fields in sorted order, a spare row ahead of each matrix
        floats, flags, neighbors = _field_arrays(n, minimal_detectable, spare=True)
        arrays = (floats[1:], flags[1:], neighbors)
        positions = np.arange(n, dtype=np.int64)
    for c0, c1 in blocks:
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        out = _run_cells(index, c0, c1, bandwidth=radius, frame=frame, sensor=sensor_local,
                         min_neighbors=min_neighbors, covariance=covariance,
                         active=active_sorted, buffers=buffers)
        if into is None:
            _block_fields(out, code, _NO_VALUES, _NO_VALUES, index.sorted_points[s0:s1],
                          sensor_local, params, test, positions[s0:s1], *arrays)
        else:
            block = _field_arrays(s1 - s0, minimal_detectable)  # the block's own rows
            _block_fields(out, code, _NO_VALUES, _NO_VALUES, index.sorted_points[s0:s1],
                          sensor_local, params, test, np.arange(s1 - s0, dtype=np.int64),
                          *block)
            into(index.order[s0:s1], _as_fields(*block))
        done += s1 - s0
        if progress is not None:
            progress(done, n)
    if into is not None:
        return None
    # to input order, one field at a time: row k + 1 scattered into row k (one stream of
    # writes into one field's pages at a time, no second set of fields)
    for rows in (floats, flags):
        for k in range(rows.shape[0] - 1):
            index.to_input_order(rows[k + 1], out=rows[k])
    return _as_fields(floats[:-1], flags[:-1], index.to_input_order(neighbors))


def _on_unique(dup, pts, again):
    """:func:`curvature` (arguments `again`) of the unique cloud, each location's result
    to its points."""
    res = run_on_unique(dup, lambda: curvature(pts[dup.first], **again), what="curvature")
    fields = dict(res.fields)
    fields["status"] = copies_degenerate(
        dup, fields["status"], too_few=FitStatus.TOO_FEW_NEIGHBORS,
        degenerate=FitStatus.DEGENERATE, min_neighbors=again["min_neighbors"])
    return replace(res, fields={k: dup.broadcast(v) for k, v in fields.items()})


def curvature(points, *, radius=None, sigma=None, alpha=0.05, test="calibrated", frame="pca",
              sensor=None, noise=None, min_neighbors=7, minimal_detectable=False, power=0.9,
              scales=None, block_size=131072, progress=None) -> CurvatureResult:
    """Statistically tested curvature and HK surface type of every point.

    Fits the weighted quadric of Crosilla et al. (2009) in a 3-D sphere around every
    point, tests it against the measurement noise, computes K, H and the principal
    curvatures, tests their significance and assigns HK surface types. Works block by
    block in a spatially sorted order, so memory does not grow with the number of
    neighbour pairs of the whole cloud.

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (any magnitude: a local origin is subtracted).
    radius : float or sequence of float, optional
        Bandwidth b (sphere radius, > 0). Several radii give the paper's multi-scale
        strategy: per point, the smallest radius whose model is accepted. Default: the
        automatic scale, per point the smallest radius of a ladder (`scales`) whose tests
        detect the curvature seen with probability `power`, else the largest one whose
        model is accepted (field ``radius``; docs/methods/curvature.md).
    sigma : float, optional
        Measurement standard deviation along the noise direction. If None it is
        estimated (:func:`estimate_sigma`, at the smallest radius).
    alpha : float
        Significance level of every test (individual K, H tests use alpha/2, Bonferroni).
    test : {'calibrated', 'paper'} or Test
        ``'paper'``: eq. 6, 7, 16-18 as printed. ``'calibrated'`` (default): the sandwich
        covariance of the WLS estimator, a Satterthwaite chi-square for v'Wv, an exact
        chi2(3) test of the second-order terms for planarity, and tests of the principal
        curvatures for K (see docs/methods/curvature.md).
    frame : {'pca', 'auto', 'z'} or Frame
        Local height axis (see :func:`fit_quadrics`); ``'pca'`` (default) follows the
        surface at any orientation, ``'z'`` is the paper's.
    sensor : (3,) array_like, optional
        Scanner position to orient normals (and the sign of H) toward.
    noise : {'z', 'range', 'normal'} or Noise, optional
        Direction of the measurement noise `sigma`: along z (airborne, range images),
        along the sensor ray (terrestrial; needs `sensor`) or isotropic. Default
        ``'range'`` when `sensor` is given, else ``'z'``. See :func:`height_variance`.
    min_neighbors : int
        Minimum neighbours (>= 7 so that the chi-square test has a degree of freedom).
    minimal_detectable : bool
        Also return ``K_min`` and ``H_min`` (eq. 19).
    spread : float or (M,) ndarray, optional
        Inequality of the height variances across each neighbourhood
        (:func:`fit_factor_spread`, default 1: equal): the chi-square's Satterthwaite
        scale is multiplied by it and its degrees of freedom divided by it.
    power : float
        Automatic scale: detection probability the chosen radius must give the curvature
        seen (eq. 19-21 per point), in [0.5, 1).
    scales : sequence of float, optional
        Automatic scale: the ladder of radii (default :func:`scale_ladder`, 3 to 8.5 point
        spacings).
    block_size : int
        Approximate points per processing block.
    progress : callable(done, total), optional
        Called after each block.

    Returns
    -------
    CurvatureResult

    Examples
    --------
    >>> from lidarstat.synth import make_surface
    >>> from lidarstat.features import curvature
    >>> cloud = make_surface("cylinder", sigma=0.001, rng=0)
    >>> res = curvature(cloud.xyz, sigma=0.001, alpha=0.01)
    >>> interior = cloud.edge_distance > 0.25
    >>> bool((res["surface_type"][interior] == 2).mean() > 0.95)   # parabolic ridge
    True
    """
    func = "curvature"
    pts = check_points(points)
    automatic = radius is None
    if automatic:
        power = check_scalar(power, "power", func=func, low=0.5, high=1.0, closed="left")
        if scales is not None:
            scales = np.atleast_1d(np.asarray(scales, dtype=object))
            scales = tuple(sorted(check_scalar(r, "scales", func=func, low=0.0)
                                  for r in scales))
            if not scales:
                raise InvalidParameterError(f"The 'scales' parameter of {func} must not be empty.")
    else:
        radii = np.atleast_1d(np.asarray(radius, dtype=object))
        radii = tuple(sorted(check_scalar(r, "radius", func=func, low=0.0) for r in radii))
        if not radii:
            raise InvalidParameterError(f"The 'radius' parameter of {func} must not be empty.")
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    test = Test.parse(test, "test", func=func)
    frame = Frame.parse(frame, "frame", func=func)
    noise = resolve_noise(noise, sensor, func=func)
    check_fit_options(func, frame=frame, covariance="sandwich", min_neighbors=min_neighbors,
                      sensor=sensor)
    block_size = check_scalar(block_size, "block_size", func=func, low=1, closed="left",
                              integer=True)
    again = dict(radius=radius, sigma=sigma, alpha=alpha, test=test, frame=frame,
                 sensor=sensor, noise=noise, min_neighbors=min_neighbors,
                 minimal_detectable=minimal_detectable, power=power, scales=scales,
                 block_size=block_size, progress=progress)  # the call, for the unique cloud
    index = None
    if not automatic:
        # the index proves distinct locations cell by cell; only a possible copy sends the
        # cloud to the exact check (the automatic ladder measures the unique cloud first)
        index = CellIndex(pts, radii[0])
    if index is None or index.may_have_copies():
        dup = find_duplicates(pts)
        if dup.any:  # every location once, its result to every point at it (_duplicates)
            del index
            return _on_unique(dup, pts, again)
    if automatic:
        radii = scales if scales is not None else scale_ladder(pts)
        index = CellIndex(pts, radii[0])
    estimated = sigma is None
    if estimated:
        # at the middle rung of the automatic ladder: the 3-D sphere censors the largest
        # residuals when the noise is a sizeable part of the radius
        est_radius = radii[len(radii) // 2] if automatic else radii[0]
        est_index = index if est_radius == radii[0] else CellIndex(pts, est_radius)
        sigma = estimate_sigma_index(est_index, noise=noise, frame=frame, sensor=sensor,
                                     min_neighbors=min_neighbors)
        del est_index  # an index of its own at the middle rung: not kept during the fits
        logger.info("estimated sigma = %g", sigma)
        if not sigma > 0:
            raise InvalidParameterError(
                f"{func}: the estimated sigma is {sigma}: the points lie exactly on quadrics; "
                "give `sigma` explicitly"
            )
    else:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    kw = dict(sigma=sigma, noise=noise, alpha=alpha, test=test, frame=frame, sensor=sensor,
              min_neighbors=min_neighbors, minimal_detectable=minimal_detectable,
              block_size=block_size)
    n = pts.shape[0]
    if automatic:
        steps = len(radii)
        first = [index]  # the first rung's index, dropped once that rung is fitted
        del index

        def run(r, active, into):
            k = radii.index(r)
            prog = None if progress is None else (
                lambda done, total: progress(k * total + done, steps * total))
            idx = first.pop() if k == 0 else CellIndex(pts, r)
            return _single_radius(idx, active=active, progress=prog, into=into, **kw)

        fields, chosen = walk_ladder(run, radii, n=n, alpha=alpha, power=power)
        fields["radius"] = chosen
        if progress is not None:
            progress(n, n)
    else:
        fields = _single_radius(index, progress=progress, **kw)
        del index
        if len(radii) > 1:
            chosen = np.full(n, radii[0])
            pending = fields["chi2_pass"] == 0
            for r in radii[1:]:
                if not pending.any():
                    break
                _single_radius(CellIndex(pts, r), active=pending, **kw,
                               into=climb_into(fields, chosen, pending, r,
                                               stop=lambda res, take: take))
            fields["radius"] = chosen
    return CurvatureResult(fields=fields, radius=radii[0] if len(radii) == 1 and not automatic
                           else radii, sigma=float(sigma), sigma_estimated=estimated,
                           alpha=alpha, test=test, frame=frame, noise=noise,
                           min_neighbors=int(min_neighbors),
                           minimal_detectable=bool(minimal_detectable),
                           automatic=automatic, power=float(power) if automatic else None)
