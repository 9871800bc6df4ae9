"""Search areas of the raw clusters over a Delaunay triangulation (seed 002, section 5.3).

The whole cloud is triangulated in plan (:func:`lidarstat.neighbors.delaunay_triangles`). The search area of a raw cluster
is the cluster itself plus every point that belongs to no raw cluster and is reachable
from the cluster along triangulation edges, through unclustered points only, within a
path length `search`. A point may lie in several search areas (roof ridges do, as in the
paper); points of another raw cluster never do.
"""

from __future__ import annotations

import heapq
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._shared._deprecate import renamed_parameters
from .._shared._jit import njit
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidPointsError, LidarstatDeprecationWarning
from ..neighbors import delaunay_triangles, find_duplicates


def delaunay_graph(points):
    """Symmetric CSR graph of the planimetric Delaunay triangulation with edge lengths.

    Points sharing a location in plan (on walls) are triangulated once; every other
    point at that location is linked to the one triangulated.

    Returns
    -------
    indptr, indices : ndarray of int64
    lengths : ndarray of float64
    """
    points = check_points(points, min_points=3)
    xy = points[:, :2] - points[:, :2].min(axis=0)
    copies = find_duplicates(np.c_[xy, np.zeros(len(xy))])
    vertex = copies.first if copies.any else np.arange(len(xy))
    s = delaunay_triangles(xy[vertex])
    if not len(s):
        raise InvalidPointsError(
            f"the {points.shape[0]:,} points have no planimetric triangulation: in plan (x, y) "
            "they lie on one line or at one location")
    s = vertex[s]
    a = np.concatenate([s[:, 0], s[:, 1], s[:, 2]])
    b = np.concatenate([s[:, 1], s[:, 2], s[:, 0]])
    if copies.any:  # each copy to the point triangulated at its location
        at = copies.first[copies.inverse]
        a = np.concatenate([a, np.arange(len(xy), dtype=np.int64)])
        b = np.concatenate([b, at])
    n = points.shape[0]
    keep = a != b
    a, b = a[keep], b[keep]
    g = sp.coo_matrix((np.ones(2 * a.size, dtype=np.int8), (np.r_[a, b], np.r_[b, a])),
                      shape=(n, n)).tocsr()
    g.sum_duplicates()
    indptr = g.indptr.astype(np.int64)
    dst = g.indices.astype(np.int64)
    src = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr))
    lengths = np.hypot(*(xy[src] - xy[dst]).T)
    return indptr, dst.astype(np.int64), lengths


@njit
def _bounded_areas(indptr, idx, lengths, labels, members_ptr, members, threshold, out_ptr,
                   out_pts, fill):
    n = labels.size
    dist = np.full(n, np.inf)
    touched = np.empty(n, dtype=np.int64)
    total = 0
    for c in range(members_ptr.size - 1):
        nt = 0
        heap = [(0.0, np.int64(0))]
        heap.pop()
        for t in range(members_ptr[c], members_ptr[c + 1]):
            p = members[t]
            dist[p] = 0.0
            touched[nt] = p
            nt += 1
            heapq.heappush(heap, (0.0, p))
        count = 0
        while len(heap) > 0:
            d, u = heapq.heappop(heap)
            if d > dist[u]:
                continue
            if labels[u] == 0:
                if fill:
                    out_pts[out_ptr[c] + count] = u
                count += 1
            for t in range(indptr[u], indptr[u + 1]):
                v = idx[t]
                if labels[v] != 0:
                    continue
                nd = d + lengths[t]
                if nd <= threshold and nd < dist[v]:
                    if dist[v] == np.inf:
                        touched[nt] = v
                        nt += 1
                    dist[v] = nd
                    heapq.heappush(heap, (nd, v))
        for k in range(nt):
            dist[touched[k]] = np.inf
        if not fill:
            out_ptr[c + 1] = count
        total += count
    return total


@dataclass(frozen=True)
class SearchAreas:
    """Extra points of each raw cluster's search area (CSR over clusters 1..C).

    Attributes
    ----------
    indptr : (C + 1,) ndarray of int64
        Row c - 1 holds the unclustered points of the search area of cluster c.
    indices : ndarray of int64
        Point indices.
    search : float
        Path length used.
    """

    indptr: np.ndarray
    indices: np.ndarray
    search: float

    @property
    def threshold(self) -> float:
        """Deprecated name of :attr:`search`."""
        warnings.warn("SearchAreas.threshold is deprecated; use search",
                      LidarstatDeprecationWarning, stacklevel=2)
        return self.search

    def area(self, labels, c):
        """All points (cluster c and its extra points) of the search area of cluster c."""
        extra = self.indices[self.indptr[c - 1]:self.indptr[c]]
        return np.concatenate([np.flatnonzero(labels == c), extra])

    @property
    def sizes(self) -> np.ndarray:
        """Extra points per cluster."""
        return np.diff(self.indptr)


@renamed_parameters(threshold="search")
def search_areas(points, labels, search, *, graph=None):
    """Search areas of raw clusters (labels 1..C, 0 unclustered) within a path `search`.

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates.
    labels : (N,) array_like of int
        Raw cluster labels.
    search : float
        Largest planimetric path length, along Delaunay edges, from the cluster (CLI
        ``--search``).
    graph : tuple, optional
        Precomputed :func:`delaunay_graph` output.

    Returns
    -------
    SearchAreas

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.segment import search_areas
    >>> g = np.mgrid[0:10, 0:3].reshape(2, -1).T.astype(float)
    >>> pts = np.c_[g, np.zeros(30)]
    >>> lab = np.where(g[:, 0] < 3, 1, 0)
    >>> sa = search_areas(pts, lab, 1.5)
    >>> sorted(set(pts[sa.indices, 0].tolist()))
    [3.0]
    """
    points = check_points(points, min_points=3)
    search = check_scalar(search, "search", func="search_areas", low=0.0, closed="left")
    labels = np.ascontiguousarray(labels, dtype=np.int64)
    indptr, idx, lengths = graph if graph is not None else delaunay_graph(points)
    c_max = int(labels.max()) if labels.size else 0
    order = np.argsort(labels, kind="stable")
    counts = np.bincount(labels, minlength=c_max + 1)
    members_ptr = np.concatenate(([0], np.cumsum(counts[1:]))).astype(np.int64)
    members = np.ascontiguousarray(order[counts[0]:], dtype=np.int64)
    out_ptr = np.zeros(c_max + 1, dtype=np.int64)
    _bounded_areas(indptr, idx, lengths, labels, members_ptr, members, search, out_ptr,
                   np.empty(0, dtype=np.int64), False)
    np.cumsum(out_ptr, out=out_ptr)
    out = np.empty(out_ptr[-1], dtype=np.int64)
    _bounded_areas(indptr, idx, lengths, labels, members_ptr, members, search, out_ptr, out,
                   True)
    return SearchAreas(out_ptr, out, search)
