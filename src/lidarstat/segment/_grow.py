"""Connected components, seeded region growing, relabelling and segment adjacency.

The criteria of a method (normals within an angle, heights within a tolerance, no ridge
in between, ...) enter as a boolean mask over CSR edges, ``edge_ok``, computed in NumPy
from the two ends of each edge (:meth:`Neighborhoods.edges`); the graph walk itself is a
Numba kernel, so no Python loop runs per point.
"""

from __future__ import annotations

import numpy as np

from .._shared._deprecate import renamed_parameters
from ..errors import InvalidParameterError
from ..neighbors import Neighborhoods
from . import _kernels



def _prepare(nbh, edge_ok, mask):
    if not isinstance(nbh, Neighborhoods):
        raise InvalidParameterError(
            f"expected a Neighborhoods object, got {type(nbh).__name__}")
    n = nbh.n_points
    if edge_ok is None:
        ok, use_ok = np.ones(1, dtype=np.bool_), False
    else:
        ok = np.ascontiguousarray(edge_ok, dtype=np.bool_)
        if ok.shape != nbh.indices.shape:
            raise InvalidParameterError(
                f"edge_ok must have one entry per neighbour pair ({nbh.nnz}), "
                f"got shape {ok.shape}")
        use_ok = True
    m = _point_mask(mask, n, "mask")
    return n, ok, use_ok, m


def _point_mask(mask, n, name):
    if mask is None:
        return np.ones(n, dtype=np.bool_)
    m = np.ascontiguousarray(mask, dtype=np.bool_)
    if m.shape != (n,):
        raise InvalidParameterError(f"{name} must have one entry per point ({n}), got {m.shape}")
    return m


@renamed_parameters(min_size="min_points")
def relabel(labels, min_points: int = 1) -> np.ndarray:
    """Renumber segments 1..n by decreasing size; segments below `min_points` become 0.

    Ties in size are broken by the smallest point index of the segment, so the result is
    a deterministic function of the partition, not of the ids that came in.

    Parameters
    ----------
    labels : (N,) array of int
        Segment id per point, 0 (or negative) for none.
    min_points : int, default 1
        Smallest segment kept.

    Returns
    -------
    (N,) ndarray of int32

    Examples
    --------
    >>> relabel(np.array([7, 7, 0, 3, 3, 3, 9]), min_points=2).tolist()
    [2, 2, 0, 1, 1, 1, 0]
    """
    labels = np.asarray(labels)
    if labels.ndim != 1:
        raise InvalidParameterError("labels must be 1-D")
    out = np.zeros(labels.size, dtype=np.int32)
    valid = labels > 0
    if not valid.any():
        return out
    ids, first, inverse, sizes = np.unique(labels[valid], return_index=True,
                                           return_inverse=True, return_counts=True)
    first = np.flatnonzero(valid)[first]
    keep = sizes >= int(min_points)
    rank = np.lexsort((first, -sizes))  # by size descending, then first member
    new_id = np.zeros(ids.size, dtype=np.int32)
    kept = rank[keep[rank]]
    new_id[kept] = np.arange(1, kept.size + 1, dtype=np.int32)
    out[valid] = new_id[inverse]
    return out


@renamed_parameters(min_size="min_points")
def components(nbh: Neighborhoods, edge_ok=None, mask=None, *, min_points: int = 1):
    """Connected components of the neighbourhood graph restricted to accepted edges.

    Two points are connected when one lists the other as a neighbour through an edge with
    ``edge_ok`` True and both are in `mask`. This is the label-merging region growing of
    seed 003 (Bae and Lichti, Fig. 4) in its order-free form: growing from every seed and
    merging labels that meet is exactly the union of accepted edges.

    Parameters
    ----------
    nbh : Neighborhoods
        CSR neighbourhoods of the cloud (rows = points, or ``nbh.query``).
    edge_ok : (nnz,) array of bool, optional
        One entry per CSR entry (aligned with ``nbh.indices``); default all True.
    mask : (N,) array of bool, optional
        Points that may belong to a segment; the others get 0.
    min_points : int, default 1
        Components smaller than this get 0.

    Returns
    -------
    (N,) ndarray of int32
        Segment ids 1..n by decreasing size (ties: smallest point index first), 0 = none.

    Examples
    --------
    >>> from lidarstat.neighbors import radius_neighbors
    >>> pts = np.array([[0., 0, 0], [1, 0, 0], [2, 0, 0], [10, 0, 0], [11, 0, 0]])
    >>> components(radius_neighbors(pts, 1.5)).tolist()
    [1, 1, 1, 2, 2]
    """
    n, ok, use_ok, m = _prepare(nbh, edge_ok, mask)
    roots = _kernels.union_find_roots(nbh.indptr, nbh.indices, nbh.query_indices(), ok,
                                      use_ok, m, n)
    return relabel(roots + 1, min_points)


