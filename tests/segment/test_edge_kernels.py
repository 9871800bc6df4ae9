"""The Numba edge selections of the covariance segmentation equal the NumPy masks they replace."""

import dataclasses

import numpy as np
import pytest
from scipy import special

from lidarstat.neighbors import knn_neighbors, radius_neighbors
from lidarstat.segment import _edge_kernels as ek
from lidarstat.segment._covariance_lines import clean_plane_points
from lidarstat.segment._covariance_segments import surface_prefix_edges, truncate_rows
from lidarstat.segment._grow import adjacency
from lidarstat.segment._scales import SCALES, planar_scales, prefix_edges


@pytest.fixture(params=["knn", "radius", "visited"])
def graph(request, rng):
    pts = np.c_[rng.uniform(0, 4, (1500, 2)), rng.normal(0, 0.01, 1500)]
    nbh = knn_neighbors(pts, 20) if request.param != "radius" else radius_neighbors(pts, 0.25)
    if request.param == "visited":  # rows visited in another order: the same selections
        nbh = dataclasses.replace(nbh, row_order=rng.permutation(len(pts)))
    labels = rng.integers(0, 6, len(pts)).astype(np.int32)
    return pts, nbh, labels


def test_prefix_and_label_selections(graph, rng):
    pts, nbh, labels = graph
    src, dst = nbh.edges()
    good = rng.random(len(pts)) < 0.8
    bad = (~good[dst]) & (dst != src)
    cs = np.cumsum(bad)
    start = nbh.indptr[:-1]
    before = np.where(start > 0, cs[np.maximum(start - 1, 0)], 0)
    assert np.array_equal(surface_prefix_edges(nbh, good),
                          (cs - np.repeat(before, nbh.counts)) == 0)
    la, lb = labels[src], labels[dst]
    keep = (la > 0) & (lb > 0) & (la < lb)
    i, j = ek.label_pairs(nbh, labels)
    assert np.array_equal(i, src[keep]) and np.array_equal(j, dst[keep])
    keep = (la > 0) & (lb > 0) & (la != lb)
    i, j = ek.label_pairs(nbh, labels, different_only=True)
    assert np.array_equal(i, src[keep]) and np.array_equal(j, dst[keep])
    # the first `width` entries of each row only (none, some, all)
    at = np.arange(nbh.nnz) - np.repeat(nbh.indptr[:-1], nbh.counts)
    for width in (0, 7, 10**6):
        near = keep & (at < width)
        i, j = ek.label_pairs(nbh, labels, different_only=True, width=width)
        assert np.array_equal(i, src[near]) and np.array_equal(j, dst[near])
        asc = (la > 0) & (la < lb) & (at < width)
        i, j = ek.label_pairs(nbh, labels, width=width)
        assert np.array_equal(i, src[asc]) and np.array_equal(j, dst[asc])
    if nbh.kind == "knn":  # the pairs of the truncated rows, without their copy
        short = truncate_rows(nbh, 7)
        for mode in (False, True):
            got = ek.label_pairs(nbh, labels, different_only=mode, width=7)
            ref = ek.label_pairs(short, labels, different_only=mode)
            assert all(np.array_equal(g, r) for g, r in zip(got, ref))
    for wide in (labels.astype(np.int64), labels.astype(np.uint64)):  # gathered as int32
        i, j = ek.label_pairs(nbh, wide, different_only=True)
        assert np.array_equal(i, src[keep]) and np.array_equal(j, dst[keep])
    big = labels.astype(np.int64) * 2**33  # too wide for int32: kept as given
    i, j = ek.label_pairs(nbh, big, different_only=True)
    assert np.array_equal(i, src[keep]) and np.array_equal(j, dst[keep])
    cand = rng.random(len(pts)) < 0.3
    use = cand[src] & (labels[dst] > 0) & (labels[src] == 0)
    s, t = ek.reintegration_pairs(nbh, cand, labels)
    assert np.array_equal(s, src[use]) and np.array_equal(t, dst[use])
    kstar = rng.integers(0, 25, len(pts))
    pos = np.arange(nbh.nnz) - np.repeat(nbh.indptr[:-1], nbh.counts)
    assert np.array_equal(prefix_edges(nbh, kstar), pos < np.repeat(kstar, nbh.counts))
    # adjacency: pairs and counts from the (a != b) edges
    a, b = labels[src].astype(np.int64), labels[dst].astype(np.int64)
    keep = (a > 0) & (b > 0) & (a != b)
    keys, counts = np.unique(np.minimum(a, b)[keep] * 6 + np.maximum(a, b)[keep],
                             return_counts=True)
    pairs, got = adjacency(nbh, labels)
    assert np.array_equal(pairs[:, 0] * 6 + pairs[:, 1], keys) and np.array_equal(got, counts)


