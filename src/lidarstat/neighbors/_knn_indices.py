"""The k nearest neighbours of every point, indices only, by the grid search where its
answer is the tree's and by the tree where a tie leaves the answer to the tree.

:meth:`KnnIndex.query_indices` gives each point's `k` nearest (itself included) in
ascending distance, as SciPy's ``cKDTree`` orders them. The grid search
(:mod:`._knn_indices_kernels`) computes the same squared distances bit for bit (both subtract
the points' lowest corner, then sum the squared coordinate differences in x, y, z order),
so where the ``k + 1`` nearest distances of a point are all distinct, the set and the
order of its `k` nearest are fixed by the distances and the two searches agree. Where two
of them are equal the tree's answer depends on its traversal: those points are searched
again with the tree (built only when there is one).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from .._shared._jit import kernel_array
from .._shared.validation import check_points, check_scalar
from ._csr import index_dtype
from ._grid_knn import knn_cell_size
from ._knn_indices_kernels import grid_rows
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
    grid_rows(0, index.n_cells, index.sorted_points, index.cell_keys, index.cell_start,
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

