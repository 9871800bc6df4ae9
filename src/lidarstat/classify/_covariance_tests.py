"""The three tests of the covariance classification (seed 003), per point, as p-values.

1. *Low curvature* (:func:`plane_test`): ``(n - 1) lambda0 / sigma^2 ~ chi2(n - 3)``.
2. *Consistent curvature* where the plane is rejected: the cylinder test
   (:func:`curved_surface_test`, the default) or the paper's variance of curvature as a
   ratio test against the scan's own planes (:func:`variation_test`).
3. *Boundary*, the paper's centroid test (:func:`boundary_test`): Hotelling's T^2 of the
   neighbourhood centroid against the index point in the tangent plane. The scan-grid
   border test of a terrestrial scan is in :mod:`._grid_boundary`.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidParameterError
from ..stats import chi2_pvalue, hotelling_pvalue, normal_pvalue

#: Default level of the centroid boundary test: it runs on every surface point, so a small
#: level keeps false boundary points rare (alpha = 0.05 would flag 5 % of interior points).
BOUNDARY_ALPHA = 0.001

#: Level of the range-continuity test of one scan-grid edge (a depth jump ends the visible
#: surface there).
JUMP_ALPHA = 0.001

#: The ``'grid'`` boundary test: a point is a boundary when the estimated end of its visible
#: surface is closer than this share of its neighbourhood's reach (about a fifth of the
#: neighbourhood's disc is then missing; docs/methods/covariance.md).
BORDER_BAND = 0.5

#: Default level of the cylinder (smooth-surface) test, which declares edges. It is
#: nested with the plane test (a plane is a cylinder of infinite radius): the planes the
#: plane test rejects by chance (alpha of them) are rejected by the cylinder test too, so
#: at alpha = 0.05 it would call about 4 % of every plane edges.
CURVED_ALPHA = 0.001


def plane_test(evals, counts, sigma):
    """p-value of ``(n - 1) lambda0 / sigma^2 ~ chi2(n - 3)`` (upper tail)."""
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        stat = (n - 1) * evals[:, 0] / np.asarray(sigma, dtype=np.float64) ** 2
        df = np.where(n > 3, n - 3, np.nan)
        return chi2_pvalue(stat, df)


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
        return normal_pvalue((np.log(ratio) - mu) / sd, sides=1)


def boundary_test(offset_uv, evals, counts):
    """Hotelling T^2 of the centroid against the index point, and its F p-value."""
    n = np.asarray(counts, dtype=np.float64)
    u, v = offset_uv[:, 0], offset_uv[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        t2 = n * (u * u / evals[:, 2] + v * v / evals[:, 1])
    return t2, hotelling_pvalue(t2, n)



def _neighbour_rows(points, features, query):
    """CSR rows (indptr, indices) of the points `query`: kept neighbourhoods, else a search.

    The rows are the neighbourhoods the features were computed on: at the automatic scale
    (``features.k`` and ``features.radius`` None) the first ``neighbors`` points of each
    kept (or searched) nearest-neighbour row; at the tested scale (``meta['rule']``
    ``'tested'``) the whole rows, of ``meta['k_max']`` points: a prefix stops as soon as
    its plane test detects a crease, often with a few points beyond it, and a circle
    through those few is refuted only by the longer arm of the V."""
    nbh = features.neighborhoods
    used = np.asarray(features.counts)[query].astype(np.int64)
    if features.meta.get("rule") == "tested":
        used = np.maximum(used, int(features.meta["k_max"]))
    if nbh is not None and nbh.query is None and len(nbh) == len(points):
        counts = np.minimum(nbh.counts[query], used)
        indptr = np.zeros(query.size + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        starts = nbh.indptr[query]
        pos = np.repeat(starts - indptr[:-1], counts) + np.arange(indptr[-1])
        return indptr, nbh.indices[pos]
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    if features.k is not None or features.radius is None:
        k = min(int(features.k if features.k is not None else max(used.max(initial=1), 1)),
                len(points))
        _, idx = tree.query(points[query], k=k, workers=-1)
        idx = np.asarray(idx).reshape(query.size, k)
        if features.k is not None:
            return np.arange(query.size + 1, dtype=np.int64) * k, idx.ravel()
        counts = np.minimum(used, k)
        indptr = np.zeros(query.size + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        return indptr, idx[np.arange(k)[None, :] < counts[:, None]]
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
        p = chi2_pvalue(stat, np.where(dof > 0, dof, np.nan))
    if return_model:
        return p, radius, centre, axes
    return p, radius


def grid_cylinders(meta, on):
    """The per-point cylinders of the ``'grid'`` test's border placement: the cylinder
    test's fits (``meta`` of :class:`CovarianceClasses`) where `on` (consistently curved
    surface points), NaN elsewhere."""
    return (np.where(on[:, None], meta["curvature_centre"], np.nan), meta["curvature_axis"],
            np.where(on, meta["curvature_radius"], np.nan))

