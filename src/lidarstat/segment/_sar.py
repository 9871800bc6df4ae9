"""Mixed nonparametric + parametric segmentation (Crosilla, Visintini and Sepic 2005).

:func:`segment_sar` chains the four steps of seed 002 and returns a
:class:`~lidarstat.segment.Segmentation`:

1. local plane regression of every point (:func:`lidarstat.features.local_planes`);
2. raw clusters by region growing on tested height and slope agreement
   (:func:`raw_clusters`);
3. a search area per raw cluster over the Delaunay triangulation (:func:`search_areas`);
4. SAR-FS refinement of every raw cluster within its search area
   (:func:`refine_cluster`); points claimed by several units go to the one they fit best
   (smallest standardised residual); adjacent surfaces are intersected into break lines.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import warnings

import numpy as np
import scipy.sparse as sp
from scipy import stats as _st

from .._shared._geometry import mean_spacing as _mean_spacing
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError, LidarstatWarning
from ..neighbors import radius_neighbors
from ..neighbors import check_copies
from ._grow import relabel
from ._intersect import intersection_lines
from ._raw_clusters import raw_clusters
from ._result import Polylines, Segmentation, segment_table
from ._sar_refine import refine_cluster, refit_unit
from ._search_area import delaunay_graph, search_areas

logger = logging.getLogger(__name__)

#: When the noise is estimated, a second pass uses the median residual standard deviation
#: of the first pass's units if it exceeds the local (lower-quartile) estimate by this
#: factor (see :func:`segment_sar`, `sigma`).
SIGMA_RATIO = 1.25

#: Forward Search stop reasons written to the table (``fs_stop``).
STOP_CODES = {"exhausted": 0, "f": 1, "residual": 2, "not searched": 3}


def _two_hop_contacts(graph, labels):
    """(point, other segment) pairs: labelled points with another segment within 2 hops."""
    indptr, idx, _ = graph
    n = labels.size
    G = sp.csr_matrix((np.ones(idx.size), idx, indptr), shape=(n, n))
    G = G + sp.identity(n, format="csr")
    lab = labels > 0
    L = sp.csr_matrix((np.ones(lab.sum()), (np.flatnonzero(lab), labels[lab] - 1)),
                      shape=(n, int(labels.max()) if labels.size else 0))
    reach = (G @ (G @ L)).tocoo()
    p, s = reach.row, reach.col + 1
    keep = lab[p] & (labels[p] != s)
    return p[keep], s[keep]


def _area_contacts(points, graph, labels, threshold):
    """(point, other segment) pairs: labelled points touching another segment's search area.

    The search area of a segment (its points plus the unlabelled points reachable within
    a Delaunay path of `threshold`, :func:`search_areas`) is widened by one triangulation
    edge; labelled points of other segments inside it are contacts. Two parts of one roof
    plane separated by a dormer or a chimney (unlabelled points a few metres wide) are
    thereby candidates for the merge, which two-hop adjacency misses.
    """
    n = labels.size
    indptr, idx, _ = graph
    lab = labels > 0
    s_max = int(labels.max()) if n else 0
    areas = search_areas(points, labels, threshold, graph=graph)
    owner = np.repeat(np.arange(s_max), np.diff(areas.indptr))
    rows = np.r_[np.flatnonzero(lab), areas.indices]
    cols = np.r_[labels[lab] - 1, owner]
    M = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, s_max))
    G = sp.csr_matrix((np.ones(idx.size), idx, indptr), shape=(n, n))
    reach = (G @ M + M).tocoo()
    p, c = reach.row, reach.col + 1
    keep = lab[p] & (labels[p] != c)
    return p[keep], c[keep]


def _assign(units, n):
    """Final labels: every accepted point to the unit it fits best."""
    pts, who, score = [], [], []
    for u, unit in enumerate(units):
        pts.append(unit.accepted)
        who.append(np.full(unit.accepted.size, u))
        sd = max(unit.sigma, 1e-12)
        sc = np.abs(unit.residuals) / sd
        sc[:unit.n_s] = -1.0  # raw clusters keep their points (listed first)
        score.append(sc)
    labels = np.zeros(n, dtype=np.int64)
    if not pts:
        return labels
    pts, who, score = (np.concatenate(a) for a in (pts, who, score))
    o = np.lexsort((who, score))
    pts, who = pts[o], who[o]
    first = np.unique(pts, return_index=True)[1]
    labels[pts[first]] = who[first] + 1
    return labels


def _table(points, labels, units, keep_units):
    table = segment_table(labels, points)
    s = len(keep_units)
    max_deg = max((units[u].degree for u in keep_units), default=1)
    powers = [(i - j, j) for i in range(max_deg + 1) for j in range(i + 1)]
    cols = {k: np.full(s, np.nan) for k in
            ["degree", "n_s", "n_sa", "m", "rho", "se_rho", "sigma_sar", "sigma", "E0", "N0",
             "normal_x", "normal_y", "normal_z", "slope_deg", "normal_se_deg", "fs_stop",
             "rho_points", "frame"]}
    for pe, pn in powers:
        cols[f"c_{pe}{pn}"] = np.full(s, np.nan)
        cols[f"se_c_{pe}{pn}"] = np.full(s, np.nan)
    for k, u in enumerate(keep_units):
        unit = units[u]
        cols["degree"][k] = unit.degree
        cols["n_s"][k], cols["n_sa"][k], cols["m"][k] = unit.n_s, unit.n_sa, unit.m
        cols["rho"][k] = unit.fit.rho
        cols["se_rho"][k] = unit.fit.se_rho
        cols["sigma_sar"][k] = np.sqrt(unit.fit.sigma2)
        cols["sigma"][k] = unit.sigma
        cols["E0"][k], cols["N0"][k] = unit.basis.center
        cols["frame"][k] = 0 if unit.frame is None else 1
        if unit.frame is None:  # coefficients of z(E, N); a wall's are in its own frame
            pw, coef, se = unit.monomials()
            for (pe, pn), c, e in zip(pw, coef, se):
                cols[f"c_{pe}{pn}"][k] = c
                cols[f"se_c_{pe}{pn}"][k] = e
        else:
            cols["E0"][k] = cols["N0"][k] = np.nan
        cen = np.array([[table["centroid_x"][k], table["centroid_y"][k],
                         table["centroid_z"][k]]])
        nrm = unit.normal(cen)[0]
        cols["normal_x"][k], cols["normal_y"][k], cols["normal_z"][k] = nrm
        cols["slope_deg"][k] = np.degrees(np.arccos(nrm[2]))
        if np.all(np.isfinite(unit.surface_cov)):
            cols["normal_se_deg"][k] = unit.normal_error(cen)[0]
        cols["fs_stop"][k] = STOP_CODES[unit.fs.stop_reason]
        cols["rho_points"][k] = unit.rho_points
    for k in ("degree", "n_s", "n_sa", "m", "fs_stop", "rho_points", "frame"):
        cols[k] = cols[k].astype(np.int64)
    table.update(cols)
    return table


def _design(points, idx, degree, origin, scale):
    """Monomials up to `degree` in coordinates relative to `origin`, divided by `scale`."""
    u = (points[idx, :2] - origin) / scale
    cols = [u[:, 0] ** (i - j) * u[:, 1] ** j for i in range(degree + 1) for j in range(i + 1)]
    return np.column_stack(cols)


def _moments(points, idx, degree, origin, scale, z0):
    """Normal-equation moments (A'A, A'z, z'z, n) of one point set (heights minus z0)."""
    A = _design(points, idx, degree, origin, scale)
    z = points[idx, 2] - z0
    return A.T @ A, A.T @ z, float(z @ z), idx.size


def _rss(mom):
    ata, atz, zz, n = mom
    try:
        coef = np.linalg.solve(ata, atz)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(ata, atz, rcond=None)[0]
    return max(zz - coef @ atz, 0.0), ata.shape[0], n


def _chow_pvalue(ma, mb):
    """p-value of the Chow F test that two point sets lie on one polynomial surface.

    ``F = ((RSS_ab - RSS_a - RSS_b) / r) / ((RSS_a + RSS_b) / (n_a + n_b - 2r))`` from the
    normal-equation moments of each set (the union's moments are their sums).
    """
    ra, r, na = _rss(ma)
    rb, _, nb = _rss(mb)
    rab, _, _ = _rss(tuple(x + y for x, y in zip(ma, mb)))
    df2 = na + nb - 2 * r
    if df2 <= 0 or ra + rb <= 0:
        return 1.0
    f = ((rab - ra - rb) / r) / ((ra + rb) / df2)
    return float(_st.f.sf(f, r, df2))


def _merge_groups(points, unit_labels, units, graph, alpha, threshold):
    """Union of nearby units whose surfaces do not differ (Chow test at `alpha`).

    Candidates are pairs with at least 4 contacts (:func:`_area_contacts` within
    `threshold`)."""
    n_units = len(units)
    parent = np.arange(n_units + 1)

    def find(u):
        while parent[u] != u:
            parent[u] = parent[parent[u]]
            u = parent[u]
        return u

    if n_units < 2:
        return parent
    pts_c, seg_c = _area_contacts(points, graph, unit_labels, threshold)
    a = unit_labels[pts_c]
    lo, hi = np.minimum(a, seg_c), np.maximum(a, seg_c)
    base = n_units + 1
    keys, counts = np.unique(lo.astype(np.int64) * base + hi, return_counts=True)
    origin = points[:, :2].min(axis=0)
    scale = max(float(np.ptp(points[:, :2], axis=0).max()), 1.0)
    z0 = float(points[:, 2].min())
    moments = {}

    def mom(u):
        # the raw cluster, not the unit's final points: the best-fit assignment splits the
        # points of one plane between two units by the sign of their residuals, and on
        # such a residual-selected split the Chow test rejects one common plane (p down to
        # 1e-5 on the synthetic town); the raw clusters are selected by the local tests.
        if u not in moments:
            moments[u] = _moments(points, units[u - 1].raw, units[u - 1].degree, origin,
                                  scale, z0)
        return moments[u]

    for key in keys[counts >= 4]:
        ua, ub = int(key // base), int(key % base)
        if units[ua - 1].degree != units[ub - 1].degree or units[ua - 1].frame is not None \
                or units[ub - 1].frame is not None:
            continue
        if _chow_pvalue(mom(ua), mom(ub)) >= alpha:
            ra, rb = find(ua), find(ub)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    return np.array([find(u) for u in range(n_units + 1)])


def _refit_unit(points, idx, group, w_radius):
    """A unit refitted on its final points `idx` (rho by ML, theta, sigma^2 and the
    surface from the group's raw clusters, residuals of every point), keeping the Table 6
    sizes (summed over a merged group) and the Forward Search record."""
    big = max(group, key=lambda u: u.m)
    raw = np.concatenate([u.raw for u in group])
    raw = raw[np.isin(raw, idx)]
    extra = idx[~np.isin(idx, raw)]
    unit = refit_unit(points, raw, extra, w_radius=w_radius, degree=group[0].degree,
                      rho_hint=big.fit.rho, fs=big.fs)
    return dataclasses.replace(unit, n_s=sum(u.n_s for u in group),
                               n_sa=sum(u.n_sa for u in group), m=sum(u.m for u in group))


def _final_units(points, labels, units, w_radius):
    """Every segment refitted on its final points (after the best-fit assignment, the
    merge and the size filter): the accepted sets of the Forward Search overlap, and the
    points given to a neighbouring unit no longer pull this unit's plane. A segment whose
    refit fails keeps its Forward Search fit."""
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(len(units) + 2))
    out = []
    for s, unit in enumerate(units, start=1):
        idx = order[starts[s]:starts[s + 1]]
        try:
            out.append(_refit_unit(points, idx, [unit], w_radius))
        except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
            out.append(unit)
    return out


#: Most points the final outlier test removes from one segment (one per iteration).
OUTLIER_MAX = 200


#: Asymptotic efficiency of the MAD scale at the normal: ``1.4826 MAD`` of n residuals
#: has the variance of a standard deviation with ``MAD_EFFICIENCY * n`` degrees of
#: freedom (the degrees of freedom of the outlier test's t reference).
MAD_EFFICIENCY = 0.3675


def _outlier_test(points, labels, units, alpha):
    """Final outlier test of the points the search added to every segment (iterated
    data snooping with a fixed robust scale).

    The points of a segment that are not in its raw cluster (the Forward Search or the
    best-fit assignment added them) are tested one at a time with their deletion
    residual from the least-squares surface of the segment's other points,
    ``w_i = e_i / (s sqrt(1 - h_ii))`` (Baarda's w-test; the point does not pull the
    surface it is tested against). The scale s is fixed before the iterations: the
    robust ``1.4826 MAD`` of all the segment's residuals about its surface, referred to
    t with ``MAD_EFFICIENCY * n`` degrees of freedom. The most significant point beyond
    the ``1 - alpha/2`` quantile leaves the segment (label 0), the surface is refitted and
    the search repeats (at most :data:`OUTLIER_MAX` points per segment), so a gross
    outlier does not mask the others. The raw clusters' points are not tested: the local
    tests accepted them. The segment's reported surface stays the raw cluster's.

    *Why a fixed scale*: with the leave-one-out scale ``s_(i)`` of the points
    still kept (Pope's tau test), every removal truncates the
    sample and shrinks the scale, so the next points cross the critical value: on the
    158k synthetic town that cascade raised the rate on true roof points from 1.12 % (one
    pass) to 1.73 % at alpha = 0.01 (docs/methods/sar.md). The MAD is neither inflated by
    gross outliers (no masking) nor shrunk by the removals.

    Returns the new labels, the units (accepted points and residuals updated) and per
    point the segment it was removed from (0: none).
    """
    from scipy.stats import t as t_dist

    labels = labels.copy()
    removed = np.zeros(labels.size, dtype=np.uint32)
    out = []
    for s, unit in enumerate(units, start=1):
        k = unit.raw.size
        acc, res = unit.accepted, unit.residuals
        r = unit.basis.n_terms
        mine = labels[acc] == s
        tested = (np.arange(acc.size) >= k) & mine
        if not tested.any() or mine.sum() <= r + 2:
            out.append(unit)
            continue
        A = unit.basis(unit._local_xy(points[acc]))
        rm = res[mine]
        scale = 1.4826 * float(np.median(np.abs(rm - np.median(rm))))
        if not scale > 0:
            out.append(unit)
            continue
        crit = t_dist.isf(alpha / 2.0, max(MAD_EFFICIENCY * (rm.size - r), 1.0))
        keep = np.ones(acc.size, dtype=bool)
        for _ in range(OUTLIER_MAX):
            idx = np.flatnonzero(keep & mine)
            if idx.size <= r + 1:
                break
            q, _ = np.linalg.qr(A[idx])
            e = res[idx] - q @ (q.T @ res[idx])
            h = np.minimum(np.einsum("ij,ij->i", q, q), 1.0 - 1e-12)
            t = np.where(tested[idx], np.abs(e) / (scale * np.sqrt(1.0 - h)), 0.0)
            j = int(np.argmax(t))
            if t[j] <= crit:
                break
            keep[idx[j]] = False
        if keep.all():
            out.append(unit)
            continue
        gone = acc[~keep]
        labels[gone] = 0
        removed[gone] = s
        out.append(dataclasses.replace(unit, accepted=acc[keep], residuals=res[keep]))
    return labels, out, removed


#: A segment whose goodness-of-fit test rejects is split in two only when the two parts'
#: pooled residual sum of squares is at most this share of the segment's: the lack of
#: fit is structure (another face), not a false rejection or a slightly rough plane.
SPLIT_GAIN = 0.5
#: Most successive splits of one segment (a segment of three faces needs two).
SPLIT_DEPTH = 3
#: Largest segment that is split (larger ones are tested only): leaked raw clusters are
#: roof faces of a few hundred points, whereas terrain pieces between buildings (not
#: planes, always rejected) would be split down to SPLIT_DEPTH at the cost of many ML
#: refits of large units (doubled the run time on an AHN3 tile).
SPLIT_MAX = 5000
#: Points on which the correlation of a segment's residuals is estimated (nearest the
#: medoid); segments larger than MAX_SEARCH are neither tested nor split.
NOISE_RHO_MAX = 150


def _unit_heights(unit, xyz):
    """Planimetric coordinates and heights of points in a unit's frame."""
    if unit.frame is None:
        return xyz[:, :2], xyz[:, 2]
    local = (xyz - unit.frame[0]) @ unit.frame[1:].T
    return local[:, :2], local[:, 2]


def _moran_z(e, q, W):
    """z-score of Moran's I of least-squares residuals `e` (design with orthonormal
    columns `q`, row-standardised W): ``I = e'We / e'e`` against its exact mean and
    variance under independent normal errors (Cliff and Ord 1981),
    ``E[I] = tr(MW) / (n - r)``,
    ``Var[I] = (tr(MWMW') + tr((MW)^2) + tr(MW)^2) / ((n - r)(n - r + 2)) - E[I]^2``,
    with the traces expanded through ``M = I - qq'`` (W has a zero diagonal)."""
    n, r = q.shape
    Wq, Wtq = W @ q, W.T @ q
    qWq = q.T @ Wq
    t1 = -np.trace(qWq)  # tr(MW)
    WW = W.multiply(W).sum()  # tr(WW')
    WWt = W.multiply(W.T).sum()  # tr(WW)
    tr_mwmwt = WW - np.sum(Wtq * Wtq) - np.sum(Wq * Wq) + np.sum(qWq * qWq)
    tr_mw2 = WWt - 2.0 * np.sum(Wtq * Wq) + np.sum(qWq * qWq.T)
    d = n - r
    mean = t1 / d
    var = (tr_mwmwt + tr_mw2 + t1 * t1) / (d * (d + 2)) - mean * mean
    ee = float(e @ e)
    if not (var > 0 and ee > 0):
        return 0.0
    return (float(e @ (W @ e)) / ee - mean) / np.sqrt(var)


def _noise_rho(xy, e, w_radius, q=None):
    """SAR interaction of a segment's residuals: 0 unless Moran's I test of the residuals
    (:func:`_moran_z`, two-sided at 0.05) rejects; then the ML estimate on at most
    NOISE_RHO_MAX points near the medoid, kept when the likelihood-ratio test of rho = 0
    also rejects at 0.05. (Moran's test first: one sparse product instead of an ML fit
    for every segment.)"""
    from ..stats import sar_fit
    from ._sar_refine import _adjacency, _standardised

    if q is not None:
        W = _standardised(_adjacency(xy, w_radius))
        if abs(_moran_z(e, q, W)) <= _st.norm.isf(0.025):
            return 0.0
    if e.size > NOISE_RHO_MAX:
        med = np.median(xy, axis=0)
        keep = np.argsort(np.sum((xy - med) ** 2, axis=1))[:NOISE_RHO_MAX]
        xy, e = xy[keep], e[keep]
    W = _standardised(_adjacency(xy, w_radius))
    n = e.size
    try:
        fit = sar_fit(e, np.ones((n, 1)), W, grid=7, xatol=1e-4, covariance=False)
    except (InvalidParameterError, ValueError, np.linalg.LinAlgError):
        return 0.0
    d = e - e.mean()
    ll0 = -0.5 * n * (np.log(max(float(d @ d), 1e-300) / n) + np.log(2 * np.pi) + 1.0)
    return fit.rho if 2.0 * (fit.loglik - ll0) > _st.chi2.ppf(0.95, 1) else 0.0


def _scale_test(points, idx, unit, sigma2, w_radius, alpha):
    """Goodness of fit of segment `idx` (its points' residual scale about their own
    least-squares surface against the noise `sigma2`), with the SAR correlation of the
    residuals (:func:`lidarstat.stats.sar_variance_test`). Returns the test and the
    residual sum of squares."""
    from ..stats import sar_variance_test
    from ._sar_refine import _adjacency, _standardised

    xy, z = _unit_heights(unit, points[idx])
    A = unit.basis.monomials(xy)  # the same column space, no triangular solve
    q, _ = np.linalg.qr(A)
    e = z - q @ (q.T @ z)
    rho = _noise_rho(xy, e, w_radius, q)
    W = _standardised(_adjacency(xy, w_radius)) if rho else None
    return sar_variance_test(z, A, W, rho, sigma2, alpha=alpha), float(e @ e)


def _kmeans(x, k, iters=20):
    """Lloyd's k-means of the rows of `x` from farthest-point seeds (deterministic)."""
    seeds = [int(np.argmax(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))]
    d = np.sum((x - x[seeds[0]]) ** 2, axis=1)
    for _ in range(k - 1):
        seeds.append(int(np.argmax(d)))
        d = np.minimum(d, np.sum((x - x[seeds[-1]]) ** 2, axis=1))
    c = x[seeds]
    lab = np.zeros(x.shape[0], dtype=np.int64)
    for _ in range(iters):
        lab = np.argmin(((x[:, None, :] - c[None]) ** 2).sum(axis=2), axis=1)
        new = np.array([x[lab == j].mean(axis=0) if np.any(lab == j) else c[j]
                        for j in range(k)])
        if np.allclose(new, c):
            break
        c = new
    return lab


def _local_normals(xy, z, k=12):
    """Upward unit normals (n, 3) of the k nearest points (3-D): the covariance
    features' normals (:func:`lidarstat.features.covariance_features`, oriented up)."""
    from ..features import covariance_features

    f = covariance_features(np.c_[xy, z], k=min(k, z.size)).fields
    return np.c_[f["NormalX"], f["NormalY"], f["NormalZ"]]


#: Tukey biweight constant (95 % efficiency at the normal) of :func:`_robust_core`.
BIWEIGHT_C = 4.685


def _robust_core(xy, z, basis, crit, iters=20):
    """Points off the main surface of a segment: M-estimate (Tukey biweight, MAD scale)
    started from the least-squares surface of the largest cluster of local normals
    (3-means); returns the mask of points whose residual exceeds `crit` robust scales."""
    A = basis.monomials(xy)
    lab = _kmeans(_local_normals(xy, z), 3)
    main = lab == np.bincount(lab).argmax()
    if main.sum() <= A.shape[1]:
        return np.zeros(z.size, dtype=bool)
    coef = np.linalg.lstsq(A[main], z[main], rcond=None)[0]
    for _ in range(iters):
        e = z - A @ coef
        scale = 1.4826 * float(np.median(np.abs(e)))
        if not scale > 0:
            break
        u = e / (BIWEIGHT_C * scale)
        w = np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        sw = np.sqrt(w)
        new = np.linalg.lstsq(A * sw[:, None], z * sw, rcond=None)[0]
        if np.allclose(new, coef, rtol=0, atol=1e-9):
            break
        coef = new
    e = z - A @ coef
    scale = 1.4826 * float(np.median(np.abs(e)))
    return np.abs(e) > crit * scale


def _two_surfaces(xy, z, basis, min_size, iters=30, k=12):
    """Split points into two surfaces of `basis`'s order.

    Starts: the 2-means of the local normals (principal axes of the k nearest points)
    and each cluster of their 3-means against the other two (a segment of three faces);
    from each, k-surfaces iterations (each point to the surface with the smaller absolute
    residual). Returns the boolean part mask and the pooled residual sum of squares of
    the best start, or None when no start gives two parts of `min_size` points."""
    from scipy.spatial import cKDTree

    n = z.size
    if n < 2 * min_size:
        return None
    nrm = _local_normals(xy, z, k)
    nb2 = cKDTree(xy).query(xy, k=min(9, n))[1]
    three = _kmeans(nrm, 3)
    starts = [_kmeans(nrm, 2) == 1] + [three == j for j in range(3)]
    A = basis.monomials(xy)
    best = None
    for g in starts:
        for _ in range(iters):
            if g.sum() < A.shape[1] + 1 or (~g).sum() < A.shape[1] + 1:
                break
            r1 = z - A @ np.linalg.lstsq(A[g], z[g], rcond=None)[0]
            r0 = z - A @ np.linalg.lstsq(A[~g], z[~g], rcond=None)[0]
            new = np.abs(r1) < np.abs(r0)
            if np.array_equal(new, g):
                break
            g = new
        # spatial coherence: faces occupy regions, whereas a split of one rough surface
        # into two layers (residual signs) interleaves; a majority vote over the
        # planimetric neighbours keeps the first and scrambles the second, whose parts
        # then no longer reduce the residual sum of squares
        for _ in range(3):
            g = np.mean(g[nb2], axis=1) > 0.5
        if g.sum() < max(min_size, A.shape[1] + 1) or (~g).sum() < max(min_size, A.shape[1] + 1):
            continue
        res = [z - A @ np.linalg.lstsq(A[m], z[m], rcond=None)[0] for m in (g, ~g)]
        rss = float(res[0][g] @ res[0][g] + res[1][~g] @ res[1][~g])
        if best is None or rss < best[1]:
            # the coherent parts pass the gain test (the caller); the points on the
            # border between them go to the part whose surface they fit better
            border = np.any(g[nb2] != g[:, None], axis=1)
            fine = np.where(border, np.abs(res[0]) < np.abs(res[1]), g)
            small = min(fine.sum(), (~fine).sum()) < max(min_size, A.shape[1] + 1)
            best = (g if small else fine, rss)
    return best


def _split_misfits(points, labels, units, removed, *, sigma2, alpha, w_radius,
                   outlier_alpha, min_size):
    """Per-segment goodness-of-fit test and the split of the segments it rejects.

    Every segment (up to MAX_SEARCH points) is tested by :func:`_scale_test`. A rejected
    segment (up to :data:`SPLIT_MAX` points) is split in two by :func:`_two_surfaces` when the split leaves at most
    :data:`SPLIT_GAIN` of its residual sum of squares; each part is refitted on its share
    of the raw cluster (:func:`refit_unit`), given the final outlier test again, and
    tested again (at most :data:`SPLIT_DEPTH` successive splits). Parts below `min_size`
    are not made (the split is refused). A part that is still rejected but cannot be
    split (pieces of further faces smaller than `min_size`) loses its points off its
    main surface (:func:`_robust_core`, the outlier test's critical value; recorded in
    ``removed`` like the outlier test's) and is refitted and tested again; this counts
    as one more step of `SPLIT_DEPTH`.

    Returns labels, units, removed (as :func:`_outlier_test`) and per segment the test
    statistic, its degrees of freedom, the p-value, the scale ratio ``s / sigma`` and the
    split depth.
    """
    from ._sar_refine import MAX_SEARCH

    n = labels.size
    out_level = outlier_alpha if outlier_alpha is not None else 0.01
    removed = removed.astype(np.int64)  # key of the work item a point was removed from
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(len(units) + 2))
    work = [(order[starts[s]:starts[s + 1]], u, 0, s) for s, u in enumerate(units, start=1)]
    next_key = len(units) + 1
    done = []
    nan4 = (np.nan, np.nan, np.nan, np.nan)
    while work:
        idx, unit, depth, key = work.pop(0)
        r = unit.basis.n_terms
        if idx.size > MAX_SEARCH or idx.size <= r + 1:
            done.append((idx, unit, depth, nan4, key))
            continue
        test, rss = _scale_test(points, idx, unit, sigma2, w_radius, alpha)
        stats = (float(test.statistic), float(test.df), float(test.pvalue),
                 float(np.sqrt(rss / (idx.size - r) / sigma2)))
        parts = None
        if bool(test.reject) and depth < SPLIT_DEPTH and idx.size <= SPLIT_MAX:
            xy, z = _unit_heights(unit, points[idx])
            parts = _two_surfaces(xy, z, unit.basis, min_size)
            if parts is not None and parts[1] > SPLIT_GAIN * rss:
                parts = None
        if parts is None and bool(test.reject) and 0 < depth < SPLIT_DEPTH \
                and idx.size <= SPLIT_MAX:
            # a part of a split raw cluster that is still not one surface (pieces of
            # further faces too small for a part of their own): its points off the main
            # surface (robust fit, the outlier test's critical value) leave it
            xy, z = _unit_heights(unit, points[idx])
            off = _robust_core(xy, z, unit.basis, _st.norm.isf(out_level / 2.0))
            if 0 < off.sum() <= idx.size // 2:
                removed[idx[off]] = key
                keep = idx[~off]
                raw = unit.raw[np.isin(unit.raw, keep)]
                try:
                    sub = refit_unit(points, raw, keep[~np.isin(keep, raw)],
                                     w_radius=w_radius, degree=unit.degree,
                                     rho_hint=unit.fit.rho, fs=unit.fs)
                    work.append((keep, dataclasses.replace(sub, n_s=int(raw.size),
                                                           n_sa=unit.n_sa, m=unit.m),
                                 depth + 1, key))
                    continue
                except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                    removed[idx[off]] = 0
        if parts is None:
            done.append((idx, unit, depth, stats, key))
            continue
        g = parts[0]
        # the points the outlier test removed from the segment go to the part whose
        # surface they fit better, and are tested again there
        back = np.flatnonzero(removed == key)
        removed[back] = 0
        if back.size:
            xy, z = _unit_heights(unit, points[idx])
            xyb, zb = _unit_heights(unit, points[back])
            A, Ab = unit.basis.monomials(xy), unit.basis.monomials(xyb)
            res = [np.abs(zb - Ab @ np.linalg.lstsq(A[m], z[m], rcond=None)[0])
                   for m in (g, ~g)]
            to1 = res[0] <= res[1]
            parts_idx = (np.r_[idx[g], back[to1]], np.r_[idx[~g], back[~to1]])
        else:
            parts_idx = (idx[g], idx[~g])
        for part in parts_idx:
            raw = unit.raw[np.isin(unit.raw, part)]
            try:
                sub = refit_unit(points, raw, part[~np.isin(part, raw)], w_radius=w_radius,
                                 degree=unit.degree, rho_hint=unit.fit.rho, fs=unit.fs)
            except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                sub = None
            if sub is None:
                done.append((part, unit, depth + 1, nan4, 0))
                continue
            sub = dataclasses.replace(sub, n_s=int(raw.size), n_sa=unit.n_sa, m=unit.m)
            if outlier_alpha is not None:
                lab = np.zeros(n, dtype=np.int64)
                lab[part] = 1
                # every point of a part is tested: its raw cluster was shown not to be
                # one surface, so the local tests' acceptance no longer exempts it
                lab, (tst,), gone = _outlier_test(
                    points, lab, [dataclasses.replace(sub, raw=sub.raw[:0])], outlier_alpha)
                sub = dataclasses.replace(tst, raw=sub.raw[np.isin(sub.raw, tst.accepted)])
                removed[gone > 0] = next_key
                part = np.flatnonzero(lab == 1)
            work.append((part, sub, depth + 1, next_key))
            next_key += 1
    new = np.zeros(n, dtype=np.int64)
    new_of_key = np.zeros(next_key, dtype=np.int64)
    out_units, info = [], []
    for idx, unit, depth, st, key in done:
        out_units.append(unit)
        info.append((*st, depth))
        new[idx] = len(out_units)
        new_of_key[key] = len(out_units) if key else 0
    return (new, out_units, new_of_key[removed].astype(np.uint32),
            np.array(info, dtype=float).reshape(-1, 5))


