"""Ground surface model from ground points: cell medians joined by a Delaunay TIN.

The TIN is evaluated by a Numba kernel, not by ``scipy.interpolate.LinearNDInterpolator``:
scipy locates each query point by a walk from the previous point's triangle, so a cloud in
acquisition or random order walks O(sqrt(T)) triangles per point, and a point outside the
hull falls back to a brute-force scan of all T triangles. Both grow faster than N (the
10-million-point classification did not finish). Here the triangles are binned once into
a regular grid of cells (CSR of the cells each triangle meets) and every point
tests only the triangles of its cell: O(N + T) whatever the order, in parallel over the
points (each writes its own value: the same values in any thread count). The
barycentric coordinates use scipy's own affine transforms (``Delaunay.transform``) in
scipy's order of operations, so values agree with ``LinearNDInterpolator`` to rounding.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._columns import column_max, column_min
from .._shared._jit import njit, njit_parallel
from ..neighbors import delaunay_triangles
from ._terrain_frame import CELLS_PER_POINT, MIN_CELLS

__all__ = ["ground_surface", "cell_keys", "TinSurface"]

_EPS = 100 * np.finfo(float).eps  # scipy's tolerance inside a simplex
_EPS_BROAD = float(np.sqrt(np.finfo(float).eps))  # scipy's tolerance at the hull
#: Fewest ground points whose cell picks run in parallel blocks (below, the serial
#: kernels on copies of their rows: no thread is woken for a few milliseconds' work).
_PARALLEL_PICK = 1 << 19


def cell_keys(xy: np.ndarray, cell: float, origin=None) -> np.ndarray:
    """One int64 key per point naming its ``cell x cell`` square (row-major, collision-free).

    ``floor((xy - origin) / cell)`` per axis, ``ix * ncol + iy`` with ``ncol`` one more than
    the largest ``iy``: the arithmetic of NumPy's vectorised expression, in one compiled
    pass without (N, 2) temporaries.
    """
    xy = np.asarray(xy, dtype=np.float64)
    out = np.empty(len(xy), np.int64)
    if not out.size:
        return out
    o = column_min(xy) if origin is None else np.asarray(origin, dtype=float)
    # floor((y - oy) / cell) is monotone in y: the largest row index is the top point's
    ncol = int(np.floor((xy[:, 1].max() - o[1]) / cell)) + 1
    _cell_keys(xy, float(o[0]), float(o[1]), float(cell), ncol, out)
    return out


@njit
def _cell_keys(xy, ox, oy, cell, ncol, out):  # pragma: no cover - compiled
    for i in range(xy.shape[0]):
        out[i] = (np.int64(np.floor((xy[i, 0] - ox) / cell)) * ncol
                  + np.int64(np.floor((xy[i, 1] - oy) / cell)))


# --------------------------------------------------------------------------- cell picks
@njit
def _less(z, a, b, rank):  # pragma: no cover - compiled
    """Order by z, ties by input index (the order of ``np.lexsort((z, key))``), or by
    ``rank`` when it is not empty (the input index of a point of a reordered cloud)."""
    if z[a] != z[b]:
        return z[a] < z[b]
    if rank.size:
        return rank[a] < rank[b]
    return a < b


@njit
def _select(buf, k, z, rank):  # pragma: no cover - compiled
    """Put the k-th smallest of `buf` (by :func:`_less`) at ``buf[k]``: quickselect, O(n)."""
    lo = 0
    hi = buf.size - 1
    while hi > lo:
        mid = (lo + hi) // 2
        # median of three as the pivot, moved to hi
        if _less(z, buf[mid], buf[lo], rank):
            buf[mid], buf[lo] = buf[lo], buf[mid]
        if _less(z, buf[hi], buf[lo], rank):
            buf[hi], buf[lo] = buf[lo], buf[hi]
        if _less(z, buf[mid], buf[hi], rank):
            buf[mid], buf[hi] = buf[hi], buf[mid]
        pivot = buf[hi]
        store = lo
        for i in range(lo, hi):
            if _less(z, buf[i], pivot, rank):
                buf[i], buf[store] = buf[store], buf[i]
                store += 1
        buf[store], buf[hi] = buf[hi], buf[store]
        if store == k:
            return
        if store < k:
            lo = store + 1
        else:
            hi = store - 1


@njit
def _pick_per_cell(order, z, starts, which_median, rank):  # pragma: no cover - compiled
    """Per cell (points ``order[starts[c]:starts[c+1]]``): the lowest or the lower median
    by z, ties broken by input index (as ``np.lexsort((z, key))``) or by `rank`."""
    m = starts.size - 1
    out = np.empty(m, np.int64)
    buf = np.empty(order.size, np.int64)
    for c in range(m):
        out[c] = pick_one(order, starts[c], starts[c + 1], z, which_median, rank, buf)
    return out


@njit
def pick_one(order, a, b, z, which_median, rank, buf):  # pragma: no cover - compiled
    """The lowest or the lower median by z of the points ``order[a:b]`` (ties as
    :func:`_pick_per_cell`); `buf` holds at least ``b - a`` positions."""
    if not which_median:
        best = order[a]
        for i in range(a + 1, b):
            if _less(z, order[i], best, rank):
                best = order[i]
        return best
    w = buf[: b - a]
    w[:] = order[a:b]
    k = (b - a - 1) // 2
    _select(w, k, z, rank)
    return w[k]


@njit
def _counting_order(key, nkeys):  # pragma: no cover - compiled
    """Stable counting sort of `key` (0 <= key < nkeys): order and the starts of the
    non-empty keys."""
    cnt = np.zeros(nkeys + 1, np.int64)
    for i in range(key.size):
        cnt[key[i] + 1] += 1
    nz = 0
    for k in range(nkeys):
        if cnt[k + 1] > 0:
            nz += 1
        cnt[k + 1] += cnt[k]
    order = np.empty(key.size, np.int64)
    pos = cnt[:-1].copy()
    for i in range(key.size):
        k = key[i]
        order[pos[k]] = i
        pos[k] += 1
    starts = np.empty(nz + 1, np.int64)
    j = 0
    for k in range(nkeys):
        if cnt[k + 1] > cnt[k]:
            starts[j] = cnt[k]
            j += 1
    starts[nz] = key.size
    return order, starts


def cell_order(key):
    """Points grouped by cell, in input order inside a cell: ``(order, starts)`` with the
    points of the c-th non-empty cell (keys ascending) at ``order[starts[c]:starts[c+1]]``.

    A counting sort (O(N)) unless the keys span a huge, mostly empty range.
    """
    key = np.ascontiguousarray(key, dtype=np.int64)
    nkeys = int(key.max()) + 1 if key.size else 0
    if nkeys <= 4 * key.size + 1_000_000:
        return _counting_order(key, nkeys)
    order = np.argsort(key, kind="stable")  # sparse cells over a huge box
    ks = key[order]
    return order, np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True]).astype(np.int64)


@njit
def _median_per_cell(order, v, starts, out):  # pragma: no cover - compiled
    """``out[i]`` = median of `v` over the cell of point i (mean of the two middle values)."""
    buf = np.empty(order.size, np.int64)
    no_rank = np.empty(0, np.int64)  # values only: how ties are ordered does not matter
    for c in range(starts.size - 1):
        a, b = starts[c], starts[c + 1]
        w = buf[: b - a]
        w[:] = order[a:b]
        k = (b - a - 1) // 2
        _select(w, k, v, no_rank)
        lo = v[w[k]]
        hi = lo
        if (b - a) % 2 == 0:  # the upper middle: the smallest value above position k
            hi = v[w[k + 1]]
            for j in range(k + 2, b - a):
                hi = min(hi, v[w[j]])
        m = 0.5 * (lo + hi)
        for j in range(a, b):
            out[order[j]] = m


def cell_median_values(key, values, *, return_cells: bool = False):
    """Each point's median of `values` over the points sharing its cell `key` (O(N)).

    With `return_cells`, also one median per non-empty cell (keys ascending).
    """
    order, starts = cell_order(key)
    out = np.empty(len(values))
    _median_per_cell(order, np.ascontiguousarray(values, dtype=np.float64), starts, out)
    if return_cells:
        return out, out[order[starts[:-1]]]
    return out


def _cell_pick(xy, z, cell, which, rank=None, where=None):
    """Index of the lowest (``'min'``) or lower-median (``'median'``) point of every cell.

    Ties in z go to the lower index, or to the lower `rank` (the points' input indices
    when the caller works on a reordered cloud, so the pick does not depend on the order).
    With `where` (ascending indices) only those points take part, as if the cloud were
    ``xy[where]``, and the indices returned are rows of `xy`.
    """
    rank = np.empty(0, np.int64) if rank is None else np.ascontiguousarray(rank, np.int64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    if where is None:
        order, starts = cell_order(cell_keys(xy, cell))
        return _pick_per_cell(order, z, starts, which == "median", rank)
    from numba import get_num_threads

    from . import _surface_kernels as k

    where = np.ascontiguousarray(where, dtype=np.int64)
    if where.size < _PARALLEL_PICK:  # the copies cost less than starting the threads
        sel = _cell_pick(np.asarray(xy)[where], z[where], cell, which,
                         rank[where] if rank.size else None)
        return where[sel]  # ties by index in the copy: by row, `where` ascending
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    # blocks of points and of cells worked in parallel; the counting sort's table holds
    # a count per key and block: as many blocks as threads only where the cells hold
    # many points each (then the table is small beside the points)
    threads = min(get_num_threads(), 8)
    key = np.empty(where.size, np.int64)
    nkeys = k.cell_keys_where(xy, where, float(cell), threads, key)
    if nkeys > 4 * key.size + 1_000_000:  # sparse cells over a huge box
        order, starts = cell_order(key)
        order = where[order]  # rows of `xy`: ties by index stay in the subset's order
    else:
        blocks = max(1, min(threads, key.size // nkeys))
        order, starts = k.order_where(key, nkeys, where, blocks)
    return k.pick_cells(order, z, starts, which == "median", rank, threads)


# --------------------------------------------------------------------------- TIN kernels
@njit
def _inside(tf, t, x, y, eps):  # pragma: no cover - compiled
    """Barycentric coordinates of (x, y) in triangle t (scipy's operation order) and
    whether all are >= -eps."""
    dx = x - tf[t, 2, 0]
    dy = y - tf[t, 2, 1]
    c0 = 0.0
    c0 += tf[t, 0, 0] * dx
    c0 += tf[t, 0, 1] * dy
    c1 = 0.0
    c1 += tf[t, 1, 0] * dx
    c1 += tf[t, 1, 1] * dy
    c2 = 1.0 - c0 - c1
    return c0, c1, c2, (c0 >= -eps) and (c1 >= -eps) and (c2 >= -eps)


@njit_parallel
def _tin_eval(q, ox, oy, g, nx, ny, indptr, tri, simplices, tf, V, eps, eps_broad,
              out):  # pragma: no cover - compiled
    """Linear interpolation on the TIN; NaN outside it (within `eps_broad` at the hull)."""
    for k in prange(q.shape[0]):
        x = q[k, 0]
        y = q[k, 1]
        out[k] = np.nan
        i = int(np.floor((x - ox) / g))
        j = int(np.floor((y - oy) / g))
        if i < 0 or i >= nx or j < 0 or j >= ny:
            # outside the vertices' box: maybe within eps_broad of it
            i = min(max(i, 0), nx - 1)
            j = min(max(j, 0), ny - 1)
        c = i * ny + j
        for attempt in range(2):
            tol = eps if attempt == 0 else eps_broad
            found = False
            for p in range(indptr[c], indptr[c + 1]):
                t = tri[p]
                c0, c1, c2, ok = _inside(tf, t, x, y, tol)
                if ok:
                    v = 0.0
                    v += c0 * V[simplices[t, 0]]
                    v += c1 * V[simplices[t, 1]]
                    v += c2 * V[simplices[t, 2]]
                    out[k] = v
                    found = True
                    break
            if found:
                break


def _transforms(P, simplices):
    """Affine maps to barycentric coordinates, laid out as ``Delaunay.transform``.

    ``T[t, :2] @ (x - T[t, 2])`` gives the first two barycentric coordinates of x in
    triangle t. scipy's own property solves each 2x2 system through LAPACK in a Python
    loop (seconds for 1e5 triangles); the closed-form inverse is vectorised. Degenerate
    triangles get NaN, as in scipy, so no point is ever located in them.
    """
    v = P[simplices]  # (T, 3, 2)
    r = v[:, 2]
    a = v[:, 0] - r  # columns of the matrix: x0 - x2, x1 - x2
    b = v[:, 1] - r
    det = a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]
    scale = np.maximum(np.abs(a).max(axis=1), np.abs(b).max(axis=1)) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.where(np.abs(det) > 1e3 * np.finfo(float).eps * scale, det, np.nan)
    T = np.empty((len(simplices), 3, 2))
    T[:, 0, 0] = b[:, 1] * inv
    T[:, 0, 1] = -b[:, 0] * inv
    T[:, 1, 0] = -a[:, 1] * inv
    T[:, 1, 1] = a[:, 0] * inv
    T[:, 2] = r
    return T


class TinSurface:
    """Linear interpolation on a Delaunay TIN; outside its hull the plane of the nearest
    vertices (:func:`_extrapolate`), the nearest vertex when there is no triangle.

    Parameters
    ----------
    P : (M, 2) ndarray
        Vertices (planimetric).
    V : (M,) ndarray
        Values at the vertices.
    cell : float
        About the vertex spacing: the triangles are binned into cells of half this side,
        or of `bin_side`.
    keep : callable, optional
        ``keep(corners) -> (T,) bool`` of the triangles' ``(T, 3, 2)`` corners: the others
        are left out (a point in one is outside the TIN). A TIN over wide empty areas
        whose triangles there hold no query then bins only the triangles near the data
        (binning costs a triangle's box).
    frame : BandFrame, optional
        `P` is given moved into this :class:`~._terrain_frame.BandFrame`; every query is
        moved into it too (a TIN over clumps far apart then bins the narrowed gaps, not
        the whole box).
    bin_side : float, optional
        Side of the bins: at a quarter of the vertex spacing a bin holds about 2.2
        triangles, 3.7 at half of it (four times fewer bins); never more bins than the
        terrain grid's cells for as many vertices.

    Examples
    --------
    >>> P = np.array([[0.0, 0.0], [1, 0], [0, 1], [1, 1]])
    >>> f = TinSurface(P, np.array([0.0, 1, 2, 3]), cell=0.5)
    >>> f(np.array([[0.5, 0.5], [0.25, 0.0], [3.0, 3.0]])).round(6).tolist()
    [1.5, 0.25, 9.0]
    """

    def __init__(self, P, V, cell: float, keep=None, frame=None, bin_side=None):
        self.frame = frame
        self.P = np.ascontiguousarray(P, dtype=np.float64)
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self._kdtree = None  # the vertices' k-d tree, built when a query needs it
        self._tri = None
        if len(self.P) >= 3:
            simp = delaunay_triangles(self.P)
            if len(simp):  # none when the vertices are collinear
                lo = column_min(self.P)
                span = column_max(self.P) - lo
                # no more bins than the terrain grid's cells (:func:`~._terrain_frame.
                # terrain_cell`) for as many vertices: sparse vertices make large
                # triangles, binned over their whole box
                limit = max(CELLS_PER_POINT * len(self.P), MIN_CELLS)
                g = max(0.5 * float(cell) if bin_side is None else float(bin_side),
                        float(span.max()) / 4096.0,
                        float(np.sqrt(span[0] * span[1] / limit)), 1e-12)
                nx, ny = (np.floor(span / g).astype(np.int64) + 1).tolist()
                if keep is not None:
                    simp = np.ascontiguousarray(simp[keep(self.P[simp])])
                from numba import get_num_threads

                from ._surface_kernels import bin_triangles

                # blocks of triangles in parallel: a count per bin and block (at most 4)
                indptr, tri = bin_triangles(self.P, simp, float(lo[0]), float(lo[1]), g,
                                            nx, ny, min(get_num_threads(), 4))
                self._tri = (float(lo[0]), float(lo[1]), g, nx, ny, indptr, tri, simp,
                             _transforms(self.P, simp))

    @property
    def _tree(self):
        """k-d tree of the vertices (outside the hull only: built on first use)."""
        if self._kdtree is None:
            from scipy.spatial import cKDTree

            self._kdtree = cKDTree(self.P)
        return self._kdtree

    def __call__(self, q) -> np.ndarray:
        q = np.ascontiguousarray(q if self.frame is None else self.frame(q),
                                 dtype=np.float64)
        if self._tri is None:
            return self.V[self._tree.query(q)[1]]
        out = np.empty(len(q))
        _tin_eval(q, *self._tri, self.V, _EPS, _EPS_BROAD, out)
        bad = np.isnan(out)
        if bad.any():
            out[bad] = _extrapolate(self.P, self.V, self._tree, q[bad])
        return out


def _extrapolate(P, V, tree, q, k=8):
    """Value at `q` of the least-squares plane through the `k` vertices nearest to it.

    Falls back to the nearest vertex where those vertices are (nearly) collinear.
    """
    k = min(k, len(P))
    d, nb = tree.query(q, k=k)
    nb = nb.reshape(len(q), k)
    if k < 3:
        return V[nb[:, 0]]
    dx = P[nb] - q[:, None, :]                      # (m, k, 2), q at the origin
    A = np.concatenate([np.ones((len(q), k, 1)), dx], axis=2)
    AtA = np.einsum("mki,mkj->mij", A, A)
    Atb = np.einsum("mki,mk->mi", A, V[nb])
    det = np.linalg.det(AtA)
    scale = np.einsum("mkj,mkj->m", dx, dx) / k
    ok = det > 1e-9 * np.maximum(scale, 1e-12) ** 2 * k ** 3
    out = V[nb[:, 0]].astype(float)
    if ok.any():
        out[ok] = np.linalg.solve(AtA[ok], Atb[ok][..., None])[:, 0, 0]
    return out


def ground_surface(xy_ground, z_ground, *, cell: float, which: str = "median", rank=None,
                   where=None, frame=None):
    """Return ``f(xy) -> z`` interpolating ground points (one per cell) linearly on a TIN.

    Parameters
    ----------
    xy_ground : (M, 2) ndarray
        Planimetric coordinates of ground points (local origin).
    z_ground : (M,) ndarray
        Their elevations.
    cell : float
        Thinning cell: one point per cell (the median or the lowest) becomes a TIN vertex,
        so the model costs O(cells) whatever the density.
    which : {'median', 'min'}
    rank : (M,) ndarray of int, optional
        Input index of each point, breaking ties in z (default: the position).
    where : (K,) ndarray of int, optional
        Ascending rows of the ground points when `xy_ground`, `z_ground` and `rank` are
        given for a whole cloud: the same surface as for ``xy_ground[where]``,
        ``z_ground[where]``, ``rank[where]``, without those copies.
    frame : BandFrame, optional
        The TIN is made in this frame (:class:`~._terrain_frame.BandFrame`: the empty
        bands of cells taken out) and moves its queries into it.

    Returns
    -------
    TinSurface
        Linear interpolation inside the hull; outside it, the plane fitted to the nearest
        vertices (a terrain slope continues to the border of the cloud instead of
        stopping at the last cell's median point, which would lift the heights of a
        whole border strip of a sloped scene). Evaluating N points costs O(N) in any
        order.
    """
    sel = _cell_pick(xy_ground, z_ground, cell, which, rank, where)
    P = xy_ground[sel]
    # quarter-cell bins: the surface is evaluated at every point of the cloud
    return TinSurface(P if frame is None else frame(P), z_ground[sel], cell, frame=frame,
                      bin_side=0.25 * cell)
