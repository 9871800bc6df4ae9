"""The k nearest neighbours of every point, indices only, by the grid search where its
answer is the tree's and by the tree where a tie leaves the answer to the tree.

:meth:`KnnIndex.query_indices` gives each point's `k` nearest (itself included) in
ascending distance, as SciPy's ``cKDTree`` orders them. The grid search
(:mod:`._grid_kernels`) computes the same squared distances bit for bit (both subtract
the points' lowest corner, then sum the squared coordinate differences in x, y, z order),
so where the ``k + 1`` nearest distances of a point are all distinct, the set and the
order of its `k` nearest are fixed by the distances and the two searches agree. Where two
of them are equal the tree's answer depends on its traversal: those points are searched
again with the tree (built only when there is one).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from numba import prange

from .._shared._jit import kernel_array, njit_parallel
from .._shared.validation import check_points, check_scalar
from ._csr import index_dtype
from ._grid_kernels import _CELL_CHUNK, _scratch, cell_block, knn_found
from ._grid_knn import knn_cell_size
from ._query import CellIndex, KnnIndex, _refuse_knn_pairs

__all__ = ["knn_indices"]


def knn_indices(points, k, *, func="knn_indices"):
    """The `k` nearest neighbours of every point, indices only: the arrays of
    ``KnnIndex(points).query_indices(k)``, by the grid search (module docstring).

    Parameters
    ----------
    points : (N, 3) ndarray of float64
        Searched cloud, N > k.
    k : int
        Neighbours per point (the point itself included).

    Returns
    -------
    SimpleNamespace
        ``indptr`` (N + 1,) int64 (``k`` per row) and ``indices`` (N k,): each row in
        ascending distance, ties in the tree's order.
    """
    points = kernel_array(check_points(points))  # one compiled type: C, writable
    n = points.shape[0]
    k = check_scalar(k, "k", func=func, low=1, high=n, closed="both", integer=True)
    _refuse_knn_pairs(n, k)
    if n <= k + 1:  # the grid search needs k + 1 points; the tree answers tiny clouds
        return KnnIndex(points).query_indices(k, func=func)
    cell, tau0 = knn_cell_size(points, k, min_k=2, min_tree=100_000)
    index = CellIndex(points, cell)
    indices = np.empty(n * k, index_dtype(n))
    tie = np.empty(n, np.uint8)
    _grid_rows(0, index.n_cells, index.sorted_points, index.cell_keys, index.cell_start,
               index.dims, float(index.cell), int(k), float(tau0), index.order, indices, tie)
    del index
    again = np.flatnonzero(tie)
    if again.size:
        tree = KnnIndex(points)
        for a in range(0, again.size, 1 << 18):
            rows = again[a:a + (1 << 18)]
            found = tree.query(k, query=rows, func=func).indices.reshape(-1, k)
            indices.reshape(n, k)[rows] = found
    return SimpleNamespace(indptr=np.arange(n + 1, dtype=np.int64) * k, indices=indices)


@njit_parallel
def _grid_rows(c0, c1, pts, cell_keys, cell_start, dims, cell, k, tau0, order, out,
               tie):  # pragma: no cover - compiled
    """The `k` nearest (ascending distance) of the points of cells ``c0..c1-1`` into
    ``out[order[i] k:(order[i] + 1) k]`` (input indices); ``tie[order[i]]`` is 1 where two
    of the point's ``k + 1`` nearest distances are equal, else 0. `tau0` is a typical
    k-th neighbour distance (a pre-filter of the candidates: speed only)."""
    ncell = c1 - c0
    nchunks = (ncell + _CELL_CHUNK - 1) // _CELL_CHUNK
    kk = k + 1
    for ch in prange(nchunks):
        work = _scratch(1024)
        ranges = np.empty((9, 2), dtype=np.int64)
        for c in range(c0 + ch * _CELL_CHUNK, min(c1, c0 + (ch + 1) * _CELL_CHUNK)):
            ix0, iy0, iz0, nr, work = cell_block(c, cell_keys, cell_start, dims, ranges, work)
            tau2 = tau0 * tau0
            for i in range(cell_start[c], cell_start[c + 1]):
                kth, _, work = knn_found(pts[i, 0], pts[i, 1], pts[i, 2], ix0, iy0, iz0, pts,
                                         cell_keys, cell_start, dims, cell, kk, True, tau2,
                                         ranges, nr, work)
                td = work[2]
                ti = work[3]
                tau2 = kth * 1.3225  # (1.15 r_k)^2 for the next point of the cell
                row = order[i] * k
                same = 0
                for t in range(k):
                    out[row + t] = order[ti[t]]
                    if td[t] == td[t + 1]:
                        same = 1
                tie[order[i]] = same
