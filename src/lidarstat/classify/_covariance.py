"""Surface / edge / boundary classification from covariance features (seed 003), with tests.

Three tests, each written beside the label as a p-value (docs/methods/covariance.md):

1. *Low curvature* - is the neighbourhood a plane with the measurement noise sigma? Under
   that hypothesis ``(n - 1) lambda0 / sigma^2 ~ chi2(n - 3)`` (lambda0 is the residual
   variance of the total-least-squares plane). Accepted -> surface. This is the paper's
   surface-variation threshold made automatic; a user threshold on ``SurfaceVariation``
   overrides it.
2. *Consistent curvature* - where the plane is rejected, is the neighbourhood a smooth
   curved surface? ``'cylinder'`` (default): a circular cylinder fitted along the
   minimum-curvature direction, its weighted residuals against ``chi2``;
   ``'variation'``: the paper's variance of curvature (eq. 5) as the squared coefficient
   of variation ``R = var(SV) / mean(SV)^2``, against the log-normal null fitted to the
   scan's own accepted planes. Accepted -> surface (curved or rough: pipes, corrugated
   roofs); rejected -> edge. A user threshold on ``CurvatureVariance`` overrides it.
3. *Boundary* - is the neighbourhood cut by the end of the visible surface?
   ``'centroid'`` (the paper's eq. 6-8, the default without a sensor): Hotelling's T^2 of
   the centroid against the index point in the tangent plane, with the factor n the
   paper's eq. 6 omits, on surface points. ``'grid'`` (the default with a sensor): the
   distance to the end of the visible surface estimated on the scan grid
   (:mod:`._grid_boundary`); a point closer than ``border_band`` of its neighbourhood's
   reach is a boundary, boundary winning over edge.
"""

from __future__ import annotations

import enum
import math

import numpy as np

from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import Noise, PointClass, height_variance
from ._covariance_noise import (estimate_plane_sigma, estimate_range_noise,
                                estimate_smooth_range_noise, noise_sensor)
from ._covariance_result import CovarianceClasses, CovarianceClassification
from ._covariance_tests import (BORDER_BAND, BOUNDARY_ALPHA, CURVED_ALPHA, JUMP_ALPHA,
                                _feature_points, boundary_test, curved_surface_test,
                                fit_variation_null, grid_cylinders, plane_test,
                                variation_ratio, variation_test)


class BoundaryTest(str, enum.Enum):
    """The boundary test of :func:`classify_covariance` (``--boundary``)."""

    #: The end of the visible surface on the scan grid (needs a sensor and the points).
    GRID = "grid"
    #: The paper's centroid test (eq. 6-8, with the factor n).
    CENTROID = "centroid"

    def __str__(self):
        return self.value


class CurvedTest(str, enum.Enum):
    """The consistent-curvature test of :func:`classify_covariance` (``--curved``)."""

    #: A circular cylinder fitted to the neighbourhood, its residuals tested.
    CYLINDER = "cylinder"
    #: The paper's variance of curvature (eq. 5) as a ratio test against the scan's planes.
    VARIATION = "variation"

    def __str__(self):
        return self.value


#: Directions of the noise `sigma` the classification models (the shared noise model).
NOISE = tuple(m.value for m in Noise)


def across_sigma(features, sigma, noise):
    """Noise std across each neighbourhood's plane for noise `sigma` along the direction
    `noise`: ``sigma |d . n|``, the shared model
    (:func:`lidarstat.features.height_variance` with the neighbourhood's normal as the
    frame axis; with a sensor ``|d . n|`` is the features' ``ray_cos``)."""
    sigma = np.asarray(sigma, dtype=np.float64)
    if noise == "range":
        return sigma * features.ray_cos
    frames = np.zeros((len(features), 3, 3))
    frames[:, 2, :] = features.normals
    with np.errstate(invalid="ignore"):
        return sigma * np.sqrt(height_variance(frames, 1.0, noise=noise))


def _grid_test(pts, features, along, meta, *, jump_alpha, smooth_alpha, cylinders):
    """The ``'grid'`` boundary test's fields (:mod:`._grid_boundary`)."""
    from ._grid_boundary import grid_boundary
    from ._scan_grid import grid_edges

    grid = grid_edges(pts, features.sensor, along)
    meta["grid_step"] = grid["step"]
    out = {"jump_z": grid["jump_z"], "jump_p": grid["jump_p"]}
    out.update(grid_boundary(pts, features.sensor, features.normals, along, grid=grid,
                             jump_alpha=jump_alpha, smooth_alpha=smooth_alpha,
                             cylinders=cylinders))
    return out