def test_adaptive_edges_and_clean_points(rng):
    pts = np.c_[rng.uniform(0, 4, (1500, 2)), rng.normal(0, 0.01, 1500)]
    nbh = knn_neighbors(pts, 20)
    n = len(pts)
    src, dst = nbh.edges()
    surface = rng.random(n) < 0.7
    joinable = surface | (rng.random(n) < 0.1)
    kstar = np.where(rng.random(n) < 0.2, 0, rng.choice([8, 12, 16, 20], n)).astype(np.int32)
    pn = rng.normal(size=(n, 3))
    pn /= np.linalg.norm(pn, axis=1, keepdims=True)
    pn[kstar == 0] = np.nan
    pn[1::2] = pn[::2][: n // 2] * np.cos(0.1)  # near-parallel pairs around the threshold
    cmin = float(np.cos(np.radians(10.0)))
    first = prefix_edges(nbh, np.full(n, 12))
    cos = np.abs(np.einsum("ij,ij->i", pn[src], pn[dst]))
    smooth = (kstar[dst] == 0) | (cos >= cmin)
    agree = (kstar[src] == 0) | (kstar[dst] == 0) | (cos >= cmin)
    ref = (surface_prefix_edges(nbh, joinable) & first & surface[src] & agree) | \
        (prefix_edges(nbh, kstar) & smooth)
    for visit in (np.arange(n), rng.permutation(n)):  # any visiting order: the same mask
        out = np.empty(nbh.nnz, dtype=bool)
        ek.adaptive_edges(visit, nbh.indptr, nbh.indices, nbh.query_indices(), joinable,
                          surface, kstar, pn, 12, cmin, out)
        assert np.array_equal(out, ref)
    labels = rng.integers(0, 4, n)
    idx = nbh.indices.reshape(n, 20)
    ok = joinable[idx] & (labels[idx] == labels[:, None])
    first = np.argmax(ok, axis=1)
    has = ok[np.arange(n), first]
    want = np.arange(n)
    want[has] = idx[has, first[has]]
    assert np.array_equal(clean_plane_points(labels, joinable, nbh), want)


def test_planar_scales_is_the_largest_accepted_prefix(rng):
    """Reference: every prefix size tested with numpy; the largest accepted one wins."""
    n = 400
    t = rng.uniform(0, np.pi, n)
    pts = np.c_[np.cos(t), rng.uniform(0, 2, n), 0.3 * np.sin(t)] + rng.normal(0, 0.003, (n, 3))
    nbh = knn_neighbors(pts, 50)
    sigma = 0.003
    kstar, p, normal = planar_scales(pts, nbh, sigma, alpha=0.05)
    idx = nbh.indices.reshape(n, 50)
    crit = special.chdtri(np.array(SCALES) - 3.0, 0.05)
    want = np.zeros(n, dtype=int)
    margin = np.full(n, np.inf)
    for i in range(n):
        for m, c in zip(SCALES, crit):
            lam0 = np.linalg.eigvalsh(np.cov(pts[idx[i, :m]].T))[0]
            stat = (m - 1) * max(lam0, 0.0) / sigma**2
            margin[i] = min(margin[i], abs(stat - c) / c)
            if stat <= c:
                want[i] = m
    clear = margin > 1e-8
    assert 0 < (want > 0).mean() < 1 and np.array_equal(kstar[clear], want[clear])
    ok = kstar > 0
    assert np.all((p[ok] > 0.05) & (p[ok] <= 1)) and np.isnan(p[~ok]).all()
    assert np.allclose(np.linalg.norm(normal[ok], axis=1), 1.0)
    # rows visited in another order (the kNN grid order in the segmentation): bit-identical
    shuffled = dataclasses.replace(nbh, row_order=rng.permutation(n))
    for a, b in zip((kstar, p, normal), planar_scales(pts, shuffled, sigma, alpha=0.05)):
        assert np.array_equal(a, b, equal_nan=True)