@renamed_parameters(min_size="min_points")
def grow_regions(nbh: Neighborhoods, edge_ok=None, order=None, can_grow=None, mask=None, *,
                 merge: bool = False, min_points: int = 1):
    """Seeded region growing over accepted edges.

    Seeds are visited in `order` (for instance by increasing curvature or residual); an
    unlabelled seed that may grow starts a new region, which expands breadth first
    through accepted edges. Points with ``can_grow`` False (edge or boundary points, say)
    are attached to the first region that reaches them but never expand it, so regions do
    not leak across them. With ``merge=True`` two regions that touch through an accepted
    edge between growing points are merged (seed 003's label merging).

    Parameters
    ----------
    nbh : Neighborhoods
    edge_ok : (nnz,) array of bool, optional
        Accepted edges (aligned with ``nbh.indices``); default all.
    order : (K,) array of int, optional
        Seed candidates in priority order; default all points in index order.
    can_grow : (N,) array of bool, optional
        Points that may seed and expand a region; default all.
    mask : (N,) array of bool, optional
        Points that may be labelled at all.
    merge : bool, default False
    min_points : int, default 1
        Regions smaller than this get 0.

    Returns
    -------
    (N,) ndarray of int32
        Region ids 1..n by decreasing size, 0 = none. Deterministic for a given `order`.

    Examples
    --------
    >>> from lidarstat.neighbors import radius_neighbors
    >>> pts = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    >>> nbh = radius_neighbors(pts, 1.1)
    >>> grow_regions(nbh, can_grow=np.array([1, 1, 0, 1, 1], bool)).tolist()
    [1, 1, 1, 2, 2]
    """
    n, ok, use_ok, m = _prepare(nbh, edge_ok, mask)
    grow = _point_mask(can_grow, n, "can_grow")
    if order is None:
        seeds = np.arange(n, dtype=np.int64)
    else:
        seeds = np.ascontiguousarray(order, dtype=np.int64)
        if seeds.ndim != 1 or (seeds.size and (seeds.min() < 0 or seeds.max() >= n)):
            raise InvalidParameterError(f"order must be 1-D point indices in [0, {n})")
    row_of = np.full(n, -1, dtype=np.int64)
    row_of[nbh.query_indices()] = np.arange(len(nbh), dtype=np.int64)
    labels = _kernels.grow_kernel(nbh.indptr, nbh.indices, row_of, ok, use_ok, seeds, grow,
                                  m, bool(merge), n)
    return relabel(labels, min_points)


def adjacency(nbh: Neighborhoods, labels, *, min_edges: int = 1):
    """Pairs of segments that touch, with the number of neighbour pairs joining them.

    Parameters
    ----------
    nbh : Neighborhoods
    labels : (N,) array of int
        Segment id per point, 0 = none (ignored).
    min_edges : int, default 1
        Keep pairs joined by at least this many CSR entries.

    Returns
    -------
    pairs : (P, 2) ndarray of int32
        ``pairs[:, 0] < pairs[:, 1]``, sorted lexicographically.
    counts : (P,) ndarray of int64
        Neighbour pairs (CSR entries, both directions counted) joining each pair.

    Examples
    --------
    >>> from lidarstat.neighbors import radius_neighbors
    >>> pts = np.c_[np.arange(4.0), np.zeros(4), np.zeros(4)]
    >>> pairs, counts = adjacency(radius_neighbors(pts, 1.1), [1, 1, 2, 2])
    >>> pairs.tolist(), counts.tolist()
    ([[1, 2]], [2])
    """
    labels = np.asarray(labels)
    if labels.shape != (nbh.n_points,):
        raise InvalidParameterError(
            f"labels must have one entry per point ({nbh.n_points}), got {labels.shape}")
    from ._edge_kernels import label_pairs

    src, dst = label_pairs(nbh, labels, different_only=True)  # labelled, different segments
    return adjacency_of_pairs(labels, src, dst, min_edges=min_edges)


def adjacency_of_pairs(labels, src, dst, *, min_edges: int = 1):
    """:func:`adjacency` from the pairs ``label_pairs(nbh, labels, different_only=True)``
    (for a caller that needs those pairs too)."""
    labels = np.asarray(labels)
    a = labels[src].astype(np.int64)
    b = labels[dst].astype(np.int64)
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    base = int(labels.max()) + 1 if labels.size else 1
    keys, counts = np.unique(lo * base + hi, return_counts=True)
    sel = counts >= int(min_edges)
    keys, counts = keys[sel], counts[sel]
    pairs = np.c_[keys // base, keys % base].astype(np.int32)
    return pairs.reshape(-1, 2), counts.astype(np.int64)
