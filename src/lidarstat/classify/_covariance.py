"""Surface / edge / boundary classification from covariance features (seed 003), with tests.

Three tests, each written beside the label as a p-value (see docs/methods/covariance.md):

1. *Low curvature* - is the neighbourhood a plane with the measurement noise sigma? Under
   that hypothesis ``(n - 1) lambda0 / sigma^2 ~ chi2(n - 3)`` (lambda0 is the residual
   variance of the total-least-squares plane). Accepted -> surface. This is the paper's
   surface-variation threshold made automatic: the critical lambda0 of the test gives, per
   point, the largest surface variation a plane with this noise and this neighbourhood
   size produces. A user threshold on ``SurfaceVariation`` overrides it.
2. *Consistent curvature* (eq. 5) - where the plane is rejected, do the neighbours'
   surface variations differ more than on the cloud's own accepted planes? The statistic
   is the squared coefficient of variation ``R = var(SV) / mean(SV)^2`` over the
   neighbourhood (eq. 5 divided by the squared mean, so that it does not grow with the
   curvature itself). Its null distribution is taken from the data: log R is close to
   normal, with mean and spread fitted to the median and lower quartile of log R over all
   points (the lower half of the distribution is the smooth surfaces of this very scan,
   its sampling and its neighbourhood size; edges only populate the upper tail).
   Accepted -> surface (curved or rough: pipes, corrugated roofs); rejected -> edge.
   A user threshold on ``CurvatureVariance`` overrides it (the paper: 0.0001).
3. *Boundary* (eq. 6-8) - is the index point the centre of its neighbourhood? Hotelling's
   T^2 of the centroid against the index point in the tangent plane,
   ``T2 = n (u^2 / lambda2 + v^2 / lambda1)``, with ``T2 (n - 2) / (2 (n - 1)) ~ F(2, n - 2)``
   under the hypothesis (Johnson and Wichern 2002, the confidence region of a mean).
   The paper's eq. 6 omits the factor n (a prediction region for one point, which no
   boundary point leaves); rejected surface points -> boundary (``boundary='centroid'``).
   ``boundary='scan'``: the same Hotelling test on the *complete disc* of the
   neighbourhood in linearised scan coordinates (:mod:`lidarstat.features._scan_kernels`),
   where an interior point of any scan pattern is the centre of a centrally symmetric set
   of grid nodes. With a sensor and the points the default is ``boundary='grid'``
   (:func:`._visible.grid_boundary`): not a symptom of the border but its
   distance - border points are estimated on the scan grid (no return, the scan window,
   a depth jump the continuity test rejects between two resolved surfaces, unless a
   recess face the grid did not sample explains it; on a pipe at its silhouette) and a
   point closer than ``border_band`` (0.5) of its neighbourhood's reach is a boundary,
   boundary winning over edge; written as ``border_distance`` / ``border_kind`` /
   ``border_p``. ``boundary='visible'`` (:mod:`._visible`): the
   complete disc gathered on the scan grid, over grid edges that pass a
   range-continuity test (a crease keeps the range continuous, an occlusion does not),
   written as ``jump_z`` / ``jump_p``. Both run on surface points (0.05 visible, 0.01
   scan; a surface point with a depth jump at it is a boundary too) and on the points
   that failed the surface tests (0.01 visible, 0.001 scan: a neighbourhood cut by the
   end of the visible surface is a boundary even where it also bends or reaches a
   crease, as on the occluded side of a pipe); with the visible test an edge candidate at
   a depth jump between two surfaces the grid resolves (``jump_resolved_p``) is a
   boundary too.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np
from scipy import special as _sp

from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import PointClass
from ..io import register_field_descriptions

#: Per-point output fields of the classification, name -> (dtype, description).
FIELDS = {
    "point_class": ("uint8", "0 undetermined,1 surface,2 edge,3 boundary"),
    "plane_p": ("float64", "p-value of the chi-square plane (low curvature) test"),
    "variation_p": ("float64", "p-value of the consistent-curvature test"),
    "boundary_T2": ("float64", "Hotelling T2 of the centroid offset"),
    "boundary_p": ("float64", "p-value of the boundary test"),
    "jump_z": ("float64", "largest range-continuity z of the grid edges"),
    "jump_p": ("float64", "p-value: a depth jump at the point"),
    "jump_resolved_p": ("float64", "p-value: a jump between two resolved surfaces"),
    "border_distance": ("float64", "distance to the estimated end of the visible surface"),
    "border_kind": ("uint8", "nearest border: 1 scan window, 2 no return, 3 depth jump"),
    "border_p": ("float64", "continuity-test p-value of the nearest border (0: observed)"),
}
register_field_descriptions(FIELDS)


@dataclass(frozen=True)
class CovarianceClasses:
    """Per-point classes and the tests behind them.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        ``point_class`` and the test fields (``FIELDS``), input order.
    sigma : float or ndarray
        Noise standard deviation used by the plane test (given or estimated).
    sigma_estimated : bool
    alpha, boundary_alpha : float
    curvature_threshold, variance_threshold : float or None
        User thresholds, when given (they replace tests 1 and 2).
    """

    fields: dict
    sigma: float | np.ndarray
    sigma_estimated: bool
    alpha: float
    boundary_alpha: float
    curvature_threshold: float | None = None
    variance_threshold: float | None = None
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    @property
    def point_class(self) -> np.ndarray:
        return self.fields["point_class"]

    def to_fields(self):
        return {k: np.asarray(v, dtype=FIELDS[k][0]) for k, v in self.fields.items()}

    def counts(self) -> dict:
        pc = self.point_class
        return {c.name.lower(): int(np.count_nonzero(pc == c)) for c in PointClass}

    def summary(self) -> str:
        n = self.point_class.size
        sig = (f"{self.sigma:.6g}" if np.ndim(self.sigma) == 0 else
               f"per point (median {np.median(self.sigma):.6g})")
        if "range_noise" in self.meta:
            a, b = self.meta["range_noise"]
            sig = f"along the rays {a:.3g} + {b:.3g} r"
        lines = [f"{n} points, sigma {sig}" + (" (estimated)" if self.sigma_estimated else "")
                 + f", alpha {self.alpha}, boundary alpha {self.boundary_alpha}"
                 + (f" ({self.meta['boundary']} test)" if "boundary" in self.meta else "")]
        if "curved" in self.meta:
            lines.append(f"consistent curvature: {self.meta['curved']} test at "
                         f"{self.meta['curved_alpha']}")
        if self.curvature_threshold is not None:
            lines.append(f"SurfaceVariation threshold {self.curvature_threshold} (user)")
        if self.variance_threshold is not None:
            lines.append(f"CurvatureVariance threshold {self.variance_threshold} (user)")
        for name, k in self.counts().items():
            lines.append(f"  {name:<13s} {k:>10d} {100.0 * k / max(n, 1):6.2f}%")
        return "\n".join(lines)


def estimate_plane_sigma(evals, counts):
    """Robust noise estimate: ``sigma^2 = median((n-1) lambda0) / median(chi2(n-3))``.

    Valid when most neighbourhoods are planar (the median ignores edges and curved parts).
    Uses the median neighbourhood size for the chi-square median.

    Returns
    -------
    float
    """
    n = np.asarray(counts, dtype=np.float64)
    l0 = np.asarray(evals)[:, 0]
    ok = (n >= 4) & np.isfinite(l0)
    if not ok.any():
        raise InvalidParameterError("cannot estimate sigma: no neighbourhood has 4 points")
    ss = (n[ok] - 1) * l0[ok]
    df = float(np.median(n[ok])) - 3
    med = _sp.chdtri(df, 0.5)  # median of chi2(df)
    return float(np.sqrt(np.median(ss) / med))


#: Re-estimations of the range noise on the points its plane test accepts (see
#: :func:`estimate_range_noise`); 0 by default, the plain per-bin medians. The trimmed
#: estimate is the consistent one for "planes with range noise": on tls_plant the median
#: gives b = 2.9e-4 (truth 5e-5: sigma 6.3 mm at 12 m against 2.6 mm) and three
#: re-estimations 9.8e-5, on tls_building both about 5e-5. But on the real pump scan the
#: trimmed estimate converges to the smoothest patches (a = 2.1 mm, b = 1.9e-5 against the
#: median's b = 1.2e-3) and the plane test then calls 41 % of the points edges (28 % with
#: the median): real surfaces are not planes with range noise at the millimetre level.
RANGE_NOISE_ITERATIONS = 0


def _range_line(rho, r, med, bins, keep=None):
    """Least-squares line ``a + b r`` through per-range-bin ``sqrt(median(rho) / med)``."""
    edges = np.unique(np.quantile(r, np.linspace(0, 1, bins + 1)))
    which = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, edges.size - 2)
    rc, sc = [], []
    for b in range(edges.size - 1):
        sel = which == b
        if keep is not None:
            sel &= keep
        if sel.sum() >= 10:
            rc.append(np.median(r[sel]))
            sc.append(np.sqrt(np.median(rho[sel]) / med))
    rc, sc = np.asarray(rc), np.asarray(sc)
    if rc.size == 0:
        return np.nan, 0.0
    if rc.size < 2 or np.ptp(rc) == 0:
        return float(np.median(sc)), 0.0
    b, a = np.polyfit(rc, sc, 1)
    if b < 0:
        return float(np.median(sc)), 0.0
    return float(a), float(b)


def estimate_range_noise(evals, counts, ray_range, ray_cos, *, bins=8,
                         alpha=0.05, iterations=RANGE_NOISE_ITERATIONS):
    """Range-noise model ``sigma_r(r) = a + b r`` of a terrestrial scan, from the data.

    Per point, ``(n-1) lambda0 / cos^2(theta)`` estimates ``sigma_r^2 chi2(n-3)`` on planes
    (theta: angle between ray and normal). Medians in range quantile bins, divided by the
    chi-square median, give ``sigma_r`` per bin; a least-squares line through them gives
    ``a, b`` (b clipped at 0). Points at grazing incidence (cos < 0.2) are left out.
    Then, `iterations` times, the same fit on the points the plane test accepts at
    `alpha` with the current line, their medians divided by the chi-square's
    ``(1 - alpha) / 2`` quantile (the median of a chi-square truncated at its ``1 -
    alpha`` quantile): curved surfaces only raise lambda0, and where they fill most of a
    range bin (pipes and tanks) the plain median follows them.

    Returns
    -------
    a, b : float
    """
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = (n - 1) * evals[:, 0] / ray_cos ** 2
    ok = (n >= 4) & np.isfinite(rho) & (ray_cos >= 0.2)
    if ok.sum() < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    df = float(np.median(n[ok])) - 3
    rho, r, nn = rho[ok], ray_range[ok], n[ok]
    a, b = _range_line(rho, r, _sp.chdtri(df, 0.5), bins)
    trunc = _sp.chdtri(df, 1.0 - (1.0 - alpha) / 2)
    for _ in range(iterations):
        with np.errstate(invalid="ignore", divide="ignore"):
            accepted = rho / (a + b * r) ** 2 < _sp.chdtri(nn - 3, alpha)
        a1, b1 = _range_line(rho, r, trunc, bins, keep=accepted)
        if not (np.isfinite(a1) and a1 + b1 * r.max() > 0 and a1 + b1 * r.min() > 0):
            break
        a, b = a1, b1
    return float(a), float(b)


#: Largest number of points whose cylinder fit enters :func:`estimate_smooth_range_noise`
#: (an even stride through the usable points beyond it): eight range-bin medians need a
#: few thousand, and the fit costs about a tenth of the classification per point.
SMOOTH_NOISE_POINTS = 8000


def estimate_smooth_range_noise(points, features, *, bins=8, max_points=SMOOTH_NOISE_POINTS):
    """Range-noise model ``sigma_r(r) = a + b r`` from the best smooth model of every
    neighbourhood (the default estimate with a sensor).

    :func:`estimate_range_noise` takes per-bin medians of the plane residual ``(n - 1)
    lambda0 / cos^2(theta)``; curved surfaces only raise it, and where pipes and tanks
    fill a range bin the median follows them (tls_plant: b = 2.9e-4 against the true
    5e-5). Here the residual is that of the smooth model of the cylinder test (a circular
    cylinder with its axis tilt fitted, of which the plane is the limit of infinite
    radius): the weighted RSS with unit range noise, each neighbour weighted by ``1 /
    max(|d . rho|, 0.1)^2`` (the share of the range noise across the surface), estimates
    ``sigma_r^2 chi2(n - 5)`` on planes and cylinders alike. Per point it is divided by
    the median of its chi-square; medians in eight range quantile bins and a least-squares
    line through their square roots give ``a, b`` (b clipped at 0), as in
    :func:`estimate_range_noise`. Edges still raise their RSS, but they are a minority in
    every range bin, where curved surfaces were not. Points at grazing incidence (cos
    theta < 0.2) are left out; at most `max_points` points (an even stride) are fitted.

    Parameters
    ----------
    points : (N, 3) ndarray
        The coordinates the features were computed on.
    features : CovarianceResult
        Computed with a sensor.
    bins : int
    max_points : int

    Returns
    -------
    a, b : float
    """
    from ..features import cylinder_test

    n = np.asarray(features.fields["neighbors"], dtype=np.float64)
    ok = (n >= 7) & np.isfinite(features.eigenvalues).all(axis=1) & (features.ray_cos >= 0.2)
    query = np.flatnonzero(ok)
    if query.size < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    if query.size > max_points:
        query = query[np.linspace(0, query.size - 1, max_points).astype(np.int64)]
    indptr, idx = _neighbour_rows(points, features, query)
    stat, dof, _ = cylinder_test(points, query, indptr, idx, _cylinder_axes(features, query),
                                 1.0, sensor=features.sensor, refine_axis=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        s2 = stat / _sp.chdtri(np.where(dof > 0, dof, np.nan), 0.5)
    good = np.isfinite(s2)
    if good.sum() < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    return _range_line(s2[good], features.ray_range[query][good], 1.0, bins)


def plane_test(evals, counts, sigma):
    """p-value of ``(n - 1) lambda0 / sigma^2 ~ chi2(n - 3)`` (upper tail)."""
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        stat = (n - 1) * evals[:, 0] / np.asarray(sigma, dtype=np.float64) ** 2
        df = np.where(n > 3, n - 3, np.nan)
        return _sp.chdtrc(df, stat)


def variation_ratio(mean_sv, var_sv):
    """Squared coefficient of variation of SurfaceVariation over each neighbourhood."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return var_sv / (mean_sv * mean_sv)


