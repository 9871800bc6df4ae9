"""Tested plane growing in each plane's own frame: the planes the SAR units leave out.

The SAR units of seed 002 are height fields z(E, N) seeded by local planes in planimetric
windows of the bandwidth b. On real roofs that misses the steep faces (a mansard or a
canal-house gable, where horizontal survey error makes the height residuals
``sigma / cos(slope)`` and the planimetric window holds a sliver of the face), the faces
narrower than b (dormer cheeks, chimney sides) and the walls. :func:`grow_planes` finds
them among the points no SAR unit took, by the same statistical logic in the plane's own
frame (orthogonal residuals, noise along the normal):

1. **Local planes.** The k nearest free points of every free point, their principal
   plane; the planarity test refers the sum of squared orthogonal residuals
   ``lambda_min`` to ``sigma^2 chi2(k - 3)`` (upper tail, `alpha`).
2. **Seeds**: planar points, most planar first.
3. **Growth by tested membership.** A region's plane (centroid c, normal n, in-plane
   axes u_1, u_2 with scatters S_1, S_2) admits a neighbouring free point x when its
   orthogonal distance passes the prediction test
   ``|n.(x - c)| <= z_{1-a/2} sigma sqrt(1 + 1/m + sum_j (u_j.(x - c))^2 / S_j)``
   (`edge_alpha`); an admitted point expands the region only when it is planar and its
   local normal agrees with the region's (Wald test of the two tilts t = U'n_local in
   the region's axes U against their covariance ``sigma^2 (U' S U)^{-1}``, S the scatter
   of the point's neighbourhood: ``t' U'SU t / sigma^2 ~ chi-square(2)``, `edge_alpha`), so a region
   stops at a crease: the points across it are admitted only within the prediction band
   and never carry the growth on.
4. **The plane's test**: every region is refitted; its residual sum of squares against
   the noise, ``RSS / sigma^2 ~ chi2(m - 3)`` (`gof_alpha`), and the standard error of
   its normal, ``sigma_hat / sqrt(S_min)`` radians (the tilt about the in-plane axis of
   least spread). Regions of `min_points` or more are kept; smaller ones (down to
   `min_size`) when the test accepts them and no point is an outlier.

Adjacent regions that are one plane (Chow's F test, the crease test) are merged first
(:mod:`._sar_plane_merge`): tested growth can cut one rough face into several regions.

:func:`attach_points` then joins the free points on the rim of a plane by the same
prediction test.
"""

from __future__ import annotations

import numpy as np

from ..neighbors import knn_neighbors
from ..stats import chi2_critical, chi2_quantile, chi2_test, z_critical
from ._sar_plane_merge import MERGE_ALPHA, merge_planes

#: Local normals this far from vertical (degrees) estimate the planimetric noise.
STEEP_DEG = 60.0
#: Quantile of the local variances that estimates the noise (planimetric, per cell).
SIGMA_QUANTILE = 0.25
#: Side (m) of the planimetric cells of the local height-noise estimate.
NOISE_CELL = 10.0


def noise_along_normal(nz, sigma_z, sigma_h):
    """Noise standard deviation along a unit normal of vertical component `nz` for
    independent vertical and planimetric errors of standard deviations `sigma_z`,
    `sigma_h`: ``sqrt(sigma_z^2 nz^2 + sigma_h^2 (1 - nz^2))``."""
    nz2 = np.minimum(np.asarray(nz, dtype=np.float64) ** 2, 1.0)
    return np.sqrt(sigma_z ** 2 * nz2 + sigma_h ** 2 * (1.0 - nz2))


#: Smallest mean |cos| between a point's local normal and its neighbours' for the point
#: to be on a coherent surface (a wall, not a crown) in the planimetric noise estimate.
COHERENCE = float(np.cos(np.radians(20.0)))