#: Units whose residual standard deviation exceeds this multiple of the local noise
#: estimate are not planes at that noise (terrain, trees, curved or merged faces) and do
#: not enter the units' noise estimate.
SIGMA_UNIT_MAX = 3.0


def _units_noise(sd, sigma_local):
    """Median residual standard deviation `sd` of the units that can be planes at the
    noise level: those within :data:`SIGMA_UNIT_MAX` times the local estimate (NaN if
    none). The units are those before the goodness-of-fit split (a split of a rough
    plane would hide the roughness the re-estimate looks for)."""
    sd = np.asarray(sd, dtype=np.float64)
    sd = sd[np.isfinite(sd) & (sd <= SIGMA_UNIT_MAX * sigma_local)]
    return float(np.median(sd)) if sd.size else np.nan


def refine_raw_clusters(points, raw_labels, *, threshold, w_radius, degrees=1, max_degree=3,
                        alpha=0.001, alpha_residual=0.001, stop="both", block=1,
                        max_steps=500, min_size=10, merge_alpha=0.01, outlier_alpha=0.01,
                        sigma=None, gof_alpha=0.001, graph=None, progress=None):
    """SAR-FS refinement of given raw clusters; returns a :class:`Segmentation`.

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    raw_labels : (N,) ndarray of int
        Raw clusters 1..C (0: none).
    threshold : float
        Search-area path length (section 5.3).
    w_radius : float
        Radius of the SAR adjacency.
    degrees : int, None or (C,) array
        Polynomial order per cluster (None: t tests up to `max_degree`).
    alpha, alpha_residual, stop, block, max_steps
        Forward Search settings (:func:`forward_search`).
    min_size : int
        Smallest raw cluster refined and smallest final segment.
    merge_alpha : float or None
        Adjacent units of the same order are merged when the Chow F test does not reject
        one common surface at this level (a plane split into two raw clusters by a dormer
        or a chimney becomes one unit again; their Table 6 sizes are summed). None: no
        merging.
    outlier_alpha : float or None
        Level of the final outlier test, per point (iterated data snooping with deletion
        residuals, :func:`_outlier_test`; default 0.01; Baarda's usual 0.001 lets wall
        and leaf points 3-3.5 sigma off the plane stay, docs/methods/sar.md): points
        added to a segment by the search (not in its raw cluster) whose residual is
        significant leave the segment (field ``surface_outlier``: the segment they left;
        table ``n_outliers``). None: no test.
    sigma : float, optional
        A priori height noise (marginal standard deviation) of the per-segment
        goodness-of-fit test; None: no test.
    gof_alpha : float or None
        Level of the per-segment goodness-of-fit test (:func:`_split_misfits`): the
        residual scale of a segment's points about their own least-squares surface
        against `sigma`, chi-square with Satterthwaite's degrees of freedom under the SAR
        correlation of the residuals (:func:`lidarstat.stats.sar_variance_test`). A
        segment it rejects is split in two surfaces (normals 2-means, then k-surfaces)
        when that removes at least half of its residual sum of squares, and the parts are
        refitted, given the outlier test and tested again (table ``gof_stat``, ``gof_df``,
        ``gof_p``, ``scale_ratio``, ``split``). None: no test.
    graph : tuple, optional
        Precomputed :func:`delaunay_graph`.
    progress : callable, optional
        ``progress(done, total)`` after each cluster.
    """
    func = "refine_raw_clusters"
    # Checked here once: refine_cluster would refuse them cluster by cluster.
    block = check_scalar(block, "block", func=func, low=1, closed="left", integer=True)
    max_steps = check_scalar(max_steps, "max_steps", func=func, low=1, closed="left",
                             integer=True)
    min_size = check_scalar(min_size, "min_size", func=func, low=1, closed="left", integer=True)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    alpha_residual = check_scalar(alpha_residual, "alpha_residual", func=func, low=0.0,
                                  high=1.0)
    for name, level in (("outlier_alpha", outlier_alpha), ("gof_alpha", gof_alpha),
                        ("merge_alpha", merge_alpha)):
        if level is not None:
            check_scalar(level, name, func=func, low=0.0, high=1.0)
    n = points.shape[0]
    raw_labels = relabel(raw_labels, min_size)
    graph = graph if graph is not None else delaunay_graph(points)
    areas = search_areas(points, raw_labels, threshold, graph=graph)
    c_max = int(raw_labels.max()) if n else 0
    order = np.argsort(raw_labels, kind="stable")
    starts = np.searchsorted(raw_labels[order], np.arange(1, c_max + 2))
    units, skipped = [], []
    for c in range(1, c_max + 1):
        raw = order[starts[c - 1]:starts[c]]
        extra = areas.indices[areas.indptr[c - 1]:areas.indptr[c]]
        deg = degrees if degrees is None or np.isscalar(degrees) else int(degrees[c - 1])
        try:
            unit = refine_cluster(points, raw, extra, w_radius=w_radius,
                                  degree=deg, max_degree=max_degree, alpha=alpha,
                                  alpha_residual=alpha_residual, stop=stop, block=block,
                                  max_steps=max_steps, covariance=False)
            units.append(unit)
        except (np.linalg.LinAlgError, InvalidParameterError, ValueError) as exc:
            skipped.append((c, int(raw.size), str(exc)))
        if progress is not None:
            progress(c, c_max)
    if skipped:
        warnings.warn(f"{len(skipped)} raw clusters could not be modelled (first: cluster "
                      f"{skipped[0][0]}, {skipped[0][1]} points: {skipped[0][2]})",
                      LidarstatWarning, stacklevel=3)
    unit_labels = _assign(units, n)
    if merge_alpha is not None and len(units) > 1:
        root = _merge_groups(points, unit_labels, units, graph, merge_alpha, threshold)
        groups = {}
        for u in range(1, len(units) + 1):
            groups.setdefault(int(root[u]), []).append(u)
        new_units, new_of = [], np.zeros(len(units) + 1, dtype=np.int64)
        for _, members in sorted(groups.items()):
            merged = None
            if len(members) > 1:
                idx = np.flatnonzero(np.isin(unit_labels, members))
                try:
                    merged = _refit_unit(points, idx, [units[u - 1] for u in members],
                                         w_radius)
                except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                    merged = None  # keep the members apart
            if merged is not None:
                new_units.append(merged)
                new_of[members] = len(new_units)
            else:
                for u in members:
                    new_units.append(units[u - 1])
                    new_of[u] = len(new_units)
        unit_labels = new_of[unit_labels]
        units = new_units
    labels = relabel(unit_labels, max(int(min_size), 1))
    # segment s (1..S) -> unit index
    keep_units = []
    for s in range(1, int(labels.max()) + 1 if n else 1):
        u = np.bincount(unit_labels[labels == s]).argmax() - 1
        keep_units.append(int(u))
    kept = _final_units(points, labels, [units[u] for u in keep_units], w_radius)
    outlier = np.zeros(n, dtype=np.uint32)  # segment a point was removed from (0: none)
    if outlier_alpha is not None:
        labels, kept, outlier = _outlier_test(points, labels, kept, outlier_alpha)
    presplit_sigma = np.array([u.sigma for u in kept])
    gof = np.full((len(kept), 5), np.nan)
    gof[:, 4] = 0
    t_gof = time.perf_counter()
    if sigma is not None and gof_alpha is not None and kept:
        labels, kept, outlier, gof = _split_misfits(
            points, labels, kept, outlier, sigma2=float(sigma) ** 2, alpha=gof_alpha,
            w_radius=w_radius, outlier_alpha=outlier_alpha, min_size=max(int(min_size), 1))
    t_gof = time.perf_counter() - t_gof
    table = _table(points, labels, kept, list(range(len(kept))))
    table["n_outliers"] = np.bincount(outlier, minlength=len(kept) + 1)[1:].astype(np.int64)
    for k, name in enumerate(("gof_stat", "gof_df", "gof_p", "scale_ratio")):
        table[name] = gof[:, k]
    table["split"] = gof[:, 4].astype(np.int64)
    if len(kept) > 1:
        pts_c, seg_c = _two_hop_contacts(graph, labels)
        lines = intersection_lines(points, labels, kept, pts_c, seg_c, max_shift=threshold)
    else:
        lines = Polylines([], {})
    residual = np.full(n, np.nan)
    for s, unit in enumerate(kept, start=1):
        mine = labels[unit.accepted] == s
        residual[unit.accepted[mine]] = unit.residuals[mine]
    fields = {"raw_cluster": raw_labels.astype(np.uint32), "surface_residual": residual,
              "surface_outlier": outlier}
    params = {"threshold": threshold, "w_radius": w_radius, "alpha": alpha,
              "alpha_residual": alpha_residual, "stop": stop, "block": block,
              "raw_clusters": c_max, "skipped": skipped, "gof_alpha": gof_alpha,
              "splits": int(np.count_nonzero(gof[:, 4])), "gof_seconds": round(t_gof, 3)}
    seg = Segmentation(labels, table, lines, fields, "sar", params)
    seg.units = kept
    seg.presplit_sigma = presplit_sigma  # the noise re-estimate of segment_sar uses these
    return seg


