import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarstat.errors import InvalidParameterError, InvalidPointsError
from lidarstat.neighbors import CellIndex, Neighborhoods, knn_neighbors, radius_neighbors


@pytest.mark.parametrize("dim", [3, 2])
def test_radius_matches_kdtree_on_utm_coordinates(rng, dim):
    pts = rng.random((5000, 3)) * [20, 20, 2] + [4.5e5, 5.2e6, 120.0]
    nb = radius_neighbors(pts, 0.7, dim=dim)
    ref = cKDTree(pts[:, :dim]).query_ball_point(pts[:, :dim], 0.7)
    assert nb.nnz == sum(len(r) for r in ref)
    for i in range(0, 5000, 37):
        idx, dist = nb.row(i)
        assert sorted(idx.tolist()) == sorted(ref[i])
        np.testing.assert_allclose(dist, np.linalg.norm((pts[idx] - pts[i])[:, :dim], axis=1),
                                   atol=1e-9)


def test_radius_query_subset_and_self_included(rng):
    pts = rng.random((2000, 3))
    q = np.array([5, 17, 1999])
    nb = radius_neighbors(pts, 0.2, query=q)
    assert len(nb) == 3
    for r, i in enumerate(q):
        idx, dist = nb.row(r)
        assert i in idx.tolist() and dist[idx.tolist().index(i)] == 0.0


def test_cell_blocks_cover_every_point_once(rng):
    pts = rng.random((10000, 3)) * [50, 50, 1]
    index = CellIndex(pts, 1.0)
    blocks = index.cell_blocks(700)
    sizes = [index.cell_start[c1] - index.cell_start[c0] for c0, c1 in blocks]
    assert sum(sizes) == 10000 and blocks[0][0] == 0 and blocks[-1][1] == index.n_cells
    assert max(sizes) < 700 + 200  # a block overshoots by at most one cell
    indptr, idx, _ = index.query_cells(*blocks[3])
    assert indptr.size - 1 == sizes[3]
    assert np.all(idx < 10000)


def test_to_input_order_inverts_the_sort(rng):
    pts = rng.random((5000, 3)) * [30, 30, 1]
    index = CellIndex(pts, 1.0)
    for values in (rng.random(5000), rng.integers(0, 255, 5000).astype(np.uint8),
                   rng.integers(-9, 9, 5000).astype(np.int32)):
        back = index.to_input_order(values[index.order])
        assert back.dtype == values.dtype and np.array_equal(back, values)
        into = np.empty_like(values)
        assert index.to_input_order(values[index.order], out=into) is into
        assert np.array_equal(into, values)


def test_knn_sorted_and_includes_self(rng):
    pts = rng.random((1000, 3))
    nb = knn_neighbors(pts, 8)
    assert (nb.counts == 8).all()
    assert (nb.indices[nb.indptr[:-1]] == np.arange(1000)).all()
    d = nb.distances.reshape(-1, 8)
    assert (np.diff(d, axis=1) >= 0).all()


def test_neighborhoods_validation():
    with pytest.raises(InvalidParameterError, match="indptr"):
        Neighborhoods(np.array([1, 2]), np.array([0]), np.array([0.0]), 1)
    with pytest.raises(InvalidParameterError, match="indices must lie"):
        Neighborhoods(np.array([0, 1]), np.array([5]), np.array([0.0]), 2)


@pytest.mark.parametrize("radius", [0, -1.0, np.nan, "a"])
def test_bad_radius(radius):
    with pytest.raises(InvalidParameterError, match="'radius' parameter"):
        radius_neighbors(np.zeros((3, 3)), radius)


def test_bad_points():
    with pytest.raises(InvalidPointsError, match="empty"):
        radius_neighbors(np.zeros((0, 3)), 1.0)
    with pytest.raises(InvalidPointsError, match="NaN or infinite"):
        radius_neighbors(np.array([[0, 0, np.nan]]), 1.0)


