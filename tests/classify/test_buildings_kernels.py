"""Kernels of the building test against plain NumPy loops: the ground sample of the noise
estimate, the non-last returns among each point's neighbours, the highest roof point of
the cells around each point, and the chunked local planes."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.classify import _buildings_kernels as _k


def _sample_reference(xy, z, mask, ux, uz, most, side):
    """The ground sample as the copied rows give it: metres, centred, whole blocks."""
    g = np.empty((int(mask.sum()), 3))
    g[:, 0] = xy[mask, 0] * ux
    g[:, 1] = xy[mask, 1] * ux
    g[:, 2] = z[mask] * uz
    g -= g.mean(axis=0)
    if len(g) > most:
        lo = g[:, :2].min(axis=0)
        every = int(np.ceil(len(g) / most))
        block = (np.floor((g[:, 0] - lo[0]) / side).astype(np.int64) * 7
                 + np.floor((g[:, 1] - lo[1]) / side).astype(np.int64) * 3)
        g = g[block % every == 0]
    return g


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("most", [150, 10_000])
def test_ground_sample_is_the_copied_rows_sample(seed, most):
    g = np.random.default_rng(seed)
    n = 4000
    xy = g.uniform(-50.0, 350.0, (n, 2)) + [5e5, 4e6]  # large coordinates: rounding
    z = g.normal(12.0, 3.0, n)
    mask = g.random(n) < 0.7
    for ux, uz in ((1.0, 1.0), (0.3048006096012192, 0.3048)):
        got = _k.ground_sample(xy, z, mask, ux, uz, most, 8.0)
        ref = _sample_reference(xy, z, mask, ux, uz, most, 8.0)
        assert got.shape == ref.shape
        assert np.array_equal(got, ref)  # bit for bit
        if most < mask.sum():
            assert 0 < len(got) < mask.sum()


@pytest.mark.parametrize("seed", range(4))
def test_neighbour_counts_and_residuals_match_a_loop(seed):
    g = np.random.default_rng(seed)
    n, k = 300, 7
    pts = g.normal(size=(n, 3))
    indices = g.integers(0, n, n * k).astype(np.int32)
    indptr = np.arange(n + 1, dtype=np.int64) * k
    centroid = g.normal(size=(n, 3))
    normal = g.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    planar = g.random(n) < 0.5
    multi = g.random(n) < 0.4
    dist, owner, count = np.empty(n), np.empty(n, np.int64), np.empty(n, np.int64)
    _k.nearest_plane_residual(pts, indptr, indices, centroid, normal, planar, multi,
                              dist, owner, count)
    for i in range(n):
        row = indices[indptr[i]:indptr[i + 1]]
        assert count[i] == multi[row].sum()
        e = (pts[i] - centroid[row]) * normal[row]  # the kernel's order of the sum
        d = np.where(planar[row], np.abs(e[:, 0] + e[:, 1] + e[:, 2]), np.inf)
        assert dist[i] == d.min()
        assert owner[i] == (row[int(np.argmin(d))] if np.isfinite(d.min()) else -1)


@pytest.mark.parametrize("seed", range(4))
def test_roof_top_is_the_highest_of_nine_cells(seed):
    g = np.random.default_rng(seed)
    width = 23
    ij = np.c_[g.integers(1, 30, 2000), g.integers(1, width - 1, 2000)]
    key = ij[:, 0] * width + ij[:, 1]
    roof = g.random(key.size) < 0.3
    zr = g.normal(size=key.size)
    seeds = np.unique(key[roof])
    zmax = np.array([zr[roof & (key == s)].max() for s in seeds])
    top = np.empty(key.size)
    _k.roof_top(key, seeds, zmax, width, top)
    dense = np.empty(key.size)  # the table of every cell: the same values
    _k.roof_top_dense(key, roof, zr, 31 * width, width, dense)
    for i in range(key.size):
        near = [key[i] + dx * width + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1)]
        hit = np.isin(seeds, near)
        assert top[i] == (zmax[hit].max() if hit.any() else -np.inf)
    assert np.array_equal(dense, top)


def test_local_planes_fit_every_row_across_chunks():
    g = np.random.default_rng(7)
    k = 9
    n = 2 * _k._CHUNK + 37  # rows in three chunks, the last one short
    normal = np.array([0.2, -0.3, 1.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    uv = g.normal(size=(n * k, 2))
    basis = np.linalg.svd(normal[None, :])[2][1:]
    pts = uv @ basis + 0.01 * g.normal(size=(n * k, 1)) * normal
    indices = np.arange(n * k, dtype=np.int32)
    indptr = np.arange(n + 1, dtype=np.int64) * k
    centroid, nrm, rss = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    _k.local_planes(pts, indptr, indices, np.arange(n), centroid, nrm, rss)
    for r in (0, _k._CHUNK - 1, _k._CHUNK, n - 1):
        q = pts[r * k:(r + 1) * k]
        c = q.mean(axis=0)
        w, v = np.linalg.eigh((q - c).T @ (q - c))
        assert np.allclose(centroid[r], c, rtol=0, atol=1e-12)
        assert np.isclose(rss[r], w[0], rtol=1e-9, atol=1e-15)
        assert np.allclose(nrm[r], v[:, 0] * np.sign(v[2, 0]), atol=1e-9)
    assert np.all(nrm[:, 2] > 0.9)