def planimetric_noise(lam_min, normals, nbr, sigma_z, *, q=SIGMA_QUANTILE, min_count=50):
    """Planimetric noise from the local planes of steep coherent surfaces (walls).

    Points whose local normal is more than :data:`STEEP_DEG` from vertical and agrees
    with its neighbours' (mean ``|n_i . n_j|`` at least :data:`COHERENCE`: crowns, whose
    local normals scatter, are left out): the `q` quantile of ``lambda_min / (k - 3)``
    corrected by ``chi2_q(k - 3) / (k - 3)``, as the height noise is estimated from the
    flattest surfaces; at least `sigma_z`, and `sigma_z` when fewer than `min_count`
    such points."""
    k = nbr.shape[1]
    coherent = np.abs(np.einsum("ij,ikj->ik", normals, normals[nbr])).mean(axis=1) >= \
        COHERENCE
    steep = (np.abs(normals[:, 2]) < np.cos(np.radians(STEEP_DEG))) & coherent
    if np.count_nonzero(steep) < min_count:
        return float(sigma_z)
    df = k - 3
    s2 = np.quantile(lam_min[steep] / df, q) / (chi2_quantile(q, df) / df)
    # the quantile mixes the planimetric and the (smaller) vertical share of the noise
    return float(max(np.sqrt(s2), sigma_z))

#: Table columns of the grown planes (one row per plane).
PLANE_COLUMNS = ("normal_x", "normal_y", "normal_z", "slope_deg", "normal_se_deg", "sigma",
                 "gof_stat", "gof_df", "gof_p", "sigma_noise")


def _local_pca(P, nbr):
    """Per point: eigenvalues (ascending) and eigenvectors of the scatter of its k
    neighbours about their centroid (chunks of 50,000 points)."""
    m, k = nbr.shape
    lam = np.empty((m, 3))
    vec = np.empty((m, 3, 3))
    for a in range(0, m, 50_000):
        Q = P[nbr[a:a + 50_000]]
        Q = Q - Q.mean(axis=1, keepdims=True)
        lam[a:a + 50_000], vec[a:a + 50_000] = np.linalg.eigh(
            np.einsum("kni,knj->kij", Q, Q))
    return np.maximum(lam, 0.0), vec


class _Plane:
    """Running sums of a region's points (relative to an origin) and its plane."""

    def __init__(self, origin):
        self.o = origin
        self.n = 0
        self.s1 = np.zeros(3)
        self.s2 = np.zeros((3, 3))

    def add(self, X):
        X = X - self.o
        self.n += len(X)
        self.s1 += X.sum(axis=0)
        self.s2 += X.T @ X

    def fit(self):
        c = self.s1 / self.n
        lam, vec = np.linalg.eigh(self.s2 - self.n * np.outer(c, c))
        return c + self.o, np.maximum(lam, 1e-12), vec


def _grow(P, nbr, planar, lam, vec, sz, sigma_h, z_band, chi_tilt, min_points):
    """Regions by tested membership; `sz` (m,) the height noise per point (a region
    takes its seed's). Returns the labels and the noise of every region."""
    m = len(P)
    labels = np.zeros(m, dtype=np.int64)
    region_sz = [np.nan]
    tried = ~planar
    order = np.argsort(lam[:, 0], kind="stable")
    order = order[planar[order]]
    nxt = 1
    for s in order:
        if labels[s] or tried[s]:
            continue
        sig = (float(sz[s]), sigma_h)
        region = nbr[s][labels[nbr[s]] == 0]
        plane = _Plane(P[s])
        plane.add(P[region])
        labels[region] = nxt
        frontier = region[planar[region]]
        members = [region]
        while frontier.size:
            cand = np.unique(nbr[frontier].ravel())
            cand = cand[labels[cand] == 0]
            if not cand.size:
                break
            c, sl, sv = plane.fit()
            nrm, u = sv[:, 0], sv[:, 1:]
            X = P[cand] - c
            h = 1.0 / plane.n + ((X @ u) ** 2 / sl[1:]).sum(axis=1)
            sigma = noise_along_normal(nrm[2], *sig)
            ok = np.abs(X @ nrm) <= z_band * sigma * np.sqrt(1.0 + h)
            cand = cand[ok]
            if not cand.size:
                break
            labels[cand] = nxt
            plane.add(P[cand])
            members.append(cand)
            # tilt of each local normal against the region's, in the region's axes
            ln = vec[cand, :, 0]
            ln = ln * np.where((ln @ nrm) < 0, -1.0, 1.0)[:, None]
            t = ln @ u  # (c, 2) small-angle tilts
            s2 = noise_along_normal(ln[:, 2], *sig) ** 2
            # Wald form t' (U' S U) t / sigma^2, S the local scatter: exact whatever the
            # local axes' orientation against the region's
            pu = np.einsum("ji,cjk->cik", u, vec[cand])
            info = np.einsum("cik,ck,cjk->cij", pu, lam[cand], pu)
            w = np.einsum("ci,cij,cj->c", t, info, t) / s2
            frontier = cand[planar[cand] & (w <= chi_tilt)]
        region = np.concatenate(members)
        if region.size < min_points:
            labels[region] = 0
            tried[region] = True
            continue
        region_sz.append(sig[0])
        nxt += 1
    return labels, np.asarray(region_sz)