def _argsort_index(points, cell, dim):
    """CellIndex as first written: NumPy keys and a stable argsort (the reference)."""
    origin = points.min(axis=0)
    local = points - origin
    extent = local.max(axis=0)
    dims = np.floor(extent / cell).astype(np.int64) + 1
    if dim == 2:
        dims[2] = 1
    ijk = np.minimum(np.floor(local / cell).astype(np.int64), dims - 1)
    if dim == 2:
        ijk[:, 2] = 0
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(keys, kind="stable")
    skeys = keys[order]
    starts = np.r_[0, np.flatnonzero(np.diff(skeys)) + 1, skeys.size]
    return order, local[order], skeys[starts[:-1]], starts


@pytest.mark.parametrize("dim", [3, 2])
@pytest.mark.parametrize("n, cell", [(70_000, 0.05), (70_000, 0.004), (3000, 0.05)])
def test_cell_index_counting_sort_equals_stable_argsort(rng, dim, n, cell):
    """Dense grids use an O(N) counting sort, sparse ones argsort: same index either way."""
    pts = np.c_[rng.uniform(0, 1, (n, 2)), rng.normal(0, 0.05, n)] + [6e5, 5.2e6, 300.0]
    pts[:50] = pts[50:100]  # duplicates keep their input order within a cell
    idx = CellIndex(pts, cell, dim=dim)
    for got, ref in zip((idx.order, idx.sorted_points, idx.cell_keys, idx.cell_start),
                        _argsort_index(pts, cell, dim)):
        assert np.array_equal(got, ref)


@pytest.mark.parametrize("parts", [1, 2, 3, 7, 5000])
def test_counting_scatter_is_the_stable_sort_for_any_split(rng, parts):
    """The counting sort splits the keys into `parts` ranges placed in parallel: the
    order is the stable argsort's for any split (empty ranges, more parts than keys)."""
    from lidarstat.neighbors._kernels import counting_scatter

    n, total = 20_000, 3000
    keys = rng.integers(0, total, n)
    keys[:800] = keys[800:1600]  # equal keys keep their input order
    keys[keys % 7 == 0] = 11  # one crowded key, many empty ones
    pts = rng.normal(0, 1, (n, 3))
    origin = np.array([0.5, -1.0, 2.0])
    counts = np.bincount(keys, minlength=total)
    start = np.cumsum(counts) - counts
    order, sorted_points = np.empty(n, dtype=np.int64), np.empty((n, 3))
    counting_scatter(pts, origin, keys, start, parts, order, sorted_points)
    ref = np.argsort(keys, kind="stable")
    assert np.array_equal(order, ref)
    assert np.array_equal(sorted_points, pts[ref] - origin)
    assert np.array_equal(start, np.cumsum(counts))


@pytest.mark.parametrize("high", [5, 1 << 22, 1 << 45])
def test_radix_order_equals_stable_argsort(rng, high):
    """Sparse grids sort their keys by LSD radix (1 to 5 passes here): the stable argsort."""
    from lidarstat.neighbors._kernels import radix_order

    keys = rng.integers(0, high, 20_000)
    keys[:500] = keys[500:1000]  # equal keys keep their input order
    order, skeys = radix_order(keys, max(high - 1, 1).bit_length())
    ref = np.argsort(keys, kind="stable")
    assert np.array_equal(order, ref)
    assert np.array_equal(skeys, keys[ref])


@pytest.mark.parametrize("high", [2, 5000, 2**40])
def test_radix_order_in_blocks_equals_stable_argsort(rng, high):
    """Above two blocks of keys each pass counts and scatters the blocks in parallel: the
    order is still the stable argsort's (equal keys in input order across blocks)."""
    from lidarstat.neighbors._kernels import _RADIX_BLOCK, radix_order

    keys = rng.integers(0, high, 3 * _RADIX_BLOCK + 12_345)
    order, skeys = radix_order(keys, max(high - 1, 1).bit_length())
    ref = np.argsort(keys, kind="stable")
    assert np.array_equal(order, ref)
    assert np.array_equal(skeys, keys[ref])