def _noise_scale(features, points, sigma, noise, meta, func):
    """The plane test's sigma (given or estimated) and whether it was estimated."""
    f = features.fields
    evals = features.eigenvalues
    counts = f["neighbors"].astype(np.float64)
    n = counts.size
    if sigma is None and noise == "range":
        if points is None:
            raise InvalidParameterError(
                f"{func}: the range noise is estimated from the `points` (give them, or "
                "`sigma`)")
        a, b = estimate_smooth_range_noise(points, features)
        # the segmentation's scale for whole-segment models (see segment_covariance)
        am, bm = estimate_range_noise(evals, counts, features.ray_range, features.ray_cos)
        meta["segment_range_noise"] = (am, bm)
        meta["segment_sigma"] = np.maximum(am + bm * features.ray_range,
                                           a + b * features.ray_range)
        meta["range_noise"] = (a, b)
        sigma = a + b * features.ray_range
        if not np.all(sigma > 0):
            raise InvalidParameterError(
                f"{func}: the estimated noise is 0 (the neighbourhoods are exact planes or "
                "lines); give `sigma` or thresholds")
        return sigma, True
    if sigma is None:
        sigma = estimate_plane_sigma(evals, counts, across_sigma(features, 1.0, noise))
        if not sigma > 0:
            raise InvalidParameterError(
                f"{func}: the estimated noise is 0 (the neighbourhoods are exact planes or "
                "lines); give `sigma` or thresholds")
        return sigma, True
    if np.ndim(sigma) == 0:
        return check_scalar(sigma, "sigma", func=func, low=0.0), False
    sigma = np.asarray(sigma, dtype=np.float64)
    if sigma.shape != (n,) or not (np.isfinite(sigma).all() and (sigma > 0).all()):
        raise InvalidParameterError(
            f"The 'sigma' parameter of {func} must be a positive float or {n} positive "
            "values.")
    return sigma, False