def local_noise(P, lam_min, nz, k, sigma, *, cell=NOISE_CELL, q=SIGMA_QUANTILE,
                min_count=30):
    """Height noise per point: per planimetric cell of `cell` metres, the `q` quantile of
    the local variances ``lambda_min / (k - 3)`` of its points on gentle local planes
    (normals within :data:`STEEP_DEG` of vertical) corrected by ``chi2_q(k-3)/(k-3)``,
    at least the global `sigma` (cells with fewer than `min_count` such points keep
    `sigma`). Roof coverings differ (tiles, gravel, vegetated roofs): one global noise
    from the smoothest surfaces makes the rough ones fail every test."""
    ij = np.floor((P[:, :2] - P[:, :2].min(axis=0)) / cell).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    _, cid = np.unique(key, return_inverse=True)
    gentle = np.abs(nz) >= np.cos(np.radians(STEEP_DEG))
    df = k - 3
    corr = chi2_quantile(q, df) / df
    out = np.full(cid.max() + 1, float(sigma))
    order = np.argsort(cid[gentle], kind="stable")
    cg = cid[gentle][order]
    vg = (lam_min[gentle] / df)[order]
    starts = np.searchsorted(cg, np.arange(cid.max() + 2))
    for c in range(cid.max() + 1):
        v = vg[starts[c]:starts[c + 1]]
        if v.size >= min_count:
            out[c] = max(float(sigma), float(np.sqrt(np.quantile(v, q) / corr)))
    return out[cid]


