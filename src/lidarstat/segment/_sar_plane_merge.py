"""Tested merge of adjacent grown planes that are one plane (second stage of the SAR
segmentation).

Tested growth (:func:`lidarstat.segment._sar_planes.grow_planes`) stops a region where a
neighbouring point's local normal disagrees with the region's; on a real roof face the
local normals of 12 points scatter (tiles, gutters, strip offsets), so one face can come
out as several regions that abut. Two adjacent regions are joined when

1. **Chow's F test** does not reject one plane for both
   (:func:`lidarstat.stats.chow_test` on the orthogonal residual sums of squares:
   ``F = ((RSS_ab - RSS_a - RSS_b) / 3) / ((RSS_a + RSS_b) / (n_a + n_b - 6))`` against
   F(3, n_a + n_b - 6), level `merge_alpha`), a test that does not need the noise, and
2. **the crease test** does not refuse: when both groups pass the plane test against
   the noise along the normal (``RSS / sigma_n^2 ~ chi2(n - 3)``, level `crease_alpha`)
   and their union fails it, the two are two faces meeting at a crease whatever F says
   (F loses power when one group is rough).

The tests run on the groups (every region already merged into either), so a chain of
pairwise merges cannot join two faces across a crease. Pairs are taken by decreasing
number of contacts (neighbourhood links between the two regions).
"""

from __future__ import annotations

import numpy as np

from ..stats import chow_test
from ._sar_merge import contact_pairs, crease_refuses_fits, find_root

#: Level of Chow's F test of the merge (as the merge of the SAR units).
MERGE_ALPHA = 0.01
#: Fewest neighbourhood links between two regions for them to be merge candidates.
MIN_CONTACTS = 4


def _rss(n, s1, s2):
    """Orthogonal residual sum of squares and unit normal of a point set from its sums."""
    c = s1 / n
    lam, vec = np.linalg.eigh(s2 - n * np.outer(c, c))
    return max(float(lam[0]), 0.0), vec[:, 0]


def merge_planes(P, labels, nbr, region_sz, sigma_h, *, merge_alpha=MERGE_ALPHA,
                 crease_alpha=0.001, noise=None):
    """Labels with the adjacent regions that are one plane joined.

    Parameters
    ----------
    P : (m, 3) ndarray
        Coordinates (relative to any origin).
    labels : (m,) int64 ndarray
        Regions 1..R (0: none).
    nbr : (m, k) int ndarray
        Neighbour indices of every point (into `P`).
    region_sz : (R + 1,) ndarray
        Height noise of every region (index 0 unused).
    sigma_h : float
        Planimetric noise.
    merge_alpha, crease_alpha : float
        Levels of Chow's F test and of the crease test (None: no crease test).
    noise : callable
        ``noise(nz, sigma_z, sigma_h)``, the noise along a normal of vertical component nz.

    Returns
    -------
    labels : (m,) int64 ndarray
        Regions 1..R' after the merge (0 kept), numbered by first region.
    region_sz : (R' + 1,) ndarray
        Height noise of every merged region (its largest member's).
    merged : int
        Number of merges.
    """
    labels = np.asarray(labels, dtype=np.int64)
    R = int(labels.max()) if labels.size else 0
    if R < 2:
        return labels, np.asarray(region_sz, dtype=np.float64), 0
    keys, counts = contact_pairs(np.repeat(labels, nbr.shape[1]), labels[nbr.ravel()], R,
                                 MIN_CONTACTS)
    keys = keys[np.argsort(-counts, kind="stable")]
    o = P.mean(axis=0)
    X = P - o
    n = np.bincount(labels, minlength=R + 1).astype(np.float64)
    s1 = np.stack([np.bincount(labels, weights=X[:, j], minlength=R + 1) for j in range(3)],
                  axis=1)
    s2 = np.stack([np.bincount(labels, weights=X[:, i] * X[:, j], minlength=R + 1)
                   for i in range(3) for j in range(3)], axis=1).reshape(-1, 3, 3)
    size = n.copy()
    sz = np.asarray(region_sz, dtype=np.float64).copy()
    parent = np.arange(R + 1)

    def fit(m, rss, nrm, s_z):
        return rss, m - 3, float(noise(nrm[2], s_z, sigma_h)) ** 2

    merged = 0
    for key in keys:
        ra = find_root(parent, int(key // (R + 1)))
        rb = find_root(parent, int(key % (R + 1)))
        if ra == rb:
            continue
        na, nb = n[ra], n[rb]
        if na < 4 or nb < 4:
            continue
        rss_a, nrm_a = _rss(na, s1[ra], s2[ra])
        rss_b, nrm_b = _rss(nb, s1[rb], s2[rb])
        rss_u, nrm_u = _rss(na + nb, s1[ra] + s1[rb], s2[ra] + s2[rb])
        if chow_test(rss_u, rss_a, rss_b, 3, int(na), int(nb), alpha=merge_alpha).reject:
            continue
        s_z = sz[ra] if size[ra] >= size[rb] else sz[rb]
        if crease_alpha is not None and crease_refuses_fits(
                fit(na, rss_a, nrm_a, sz[ra]), fit(nb, rss_b, nrm_b, sz[rb]),
                fit(na + nb, rss_u, nrm_u, s_z), crease_alpha):
            continue
        root, other = (ra, rb) if size[ra] >= size[rb] else (rb, ra)
        parent[other] = root
        n[root] += n[other]
        s1[root] += s1[other]
        s2[root] += s2[other]
        merged += 1
    roots = np.array([find_root(parent, u) for u in range(R + 1)])
    uniq = np.unique(roots[1:])
    new = np.zeros(R + 1, dtype=np.int64)
    new[uniq] = np.arange(1, uniq.size + 1)
    return new[roots][labels], np.r_[np.nan, sz[uniq]], merged