def fit_variation_null(ratio, null):
    """Normal model of ``log(ratio)`` on the `null` points: ``(mu, sd)`` from lower quantiles.

    ``mu`` is the median and ``sd = (median - q25) / 0.6745``: the lower half is used
    because the contamination of `null` (neighbourhoods reaching an edge) lies in the
    upper tail, so the fit holds while smooth surfaces are the majority. On planes of many sizes and noise levels log R is
    close to normal (skewness and excess kurtosis below 0.15). Returns NaN when fewer
    than 30 null points.
    """
    r = ratio[null & np.isfinite(ratio) & (ratio > 0)]
    if r.size < 30:
        return np.nan, np.nan
    q25, q50 = np.quantile(np.log(r), [0.25, 0.5])
    return float(q50), float((q50 - q25) / 0.6744897501960817)


def variation_test(ratio, mu, sd):
    """p-value of the consistent-curvature test: ``(log ratio - mu) / sd ~ N(0, 1)``, upper tail."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _sp.ndtr(-(np.log(ratio) - mu) / sd)


def hotelling_p(t2, counts):
    """Upper-tail p-value of a bivariate Hotelling T^2 of a mean from `counts` points:
    ``T2 (n - 2) / (2 (n - 1)) ~ F(2, n - 2)``."""
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = t2 * (n - 2) / (2 * (n - 1))
        return _sp.fdtrc(2.0, np.where(n > 2, n - 2, np.nan), f)


def boundary_test(offset_uv, evals, counts):
    """Hotelling T^2 of the centroid against the index point, and its F p-value."""
    n = np.asarray(counts, dtype=np.float64)
    u, v = offset_uv[:, 0], offset_uv[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        t2 = n * (u * u / evals[:, 2] + v * v / evals[:, 1])
    return t2, hotelling_p(t2, n)


def scan_boundary_test(scan_boundary):
    """The ``'scan'`` boundary test from ``CovarianceResult.scan_boundary``: (T2, p)."""
    t2 = scan_boundary[:, 0]
    return t2, hotelling_p(t2, scan_boundary[:, 1])


#: Default level of the boundary test: it runs on every surface point, so a small level
#: keeps false boundary points rare (alpha = 0.05 would flag 5 % of interior points).
BOUNDARY_ALPHA = 0.001

#: Default level of the ``'scan'`` boundary test. On a scan grid it is conservative (an
#: interior point is the exact centre of its complete disc), so a larger level costs few
#: false boundaries and finds borders farther inside the neighbourhood.
SCAN_BOUNDARY_ALPHA = 0.01

BOUNDARY = ("grid", "visible", "scan", "centroid")

#: Default levels of the ``'visible'`` boundary test (the visible disc on the scan grid,
#: :mod:`._visible`) on surface points and on edge candidates. On a grid the F null is
#: conservative: interior points have T2 = 0 to rounding (a complete disc is centrally
#: symmetric), so the level sets how far inside the disc a border is seen, not a rate of
#: false boundaries (measured: docs/methods/covariance.md).
VISIBLE_BOUNDARY_ALPHA = 0.05
VISIBLE_EDGE_BOUNDARY_ALPHA = 0.01

#: Level of the range-continuity test of one grid edge (a depth jump cuts the visible
#: disc there).
JUMP_ALPHA = 0.001

#: The ``'grid'`` boundary test: a point is a boundary when the estimated end of its visible
#: surface is closer than this share of its neighbourhood's reach (about a fifth of the
#: neighbourhood's disc is then missing; docs/methods/covariance.md).
BORDER_BAND = 0.5

#: Default level of the ``'scan'`` boundary test on the points that failed the surface
#: tests (edge candidates): a neighbourhood cut by the end of the visible surface is a
#: boundary even where it also bends (a pipe's occluded side); stricter than
#: ``SCAN_BOUNDARY_ALPHA`` because beside a crease the complete disc is smaller.
EDGE_BOUNDARY_ALPHA = 0.001

NOISE = ("normal", "range")
NOISE_ESTIMATE = ("smooth", "median")
CURVED = ("cylinder", "variation")

#: Default level of the cylinder (smooth-surface) test, which declares edges. It is
#: nested with the plane test (a plane is a cylinder of infinite radius): the planes the
#: plane test rejects by chance (alpha of them) are rejected by the cylinder test too, so
#: at alpha = 0.05 it would call about 4 % of every plane edges.
CURVED_ALPHA = 0.001


def _neighbour_rows(points, features, query):
    """CSR rows (indptr, indices) of the points `query`: kept neighbourhoods, else a search."""
    nbh = features.neighborhoods
    if nbh is not None and nbh.query is None and len(nbh) == len(points):
        counts = nbh.counts[query]
        indptr = np.zeros(query.size + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        starts = nbh.indptr[query]
        pos = np.repeat(starts - indptr[:-1], counts) + np.arange(indptr[-1])
        return indptr, nbh.indices[pos]
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    if features.k is not None:
        k = min(int(features.k), len(points))
        _, idx = tree.query(points[query], k=k, workers=-1)
        idx = np.asarray(idx).reshape(query.size, k)
        return np.arange(query.size + 1, dtype=np.int64) * k, idx.ravel()
    rows = tree.query_ball_point(points[query], features.radius, workers=-1)
    counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=query.size)
    indptr = np.zeros(query.size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    idx = np.fromiter((j for r in rows for j in r), dtype=np.int64, count=int(indptr[-1]))
    return indptr, idx


def _feature_points(points, n, func):
    """`points` as float64, checked to be the (n, 3) points of the features."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (n, 3):
        raise InvalidParameterError(
            f"{func}: `points` must be the {n} points of the features, got shape "
            f"{points.shape}")
    return points