def grow_planes(points, free, *, sigma, k=12, alpha=0.05, edge_alpha=0.05, min_points=30,
                gof_alpha=0.001, local=True, min_size=None, merge_alpha=MERGE_ALPHA):
    """Planes among the `free` points by tested growth in their own frame.

    Parameters
    ----------
    points : (N, 3) ndarray
    free : (N,) bool ndarray
        Points available (those no SAR unit took).
    sigma : float
        Noise standard deviation along the normal.
    k : int
        Neighbours of the local planes (the point included).
    alpha, edge_alpha, gof_alpha : float
        Levels of the local planarity test, of the membership and tilt tests, and of
        each plane's test against the noise.
    min_points : int
        Smallest plane kept whatever its test says.
    min_size : int, optional
        Smallest plane grown (default `min_points`); planes of `min_size` to
        `min_points` - 1 points are kept when their own test accepts them (small faces:
        dormer cheeks, chimney sides).
    merge_alpha : float or None
        Level of Chow's F test of the merge of adjacent regions that are one plane
        (:func:`lidarstat.segment._sar_plane_merge.merge_planes`, with the crease test at
        `gof_alpha`); None: no merge.

    Returns
    -------
    labels : (N,) int64 ndarray
        Plane id 1.. (0: none), by decreasing size.
    residual : (N,) ndarray
        Orthogonal residual from the plane (NaN off the planes).
    table : dict of str to ndarray
        :data:`PLANE_COLUMNS`, one row per plane.
    sigma_h : float
        Planimetric noise.
    merged : int
        Merges of adjacent regions.
    """
    n = len(points)
    labels = np.zeros(n, dtype=np.int64)
    residual = np.full(n, np.nan)
    table = {c: np.empty(0) for c in PLANE_COLUMNS}
    idx = np.flatnonzero(free)
    if idx.size < max(min_points, k) or not np.isfinite(sigma) or sigma <= 0:
        return labels, residual, table, float(sigma), 0
    P = points[idx] - points[idx].min(axis=0)
    nbr = knn_neighbors(P, k).indices.reshape(-1, k)
    lam, vec = _local_pca(P, nbr)
    sigma_h = planimetric_noise(lam[:, 0], vec[:, :, 0], nbr, sigma)
    sz = local_noise(P, lam[:, 0], vec[:, 2, 0], k, sigma) if local else \
        np.full(len(P), float(sigma))
    planar = lam[:, 0] <= chi2_critical(alpha, k - 3) * noise_along_normal(
        vec[:, 2, 0], sz, sigma_h) ** 2
    lab, reg_sz = _grow(P, nbr, planar, lam, vec, sz, sigma_h, z_critical(edge_alpha),
                        chi2_critical(edge_alpha, 2),
                        min_points if min_size is None else min_size)
    merged = 0
    if merge_alpha is not None:
        lab, reg_sz, merged = merge_planes(P, lab, nbr, reg_sz, sigma_h,
                                           merge_alpha=merge_alpha, crease_alpha=gof_alpha,
                                           noise=noise_along_normal)
    sizes = np.bincount(lab)[1:]
    rank = np.zeros(sizes.size + 1, dtype=np.int64)
    rank[1 + np.argsort(-sizes, kind="stable")] = np.arange(1, sizes.size + 1)
    lab = rank[lab]
    plane_sz = np.empty(sizes.size)
    plane_sz[rank[1:] - 1] = reg_sz[1:]
    labels[idx] = lab
    sizes = np.bincount(lab, minlength=sizes.size + 1)[1:]  # in rank order
    rows = {c: [] for c in PLANE_COLUMNS}
    max_z = np.zeros(sizes.size)
    order = np.argsort(lab, kind="stable")
    starts = np.searchsorted(lab[order], np.arange(1, sizes.size + 2))
    for r in range(sizes.size):
        mem = order[starts[r]:starts[r + 1]]
        X = P[mem] - P[mem].mean(axis=0)
        lam_r, vec_r = np.linalg.eigh(X.T @ X)
        nrm = vec_r[:, 0] if vec_r[2, 0] >= 0 else -vec_r[:, 0]
        e = X @ nrm
        residual[idx[mem]] = e
        rss, df = float(e @ e), mem.size - 3
        s0 = float(noise_along_normal(nrm[2], plane_sz[r], sigma_h))
        # the p-value does not depend on the level; gof_alpha None keeps no small plane
        test = chi2_test(rss / s0 ** 2, df, alpha=gof_alpha or 0.001)
        s_hat = np.sqrt(rss / df)
        max_z[r] = np.abs(e).max() / s0
        for key, v in zip(PLANE_COLUMNS, (*nrm, np.degrees(np.arccos(min(abs(nrm[2]), 1.0))),
                                          np.degrees(s_hat / np.sqrt(max(lam_r[1], 1e-12))),
                                          s_hat, rss / s0 ** 2, df, float(test.pvalue),
                                          plane_sz[r])):
            rows[key].append(v)
    table = {c: np.asarray(v, dtype=np.float64) for c, v in rows.items()}
    # planes below min_points are kept only when their own test accepts them and no
    # point of theirs is an outlier (largest |residual| / noise against the two-sided
    # Bonferroni normal critical value at gof_alpha): a few points of a crown over a
    # roof can tilt a 12-point plane until its sum of squares passes
    small = sizes < min_points
    if gof_alpha is not None:
        small &= (table["gof_p"] < gof_alpha) | (max_z > z_critical(gof_alpha / sizes))
    if small.any():
        keep = np.flatnonzero(~small)
        new = np.zeros(sizes.size + 1, dtype=np.int64)
        new[keep + 1] = np.arange(1, keep.size + 1)
        gone = labels > 0
        gone[gone] = small[labels[gone] - 1]
        residual[gone] = np.nan
        labels = new[labels]
        table = {c: v[keep] for c, v in table.items()}
    return labels, residual, table, sigma_h, merged


