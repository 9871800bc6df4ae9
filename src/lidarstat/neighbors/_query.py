"""Neighbourhood queries: fixed radius (3-D sphere or 2-D disc) and k nearest neighbours."""

from __future__ import annotations

from types import SimpleNamespace

import numba
import numpy as np

from .._shared._columns import column_max, column_min
from .._shared._jit import kernel_array
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError, TooManyNeighborsError
from . import _budget, _kernels
from ._csr import Neighborhoods, index_dtype

#: Largest number of grid cells per axis before the cell size is enlarged.
_MAX_CELLS_PER_AXIS = 1 << 20


class CellIndex:
    """Uniform-grid (cell list) index for fixed-radius queries.

    The points are sorted by cell once (O(N): counting or radix sort); a query visits the
    27 (3-D) or 9 (2-D) cells around the query point. For a fixed radius this is the textbook optimal
    structure and, on this project's benchmark, several times faster than KD-tree ball
    queries, which return Python lists. The sort order is also a spatially coherent order
    in which to process points (cache locality), exposed as :attr:`order`.

    Parameters
    ----------
    points : (N, 3) ndarray of float64
        Searched points.
    radius : float
        Largest radius that will be queried (the cell edge).
    dim : {3, 2}
        3 for spheres, 2 for planimetric discs (z ignored).

    Attributes
    ----------
    order : (N,) ndarray of int64
        Permutation sorting the points by cell (row-major cell key).
    sorted_points : (N, 3) ndarray of float64
        ``points[order]`` relative to :attr:`origin` (local origin keeps UTM precision).
    origin : (3,) ndarray
        Subtracted from the coordinates before any arithmetic (the grid starts there).
    """

    def __init__(self, points, radius, *, dim=3):
        points = kernel_array(check_points(points))  # one compiled type: C, writable
        radius = check_scalar(radius, "radius", func="CellIndex", low=0.0)
        if dim not in (2, 3):
            raise InvalidParameterError(f"The 'dim' parameter of CellIndex must be 2 or 3. Got {dim!r} instead.")
        self.dim = dim
        self.radius = radius
        self.n_points = points.shape[0]
        self.origin = column_min(points)
        extent = column_max(points) - self.origin  # == (points - origin).max(axis=0)
        cell = max(radius, float(extent[:dim].max()) / _MAX_CELLS_PER_AXIS)
        self.cell = cell
        dims = np.floor(extent / cell).astype(np.int64) + 1
        if dim == 2:
            dims[2] = 1
        self.dims = dims
        n = self.n_points
        keys = np.empty(n, dtype=np.int64)
        _kernels.grid_keys(points, self.origin, cell, dims, dim == 2, keys)
        total = int(np.prod([int(d) for d in dims]))
        if n >= 65536 and total <= 4 * n:
            # stable counting sort over the key range: same order as the stable argsort
            # below, in O(N) (dense clouds; sparse grids and small clouds sort the keys)
            counts = np.bincount(keys, minlength=total)
            start = np.cumsum(counts) - counts
            occupied = np.flatnonzero(counts)
            self.order = np.empty(n, dtype=np.int64)
            self.sorted_points = np.empty((n, 3))
            _kernels.counting_scatter(points, self.origin, keys, start,
                                      numba.get_num_threads(), self.order,
                                      self.sorted_points)
            self.cell_keys = occupied.astype(np.int64)
            cell_start = np.empty(occupied.size + 1, dtype=np.int64)
            cell_start[0] = 0
            np.cumsum(counts[occupied], out=cell_start[1:])
            self.cell_start = cell_start
        else:
            # stable LSD radix sort of the keys: the stable argsort's order in O(N)
            self.order, skeys = _kernels.radix_order(keys, max(total - 1, 1).bit_length())
            self.sorted_points = np.ascontiguousarray(points[self.order] - self.origin)
            boundaries = np.flatnonzero(np.diff(skeys)) + 1
            starts = np.concatenate(([0], boundaries, [skeys.size])).astype(np.int64)
            self.cell_keys = np.ascontiguousarray(skeys[starts[:-1]])
            self.cell_start = starts

    def to_input_order(self, values, out=None):
        """Per-point `values` (N,) in the sorted order of the index, in input order (a
        scatter through :attr:`order`: parallel for float64, the bulk of a result's fields;
        NumPy for the few integer fields, so the kernel has one signature). `out` (N,) of
        the same dtype, not overlapping `values`, receives them if given."""
        values = np.ascontiguousarray(values)
        if out is None:
            out = np.empty_like(values)
        if values.dtype == np.float64:
            _kernels.scatter_to(values, self.order, out)
        else:
            out[self.order] = values
        return out

    def may_have_copies(self) -> bool:
        """False when no two indexed points share a location.

        Equal points fall in one cell, so the cells are compared pairwise, in parallel
        (a cell of more than a few hundred points counts as a possible copy): a proof of
        distinct locations at a small part of the cost of :func:`find_duplicates`, which
        a True sends the caller to.
        """
        return bool(_kernels.cells_may_share(self.sorted_points, self.cell_start))

    @property
    def n_cells(self) -> int:
        """Number of occupied cells."""
        return self.cell_keys.size

    def cell_blocks(self, max_points):
        """Split the occupied cells into consecutive ranges of at most ~`max_points` points.

        Returns a list of ``(c0, c1)``; the query points of a block are the sorted
        positions ``cell_start[c0]:cell_start[c1]``. A single cell larger than
        `max_points` forms a block on its own.
        """
        bounds = [0]
        starts = self.cell_start
        c = 0
        while c < self.n_cells:
            target = starts[c] + max_points
            nxt = int(np.searchsorted(starts, target, side="right")) - 1
            nxt = min(max(nxt, c + 1), self.n_cells)
            bounds.append(nxt)
            c = nxt
        return list(zip(bounds[:-1], bounds[1:]))

    def query_cells(self, c0, c1, radius=None):
        """CSR neighbourhoods, in sorted positions, of the points of cells ``c0..c1-1``.

        Row ``i`` belongs to sorted position ``cell_start[c0] + i``. This is the fast path
        used by the local-model drivers, which work block by block in the sorted order so
        that memory does not grow with the cloud.
        """
        radius = self._check_radius(radius)
        self.bound_pairs(c0, c1, radius)
        args = (self.sorted_points, self.cell_keys, self.cell_start, self.dims, radius, self.dim)
        counts = _kernels.count_cells(c0, c1, *args)
        indptr = np.zeros(counts.size + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        self._check_total(int(indptr[-1]), radius, counts.size)
        idx = np.empty(indptr[-1], dtype=index_dtype(self.sorted_points.shape[0]))
        dist = np.empty(indptr[-1], dtype=np.float64)
        _kernels.fill_cells(c0, c1, *args, indptr, idx, dist)
        return indptr, idx, dist

    def bound_pairs(self, c0=0, c1=None, radius=None):
        """Refuse a search of cells ``c0..c1-1`` whose neighbour pairs exceed the ceiling.

        Cheap bounds first (module :mod:`lidarstat.neighbors._budget`): the cell
        populations give an upper bound in O(cells); only above the ceiling, a lower
        bound from half-radius cells decides (O(N log N)). Callers that scan the cells
        themselves (the fused drivers of the local fits) call this before their loop;
        :meth:`query_cells` does it before allocating.

        Returns
        -------
        int
            The upper bound of the pairs (points scanned).

        Raises
        ------
        TooManyNeighborsError
            If at least :func:`~lidarstat.neighbors.max_pairs` pairs are certain.
        """
        radius = self._check_radius(radius)
        c1 = self.n_cells if c1 is None else c1
        upper = int(_kernels.cell_candidates(c0, c1, self.cell_keys, self.cell_start,
                                             self.dims, self.dim))
        ceiling = _budget.max_pairs()
        if upper > ceiling:
            s0, s1 = int(self.cell_start[c0]), int(self.cell_start[c1])
            lower = int(_budget.half_radius_population(
                self.sorted_points, self.sorted_points[s0:s1], radius, self.dim).sum())
            if lower > ceiling:
                _budget.refuse_pairs(lower, radius=radius, exact=False, ceiling=ceiling,
                                     n_query=s1 - s0)
        return upper

    def _bound_queries(self, q, radius):
        """:meth:`bound_pairs` for arbitrary query coordinates (local frame)."""
        upper = int(_kernels.query_candidates(q, self.cell_keys, self.cell_start, self.cell,
                                              self.dims, self.dim))
        ceiling = _budget.max_pairs()
        if upper > ceiling:
            lower = int(_budget.half_radius_population(self.sorted_points, q, radius,
                                                       self.dim).sum())
            if lower > ceiling:
                _budget.refuse_pairs(lower, radius=radius, exact=False, ceiling=ceiling,
                                     n_query=q.shape[0])

    @staticmethod
    def _check_total(total, radius, n_query):
        ceiling = _budget.max_pairs()
        if total > ceiling:
            _budget.refuse_pairs(total, radius=radius, exact=True, ceiling=ceiling,
                                 n_query=n_query)

    def _check_radius(self, radius):
        radius = self.radius if radius is None else float(radius)
        if radius > self.cell * (1 + 1e-12):
            raise InvalidParameterError(
                f"query radius {radius} exceeds the index cell size {self.cell}"
            )
        return radius

    def _query_local(self, q, radius=None):
        radius = self._check_radius(radius)
        q = np.ascontiguousarray(q, dtype=np.float64)
        args = (self.sorted_points, self.cell_keys, self.cell_start, self.cell,
                self.dims, float(radius), self.dim)
        self._bound_queries(q, radius)
        counts = _kernels.count_radius(q, *args)
        indptr = np.zeros(q.shape[0] + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        self._check_total(int(indptr[-1]), radius, q.shape[0])
        idx = np.empty(indptr[-1], dtype=index_dtype(self.sorted_points.shape[0]))
        dist = np.empty(indptr[-1], dtype=np.float64)
        _kernels.fill_radius(q, *args, indptr, idx, dist)
        return indptr, idx, dist

    def query(self, points, radius=None):
        """Neighbourhoods of arbitrary query coordinates, as original point indices."""
        q = check_points(points, name="query points") - self.origin
        indptr, idx, dist = self._query_local(q, radius)
        _kernels.remap(idx, self.order)
        return indptr, idx, dist


def radius_neighbors(points, radius, *, dim=3, query=None):
    """All points within `radius` of each query point (the point itself included).

    Parameters
    ----------
    points : (N, 3) array_like
        Searched cloud.
    radius : float
        Search radius, > 0: a 3-D sphere (``dim=3``, the choice of Crosilla et al. 2009, so
        that data slips are not bridged) or a planimetric disc (``dim=2``).
    dim : {3, 2}, optional
        Sphere or disc.
    query : (M,) array_like of int, optional
        Indices of the query points; default every point.

    Returns
    -------
    Neighborhoods
        CSR neighbourhoods, one row per query point, neighbour indices into `points`.
        Rows are not sorted by distance.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.neighbors import radius_neighbors
    >>> pts = np.array([[0., 0, 0], [0.5, 0, 0], [2, 0, 0]])
    >>> nb = radius_neighbors(pts, 1.0)
    >>> nb.counts.tolist()
    [2, 2, 1]
    """
    points = check_points(points)
    radius = check_scalar(radius, "radius", func="radius_neighbors", low=0.0)
    check_option(dim, "dim", (2, 3), func="radius_neighbors")
    index = CellIndex(points, radius, dim=dim)
    if query is None:
        indptr, idx, dist = index.query_cells(0, index.n_cells)
        # rows are in sorted order: row r of the output is sorted row inverse[r]
        inverse = np.empty_like(index.order)
        inverse[index.order] = np.arange(index.order.size)
        indptr, idx, dist = _kernels.permute_rows(indptr, idx, dist, inverse, index.order)
        return Neighborhoods(indptr, idx, dist, points.shape[0],
                             kind="sphere" if dim == 3 else "disc", radius=radius)
    else:
        qidx = np.asarray(query, dtype=np.int64).ravel()
        if qidx.size and (qidx.min() < 0 or qidx.max() >= points.shape[0]):
            raise InvalidParameterError("radius_neighbors: `query` indices out of range")
        q = points[qidx]
    indptr, idx, dist = index.query(q)
    return Neighborhoods(indptr, idx, dist, points.shape[0], kind="sphere" if dim == 3 else "disc",
                         radius=radius, query=qidx)


def knn_neighbors(points, k, *, query=None, workers=-1):
    """The `k` nearest neighbours of each query point (the point itself included).

    Uses SciPy's ``cKDTree`` (parallel queries). Rows are sorted by distance.

    Parameters
    ----------
    points : (N, 3) array_like
        Searched cloud.
    k : int
        Neighbours per point, 1 <= k <= N.
    query : (M,) array_like of int, optional
        Indices of the query points; default every point.
    workers : int, optional
        Threads for the query (-1: all cores).

    Returns
    -------
    Neighborhoods
    """
    return KnnIndex(points).query(k, query=query, workers=workers, func="knn_neighbors")


class KnnIndex:
    """A k-d tree of `points` for repeated k-nearest-neighbour queries of their subsets.

    Built once (SciPy's ``cKDTree`` about the points' lowest corner); :meth:`query`
    answers as :func:`knn_neighbors` does, which builds one for a single query: callers
    that query the same cloud block by block keep one index instead of a tree a block.

    Parameters
    ----------
    points : (N, 3) array_like
        Searched cloud.
    """

    def __init__(self, points):
        from scipy.spatial import cKDTree

        self.points = check_points(points)
        self.origin = self.points.min(axis=0)
        self.tree = cKDTree(self.points - self.origin)

    def query(self, k, *, query=None, workers=-1, func="KnnIndex.query"):
        """The `k` nearest neighbours of the points `query` (indices; default all), as
        :func:`knn_neighbors`."""
        points = self.points
        k = check_scalar(k, "k", func=func, low=1, high=points.shape[0], closed="both",
                         integer=True)
        qidx = None if query is None else np.asarray(query, dtype=np.int64).ravel()
        _refuse_knn_pairs(points.shape[0] if qidx is None else qidx.size, k)
        q = points if qidx is None else points[qidx]
        dist, idx = self.tree.query(q - self.origin, k=k, workers=workers)
        dist = np.asarray(dist, dtype=np.float64).reshape(q.shape[0], k)
        idx = np.asarray(idx, dtype=index_dtype(points.shape[0])).reshape(q.shape[0], k)
        indptr = np.arange(q.shape[0] + 1, dtype=np.int64) * k
        return Neighborhoods(indptr, idx.ravel(), dist.ravel(), points.shape[0], kind="knn",
                             k=k, query=qidx)

    def query_indices(self, k, *, block=1 << 18, func="KnnIndex.query_indices"):
        """The `k` nearest neighbours of every point, indices only (``indptr``,
        ``indices``: the rows of :meth:`query`), searched `block` points at a time into
        one index array: the distances and wide indices of the search are a block's, not
        the cloud's. The whole search is refused above the pairs' ceiling, as
        :meth:`query`."""
        n = self.points.shape[0]
        k = check_scalar(k, "k", func=func, low=1, high=n, closed="both", integer=True)
        _refuse_knn_pairs(n, k)
        indices = np.empty(n * k, index_dtype(n))
        for a in range(0, n, block):
            b = min(n, a + block)
            indices[a * k:b * k] = self.query(k, query=np.arange(a, b), func=func).indices
        return SimpleNamespace(indptr=np.arange(n + 1, dtype=np.int64) * k, indices=indices)


def _refuse_knn_pairs(n_query, k):
    """Raise :class:`TooManyNeighborsError` when `n_query` points' `k` nearest neighbours
    pass the pairs' ceiling (:func:`~lidarstat.neighbors.max_pairs`)."""
    ceiling = _budget.max_pairs()
    if n_query * k > ceiling:
        raise TooManyNeighborsError(
            f"k = {k} gives {n_query * k:,} neighbour pairs ({n_query:,} points), above "
            f"the ceiling of {ceiling:,} (LIDARSTAT_MAX_PAIRS); lower k or thin the cloud")