def _cylinder_axes(features, query):
    """Minimum-curvature direction ``Normal x PrincipalDir`` of the points `query` (the
    largest eigenvector where it is undefined): the cylinder test's starting axis."""
    f = features.fields
    normal = features.normals[query]
    pdir = np.stack([f["PrincipalDirX"][query], f["PrincipalDirY"][query],
                     f["PrincipalDirZ"][query]], axis=1)
    axis = np.cross(normal, pdir)
    nrm = np.linalg.norm(axis, axis=1, keepdims=True)
    bad = ~(nrm[:, 0] > 1e-12)
    return np.where(bad[:, None], features.major[query],
                    axis / np.where(bad[:, None], 1.0, nrm))


def curved_surface_test(points, features, query, sigma, *, sensor=None, return_model=False):
    """p-values of the cylinder test (:func:`lidarstat.features.cylinder_test`) at the points `query`.

    `sigma` (scalar or per point) is along the rays with a `sensor`, else across the
    surface.

    Returns
    -------
    p, radius : (M,) ndarray
        Upper-tail chi-square p-value of the weighted circle-fit residuals and the fitted
        radius of curvature (inf: planar across the axis).
    centre, axis : (M, 3) ndarray
        A point of the fitted cylinder's axis (NaN where planar) and its unit axis (the
        starting axis, to which the radius and centre belong); with `return_model` only.
    """
    from ..features import cylinder_test

    indptr, idx = _neighbour_rows(points, features, query)
    axes = _cylinder_axes(features, query)
    stat, dof, radius, centre = cylinder_test(points, query, indptr, idx, axes, sigma,
                                              sensor=sensor, refine_axis=True,
                                              return_centre=True)
    with np.errstate(invalid="ignore"):
        p = _sp.chdtrc(np.where(dof > 0, dof, np.nan), stat)
    if return_model:
        return p, radius, centre, axes
    return p, radius