def classify_covariance(features, *, sigma=None, noise=None, alpha=0.05,
                        boundary_alpha=None, curvature_threshold=None,
                        variance_threshold=None, points=None, curved=None,
                        curved_alpha=None, boundary=None, jump_alpha=JUMP_ALPHA,
                        border_band=BORDER_BAND) -> CovarianceClasses:
    """Label every point surface, edge or boundary from its covariance features.

    Parameters
    ----------
    features : CovarianceResult
        From :func:`lidarstat.features.covariance_features`.
    sigma : float or (N,) array_like, optional
        Noise standard deviation (per point allowed) along the direction `noise`.
        Default: estimated, by :func:`estimate_plane_sigma` (``'z'``, ``'normal'``) or, for ``'range'``, as the model ``a + b r`` from the
        residuals of the best smooth model (cylinder or plane) of every neighbourhood
        (:func:`estimate_smooth_range_noise`, which needs the `points`).
    noise : Noise or {'z', 'range', 'normal'}, optional
        Direction of the noise `sigma` (the shared noise model): across a neighbourhood
        of normal n the plane test's noise is ``sigma |d . n|``. ``'range'`` (default
        when the features were computed with a sensor): along the scanner's rays, so
        ``sigma |cos theta|`` at incidence theta - terrestrial scans, where a single
        normal sigma would call the walls facing the scanner rough and the grazing
        ground smooth. ``'z'`` (default without a sensor): along z, ``sigma |n_z|`` -
        range images and airborne scans, whose steep faces are smoother across than
        the height noise. ``'normal'``: across the surface (isotropic noise).
    alpha : float
        Level of the plane test (and of the variation test, whose level defaults to it).
    boundary_alpha : float, optional
        Level of the centroid boundary test [0.001: it runs on every surface point, so a
        small level keeps false boundaries rare]. Refused with the ``'grid'`` test.
    curvature_threshold : float, optional
        Paper mode: SurfaceVariation above this is "high curvature" (replaces test 1).
    variance_threshold : float, optional
        Paper mode: CurvatureVariance above this is an edge (replaces test 2; the
        paper used 0.0001).
    points : (N, 3) array_like, optional
        The coordinates the features were computed on; needed by ``curved='cylinder'``,
        the ``'grid'`` test and the range-noise estimate.
    curved : CurvedTest or {'cylinder', 'variation'}, optional
        Test 2, where the plane is rejected: ``'cylinder'`` (default when `points` are
        given) fits a circular cylinder along the minimum-curvature direction and tests
        its weighted residuals against chi-square
        (:func:`lidarstat.features.cylinder_test`); ``'variation'`` is the paper's
        variance of curvature as a ratio test against the scan's own planes.
    curved_alpha : float, optional
        Level of test 2 (rejected -> edge). Default: 0.001 (``CURVED_ALPHA``) for the
        cylinder test, `alpha` for the variation test.
    boundary : BoundaryTest or {'grid', 'centroid'}, optional
        Test 3. ``'grid'`` (default when the features were computed with a sensor): the
        distance to the estimated end of the visible surface on the scan grid (a missing
        return, the scan window, or a depth jump rejected by the continuity test between
        two surfaces resolved on both sides; :mod:`lidarstat.classify._grid_boundary`); a
        point closer than `border_band` times its neighbourhood's reach is a boundary,
        whatever its surface tests say; writes ``jump_z``, ``jump_p``,
        ``border_distance``, ``border_kind``, ``border_p``. ``'centroid'`` (default
        without a sensor): the paper's eq. 6-8 (with the factor n) in the tangent plane,
        on surface points; writes ``boundary_T2``, ``boundary_p``.
    jump_alpha : float
        ``'grid'`` test: level of the range-continuity test of one grid edge.
    border_band : float
        ``'grid'`` test: the share of the neighbourhood's reach within which the end of
        the visible surface makes a boundary (0.5: about a fifth of the neighbourhood's
        disc is then missing).

    Returns
    -------
    CovarianceClasses

    Notes
    -----
    Points with fewer than 4 neighbours stay undetermined (0).
    """
    func = "classify_covariance"
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    has_sensor = getattr(features, "sensor", None) is not None
    if boundary is None:
        boundary = BoundaryTest.GRID if has_sensor else BoundaryTest.CENTROID
    boundary = BoundaryTest(check_option(boundary, "boundary",
                                         [b.value for b in BoundaryTest], func=func))
    grid = boundary is BoundaryTest.GRID
    if grid and not has_sensor:
        raise InvalidParameterError(f"{func}: boundary='grid' needs features computed "
                                    "with a sensor")
    if grid and points is None:
        raise InvalidParameterError(f"{func}: boundary='grid' needs the `points`")
    border_band = check_scalar(border_band, "border_band", func=func, low=0.0,
                               closed="neither")
    jump_alpha = check_scalar(jump_alpha, "jump_alpha", func=func, low=0.0, high=1.0,
                              closed="neither")
    if grid and boundary_alpha is not None:
        raise InvalidParameterError(
            f"{func}: boundary_alpha is the level of the 'centroid' test; the 'grid' test "
            "uses border_band and jump_alpha")
    if not grid:
        boundary_alpha = check_scalar(BOUNDARY_ALPHA if boundary_alpha is None else
                                      boundary_alpha, "boundary_alpha", func=func, low=0.0,
                                      high=1.0)
    if curvature_threshold is not None:
        curvature_threshold = check_scalar(curvature_threshold, "curvature_threshold",
                                           func=func, low=0.0, closed="left")
    if variance_threshold is not None:
        variance_threshold = check_scalar(variance_threshold, "variance_threshold", func=func,
                                          low=0.0, closed="left")
    if noise is None:
        noise = Noise.RANGE if has_sensor else Noise.Z
    noise = str(Noise.parse(noise, "noise", func=func))
    if noise == "range" and not has_sensor:
        raise InvalidParameterError(f"{func}: noise='range' needs features computed with a sensor")
    if curved is None:
        curved = CurvedTest.CYLINDER if points is not None else CurvedTest.VARIATION
    curved = CurvedTest(check_option(curved, "curved", [c.value for c in CurvedTest],
                                     func=func))
    f = features.fields
    evals = features.eigenvalues
    counts = f["neighbors"].astype(np.float64)
    n = counts.size
    if points is not None:
        points = _feature_points(points, n, func)
    meta = {"noise": noise, "boundary": boundary.value}
    sigma, estimated = _noise_scale(features, points, sigma, noise, meta, func)
    valid = (counts >= 4) & np.isfinite(evals).all(axis=1)
    across = across_sigma(features, sigma, noise)
    # the point the noise runs from, for the models that weight each neighbour by its
    # own noise (cylinder fits, segment models): the sensor, or a point far up for 'z'
    meta["noise_sensor"] = noise_sensor(noise, features.sensor, points)
    plane_p = plane_test(evals, counts, across)
    if curvature_threshold is None:
        low = plane_p >= alpha
    else:
        low = f["SurfaceVariation"] <= curvature_threshold
    meta["curved"] = curved.value
    if curved_alpha is None:
        curved_alpha = CURVED_ALPHA if curved is CurvedTest.CYLINDER else alpha
    curved_alpha = check_scalar(curved_alpha, "curved_alpha", func=func, low=0.0, high=1.0)
    meta["curved_alpha"] = curved_alpha
    if curved is CurvedTest.CYLINDER:
        if points is None:
            raise InvalidParameterError(f"{func}: curved='cylinder' needs the `points`")
        variation_p = np.full(n, np.nan)
        curv_radius = np.full(n, np.nan)
        cyl_centre = np.full((n, 3), np.nan)
        cyl_axis = np.full((n, 3), np.nan)
        query = np.flatnonzero(valid & ~low)
        if query.size:
            variation_p[query], curv_radius[query], cyl_centre[query], cyl_axis[query] = \
                curved_surface_test(points, features, query, sigma,
                                    sensor=meta["noise_sensor"], return_model=True)
        meta["curvature_radius"] = curv_radius
        # the fitted cylinders (a point of the axis, the unit axis), with the radius the
        # model on which the 'grid' test places the borders of curved-surface nodes
        meta["curvature_centre"] = cyl_centre
        meta["curvature_axis"] = cyl_axis
        variation_p[valid & low] = 1.0  # not tested: the plane is accepted
    else:
        ratio = variation_ratio(features.mean_variation, f["CurvatureVariance"])
        mu, sd = fit_variation_null(ratio, valid & low)
        variation_p = variation_test(ratio, mu, sd)
    if variance_threshold is None:
        consistent = variation_p >= curved_alpha
    else:
        consistent = f["CurvatureVariance"] <= variance_threshold
    surface = valid & (low | consistent)
    if grid:
        meta["jump_alpha"] = jump_alpha
        meta["border_band"] = border_band
        along = sigma if noise == "range" else across / np.maximum(features.ray_cos, 0.05)
        cylinders = None
        if curved is CurvedTest.CYLINDER:
            # the border of a node on a consistently curved surface is placed on its
            # fitted cylinder (the silhouette of a pipe), not on its tangent plane
            cylinders = grid_cylinders(meta, valid & ~low & consistent)
        extra = _grid_test(points, features, along, meta, jump_alpha=jump_alpha,
                           smooth_alpha=alpha, cylinders=cylinders)
        with np.errstate(invalid="ignore"):
            # the end of the visible surface within border_band of the neighbourhood's
            # reach: a missing return, the scan window or a tested depth jump between two
            # resolved surfaces (boundary wins over edge, as in the truth)
            one_sided = valid & (extra["border_distance"]
                                 < border_band * features.scan_boundary[:, 3])
    else:
        t2, boundary_p = boundary_test(features.offset_uv, evals, counts)
        extra = {"boundary_T2": t2, "boundary_p": boundary_p}
        with np.errstate(invalid="ignore"):
            one_sided = surface & (boundary_p < boundary_alpha)
    pc = np.zeros(n, dtype=np.uint8)
    pc[valid] = PointClass.EDGE
    pc[surface] = PointClass.SURFACE
    pc[one_sided] = PointClass.BOUNDARY
    fields = {"point_class": pc, "plane_p": plane_p, "variation_p": variation_p, **extra}
    return CovarianceClasses(fields=fields, sigma=sigma, sigma_estimated=estimated, alpha=alpha,
                             boundary_alpha=boundary_alpha,
                             curvature_threshold=curvature_threshold,
                             variance_threshold=variance_threshold, meta=meta)


