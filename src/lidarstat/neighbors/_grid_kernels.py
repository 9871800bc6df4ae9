"""Numba kernels of the exact k-nearest-neighbour search on a uniform grid.

Per point, the candidates are the points of the (2R+1)^3 cells of a :class:`CellIndex`
around its cell (:func:`_block_ranges`), binned by distance and selected
(:func:`_knn_point`), with R grown until the k-th candidate is closer than the faces of
the block, so the result is exact. Exported from :mod:`lidarstat.neighbors` as
``grid_knn_point``, ``grid_block_ranges``, ``grid_candidate_count``, ``grid_knn_scratch``,
``grid_guaranteed`` and ``GRID_CELL_CHUNK`` (and, in plan, ``grid_walk_block_2d``,
``grid_block_2d`` and ``grid_select_2d``: a cell's 3 x 3 block copied once, then each of
its points' nearest), for the drivers that fuse the search with a per-point model
while the neighbours are in cache: the covariance features (3-D,
:func:`lidarstat.features._covariance_kernels.knn_cells`) and the planimetric patch
graph of the moments classification (2-D, :mod:`lidarstat.classify._continuity`).
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit

_CELL_CHUNK = 32  # grid cells per parallel task of the drivers of this search


_NBIN = 64  # distance bins of the k-nearest selection
_SMALL = 32  # a bin with more candidates (duplicates, ties) is sorted by mergesort


@njit
def _scratch(cap):
    """Work arrays of :func:`_knn_point` for up to `cap` candidates: the candidates'
    squared distances and indices (bd, bi) and those of :func:`_nearest`."""
    return (np.empty(cap + 1), np.empty(cap + 1, dtype=np.int64),
            np.empty(cap + 1), np.empty(cap + 1, dtype=np.int64),
            np.empty(cap + 1, dtype=np.int32), np.empty(cap + 1),
            np.empty(cap + 1, dtype=np.int64), np.empty(_NBIN + 1, dtype=np.int64))


@njit
def _insertion(d, i, n):
    """Insertion sort of ``d[:n]`` with ``i`` (stable; linear on nearly sorted input)."""
    for a in range(1, n):
        x = d[a]
        y = i[a]
        b = a - 1
        while b >= 0 and d[b] > x:
            d[b + 1] = d[b]
            i[b + 1] = i[b]
            b -= 1
        d[b + 1] = x
        i[b + 1] = y


@njit
def _sort_pairs(d, i, n):
    """Sort ``d[:n]`` ascending with ``i``; equal keys keep their order (stable)."""
    if n <= _SMALL:
        _insertion(d, i, n)
        return
    o = np.argsort(d[:n], kind="mergesort")
    dd = d[:n][o]
    ii = i[:n][o]
    d[:n] = dd
    i[:n] = ii


@njit
def _nearest(bd, bi, m, k, sort, td, ti, tb, sd, si, cnt):
    """The k smallest of the squared distances ``bd[:m]`` (``m >= k``), with their ``bi``.

    Written to ``td[:k]``, ``ti[:k]``; returns the k-th smallest. A counting pass over
    `_NBIN` equal bins of ``[0, max]`` finds the bin that holds the k-th value: every
    candidate of a lower bin is selected, the bin itself is sorted and cut (bins are
    monotone in the distance, so this is exact). With `sort` the selected candidates are
    placed bin by bin (counting sort) and finished by insertion sort (ascending
    distance, equal distances in candidate order); without, the lower bins keep the
    candidate order and the cut bin follows in ascending distance.
    """
    dmax = 0.0
    for t in range(m):
        dmax = max(dmax, bd[t])
    scale = _NBIN / dmax if dmax > 0.0 else 0.0
    for b in range(_NBIN + 1):
        cnt[b] = 0
    for t in range(m):
        b = min(int(bd[t] * scale), _NBIN - 1)
        tb[t] = b
        cnt[b] += 1
    big = 0
    before = 0
    cut = 0
    for b in range(_NBIN):
        big = max(big, cnt[b])
        if before + cnt[b] >= k:
            cut = b
            break
        before += cnt[b]
    need = k - before
    if sort:
        # counting sort of the candidates of bins <= cut: cnt becomes bin starts
        acc = 0
        for b in range(cut + 1):
            c = cnt[b]
            cnt[b] = acc
            acc += c
        for t in range(m):
            b = tb[t]
            if b <= cut:
                p = cnt[b]
                td[p] = bd[t]
                ti[p] = bi[t]
                cnt[b] = p + 1
        # the bins are in order: sort within them (one insertion sort when all are small)
        if big <= _SMALL:
            _insertion(td, ti, acc)
        else:
            start = 0
            for b in range(cut + 1):
                _sort_pairs(td[start:], ti[start:], cnt[b] - start)
                start = cnt[b]
        return td[k - 1]
    p = 0
    q = 0
    for t in range(m):
        b = tb[t]
        d = bd[t]
        j = bi[t]
        td[p] = d
        ti[p] = j
        p += b < cut
        sd[q] = d
        si[q] = j
        q += b == cut
    _sort_pairs(sd, si, q)
    for t in range(need):
        td[before + t] = sd[t]
        ti[before + t] = si[t]
    return td[k - 1]


@njit
def _block_ranges(ix0, iy0, iz0, rad, cell_keys, cell_start, dims, ranges):
    """Sorted-position ranges of the occupied cells within `rad` cells of (ix0, iy0, iz0).

    `ranges` must hold (2 rad + 1)^2 rows. Returns the number of ranges.
    """
    return column_ranges(ix0, iy0, rad, max(iz0 - rad, 0), min(iz0 + rad, dims[2] - 1),
                         cell_keys, cell_start, dims, ranges)


@njit
def column_ranges(ix0, iy0, rad, kz0, kz1, cell_keys, cell_start, dims, ranges):
    """Sorted-position ranges of the occupied cells of layers kz0..kz1 in the (ix, iy)
    columns within `rad` cells of (ix0, iy0), column by column (ix, then iy, ascending).

    Cells of one (ix, iy) column have consecutive keys: one binary search pair per column.
    Returns the number of ranges written to `ranges`.
    """
    n = 0
    if kz1 < kz0:
        return 0
    for ix in range(max(ix0 - rad, 0), min(ix0 + rad, dims[0] - 1) + 1):
        for iy in range(max(iy0 - rad, 0), min(iy0 + rad, dims[1] - 1) + 1):
            k0 = (ix * dims[1] + iy) * dims[2] + kz0
            k1 = (ix * dims[1] + iy) * dims[2] + kz1
            a = np.searchsorted(cell_keys, k0)
            b = np.searchsorted(cell_keys, k1, side="right")
            if b > a:
                ranges[n, 0] = cell_start[a]
                ranges[n, 1] = cell_start[b]
                n += 1
    return n


@njit
def _guaranteed(px, py, pz, ix0, iy0, iz0, rad, cell, dims):
    """Radius around the point inside which the block of `rad` cells holds every point.

    Faces of the block on the border of the grid do not limit it (nothing lies beyond).
    """
    g = np.inf
    if ix0 - rad > 0:
        g = min(g, px - (ix0 - rad) * cell)
    if ix0 + rad < dims[0] - 1:
        g = min(g, (ix0 + rad + 1) * cell - px)
    if iy0 - rad > 0:
        g = min(g, py - (iy0 - rad) * cell)
    if iy0 + rad < dims[1] - 1:
        g = min(g, (iy0 + rad + 1) * cell - py)
    if iz0 - rad > 0:
        g = min(g, pz - (iz0 - rad) * cell)
    if iz0 + rad < dims[2] - 1:
        g = min(g, (iz0 + rad + 1) * cell - pz)
    return g


@njit
def _gather(px, py, pz, pts, ranges, nr, bd, bi):
    """Squared distances of every point of `ranges` to (px, py, pz) into bd, bi."""
    n = 0
    for t in range(nr):
        for j in range(ranges[t, 0], ranges[t, 1]):
            dx = pts[j, 0] - px
            dy = pts[j, 1] - py
            dz = pts[j, 2] - pz
            bd[n] = dx * dx + dy * dy + dz * dz
            bi[n] = j
            n += 1
    return n


@njit
def _gather_within(px, py, pz, pts, ranges, nr, tau2, bd, bi):
    """Like :func:`_gather` but keeps only squared distances <= tau2 (branch-free store)."""
    n = 0
    for t in range(nr):
        for j in range(ranges[t, 0], ranges[t, 1]):
            dx = pts[j, 0] - px
            dy = pts[j, 1] - py
            dz = pts[j, 2] - pz
            d = dx * dx + dy * dy + dz * dz
            bd[n] = d
            bi[n] = j
            n += d <= tau2
    return n


@njit
def _count(ranges, nr):
    n = 0
    for t in range(nr):
        n += ranges[t, 1] - ranges[t, 0]
    return n


@njit
def _knn_point(px, py, pz, ix0, iy0, iz0, pts, cell_keys, cell_start, dims, cell, k, sort,
               tau2, ranges, nr, bd, bi, td, ti, tb, sd, si, cnt):
    """Exact `k` nearest of the point (px, py, pz) of cell (ix0, iy0, iz0) into ``td[:k]``
    (squared distances) and ``ti[:k]`` (sorted positions), in ascending distance if `sort`.

    The candidates are the points of `ranges` (the 3 x 3 (x 3) cells around the point)
    within ``sqrt(tau2)``, all of them if fewer than k; while the k-th distance exceeds the
    radius the block of cells is guaranteed to cover (:func:`_guaranteed`), the block
    grows by one cell. Returns ``(kth, m, need)``: the k-th squared distance, the number
    of candidates, and 0, or the number of candidates a grown block needs when the work
    arrays (:func:`_scratch`) are too small; then call again with larger ones.
    """
    cap = bd.size - 1
    maxrad = max(dims[0], max(dims[1], dims[2]))
    m = _gather_within(px, py, pz, pts, ranges, nr, tau2, bd, bi)
    if m < k:
        m = _gather(px, py, pz, pts, ranges, nr, bd, bi)
    rad = 1
    kth = np.inf
    if m >= k:
        kth = _nearest(bd, bi, m, k, sort, td, ti, tb, sd, si, cnt)
    while m < k or kth > _guaranteed(px, py, pz, ix0, iy0, iz0, rad, cell, dims) ** 2:
        if rad > maxrad:
            break
        rad += 1
        big = np.empty(((2 * rad + 1) ** 2, 2), dtype=np.int64)
        nb = _block_ranges(ix0, iy0, iz0, rad, cell_keys, cell_start, dims, big)
        need = _count(big, nb)
        if need > cap:
            return kth, m, need
        m = _gather(px, py, pz, pts, big, nb, bd, bi)
        if m >= k:
            kth = _nearest(bd, bi, m, k, sort, td, ti, tb, sd, si, cnt)
    return kth, m, 0


@njit(inline="always")
def cell_ranges(c, cell_keys, cell_start, dims, ranges):
    """Cell `c`'s grid position ``(ix0, iy0, iz0)`` and the column ranges of its 27-cell
    block in `ranges` with their number: ``(ix0, iy0, iz0, nr)``."""
    key = cell_keys[c]
    iz0 = key % dims[2]
    rest = key // dims[2]
    ix0 = rest // dims[1]
    iy0 = rest % dims[1]
    nr = _block_ranges(ix0, iy0, iz0, 1, cell_keys, cell_start, dims, ranges)
    return ix0, iy0, iz0, nr


@njit(inline="always")
def cell_block(c, cell_keys, cell_start, dims, ranges, work):
    """:func:`cell_ranges`, and `work` (:func:`_scratch` arrays) grown to hold every
    candidate of the block: ``(ix0, iy0, iz0, nr, work)``."""
    ix0, iy0, iz0, nr = cell_ranges(c, cell_keys, cell_start, dims, ranges)
    need = _count(ranges, nr)
    cap = work[0].size - 1
    if need > cap:
        work = _scratch(max(need, 2 * cap))
    return ix0, iy0, iz0, nr, work


@njit(inline="always")
def knn_found(px, py, pz, ix0, iy0, iz0, pts, cell_keys, cell_start, dims, cell, k, sort,
              tau2, ranges, nr, work):
    """:func:`_knn_point` with its work arrays `work` (:func:`_scratch`) grown until the
    candidates fit: ``(kth, m, work)``, the distances and positions in ``work[2]`` and
    ``work[3]``."""
    while True:
        bd, bi, td, ti, tb, sd, si, cnt = work
        kth, m, need = _knn_point(px, py, pz, ix0, iy0, iz0, pts, cell_keys, cell_start, dims,
                                  cell, k, sort, tau2, ranges, nr, bd, bi, td, ti, tb, sd, si,
                                  cnt)
        if not need:
            return kth, m, work
        work = _scratch(max(need, 2 * (bd.size - 1)))


@njit
def walk_block_2d(ix0, iy0, cell_keys, cell_start, dims, ptr, ranges):
    """Sorted-position ranges of the occupied cells of the 3 x 3 block around (ix0, iy0)
    of a planimetric grid (``dims[2] == 1``): one range per column, the same points in
    the same order as :func:`_block_ranges` with ``rad = 1``.

    `ptr` (6 values) holds the cell indices found for the previous cell; set them to -1
    before the first cell. Cells visited in ascending key move every bound forward, so
    the bounds are walked rather than searched. Returns the number of ranges.
    """
    n = 0
    ncell = cell_keys.size
    for u in range(3):
        ix = ix0 - 1 + u
        if ix < 0 or ix > dims[0] - 1:
            continue
        lo = ix * dims[1] + max(iy0 - 1, 0)
        hi = ix * dims[1] + min(iy0 + 1, dims[1] - 1)
        a = ptr[2 * u]
        if a < 0:
            a = np.searchsorted(cell_keys, lo)
        while a < ncell and cell_keys[a] < lo:
            a += 1
        b = max(ptr[2 * u + 1], a)
        while b < ncell and cell_keys[b] <= hi:
            b += 1
        ptr[2 * u] = a
        ptr[2 * u + 1] = b
        if b > a:
            ranges[n, 0] = cell_start[a]
            ranges[n, 1] = cell_start[b]
            n += 1
    return n


@njit
def block_2d(pts, ranges, nr, bx, by, bj):
    """Copy x, y and the sorted position of every point of `ranges` into bx, by, bj
    (contiguous, ascending position); returns their number. The planimetric searches of
    the points of one cell (:func:`select_2d`) then read one block instead of `ranges`."""
    n = 0
    for t in range(nr):
        for j in range(ranges[t, 0], ranges[t, 1]):
            bx[n] = pts[j, 0]
            by[n] = pts[j, 1]
            bj[n] = j
            n += 1
    return n


@njit
def select_2d(px, py, bx, by, bj, m, k, tau2, bd, bc, td, ti):
    """The `k` nearest in plan of (px, py) among ``bx/by/bj[:m]``.

    Written to ``td[:k]`` (squared distances, computed as :func:`_gather`'s with z = 0)
    and ``ti`` (``bj`` values) in ascending (distance, position) order: at equal
    distances the lower position first, as :func:`_knn_point` chooses among candidates
    gathered in ascending position. The distances go to ``bd[:m]`` in one pass; only
    those within ``sqrt(tau2)`` are indexed in ``bc`` and sorted into the list, the
    radius doubling (in area) while fewer than `k` are within it (all candidates after
    four tries). Returns ``min(k, m)``.
    """
    for t in range(m):
        dx = bx[t] - px
        dy = by[t] - py
        bd[t] = dx * dx + dy * dy
    q = 0
    if m >= k:
        for grow in range(4):  # widen the radius until k are within it
            q = 0
            for t in range(m):
                bc[q] = t
                q += bd[t] <= tau2
            if q >= k:
                break
            tau2 *= 2.0
    if q < k:
        for t in range(m):
            bc[t] = t
        q = m
    s = 0
    for u in range(q):
        t = bc[u]
        d = bd[t]
        j = bj[t]
        if s == k:
            if d > td[k - 1] or (d == td[k - 1] and j > ti[k - 1]):
                continue
            p = k - 1
        else:
            p = s
            s += 1
        while p > 0 and (td[p - 1] > d or (td[p - 1] == d and ti[p - 1] > j)):
            td[p] = td[p - 1]
            ti[p] = ti[p - 1]
            p -= 1
        td[p] = d
        ti[p] = j
    return s