def grid_cylinders(meta, on):
    """The per-point cylinders of the ``'grid'`` test's border placement: the cylinder
    test's fits (``meta`` of :class:`CovarianceClasses`) where `on` (consistently curved
    surface points), NaN elsewhere."""
    return (np.where(on[:, None], meta["curvature_centre"], np.nan), meta["curvature_axis"],
            np.where(on, meta["curvature_radius"], np.nan))


def classify_covariance(features, *, sigma=None, noise=None, alpha=0.05,
                        boundary_alpha=None, curvature_threshold=None,
                        variance_threshold=None, points=None, curved=None,
                        curved_alpha=None, boundary=None,
                        edge_boundary_alpha="auto", jump_alpha=JUMP_ALPHA,
                        noise_estimate=None, border_band=BORDER_BAND) -> CovarianceClasses:
    """Label every point surface, edge or boundary from its covariance features.

    Parameters
    ----------
    features : CovarianceResult
        From :func:`lidarstat.features.covariance_features`.
    sigma : float or (N,) array_like, optional
        Noise standard deviation (per point allowed): across the surface
        (``noise='normal'``) or along the ray (``'range'``). Default: estimated, by
        :func:`estimate_plane_sigma` or, for ``'range'``, as the model ``a + b r`` (see
        `noise_estimate`).
    noise : {'normal', 'range'}, optional
        ``'range'`` (default when the features were computed with a sensor): the noise
        runs along the scanner's rays, so across a surface seen at incidence theta it is
        ``sigma |cos theta|`` - terrestrial scans, where a single normal sigma would call
        the walls facing the scanner rough and the grazing ground smooth.
    alpha : float
        Level of the plane and consistent-curvature tests.
    boundary_alpha : float, optional
        Level of the boundary test. Default: 0.001 (``BOUNDARY_ALPHA``) for the centroid
        test, which runs on every surface point, 0.01 (``SCAN_BOUNDARY_ALPHA``) for the
        scan test, which is conservative on a scan grid.
    curvature_threshold : float, optional
        Paper mode: SurfaceVariation above this is "high curvature" (replaces test 1).
    variance_threshold : float, optional
        Paper mode: CurvatureVariance above this is an edge (replaces test 2; the
        paper used 0.0001).
    points : (N, 3) array_like, optional
        The coordinates the features were computed on; needed by ``curved='cylinder'``.
    curved : {'cylinder', 'variation'}, optional
        Test 2, where the plane is rejected: ``'cylinder'`` (default when `points` are
        given) fits a circular cylinder along the minimum-curvature direction and tests
        its weighted residuals, ``chi2(n - 3)`` (:func:`lidarstat.features.cylinder_test`);
        ``'variation'`` is the paper's variance of curvature as a ratio test against
        the scan's own planes.
    curved_alpha : float, optional
        Level of test 2 (rejected -> edge). Default: 0.001 (``CURVED_ALPHA``) for the
        cylinder test, `alpha` for the variation test.
    boundary : {'visible', 'grid', 'scan', 'centroid'}, optional
        Test 3. ``'grid'`` (default when the features were computed with a sensor and
        `points` are given; see below). ``'visible'``: the Hotelling test of the point's
        *visible disc*, the grid
        directions within its complete disc reached from it over grid edges without a
        depth jump (:mod:`lidarstat.classify._visible`), on every point (boundary wins
        over edge); writes ``jump_z`` / ``jump_p`` (range continuity at the point).
        ``'scan'`` (the default with a sensor and no `points`): the same test on the
        complete disc of the kNN table; ``'centroid'``: the paper's eq. 6-8 (with the
        factor n) in the tangent plane, on surface points. ``'grid'``: the
        distance to the estimated end of the visible surface on the scan grid (a missing
        return, the scan window, or a depth jump rejected by the continuity test between
        two surfaces resolved on both sides; :func:`lidarstat.classify._visible.grid_boundary`);
        a point closer than `border_band` times its neighbourhood's reach is a boundary,
        whatever its surface tests say; writes ``border_distance``, ``border_kind``,
        ``border_p`` besides the visible test's fields.
    edge_boundary_alpha : float, None or 'auto'
        With the scan or visible test: level at which a point that failed the surface
        tests (an edge candidate) becomes a boundary ('auto': 0.001 scan, 0.01 visible);
        None: edges stay edges.
    jump_alpha : float
        Level of the range-continuity test of one grid edge (``'visible'``).
    border_band : float
        ``'grid'`` test: the share of the neighbourhood's reach within which the end of
        the visible surface makes a boundary (0.5: about a fifth of the neighbourhood's
        disc is then missing).
    noise_estimate : {'smooth', 'median'}, optional
        How the range noise is estimated when `sigma` is not given (``noise='range'``):
        ``'smooth'`` (default when `points` are given) from the residuals of the best
        smooth model (cylinder or plane) of every neighbourhood,
        :func:`estimate_smooth_range_noise`; ``'median'`` from the plane residuals,
        :func:`estimate_range_noise` (inflated where curved surfaces
        fill a range bin).

    Returns
    -------
    CovarianceClasses

    Notes
    -----
    Points with fewer than 4 neighbours stay undetermined (0).
    """
    func = "classify_covariance"
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    scan_feats = getattr(features, "scan_boundary", None) is not None
    if boundary is None:
        boundary = ("centroid" if not scan_feats else
                    "grid" if points is not None else "scan")
    if boundary not in BOUNDARY:
        raise InvalidParameterError(
            f"The 'boundary' parameter of {func} must be one of 'grid', 'visible', 'scan', "
            f"'centroid'. Got {boundary!r} instead.")
    if boundary in ("scan", "visible", "grid") and not scan_feats:
        raise InvalidParameterError(f"{func}: boundary={boundary!r} needs features computed "
                                    "with a sensor")
    if boundary in ("visible", "grid") and points is None:
        raise InvalidParameterError(f"{func}: boundary={boundary!r} needs the `points`")
    border_band = check_scalar(border_band, "border_band", func=func, low=0.0,
                               closed="neither")
    if boundary_alpha is None:
        boundary_alpha = {"scan": SCAN_BOUNDARY_ALPHA, "visible": VISIBLE_BOUNDARY_ALPHA,
                          "grid": VISIBLE_BOUNDARY_ALPHA, "centroid": BOUNDARY_ALPHA}[boundary]
    boundary_alpha = check_scalar(boundary_alpha, "boundary_alpha", func=func, low=0.0, high=1.0)
    jump_alpha = check_scalar(jump_alpha, "jump_alpha", func=func, low=0.0, high=1.0,
                              closed="neither")
    if isinstance(edge_boundary_alpha, str) and edge_boundary_alpha == "auto":
        edge_boundary_alpha = (VISIBLE_EDGE_BOUNDARY_ALPHA if boundary == "visible" else
                               EDGE_BOUNDARY_ALPHA)
    if edge_boundary_alpha is not None:
        edge_boundary_alpha = check_scalar(edge_boundary_alpha, "edge_boundary_alpha",
                                           func=func, low=0.0, high=1.0)
    if curvature_threshold is not None:
        curvature_threshold = check_scalar(curvature_threshold, "curvature_threshold",
                                           func=func, low=0.0, closed="left")
    if variance_threshold is not None:
        variance_threshold = check_scalar(variance_threshold, "variance_threshold", func=func,
                                          low=0.0, closed="left")
    f = features.fields
    evals = features.eigenvalues
    counts = f["neighbors"].astype(np.float64)
    n = counts.size
    if noise is None:
        noise = "range" if features.sensor is not None else "normal"
    if noise not in NOISE:
        raise InvalidParameterError(
            f"The 'noise' parameter of {func} must be one of 'normal', 'range'. "
            f"Got {noise!r} instead.")
    if noise == "range" and features.sensor is None:
        raise InvalidParameterError(f"{func}: noise='range' needs features computed with a sensor")
    estimated = sigma is None
    meta = {"noise": noise, "boundary": boundary}
    if boundary != "centroid":
        meta["edge_boundary_alpha"] = edge_boundary_alpha
    if noise_estimate is None:
        noise_estimate = "smooth" if points is not None else "median"
    check_option(noise_estimate, "noise_estimate", NOISE_ESTIMATE, func=func)
    if estimated and noise == "range":
        if noise_estimate == "smooth":
            if points is None:
                raise InvalidParameterError(
                    f"{func}: noise_estimate='smooth' needs the `points`")
            points = _feature_points(points, n, func)
            a, b = estimate_smooth_range_noise(points, features)
            # the segmentation's scale for whole-segment models (see segment_covariance)
            am, bm = estimate_range_noise(evals, counts, features.ray_range, features.ray_cos)
            meta["segment_range_noise"] = (am, bm)
            meta["segment_sigma"] = np.maximum(am + bm * features.ray_range,
                                               a + b * features.ray_range)
        else:
            a, b = estimate_range_noise(evals, counts, features.ray_range, features.ray_cos)
        meta["range_noise"] = (a, b)
        meta["noise_estimate"] = noise_estimate
        sigma = a + b * features.ray_range
        if not np.all(sigma > 0):
            raise InvalidParameterError(
                f"{func}: the estimated noise is 0 (the neighbourhoods are exact planes or "
                "lines); give `sigma` or thresholds")
    elif estimated:
        sigma = estimate_plane_sigma(evals, counts)
        if not sigma > 0:
            raise InvalidParameterError(
                f"{func}: the estimated noise is 0 (the neighbourhoods are exact planes or "
                "lines); give `sigma` or thresholds")
    elif np.ndim(sigma) == 0:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    else:
        sigma = np.asarray(sigma, dtype=np.float64)
        if sigma.shape != (n,) or not (np.isfinite(sigma).all() and (sigma > 0).all()):
            raise InvalidParameterError(
                f"The 'sigma' parameter of {func} must be a positive float or {n} positive "
                "values.")
    valid = (counts >= 4) & np.isfinite(evals).all(axis=1)
    across = sigma if noise == "normal" else sigma * features.ray_cos
    plane_p = plane_test(evals, counts, across)
    extra = {}
    if boundary == "scan":
        t2, boundary_p = scan_boundary_test(features.scan_boundary)
    elif boundary in ("visible", "grid"):
        from ._visible import grid_boundary, visible_boundary

        pts = np.asarray(points, dtype=np.float64)
        if pts.shape != (n, 3):
            raise InvalidParameterError(
                f"{func}: `points` must be the {n} points of the features, got shape "
                f"{pts.shape}")
        along = sigma if noise == "range" else sigma / np.maximum(features.ray_cos, 0.05)
        sb = features.scan_boundary
        # the complete disc's radius rho (the reach shrunk by the density gradient g)
        vis = visible_boundary(pts, features.sensor, features.normals, features.major, along,
                               sb[:, 2] * sb[:, 3], jump_alpha=jump_alpha, linear_alpha=alpha)
        t2 = vis["t2"]
        boundary_p = hotelling_p(t2, vis["m"])
        extra = {"jump_z": vis["jump_z"], "jump_p": vis["jump_p"],
                 "jump_resolved_p": vis["jump_resolved_p"]}
        meta["jump_alpha"] = jump_alpha
        meta["grid_step"] = vis["step"]
        if boundary == "grid":
            meta["border_band"] = border_band
    else:
        t2, boundary_p = boundary_test(features.offset_uv, evals, counts)
    if curvature_threshold is None:
        low = plane_p >= alpha
    else:
        low = f["SurfaceVariation"] <= curvature_threshold
    if curved is None:
        curved = "cylinder" if points is not None else "variation"
    if curved not in CURVED:
        raise InvalidParameterError(
            f"The 'curved' parameter of {func} must be one of 'cylinder', 'variation'. "
            f"Got {curved!r} instead.")
    meta["curved"] = curved
    if curved_alpha is None:
        curved_alpha = CURVED_ALPHA if curved == "cylinder" else alpha
    curved_alpha = check_scalar(curved_alpha, "curved_alpha", func=func, low=0.0, high=1.0)
    meta["curved_alpha"] = curved_alpha
    if curved == "cylinder":
        if points is None:
            raise InvalidParameterError(f"{func}: curved='cylinder' needs the `points`")
        points = _feature_points(points, n, func)
        variation_p = np.full(n, np.nan)
        curv_radius = np.full(n, np.nan)
        cyl_centre = np.full((n, 3), np.nan)
        cyl_axis = np.full((n, 3), np.nan)
        query = np.flatnonzero(valid & ~low)
        if query.size:
            variation_p[query], curv_radius[query], cyl_centre[query], cyl_axis[query] = \
                curved_surface_test(points, features, query, sigma,
                                    sensor=features.sensor if noise == "range" else None,
                                    return_model=True)
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
    if boundary == "grid":
        cylinders = None
        if curved == "cylinder":
            # the border of a node on a consistently curved surface is placed on its
            # fitted cylinder (the silhouette of a pipe), not on its tangent plane
            cylinders = grid_cylinders(meta, valid & ~low & consistent)
        extra.update(grid_boundary(pts, features.sensor, features.normals, along, vis=vis,
                                   jump_alpha=jump_alpha, smooth_alpha=alpha,
                                   cylinders=cylinders))
    with np.errstate(invalid="ignore"):
        if boundary == "grid":
            # the end of the visible surface within border_band of the neighbourhood's
            # reach: a missing return, the scan window or a tested depth jump between two
            # resolved surfaces (boundary wins over edge, as in the truth)
            one_sided = valid & (extra["border_distance"]
                                 < border_band * features.scan_boundary[:, 3])
        else:
            one_sided = surface & (boundary_p < boundary_alpha)
        if boundary == "visible":
            # a surface point beside a depth jump is where its visible surface ends: the
            # union of the two tests has level <= boundary_alpha + jump_alpha there (edge
            # candidates are left to the disc test: a face narrower than two grid steps,
            # a soffit or a window jamb, looks like a jump to the continuity test)
            one_sided |= surface & (extra["jump_p"] < jump_alpha)
        if boundary in ("scan", "visible") and edge_boundary_alpha is not None:
            one_sided |= valid & ~surface & (boundary_p < edge_boundary_alpha)
            if boundary == "visible":
                # an edge candidate at a depth jump between two resolved surfaces (both
                # sides linear over three grid nodes) is where its visible surface ends;
                # a jump onto a face narrower than the grid is not resolved and stays
                # with the disc test
                one_sided |= valid & ~surface & (extra["jump_resolved_p"] < jump_alpha)
    pc = np.zeros(n, dtype=np.uint8)
    pc[valid] = PointClass.EDGE
    pc[surface] = PointClass.SURFACE
    pc[one_sided] = PointClass.BOUNDARY
    fields = {"point_class": pc, "plane_p": plane_p, "variation_p": variation_p,
              "boundary_T2": t2, "boundary_p": boundary_p, **extra}
    return CovarianceClasses(fields=fields, sigma=sigma, sigma_estimated=estimated, alpha=alpha,
                             boundary_alpha=boundary_alpha,
                             curvature_threshold=curvature_threshold,
                             variance_threshold=variance_threshold, meta=meta)


