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
from ..stats import chi2_test, z_critical
from . import _curvature_kernels as _ck
from . import _quadric_kernels as _k
from ._curvature_result import CurvatureResult
from ._curvature_scale import climb_into, scale_ladder, walk_ladder
from ._hk import hk_surface_types
from ._noise import (estimate_sigma, estimate_sigma_index, fit_variance_and_spread,
                     resolve_noise)
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
    sigma2 = kernel_array(np.broadcast_to(np.asarray(sigma2, dtype=np.float64), (m,)))
    st = np.empty((m, _ck.NCOL))
    test = Test.parse(test, "test", func="curvature_tests")
    mode = _ck.TEST_PAPER if test == Test.PAPER else _ck.TEST_CALIBRATED
    _ck.curvature_statistics(out["status"], out["npts"], out["beta"], out["cof"], out["stats"],
                             out["frames"], sigma2, mode, st)
    col = {name: st[:, getattr(_ck, "C_" + name)] for name in
           ("K", "H", "KMIN", "KMAX", "SDK", "SDH", "CHI2", "CHI2DF", "S0", "PLANP", "KP",
            "HP")}
    K, H = col["K"], col["H"]
    fitted = out["status"] == _k.OK
    # v'Wv against its (Satterthwaite) chi-square; the kernel writes the statistic per point
    rho = 1.0 if spread is None else np.asarray(spread, dtype=np.float64)
    chi2_p = chi2_test(col["CHI2"] / rho,
                       np.where(col["CHI2DF"] > 0, col["CHI2DF"] / rho, np.nan),
                       alpha=alpha).pvalue
    planar_p, K_p, H_p = col["PLANP"], col["KP"], col["HP"]
    half = alpha / 2
    chi2_pass = fitted & np.isfinite(chi2_p) & ~(chi2_p < alpha)
    planar = ~(planar_p < alpha)
    K_sig = K_p < half
    H_sig = H_p < half
    status = out["status"].copy()
    status[fitted & ~chi2_pass] = FitStatus.MODEL_REJECTED
    surface_type = hk_surface_types(K, H, tested=chi2_pass, planar=planar, K_sig=K_sig,
                                    H_sig=H_sig)
    frames, beta = out["frames"], out["beta"]
    res = {
        "neighbors": out["npts"],
        "z0": beta[:, 0] * frames[:, 2, 2],  # z offset of the fitted point; caller adds z
        "sigma0_sq": col["S0"],
        "chi2_pass": chi2_pass.astype(np.uint8),
        "K": K, "H": H, "kmin": col["KMIN"], "kmax": col["KMAX"],
        "K_sig": (chi2_pass & K_sig).astype(np.uint8),
        "H_sig": (chi2_pass & H_sig).astype(np.uint8),
        "surface_type": surface_type,
        "status": status,
        "dz0": beta[:, 0],
        "chi2_p": chi2_p, "planar_p": planar_p, "K_p": K_p, "H_p": H_p,
        "NormalX": st[:, _ck.C_NX], "NormalY": st[:, _ck.C_NY], "NormalZ": st[:, _ck.C_NZ],
    }
    if minimal_detectable:
        zc = z_critical(alpha / 2)  # two-sided at alpha/2 (Bonferroni), eq. 19
        res["K_min"] = zc * col["SDK"]
        res["H_min"] = zc * col["SDH"]
    return res

def _single_radius(index, *, sigma, noise, alpha, test, frame, sensor, min_neighbors,
                   minimal_detectable, block_size, progress=None, active=None, into=None):
    """The curvature pipeline at the index's radius, block by block; fields in input order.

    `active` (bool per input point) restricts the work to some points (multi-scale); the
    other rows are NaN / unclassified. With `into`, each block's fields go to
    `into(rows, block_fields)` (`rows`: the block's input positions) and nothing is kept
    or returned: a rung of a ladder writes into the chosen fields without a second set of
    fields for the whole cloud.
    """
    radius = index.radius
    active_sorted = None if active is None else active[index.order].astype(np.uint8)
    sensor_local = None if sensor is None else np.asarray(sensor, float) - index.origin
    n = index.n_points
    fields = None
    done = 0
    covariance = "paper" if test == Test.PAPER else "sandwich"
    blocks = index.cell_blocks(block_size)
    # one set of kernel outputs for every block: each block's fields are copied out of it
    largest = max(int(index.cell_start[c1] - index.cell_start[c0]) for c0, c1 in blocks)
    buffers = _allocate(largest)
    for c0, c1 in blocks:
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        out = _run_cells(index, c0, c1, bandwidth=radius, frame=frame, sensor=sensor_local,
                         min_neighbors=min_neighbors, covariance=covariance,
                         active=active_sorted, buffers=buffers)
        sigma2, spread = fit_variance_and_spread(
            out["beta"], out["frames"], sigma, noise=noise, radius=radius,
            points=index.sorted_points[s0:s1], sensor=sensor_local)
        res = curvature_tests(out, sigma2=sigma2, alpha=alpha, test=test,
                              minimal_detectable=minimal_detectable, spread=spread)
        res["z0"] = res["z0"] + index.sorted_points[s0:s1, 2] + index.origin[2]
        if into is not None:
            into(index.order[s0:s1], res)  # the block's input positions
            done += s1 - s0
            if progress is not None:
                progress(done, n)
            continue
        if fields is None:
            fields = {k: np.empty(n, dtype=v.dtype) for k, v in res.items()}
        for k, v in res.items():  # sorted order: contiguous slices
            fields[k][s0:s1] = v
        done += s1 - s0
        if progress is not None:
            progress(done, n)
    if fields is not None:
        for k in list(fields):  # one permutation per field, each replaced as it is done
            fields[k] = index.to_input_order(fields[k])
    return fields


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
    dup = find_duplicates(pts)
    if dup.any:  # every location once, its result to every point at it (_duplicates)
        res = run_on_unique(dup, lambda: curvature(
            pts[dup.first], radius=radius, sigma=sigma, alpha=alpha, test=test, frame=frame,
            sensor=sensor, noise=noise, min_neighbors=min_neighbors,
            minimal_detectable=minimal_detectable, power=power, scales=scales,
            block_size=block_size, progress=progress), what=func)
        fields = dict(res.fields)
        fields["status"] = copies_degenerate(
            dup, fields["status"], too_few=FitStatus.TOO_FEW_NEIGHBORS,
            degenerate=FitStatus.DEGENERATE, min_neighbors=min_neighbors)
        return replace(res, fields={k: dup.broadcast(v) for k, v in fields.items()})
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