def segment_planes(points, labels):
    """Orthogonal-regression plane of every segment: centroid (S, 3), eigenvalues (S, 3)
    ascending and eigenvectors (S, 3, 3) of its scatter (NaN for segments under 3
    points)."""
    s_max = int(labels.max()) if labels.size else 0
    cen = np.full((s_max, 3), np.nan)
    lam = np.full((s_max, 3), np.nan)
    vec = np.full((s_max, 3, 3), np.nan)
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(1, s_max + 2))
    for s in range(s_max):
        mem = order[starts[s]:starts[s + 1]]
        if mem.size < 3:
            continue
        cen[s] = points[mem].mean(axis=0)
        X = points[mem] - cen[s]
        lam[s], vec[s] = np.linalg.eigh(X.T @ X)
    return cen, np.maximum(lam, 1e-12), vec


def attach_points(points, labels, sigma_z, sigma_h, *, k=12, edge_alpha=0.05, rounds=5, eligible=None,
                  min_share=0.25):
    """Unlabelled points joined to a neighbouring plane by the membership test.

    A free point at least `min_share` of whose `k` nearest neighbours are points of
    segment s (a point on the segment's rim, not one of a tree or a chimney that merely
    touches it) joins s when its orthogonal distance to the plane of s passes the prediction test of
    :func:`grow_planes` (level `edge_alpha`, noise :func:`noise_along_normal` with
    ``sig = (sigma_z, sigma_h)``); with several such segments, the one of the smallest
    standardised distance. Repeated `rounds` times (the planes are not refitted: the
    admitted points are a thin rim). Only segments flagged in `eligible` (S,) admit.

    Returns the new labels and the orthogonal residuals of the admitted points (NaN
    elsewhere).
    """
    labels = np.asarray(labels, dtype=np.int64).copy()
    sigma_z = np.asarray(sigma_z, dtype=np.float64)
    resid = np.full(len(points), np.nan)
    if not labels.any():
        return labels, resid
    origin = points.min(axis=0)
    P = points - origin
    cen, lam, vec = segment_planes(P, labels)
    s_max = len(cen)
    ok_seg = np.isfinite(cen).all(axis=1) if eligible is None else \
        (np.asarray(eligible, bool) & np.isfinite(cen).all(axis=1))
    nrm = vec[:, :, 0]
    count = np.bincount(labels, minlength=s_max + 1)[1:]
    zc = z_critical(edge_alpha)
    nbr = knn_neighbors(P, k).indices.reshape(-1, k)
    for _ in range(rounds):
        free = np.flatnonzero(labels == 0)
        if not free.size:
            break
        cand_seg = labels[nbr[free]]  # (f, k)
        share = (cand_seg[:, :, None] == cand_seg[:, None, :]).sum(axis=2)
        cand_seg = np.where(share >= min_share * k, cand_seg, 0)
        best = np.zeros(free.size, dtype=np.int64)
        best_w = np.full(free.size, np.inf)
        for j in range(k):
            s = cand_seg[:, j]
            has = (s > 0)
            has[has] = ok_seg[s[has] - 1]
            if not has.any():
                continue
            rows = np.flatnonzero(has)
            si = s[rows] - 1
            X = P[free[rows]] - cen[si]
            d = np.einsum("ij,ij->i", X, nrm[si])
            h = 1.0 / count[si] + (np.einsum("ij,ij->i", X, vec[si, :, 1]) ** 2 / lam[si, 1]
                                   + np.einsum("ij,ij->i", X, vec[si, :, 2]) ** 2 / lam[si, 2])
            w = np.abs(d) / (noise_along_normal(nrm[si, 2], sigma_z[si], sigma_h) *
                             np.sqrt(1.0 + h))
            better = (w <= zc) & (w < best_w[rows])
            best[rows[better]] = si[better] + 1
            best_w[rows[better]] = w[better]
            resid[free[rows[better]]] = d[better]
        if not best.any():
            break
        labels[free] = best
    resid[labels == 0] = np.nan
    return labels, resid
