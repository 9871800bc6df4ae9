"""Split of a segment that is not one surface into two (goodness-of-fit step of SAR-FS).

Two surfaces of the segment's order by k-surfaces iterations started from clusters of
the local normals (:func:`two_surfaces`), and the points off the main surface of a
segment that cannot be split (:func:`robust_core`, Tukey's biweight M-estimate).
"""

from __future__ import annotations

import numpy as np


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


#: Tukey biweight constant (95 % efficiency at the normal) of :func:`robust_core`.
BIWEIGHT_C = 4.685


def robust_core(xy, z, basis, crit, iters=20):
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


def two_surfaces(xy, z, basis, min_points, iters=30, k=12):
    """Split points into two surfaces of `basis`'s order.

    Starts: the 2-means of the local normals (principal axes of the k nearest points)
    and each cluster of their 3-means against the other two (a segment of three faces);
    from each, k-surfaces iterations (each point to the surface with the smaller absolute
    residual). Returns the boolean part mask and the pooled residual sum of squares of
    the best start, or None when no start gives two parts of `min_points` points."""
    from scipy.spatial import cKDTree

    n = z.size
    if n < 2 * min_points:
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
        least = max(min_points, A.shape[1] + 1)
        if g.sum() < least or (~g).sum() < least:
            continue
        res = [z - A @ np.linalg.lstsq(A[m], z[m], rcond=None)[0] for m in (g, ~g)]
        rss = float(res[0][g] @ res[0][g] + res[1][~g] @ res[1][~g])
        if best is None or rss < best[1]:
            # the coherent parts pass the gain test (the caller); the points on the
            # border between them go to the part whose surface they fit better
            border = np.any(g[nb2] != g[:, None], axis=1)
            fine = np.where(border, np.abs(res[0]) < np.abs(res[1]), g)
            small = min(fine.sum(), (~fine).sum()) < least
            best = (g if small else fine, rss)
    return best