def segment_sar(points, *, bandwidth=None, sigma=None, alpha=0.05, edge_alpha=0.05,
                fs_alpha=0.001, alpha_residual=0.001, stop="both", degree=1, max_degree=3,
                adaptive="multiscale", grow_radius=None, threshold=None, w_radius=None,
                min_size=30, block=1, max_steps=500, outlier_alpha=0.01, gof_alpha=0.001,
                progress=None, rng=0):
    """Segment a cloud into planar (or polynomial) surface units by SAR-FS (seed 002).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (E, N, height).
    bandwidth : float, optional
        Plane-regression bandwidth b; default chosen by :func:`select_plane_bandwidth`.
    sigma : float, optional
        Height noise. Default: estimated in up to two passes. The first uses the lower
        quartile of the local-plane variances (the noise of the smoothest surfaces); when
        the median residual standard deviation of the resulting units about their
        fitted surfaces (units within :data:`SIGMA_UNIT_MAX` times that estimate: the
        others are not planes at this noise) exceeds it by more than
        :data:`SIGMA_RATIO` (real surveys: strip offsets, roof texture), the
        segmentation is redone with that median, the noise about actual roof planes. ``params`` records ``sigma_local``, ``sigma_units`` and
        ``sigma_passes``.
    alpha : float
        Level of the local planarity test.
    edge_alpha : float
        Level of the height and slope tests of region growing.
    fs_alpha, alpha_residual, stop, block, max_steps
        Forward Search settings (:func:`forward_search`).
    degree : int or None
        Polynomial order of every unit (1: planes); None chooses it by t tests.
    max_degree : int
        Largest order considered when `degree` is None.
    adaptive : bool or {'multiscale', 'geary', 'none'}
        Per-point bandwidths of the local planes. ``'multiscale'`` (default): every point
        takes the largest of b, 0.75 b, 0.5 b whose local plane passes the planarity test,
        and raw clusters grow only through points planar at b (the others are attached,
        never expand), so faces narrower than the automatic b keep their edge points
        without windows bridging hip lines. ``True``/``'geary'``: Geary's local
        indicator (section 4.1). ``False``/``'none'``: one b for the whole cloud.
    grow_radius : float, optional
        Radius of the region-growing graph (default ``min(b, 2 * spacing)``).
    threshold : float, optional
        Search-area path length (default b).
    w_radius : float, optional
        Radius of the SAR adjacency W (default ``1.5 * spacing``).
    min_size : int
        Smallest raw cluster and final segment (points).
    outlier_alpha : float or None
        Level of the final per-point outlier test (:func:`refine_raw_clusters`).
    gof_alpha : float or None
        Level of the per-segment goodness-of-fit test against the noise `sigma` (given or
        estimated) and of the split of the segments it rejects (:func:`refine_raw_clusters`).
    progress : callable, optional
        ``progress(done, total)``.
    rng : int or Generator
        Seed of the bandwidth subsample.

    Returns
    -------
    Segmentation
        ``labels`` (0: no unit), the table (Table 6 sizes ``n_s``, ``n_sa``, ``m``; ``rho``,
        ``sigma``; surface coefficients ``c_pq`` of ``(E - E0)^p (N - N0)^q`` with
        standard errors; normal and slope at the centroid), the intersection lines and
        per-point ``raw_cluster``, ``z0``, ``slope_e``, ``slope_n``, ``plane_pass``,
        ``surface_residual``.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.segment import segment_sar
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 20, (4000, 2))
    >>> z = np.where(xy[:, 0] < 10, 0.5 * xy[:, 0], 10 - 0.5 * xy[:, 0])   # a gable roof
    >>> seg = segment_sar(np.c_[xy, z + rng.normal(0, 0.03, 4000)], bandwidth=1.5)
    >>> seg.n_segments, np.round(np.abs(seg.table["c_10"]), 2).tolist()
    (2, [0.5, 0.5])
    """
    from ..features import local_planes, select_plane_bandwidth

    func = "segment_sar"
    points = check_points(points, min_points=10)
    check_copies(points, what=func)  # neighbors/_duplicates.py
    if bandwidth is None:
        bandwidth = select_plane_bandwidth(points, rng=rng).bandwidth
    b = check_scalar(bandwidth, "bandwidth", func=func, low=0.0)
    spacing = _mean_spacing(points)
    grow_radius = (min(b, 2.0 * spacing) if grow_radius is None else
                   check_scalar(grow_radius, "grow_radius", func=func, low=0.0))
    threshold = (3.0 * b if threshold is None else
                 check_scalar(threshold, "threshold", func=func, low=0.0))
    w_radius = (1.5 * spacing if w_radius is None else
                check_scalar(w_radius, "w_radius", func=func, low=0.0))
    graph = delaunay_graph(points)
    nbh = radius_neighbors(points, grow_radius, dim=2)

    def one_pass(noise):
        fit = local_planes(points, b, sigma=noise, alpha=alpha, adaptive=adaptive)
        core = (fit.bandwidth >= b) if fit.params.get("adaptive") == "multiscale" else None
        raw = raw_clusters(points, fit, nbh, alpha=edge_alpha, min_size=min_size, core=core)
        seg = refine_raw_clusters(points, raw.labels, threshold=threshold, w_radius=w_radius,
                                  degrees=degree, max_degree=max_degree, alpha=fs_alpha,
                                  alpha_residual=alpha_residual, stop=stop, block=block,
                                  max_steps=max_steps, min_size=min_size, graph=graph,
                                  outlier_alpha=outlier_alpha,
                                  sigma=float(np.sqrt(fit.sigma2)), gof_alpha=gof_alpha,
                                  progress=progress)
        return fit, seg

    fit, seg = one_pass(sigma)
    sigma_local = float(np.sqrt(fit.sigma2))
    sigma_units = _units_noise(seg.presplit_sigma, sigma_local)
    passes = 1
    if sigma is None and sigma_units > SIGMA_RATIO * sigma_local:
        fit, seg = one_pass(sigma_units)
        passes = 2
    f = fit.to_fields()
    seg.fields.update({"z0": f["z0"], "slope_e": f["slope_e"], "slope_n": f["slope_n"],
                       "plane_pass": f["plane_pass"]})
    seg.params.update({"bandwidth": b, "sigma": float(np.sqrt(fit.sigma2)),
                       "sigma_local": sigma_local, "sigma_units": sigma_units,
                       "sigma_passes": passes,
                       "grow_radius": grow_radius, "spacing": spacing, "adaptive": adaptive,
                       "degree": degree})
    return seg
