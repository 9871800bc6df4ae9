"""The CSR neighbourhood container shared by every local model."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidParameterError


def index_dtype(n_points):
    """The dtype of neighbour indices into a cloud of `n_points` points.

    int32 below 2**31 points, else int64. Every producer of neighbour indices (the
    searches, the fused drivers' buffers, :class:`Neighborhoods`) uses it, so a kernel
    taking them is compiled for one index type, not for both.

    Examples
    --------
    >>> index_dtype(1000), index_dtype(2**31)
    (<class 'numpy.int32'>, <class 'numpy.int64'>)
    """
    return np.int32 if n_points < 2**31 else np.int64


@dataclass(frozen=True)
class Neighborhoods:
    """Neighbourhoods of a set of query points in compressed sparse row (CSR) form.

    Row ``i`` lists the neighbours of query point ``i``:
    ``indices[indptr[i]:indptr[i + 1]]`` are indices into the searched cloud and
    ``distances[indptr[i]:indptr[i + 1]]`` their distances (3-D for spheres and kNN,
    planimetric for discs). Memory is proportional to the number of neighbour pairs.

    Attributes
    ----------
    indptr : (M + 1,) ndarray of int64
        Row pointers, ``indptr[0] == 0``, non-decreasing.
    indices : (nnz,) ndarray of int32 (int64 from 2**31 points)
        Neighbour indices into the searched cloud of `n_points` points, of
        :func:`index_dtype`: one dtype whatever the search, so that every kernel taking
        neighbour indices is compiled once, and half the memory of int64.
    distances : (nnz,) ndarray of float64
        Distance of each neighbour from its query point.
    n_points : int
        Size of the searched cloud.
    kind : {'sphere', 'disc', 'knn'}
        How the neighbourhoods were built.
    radius : float or None
        Search radius for 'sphere' and 'disc'.
    k : int or None
        Number of neighbours for 'knn'.
    query : (M,) ndarray of int64 or None
        Indices (into the searched cloud) of the query points, or None when the query
        points are the cloud itself in order.
    row_order : (M,) ndarray of int64 or None
        A permutation of the rows that walks them in a spatially coherent order (the
        kNN search gives its grid order), or None (row order). Kernels whose rows are
        independent visit the rows in this order so that the neighbours of consecutive
        rows share cache lines (:meth:`visit_order`); their results never depend on it.
    """

    indptr: np.ndarray
    indices: np.ndarray
    distances: np.ndarray
    n_points: int
    kind: str = "sphere"
    radius: float | None = None
    k: int | None = None
    query: np.ndarray | None = field(default=None)
    row_order: np.ndarray | None = field(default=None)

    def __post_init__(self):
        indptr = np.ascontiguousarray(self.indptr, dtype=np.int64)
        indices = np.ascontiguousarray(self.indices, dtype=index_dtype(self.n_points))
        distances = np.ascontiguousarray(self.distances, dtype=np.float64)
        object.__setattr__(self, "indptr", indptr)
        object.__setattr__(self, "indices", indices)
        object.__setattr__(self, "distances", distances)
        if self.query is not None:
            object.__setattr__(self, "query", np.ascontiguousarray(self.query, dtype=np.int64))
        if indptr.ndim != 1 or indptr.size < 1 or indptr[0] != 0:
            raise InvalidParameterError("Neighborhoods: `indptr` must be 1-D and start at 0")
        if indptr[-1] != indices.size or indices.size != distances.size:
            raise InvalidParameterError(
                f"Neighborhoods: indptr[-1] ({indptr[-1]}), len(indices) ({indices.size}) and "
                f"len(distances) ({distances.size}) must agree"
            )
        if indptr.size > 1 and np.any(np.diff(indptr) < 0):
            raise InvalidParameterError("Neighborhoods: `indptr` must be non-decreasing")
        if indices.size and (indices.min() < 0 or indices.max() >= self.n_points):
            raise InvalidParameterError(
                f"Neighborhoods: indices must lie in [0, {self.n_points})"
            )
        if self.query is not None and self.query.size != indptr.size - 1:
            raise InvalidParameterError("Neighborhoods: `query` must have one entry per row")
        if self.row_order is not None:
            order = np.ascontiguousarray(self.row_order, dtype=np.int64)
            object.__setattr__(self, "row_order", order)
            m = indptr.size - 1
            if order.shape != (m,) or (m and (order.min() < 0 or order.max() >= m
                                              or np.bincount(order, minlength=m).max() > 1)):
                raise InvalidParameterError(
                    "Neighborhoods: `row_order` must be a permutation of the rows")

    def __len__(self) -> int:
        return self.indptr.size - 1

    @property
    def counts(self) -> np.ndarray:
        """Number of neighbours of each query point, shape (M,)."""
        return np.diff(self.indptr)

    @property
    def nnz(self) -> int:
        """Total number of neighbour pairs."""
        return int(self.indptr[-1])

    def row(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances of the neighbours of query point `i`."""
        s, e = self.indptr[i], self.indptr[i + 1]
        return self.indices[s:e], self.distances[s:e]

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Both ends of every neighbour pair, aligned with `indices`.

        Returns
        -------
        src, dst : (nnz,) ndarray of int64
            ``src[e]`` is the query point (an index into the searched cloud) of CSR entry
            ``e`` and ``dst[e] == indices[e]`` its neighbour. Per-edge criteria of region
            growing (``edge_ok`` masks) are vectorised expressions of ``src`` and ``dst``.
        """
        src = np.repeat(self.query_indices(), self.counts)
        return src, self.indices

    def visit_order(self) -> np.ndarray:
        """The rows in the order row-independent kernels should visit them (int64).

        :attr:`row_order` when the producer gave one, else ``0..M-1``.

        Examples
        --------
        >>> nb = Neighborhoods(np.array([0, 1, 2]), np.array([1, 0]), np.zeros(2), 2,
        ...                    row_order=[1, 0])
        >>> nb.visit_order().tolist()
        [1, 0]
        """
        if self.row_order is None:
            return np.arange(len(self), dtype=np.int64)
        return self.row_order

    def query_indices(self) -> np.ndarray:
        """Indices of the query points in the searched cloud."""
        if self.query is None:
            return np.arange(len(self), dtype=np.int64)
        return self.query
