"""Copies found by one sort, and neighbourhood queries sized before they allocate."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.errors import DuplicatePointsError, InvalidParameterError, TooManyNeighborsError
from lidarstat.neighbors import (
    CellIndex,
    find_duplicates,
    knn_neighbors,
    location_hash,
    max_pairs,
    radius_neighbors,
)
from lidarstat.neighbors._budget import half_radius_population
from lidarstat.neighbors._duplicates import map_rows, refuse_dominated


@pytest.mark.parametrize("seed", range(4))
def test_find_duplicates_matches_numpy_unique(seed):
    g = np.random.default_rng(seed)
    pts = g.integers(-3, 4, (4000, 3)).astype(float) * 0.25 + [5e5, 5e6, 100.0]
    pts[g.random(4000) < 0.3] = [5e5, 5e6, 100.0]
    d = find_duplicates(pts)
    u, first, counts = np.unique(pts, axis=0, return_index=True, return_counts=True)
    assert d.n_unique == len(u) and d.n_copies == 4000 - len(u)
    np.testing.assert_array_equal(d.first, np.sort(first))    # first copies, input order
    np.testing.assert_array_equal(pts[d.first][d.inverse], pts)
    np.testing.assert_array_equal(np.sort(d.counts), np.sort(counts))
    assert d.largest == counts.max()


def test_find_duplicates_edge_cases():
    assert not find_duplicates(np.empty((0, 3))).any
    d = find_duplicates([[0.0, -0.0, 1.0], [-0.0, 0.0, 1.0], [0.0, 0.0, 2.0]])
    assert d.n_unique == 2 and d.inverse.tolist() == [0, 0, 1]   # -0.0 == 0.0
    d = find_duplicates(np.random.default_rng(0).normal(size=(1000, 3)))
    assert not d.any and d.describe() == "1,000 points share 1,000 locations"


def _hash_reference(pts):
    """The location hash in NumPy: the bits of +0.0 for -0.0, three products, two mixes."""
    b = (pts + 0.0).view(np.uint64)  # -0.0 + 0.0 is +0.0
    with np.errstate(over="ignore"):
        h = ((b[:, 0] * np.uint64(0x9E3779B97F4A7C15))
             ^ (b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F))
             ^ (b[:, 2] * np.uint64(0x165667B19E3779F9)))
        h ^= h >> np.uint64(29)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(32)
    return h


@pytest.mark.parametrize("block", [7, 1 << 18])
def test_location_hash_of_columns_equals_the_row_hash(monkeypatch, block):
    # one kernel for the rows of an (N, 3) array and for separate columns (an (N, 2) block
    # and a z array), over blocks of rows that need not divide N
    from lidarstat.neighbors import _duplicates

    monkeypatch.setattr(_duplicates, "_HASH_BLOCK", block)
    g = np.random.default_rng(3)
    pts = np.round(g.uniform(-2, 2, (1000, 3)), 1)
    pts[:5] = [[-0.0, 1.0, 0.0], [0.0, 1.0, -0.0], [0.0, -0.0, 0.0], [-0.0, 0.0, -0.0],
               [0.0, 0.0, 0.0]]
    ref = _hash_reference(pts)
    xy, z = np.ascontiguousarray(pts[:, :2]), pts[:, 2].copy()
    z.flags.writeable = False  # a read-only column hashes the same (copied per block)
    assert np.array_equal(location_hash(pts[:, 0], pts[:, 1], pts[:, 2]), ref)
    assert np.array_equal(location_hash(xy[:, 0], xy[:, 1], z), ref)
    assert np.array_equal(_duplicates._row_hash(pts), ref.view(np.int64))
    assert ref[0] == ref[1] and ref[2] == ref[3] == ref[4] and ref[0] != ref[2]


def test_refuse_dominated_names_the_counts():
    pts = np.r_[np.zeros((30, 3)), np.eye(3)]
    d = find_duplicates(pts)
    with pytest.raises(DuplicatePointsError,
                       match=r"33 points share 4 locations \(up to 30 at one\) \(88% of "):
        refuse_dominated(d, what="the method")
    refuse_dominated(find_duplicates(np.r_[pts[:2], np.eye(3)]), what="the method")
    with pytest.raises(DuplicatePointsError, match="more than 1 at one location"):
        refuse_dominated(find_duplicates(np.r_[pts[:2], np.eye(3)]), what="m", max_copies=1)


def test_map_rows_broadcasts_per_point_arrays_only():
    d = find_duplicates([[0.0, 0, 0], [1, 0, 0], [0, 0, 0]])
    out = map_rows({"a": np.array([5, 6]), "b": np.arange(3), "s": 1.5}, 2, d.inverse)
    assert out["a"].tolist() == [5, 6, 5] and out["b"].tolist() == [0, 1, 2]
    assert out["s"] == 1.5


def test_half_radius_population_is_a_lower_bound(rng):
    pts = rng.uniform(0, 1, (3000, 3))
    nb = radius_neighbors(pts, 0.2)
    lower = half_radius_population(pts, pts, 0.2, 3)
    assert (lower <= nb.counts).all() and lower.sum() > 0


def test_radius_query_refused_from_the_bounds(monkeypatch):
    pts = np.zeros((5000, 3))
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", "1000000")
    with pytest.raises(TooManyNeighborsError, match=r"radius 0.5 gives at least 25,000,000 "
                       r"neighbour pairs \(400.0 MB, 5,000 per point\), above the ceiling"):
        radius_neighbors(pts, 0.5)
    with pytest.raises(TooManyNeighborsError):
        CellIndex(pts, 0.5).query(pts[:300])
    with pytest.raises(TooManyNeighborsError):
        CellIndex(pts, 0.5).bound_pairs()


def test_radius_query_refused_by_the_exact_count(monkeypatch, rng):
    """Between the bounds, the counting pass decides, before the CSR is allocated."""
    pts = rng.uniform(0, 1, (4000, 3))
    nnz = radius_neighbors(pts, 0.3).nnz
    lower = int(half_radius_population(pts, pts, 0.3, 3).sum())
    assert lower < nnz
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", str((lower + nnz) // 2))
    with pytest.raises(TooManyNeighborsError, match=f"radius 0.3 gives {nnz:,} neighbour"):
        radius_neighbors(pts, 0.3)
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", str(nnz))
    assert radius_neighbors(pts, 0.3).nnz == nnz


def test_knn_refused_above_the_ceiling(monkeypatch, rng):
    pts = rng.uniform(0, 1, (1000, 3))
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", "9999")
    with pytest.raises(TooManyNeighborsError, match=r"k = 10 gives 10,000 neighbour pairs"):
        knn_neighbors(pts, 10)
    assert knn_neighbors(pts, 9).nnz == 9000


def test_max_pairs_setting(monkeypatch):
    monkeypatch.delenv("LIDARSTAT_MAX_PAIRS", raising=False)
    assert max_pairs() >= 1 << 26
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", "1e6")
    assert max_pairs() == 1_000_000
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", "-3")
    with pytest.raises(InvalidParameterError, match="LIDARSTAT_MAX_PAIRS"):
        max_pairs()
