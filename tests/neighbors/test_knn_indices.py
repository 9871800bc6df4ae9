"""The grid kNN of every point (:func:`lidarstat.neighbors.knn_indices`) gives the tree's
rows bit for bit: where distances are distinct by the grid search, where two are equal
(points on a coarse lattice, copies of points) by the tree."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError, TooManyNeighborsError
from lidarstat.neighbors import KnnIndex, knn_indices


def _same(pts, k):
    got = knn_indices(pts, k)
    ref = KnnIndex(pts).query_indices(k)
    assert got.indices.dtype == ref.indices.dtype
    assert np.array_equal(got.indptr, ref.indptr)
    assert np.array_equal(got.indices, ref.indices)
    return got


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("k", [1, 5, 12])
def test_rows_are_the_trees_on_surfaces_and_in_volumes(seed, k):
    g = np.random.default_rng(seed)
    roof = np.c_[g.uniform(0, 40, (3000, 2)), np.zeros(3000)]
    roof[:, 2] = 0.3 * roof[:, 0] + g.normal(0, 0.02, 3000)  # a tilted plane
    crown = g.normal([60.0, 20.0, 8.0], 2.0, (1500, 3))  # a volume
    pts = np.vstack([roof, crown]) + [5e5, 4e6, 10.0]  # map coordinates
    _same(pts, k)


@pytest.mark.parametrize("seed", range(4))
def test_ties_are_ordered_as_the_tree_orders_them(seed, monkeypatch):
    import lidarstat.neighbors._knn_indices as mod

    asked = []

    class Counted(KnnIndex):
        def query(self, k, *, query=None, **kw):
            asked.append(0 if query is None else len(query))
            return super().query(k, query=query, **kw)

    monkeypatch.setattr(mod, "KnnIndex", Counted)
    g = np.random.default_rng(seed)
    lattice = np.round(g.uniform(0, 3, (3000, 3)), 1)  # decimetre grid: many equal distances
    copies = np.vstack([lattice, lattice[g.choice(3000, 200, replace=False)]])
    for pts in (lattice, copies):
        asked.clear()
        _same(pts, 12)
        # the rows with equal distances (and only they) went to the tree
        assert 0 < sum(asked) < len(pts)
    asked.clear()
    _same(g.random((3000, 3)), 12)  # distinct distances: the grid alone
    assert sum(asked) == 0


@pytest.mark.parametrize("seed", range(4))
def test_sparse_points_far_from_a_dense_cluster_are_exact(seed):
    # the cell follows the dense majority: the sparse points' neighbours lie many cells
    # away, found shell by shell of cells
    g = np.random.default_rng(seed)
    dense = g.normal([10.0, 10.0, 10.0], 0.3, (4000, 3))
    sparse = g.uniform(0, 60, (60, 3))
    _same(np.vstack([dense, sparse]), 12)
    _same(np.vstack([sparse, dense[:200]]), 5)


def test_tiny_clouds_and_bad_arguments():
    pts = np.random.default_rng(0).random((6, 3))
    for k in (1, 5, 6):
        _same(pts, k)
    with pytest.raises(InvalidParameterError):
        knn_indices(pts, 7)
    with pytest.raises(InvalidParameterError):
        knn_indices(pts, 0)


def test_the_pairs_ceiling_refuses_the_search(monkeypatch):
    pts = np.random.default_rng(1).random((500, 3))
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", str(12 * 500 - 1))
    with pytest.raises(TooManyNeighborsError, match="LIDARSTAT_MAX_PAIRS"):
        knn_indices(pts, 12)
