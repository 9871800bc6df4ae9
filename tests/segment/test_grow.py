"""Graph kernels of segmentation against SciPy's connected components and brute force."""

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from lidarstat.errors import InvalidParameterError
from lidarstat.neighbors import Neighborhoods, radius_neighbors
from lidarstat.segment import adjacency, components, grow_regions, relabel


def _same_partition(a, b):
    """True when two labellings define the same groups (ids may differ)."""
    pairs = np.unique(np.c_[a, b], axis=0)
    return len(np.unique(pairs[:, 0])) == len(pairs) == len(np.unique(pairs[:, 1]))


@pytest.fixture
def cloud(rng):
    pts = rng.uniform(0, 10, size=(3000, 3)) * [1, 1, 0.1]
    return pts, radius_neighbors(pts, 0.35)


def test_components_match_scipy(cloud, rng):
    pts, nbh = cloud
    src, dst = nbh.edges()
    ok = rng.random(nbh.nnz) < 0.5
    mask = rng.random(len(pts)) < 0.9
    lab = components(nbh, ok, mask)
    keep = ok & mask[src] & mask[dst]
    g = csr_matrix((np.ones(keep.sum()), (src[keep], dst[keep])), shape=(len(pts),) * 2)
    _, ref = connected_components(g, directed=True, connection="weak")
    assert np.all(lab[~mask] == 0) and np.all(lab[mask] > 0)
    assert _same_partition(lab[mask], ref[mask])
    sizes = np.bincount(lab)[1:]
    assert np.all(np.diff(sizes) <= 0)  # ids by decreasing size


def test_components_min_size_and_determinism(cloud):
    pts, nbh = cloud
    lab = components(nbh, min_points=5)
    sizes = np.bincount(lab)[1:]
    assert sizes.min() >= 5
    # The same partition given through permuted points gives the same sizes per id.
    perm = np.random.default_rng(1).permutation(len(pts))
    lab2 = components(radius_neighbors(pts[perm], 0.35), min_points=5)
    assert np.array_equal(np.bincount(lab2)[1:], sizes)


def test_grow_without_barriers_equals_components(cloud, rng):
    pts, nbh = cloud
    src, dst = nbh.edges()
    # Region growing needs symmetric criteria to equal components: use a symmetric one.
    ok = np.abs(pts[src, 2] - pts[dst, 2]) < 0.5
    order = rng.permutation(len(pts))
    assert _same_partition(grow_regions(nbh, ok, order), components(nbh, ok))


def test_grow_stops_at_non_growing_points():
    # Two faces of a roof meeting at a ridge line x = 0; ridge points may not grow.
    g = np.arange(-2, 2.001, 0.1)
    x, y = np.meshgrid(g, g)
    pts = np.c_[x.ravel(), y.ravel(), -np.abs(x.ravel())]
    nbh = radius_neighbors(pts, 0.15)
    ridge = np.abs(pts[:, 0]) < 0.05
    lab = grow_regions(nbh, can_grow=~ridge)
    left, right = lab[pts[:, 0] < -0.05], lab[pts[:, 0] > 0.05]
    assert len(np.unique(left)) == 1 and len(np.unique(right)) == 1
    assert left[0] != right[0]
    assert np.all(lab[ridge] > 0)  # ridge points are attached, not dropped
    # Merging does not cross the barrier either; without it everything is one region.
    assert lab.max() == grow_regions(nbh, can_grow=~ridge, merge=True).max() == 2
    assert grow_regions(nbh).max() == 1


def test_grow_merge_joins_regions_met_through_accepted_edges():
    pts = np.c_[np.arange(6.0), np.zeros(6), np.zeros(6)]
    nbh = radius_neighbors(pts, 1.1)
    src, dst = nbh.edges()
    # Directed criterion: edges may only be walked to the right.
    ok = dst >= src
    order = np.array([3, 0])
    no_merge = grow_regions(nbh, ok, order)
    assert no_merge.tolist() == [1, 1, 1, 2, 2, 2]  # equal sizes: first point first
    merged = grow_regions(nbh, ok, order, merge=True)
    assert merged.tolist() == [1] * 6


def test_relabel_is_independent_of_input_ids():
    a = np.array([4, 4, 4, 9, 9, 0, 2, 2, 2])
    b = np.array([1, 1, 1, 3, 3, 0, 7, 7, 7])
    assert relabel(a).tolist() == relabel(b).tolist() == [1, 1, 1, 3, 3, 0, 2, 2, 2]
    assert relabel(a, min_points=3).tolist() == [1, 1, 1, 0, 0, 0, 2, 2, 2]


def test_adjacency_matches_brute_force(cloud, rng):
    pts, nbh = cloud
    lab = (pts[:, 0] // 2.5).astype(int) + 4 * (pts[:, 1] // 5).astype(int) + 1
    lab[rng.random(len(pts)) < 0.05] = 0
    pairs, counts = adjacency(nbh, lab)
    ref = {}
    for i in range(len(pts)):
        for j in nbh.row(i)[0]:
            a, b = lab[i], lab[j]
            if a and b and a != b:
                key = (min(a, b), max(a, b))
                ref[key] = ref.get(key, 0) + 1
    assert {tuple(p): c for p, c in zip(pairs.tolist(), counts.tolist())} == ref


def test_bad_input():
    nbh = radius_neighbors(np.eye(3), 2.0)
    with pytest.raises(InvalidParameterError, match="edge_ok"):
        components(nbh, edge_ok=np.ones(2, bool))
    with pytest.raises(InvalidParameterError, match="mask"):
        components(nbh, mask=np.ones(5, bool))
    with pytest.raises(InvalidParameterError, match="order"):
        grow_regions(nbh, order=[0, 7])
    with pytest.raises(InvalidParameterError, match="Neighborhoods"):
        components(np.eye(3))


def test_query_rows_subset():
    # Rows for a subset of points only: the others can still be reached.
    pts = np.c_[np.arange(4.0), np.zeros(4), np.zeros(4)]
    full = radius_neighbors(pts, 1.1)
    rows = [0, 2]
    indptr = np.r_[0, np.cumsum([full.counts[r] for r in rows])]
    sub = Neighborhoods(indptr, np.concatenate([full.row(r)[0] for r in rows]),
                        np.concatenate([full.row(r)[1] for r in rows]), 4, query=rows)
    assert components(sub).tolist() == [1, 1, 1, 1]
