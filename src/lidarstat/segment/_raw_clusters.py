"""Raw clusters by region growing on height and slope differences (seed 002, section 5.2).

Two neighbouring points belong to the same raw cluster when their local planes agree:
the slopes do not differ significantly (a Wald chi-square(2) test of the slope difference)
and the height of one plane, extrapolated to the other point, does not differ
significantly from that point's fitted height (a z test). Both tests use the regression's
own standard errors, so the thresholds follow the noise and the point density instead of
being fixed numbers. Only points whose neighbourhood passes the planarity test may be in a
raw cluster (ridges, walls, trees and chimneys stay out, as in the paper's Figure 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared._jit import njit_parallel
from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ..stats import chi2_critical, z_critical


@njit_parallel
def _edge_tests(xy, beta, cof, sigma2, ok, indptr, idx, crit_slope, crit_height,
                max_dslope, max_dheight, edge_ok):
    for i in numba.prange(indptr.size - 1):
        for t in range(indptr[i], indptr[i + 1]):
            j = idx[t]
            if not (ok[i] and ok[j]) or i == j:
                edge_ok[t] = ok[i] and i == j
                continue
            # slope difference, covariance sigma^2 (C_i + C_j) (correlation ignored)
            d1 = beta[j, 1] - beta[i, 1]
            d2 = beta[j, 2] - beta[i, 2]
            c11 = sigma2 * (cof[i, 1, 1] + cof[j, 1, 1])
            c12 = sigma2 * (cof[i, 1, 2] + cof[j, 1, 2])
            c22 = sigma2 * (cof[i, 2, 2] + cof[j, 2, 2])
            det = c11 * c22 - c12 * c12
            if det <= 0.0:
                edge_ok[t] = False
                continue
            w = (c22 * d1 * d1 - 2.0 * c12 * d1 * d2 + c11 * d2 * d2) / det
            if w > crit_slope or abs(d1) > max_dslope or abs(d2) > max_dslope:
                edge_ok[t] = False
                continue
            # plane of i extrapolated to j against the fitted height at j
            de = xy[j, 0] - xy[i, 0]
            dn = xy[j, 1] - xy[i, 1]
            dh = beta[j, 0] - (beta[i, 0] + beta[i, 1] * de + beta[i, 2] * dn)
            var = cof[j, 0, 0]
            g0 = 1.0
            g = (g0, de, dn)
            for u in range(3):
                for v in range(3):
                    var += g[u] * cof[i, u, v] * g[v]
            var *= sigma2
            edge_ok[t] = dh * dh <= crit_height * crit_height * var and abs(dh) <= max_dheight


@dataclass(frozen=True)
class RawClusters:
    """Raw clusters of points with agreeing local planes.

    Attributes
    ----------
    labels : (N,) ndarray of int32
        Cluster id (1.., by decreasing size), 0 for points in no cluster.
    edge_ok : (nnz,) ndarray of bool
        Accepted growth edges, aligned with the neighbourhoods' CSR indices.
    growable : (N,) ndarray of bool
        Points allowed in a cluster (fitted and planar).
    """

    labels: np.ndarray
    edge_ok: np.ndarray
    growable: np.ndarray


def plane_edges(points, fit, neighborhoods, *, alpha=0.01, max_slope_diff=np.inf,
                max_height_diff=np.inf, require_planar=True):
    """Accept or reject every neighbour pair by the height and slope tests.

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    fit : LocalPlaneFit
        Local planes of `points` (:func:`lidarstat.features.local_planes`).
    neighborhoods : Neighborhoods
        Growth graph (e.g. 2-D discs of a radius about the bandwidth).
    alpha : float
        Level of each of the two tests.
    max_slope_diff, max_height_diff : float
        Optional fixed thresholds (the paper's) applied on top of the tests.
    require_planar : bool
        Only points whose planarity test accepts may grow.

    Returns
    -------
    edge_ok : (nnz,) ndarray of bool
    growable : (N,) ndarray of bool
    """
    func = "plane_edges"
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    n = points.shape[0]
    if len(neighborhoods) != n or neighborhoods.query is not None:
        raise InvalidParameterError(f"{func}: `neighborhoods` must have one row per point")
    ok = fit.ok.copy()
    if require_planar:
        ok &= ~fit.planarity.reject
    ok &= np.isfinite(fit.beta).all(axis=1)
    crit_slope = chi2_critical(alpha, 2)
    crit_height = z_critical(alpha)
    xy = np.ascontiguousarray(points[:, :2] - points[:, :2].min(axis=0))
    beta = np.ascontiguousarray(fit.beta.copy())
    beta[:, 0] -= np.nanmin(beta[:, 0]) if np.isfinite(beta[:, 0]).any() else 0.0
    edge_ok = np.zeros(neighborhoods.indices.size, dtype=bool)
    _edge_tests(xy, beta, np.ascontiguousarray(fit.cofactor), float(fit.sigma2), ok,
                neighborhoods.indptr, neighborhoods.indices, crit_slope, crit_height,
                float(max_slope_diff), float(max_height_diff), edge_ok)
    return edge_ok, ok


@renamed_parameters(min_size="min_points")
def raw_clusters(points, fit, neighborhoods, *, alpha=0.01, min_points=10, core=None,
                 **kwargs):
    """Region growing of raw clusters on the tested plane agreement (section 5.2).

    Connected components of the accepted edges among growable points (union-find,
    deterministic ids by decreasing size, the :func:`components` kernel);
    clusters smaller than `min_points` are dropped (label 0).

    With `core` (e.g. the points whose plane passed at the full bandwidth of a
    multi-scale fit), only core points expand a cluster; other growable points are
    attached to the first cluster that reaches them through an accepted edge but never
    expand it, so the small windows near roof edges (whose slopes change gradually
    across a hip line) cannot bridge two faces.

    Returns
    -------
    RawClusters
    """
    from . import components, grow_regions, relabel

    edge_ok, ok = plane_edges(points, fit, neighborhoods, alpha=alpha, **kwargs)
    if core is None:
        labels = components(neighborhoods, edge_ok=edge_ok, mask=ok)
    else:
        core = np.asarray(core, dtype=bool)
        labels = grow_regions(neighborhoods, edge_ok=edge_ok, can_grow=ok & core, mask=ok)
    labels = relabel(labels, min_points)
    return RawClusters(np.asarray(labels, dtype=np.int32), edge_ok, ok)