def test_neighborhoods_hold_one_index_dtype(rng):
    """Every search gives int32 indices below 2**31 points, whatever type it was given, so
    each kernel taking neighbour indices compiles once (half the memory of int64)."""
    from lidarstat.neighbors._csr import index_dtype

    ptr = np.array([0, 2, 3])
    for dt in (np.int16, np.int32, np.int64, np.uint32):
        nb = Neighborhoods(ptr, np.array([0, 1, 1], dtype=dt), np.zeros(3), 2)
        assert nb.indices.dtype == np.int32
    assert index_dtype(2**31 - 1) == np.int32 and index_dtype(2**31) == np.int64
    pts = rng.uniform(0, 3, (400, 3))
    index = CellIndex(pts, 0.6)
    assert index.query_cells(0, index.n_cells)[1].dtype == np.int32
    assert index.query(pts[:5])[1].dtype == np.int32
    for nb in (radius_neighbors(pts, 0.6), radius_neighbors(pts, 0.6, query=[3, 4]),
               radius_neighbors(pts, 0.6, dim=2), knn_neighbors(pts, 8)):
        assert nb.indices.dtype == np.int32


def test_row_order_is_a_checked_permutation():
    ptr = np.array([0, 1, 2, 3])
    nb = Neighborhoods(ptr, np.array([1, 2, 0]), np.zeros(3), 3, row_order=[2, 0, 1])
    assert nb.visit_order().tolist() == [2, 0, 1] and nb.row_order.dtype == np.int64
    assert Neighborhoods(ptr, np.array([1, 2, 0]), np.zeros(3), 3).visit_order().tolist() == \
        [0, 1, 2]
    for bad in ([0, 0, 1], [0, 1], [0, 1, 3]):
        with pytest.raises(InvalidParameterError, match="row_order"):
            Neighborhoods(ptr, np.array([1, 2, 0]), np.zeros(3), 3, row_order=bad)


@pytest.mark.parametrize("seed", range(4))
def test_may_have_copies_proves_distinct_locations(seed):
    from lidarstat.neighbors import CellIndex, find_duplicates

    rng = np.random.default_rng(seed)
    pts = np.round(rng.random((4000, 3)) * [8, 8, 1], 2) + [5e5, 5e6, 100]
    pts = np.unique(pts, axis=0)
    # neighbours one unit in the last place apart stay distinct
    pts[1] = pts[0]
    pts[1, 2] = np.nextafter(pts[0, 2], np.inf)
    index = CellIndex(pts, 0.5)
    assert not find_duplicates(pts).any and not index.may_have_copies()
    # one copy anywhere is seen, whatever the order of the points
    k = int(rng.integers(pts.shape[0]))
    dup = np.vstack([pts, pts[k]])[rng.permutation(pts.shape[0] + 1)]
    assert CellIndex(dup, 0.5).may_have_copies()
    # a cell too large to compare pairwise counts as a possible copy
    crowded = np.vstack([pts, rng.random((300, 3)) * 0.01 + pts[0]])
    assert CellIndex(crowded, 0.5).may_have_copies()


@pytest.mark.parametrize("seed", range(3))
def test_knn_indices_by_blocks_give_the_whole_search(seed, monkeypatch):
    # the neighbours found a block of query points at a time (the building tests' search)
    # are the rows of one search of the whole cloud, ties (points on a millimetre grid)
    # included
    from lidarstat.errors import TooManyNeighborsError
    from lidarstat.neighbors import KnnIndex, knn_neighbors

    g = np.random.default_rng(seed)
    pts = np.round(g.uniform(0, 5, (4000, 3)), 2)
    got = KnnIndex(pts).query_indices(12, block=333)
    ref = knn_neighbors(pts, 12)
    assert got.indices.dtype == ref.indices.dtype == np.int32
    assert np.array_equal(got.indptr, ref.indptr) and np.array_equal(got.indices, ref.indices)
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", str(12 * 4000 - 1))
    with pytest.raises(TooManyNeighborsError, match="LIDARSTAT_MAX_PAIRS"):
        KnnIndex(pts).query_indices(12, block=333)