@dataclass(frozen=True)
class CovarianceClassification:
    """Features and classes of :func:`covariance` (what ``lidarstat covariance`` writes).

    Attributes
    ----------
    features : CovarianceResult
    classes : CovarianceClasses
    """

    features: object
    classes: CovarianceClasses

    def __getitem__(self, name):
        if name in self.classes.fields:
            return self.classes.fields[name]
        return self.features.fields[name]

    @property
    def point_class(self) -> np.ndarray:
        return self.classes.point_class

    def to_fields(self):
        """Every per-point field with its file dtype: ``point_class`` first."""
        c = self.classes.to_fields()
        return {"point_class": c.pop("point_class"), **self.features.to_fields(), **c}

    def summary(self) -> str:
        f = self.features
        nb = f.k if f.k is not None else f"radius {f.radius}"
        return (f"neighbourhoods: {'k ' + str(nb) if f.k is not None else nb}, median "
                f"{np.median(f.counts):.0f} points\n" + self.classes.summary())


def covariance(points, *, k=50, radius=None, sensor=None, sigma=None, noise=None, alpha=0.05,
               boundary_alpha=None, curvature_threshold=None, variance_threshold=None,
               curved="cylinder", curved_alpha=None, eigen_mode="raw", keep_neighbors=False,
               progress=None, boundary=None, edge_boundary_alpha="auto", jump_alpha=JUMP_ALPHA,
               noise_estimate=None, border_band=BORDER_BAND):
    """Covariance features and surface / edge / boundary classes of every point (seed 003).

    One call of :func:`lidarstat.features.covariance_features` and
    :func:`classify_covariance`; see them for the parameters.

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
    dup = find_duplicates(pts)
    if dup.any and keep_neighbors:
        # the neighbourhoods of every point are kept: each copy is searched, so a cloud
        # dominated by copies is refused (as by the segmentations that need them)
        refuse_dominated(dup, what="covariance with keep_neighbors",
                         max_copies=math.isqrt(max_pairs()))
    elif dup.any:
        # every location once, its result to every point at it (neighbors/_duplicates.py)
        res = run_on_unique(dup, lambda: covariance(
            pts[dup.first], k=k, radius=radius, sensor=sensor, sigma=sigma, noise=noise,
            alpha=alpha, boundary_alpha=boundary_alpha,
            curvature_threshold=curvature_threshold, variance_threshold=variance_threshold,
            curved=curved, curved_alpha=curved_alpha, eigen_mode=eigen_mode,
            progress=progress, boundary=boundary, edge_boundary_alpha=edge_boundary_alpha,
            jump_alpha=jump_alpha, noise_estimate=noise_estimate, border_band=border_band),
            what="covariance")
        return map_rows(res, dup.n_unique, dup.inverse)
    feats = covariance_features(points, k=k, radius=radius, sensor=sensor,
                                eigen_mode=eigen_mode, keep_neighbors=keep_neighbors,
                                progress=progress)
    classes = classify_covariance(feats, sigma=sigma, noise=noise, alpha=alpha,
                                  boundary_alpha=boundary_alpha,
                                  curvature_threshold=curvature_threshold,
                                  variance_threshold=variance_threshold, points=points,
                                  curved=curved, curved_alpha=curved_alpha,
                                  boundary=boundary,
                                  edge_boundary_alpha=edge_boundary_alpha,
                                  border_band=border_band,
                                  jump_alpha=jump_alpha,
                                  noise_estimate=noise_estimate)
    return CovarianceClassification(features=feats, classes=classes)