def covariance(points, *, k=None, radius=None, sensor=None, sigma=None, noise=None, alpha=0.05,
               boundary=None, boundary_alpha=None, jump_alpha=JUMP_ALPHA,
               border_band=BORDER_BAND, curved="cylinder", curved_alpha=None,
               curvature_threshold=None, variance_threshold=None, eigen_mode="raw",
               keep_neighbors=False, progress=None):
    """Covariance features and surface / edge / boundary classes of every point (seed 003).

    One call of :func:`lidarstat.features.covariance_features` and
    :func:`classify_covariance`; see them for the parameters. Without `k` and `radius`
    every point gets its own neighbourhood size (:func:`_tested_features`; fields
    ``OptimalKNN``, ``OptimalRadius``); with a `curvature_threshold` (no noise model) the
    minimum-eigenentropy size of :func:`lidarstat.features.covariance_features`.

    Returns
    -------
    CovarianceClassification

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.classify import covariance
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 10, (5000, 2))
    >>> pts = np.c_[xy, rng.normal(0, 0.002, 5000)]
    >>> res = covariance(pts, k=30)
    >>> inside = (np.abs(xy - 5) < 4).all(axis=1)
    >>> bool((res.point_class[inside] == 1).mean() > 0.85)
    True
    """
    from ..features import covariance_features
    from ..neighbors import (find_duplicates, map_rows, max_pairs, refuse_dominated,
                             run_on_unique)

    pts = check_points(points)
    opts = dict(sigma=sigma, noise=noise, alpha=alpha, boundary=boundary,
                boundary_alpha=boundary_alpha, jump_alpha=jump_alpha,
                border_band=border_band, curved=curved, curved_alpha=curved_alpha,
                curvature_threshold=curvature_threshold,
                variance_threshold=variance_threshold)
    dup = find_duplicates(pts)
    if dup.any and keep_neighbors:
        # the neighbourhoods of every point are kept: each copy is searched, so a cloud
        # dominated by copies is refused (as by the segmentations that need them)
        refuse_dominated(dup, what="covariance with keep_neighbors",
                         max_copies=math.isqrt(max_pairs()))
    elif dup.any:
        # every location once, its result to every point at it (neighbors/_duplicates.py)
        res = run_on_unique(dup, lambda: covariance(
            pts[dup.first], k=k, radius=radius, sensor=sensor, eigen_mode=eigen_mode,
            progress=progress, **opts), what="covariance")
        return map_rows(res, dup.n_unique, dup.inverse)
    if k is None and radius is None and curvature_threshold is None:
        feats = _tested_features(pts, sensor=sensor, sigma=sigma, noise=noise, alpha=alpha,
                                 eigen_mode=eigen_mode, keep_neighbors=keep_neighbors,
                                 progress=progress)
    else:
        feats = covariance_features(points, k=k, radius=radius, sensor=sensor,
                                    eigen_mode=eigen_mode, keep_neighbors=keep_neighbors,
                                    progress=progress)
    classes = classify_covariance(feats, points=points, **opts)
    return CovarianceClassification(features=feats, classes=classes)


def _tested_features(pts, *, sensor, sigma, noise, alpha, eigen_mode, keep_neighbors,
                     progress):
    """Features at the tested scale: the smallest of a point's 20 to 50 nearest-neighbour
    prefixes whose plane test detects a crease with power, else all 50
    (:func:`lidarstat.features.tested_scale`), with the noise given or estimated on the
    k = 50 neighbourhoods (:func:`_noise_scale`)."""
    from ..features import OPTIMAL_K_MAX, OPTIMAL_K_MIN, covariance_features, tested_features

    func = "covariance"
    n = pts.shape[0]
    if n < 4:
        raise InvalidParameterError(f"{func}: the automatic scale needs at least 4 points, "
                                    f"got {n}")
    k_max = min(OPTIMAL_K_MAX, n)
    k_min = min(OPTIMAL_K_MIN, k_max)
    full = covariance_features(pts, k=k_max, sensor=sensor)
    if noise is None:
        noise = Noise.RANGE if sensor is not None else Noise.Z
    noise = str(Noise.parse(noise, "noise", func=func))
    if noise == "range" and sensor is None:
        return full  # refused by classify_covariance, with the other methods' message
    scale, _ = _noise_scale(full, pts, sigma, noise, {}, func)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0, closed="neither")
    noise_sensor = full.sensor
    del full  # the rows are searched again block by block (features._covariance_scale_blocks)
    return tested_features(pts, k_max, sigma=scale, noise=noise, sensor=noise_sensor,
                           k_min=k_min, alpha=alpha, eigen_mode=eigen_mode,
                           keep_neighbors=keep_neighbors, progress=progress)
