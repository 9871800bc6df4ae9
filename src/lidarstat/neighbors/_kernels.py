"""Numba kernels of the cell-list (uniform grid) fixed-radius search.

The searched points are sorted by cell key; ``cell_keys`` holds the sorted unique keys
and ``cell_start`` the first sorted position of each cell (with a sentinel at the end).
A query visits the 3**dim cells around its own and keeps the points within ``radius``.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ._grid_kernels import column_ranges


@njit
def _find_cell(cell_keys, key):
    pos = np.searchsorted(cell_keys, key)
    if pos < cell_keys.size and cell_keys[pos] == key:
        return pos
    return -1


@njit
def _visit(q, pts, cell_keys, cell_start, cell, dims, radius, ndim, out_idx, out_dist, start,
           mode):
    """Count (and, by `mode`, store) the neighbours of arbitrary query coordinates `q`."""
    cx = int(np.floor(q[0] / cell))
    cy = int(np.floor(q[1] / cell))
    cz = int(np.floor(q[2] / cell)) if ndim == 3 else 0
    ranges = np.empty((9, 2), dtype=np.int64)
    nr = _ranges_at(cx, cy, cz, cell_keys, cell_start, dims, ndim, ranges)
    return _scan(q[0], q[1], q[2], pts, ranges, nr, radius * radius, ndim, out_idx, out_dist,
                 start, mode)


@njit_parallel
def count_radius(queries, pts, cell_keys, cell_start, cell, dims, radius, ndim):
    """Number of neighbours of every query point (parallel over queries)."""
    m = queries.shape[0]
    counts = np.empty(m, dtype=np.int64)
    dummy_i = np.empty(0, dtype=np.int32)
    dummy_d = np.empty(0, dtype=np.float64)
    for i in prange(m):
        counts[i] = _visit(queries[i], pts, cell_keys, cell_start, cell, dims, radius, ndim,
                           dummy_i, dummy_d, 0, COUNT)
    return counts


@njit_parallel
def fill_radius(queries, pts, cell_keys, cell_start, cell, dims, radius, ndim, indptr,
                out_idx, out_dist):
    """Write neighbour (sorted-order) indices and distances into preallocated CSR arrays."""
    m = queries.shape[0]
    for i in prange(m):
        _visit(queries[i], pts, cell_keys, cell_start, cell, dims, radius, ndim, out_idx,
               out_dist, indptr[i], STORE)


@njit_parallel
def remap(indices, order):
    """Map sorted positions back to original point indices, in place."""
    for i in prange(indices.size):
        indices[i] = order[indices[i]]


@njit
def _cell_ranges(c, cell_keys, cell_start, dims, ndim, ranges):
    """Sorted-position ranges of the (up to 27) cells around occupied cell `c`."""
    key = cell_keys[c]
    iz0 = key % dims[2]
    rest = key // dims[2]
    return _ranges_at(rest // dims[1], rest % dims[1], iz0, cell_keys, cell_start, dims, ndim,
                      ranges)


@njit
def _ranges_at(ix0, iy0, iz0, cell_keys, cell_start, dims, ndim, ranges):
    """Sorted-position ranges of the occupied cells around cell (ix0, iy0, iz0).

    The cells (ix, iy, iz0-1..iz0+1) (iz0 alone for 2-D) of each of the nine columns have
    consecutive keys (:func:`column_ranges`). Returns the number of ranges.
    """
    zr = 1 if ndim == 3 else 0
    return column_ranges(ix0, iy0, 1, max(iz0 - zr, 0), min(iz0 + zr, dims[2] - 1), cell_keys,
                         cell_start, dims, ranges)


#: Modes of :func:`_scan`: count only; store the neighbours at ``start`` (exact room);
#: store every candidate, advancing over those inside (room for every candidate).
COUNT, STORE, STORE_ALL = 0, 1, 2


@njit(inline="always")
def _scan(qx, qy, qz, pts, ranges, nr, r2, ndim, out_idx, out_dist, start, mode):
    """Count (and store) the points of `ranges` within sqrt(r2) of (qx, qy, qz).

    The neighbours go, in the order of `ranges`, to ``out_idx[start:start + n]`` and
    their distances to ``out_dist[start:start + n]``; returns n. `mode` is a constant
    of every call site, so the compiled loop has one branch of it:

    * ``COUNT``: nothing is stored;
    * ``STORE``: only the neighbours are stored (the outputs need room for n: CSR rows);
    * ``STORE_ALL``: branch-free, every candidate is stored and the count advances only
      for those inside, so the outcome of the distance test (inside about one time in
      three in a 27-cell block) is never mispredicted; the outputs need room for every
      candidate of `ranges` (a per-thread buffer).

    The squared distances are stored and their square roots taken afterwards, of the
    neighbours only. Inlined by Numba into each caller, where `mode` is a constant, so
    the dead branches go (left to LLVM, the fused scan was about 15 % slower).
    """
    n = 0
    for t in range(nr):
        for j in range(ranges[t, 0], ranges[t, 1]):
            dx = pts[j, 0] - qx
            dy = pts[j, 1] - qy
            d2 = dx * dx + dy * dy
            if ndim == 3:
                dz = pts[j, 2] - qz
                d2 += dz * dz
            if mode == STORE_ALL:
                out_idx[start + n] = j
                out_dist[start + n] = d2
                n += d2 <= r2
            elif d2 <= r2:
                if mode == STORE:
                    out_idx[start + n] = j
                    out_dist[start + n] = d2
                n += 1
    if mode != COUNT:
        for t in range(start, start + n):
            out_dist[t] = np.sqrt(out_dist[t])
    return n


@njit_parallel
def count_cells(c0, c1, pts, cell_keys, cell_start, dims, radius, ndim):
    """Neighbour counts of the points of occupied cells c0..c1-1 (sorted order)."""
    base = cell_start[c0]
    counts = np.zeros(cell_start[c1] - base, dtype=np.int64)
    r2 = radius * radius
    dummy_i = np.empty(0, dtype=np.int32)
    dummy_d = np.empty(0, dtype=np.float64)
    for c in prange(c0, c1):
        ranges = np.empty((9, 2), dtype=np.int64)
        nr = _cell_ranges(c, cell_keys, cell_start, dims, ndim, ranges)
        for i in range(cell_start[c], cell_start[c + 1]):
            counts[i - base] = _scan(pts[i, 0], pts[i, 1], pts[i, 2], pts, ranges, nr, r2, ndim,
                                     dummy_i, dummy_d, 0, COUNT)
    return counts


@njit_parallel
def fill_cells(c0, c1, pts, cell_keys, cell_start, dims, radius, ndim, indptr, out_idx,
               out_dist):
    """Fill CSR rows (sorted positions) for the points of occupied cells c0..c1-1."""
    base = cell_start[c0]
    r2 = radius * radius
    for c in prange(c0, c1):
        ranges = np.empty((9, 2), dtype=np.int64)
        nr = _cell_ranges(c, cell_keys, cell_start, dims, ndim, ranges)
        for i in range(cell_start[c], cell_start[c + 1]):
            _scan(pts[i, 0], pts[i, 1], pts[i, 2], pts, ranges, nr, r2, ndim, out_idx, out_dist,
                  indptr[i - base], STORE)


@njit_parallel
def cell_candidates(c0, c1, cell_keys, cell_start, dims, ndim):
    """Upper bound of the neighbour pairs of the points of cells c0..c1-1.

    Each point is paired with every point of the 3**ndim cells around its own (what the
    search scans), so the sum is exact work and at least the number of pairs. O(cells),
    parallel over chunks of cells (integer sums: the same total in any order).
    """
    nchunks = (c1 - c0 + _COUNT_CHUNK - 1) // _COUNT_CHUNK
    total = 0
    for ch in prange(nchunks):
        ranges = np.empty((9, 2), dtype=np.int64)
        part = 0
        for c in range(c0 + ch * _COUNT_CHUNK, min(c1, c0 + (ch + 1) * _COUNT_CHUNK)):
            nr = _cell_ranges(c, cell_keys, cell_start, dims, ndim, ranges)
            near = 0
            for t in range(nr):
                near += ranges[t, 1] - ranges[t, 0]
            part += (cell_start[c + 1] - cell_start[c]) * near
        total += part
    return total


_COUNT_CHUNK = 1024  # cells per parallel task of cell_candidates


@njit
def query_candidates(queries, cell_keys, cell_start, cell, dims, ndim):
    """Points scanned by a radius search of every query coordinate (an upper bound of pairs)."""
    total = 0
    ranges = np.empty((9, 2), dtype=np.int64)
    for i in range(queries.shape[0]):
        cx = int(np.floor(queries[i, 0] / cell))
        cy = int(np.floor(queries[i, 1] / cell))
        cz = int(np.floor(queries[i, 2] / cell)) if ndim == 3 else 0
        nr = _ranges_at(cx, cy, cz, cell_keys, cell_start, dims, ndim, ranges)
        for t in range(nr):
            total += ranges[t, 1] - ranges[t, 0]
    return total


@njit_parallel
def permute_rows(indptr, indices, distances, row_of, order):
    """Reorder CSR rows: output row ``r`` is input row ``row_of[r]``; indices mapped by `order`."""
    m = row_of.size
    new_ptr = np.zeros(m + 1, dtype=np.int64)
    for r in range(m):
        s = row_of[r]
        new_ptr[r + 1] = new_ptr[r] + indptr[s + 1] - indptr[s]
    new_idx = np.empty(new_ptr[m], dtype=indices.dtype)
    new_dist = np.empty(new_ptr[m], dtype=np.float64)
    for r in prange(m):
        s = row_of[r]
        o = new_ptr[r]
        for t in range(indptr[s], indptr[s + 1]):
            new_idx[o] = order[indices[t]]
            new_dist[o] = distances[t]
            o += 1
    return new_ptr, new_idx, new_dist


# ------------------------------------------------------------------ building the index
@njit_parallel
def scatter_to(values, order, out):
    """``out[order[i]] = values[i]``: sorted-order values back to input order, in parallel."""
    for i in prange(order.size):
        out[order[i]] = values[i]


@njit
def grid_keys(points, origin, cell, dims, flat, keys):
    """Row-major cell key of every point: ``floor((p - origin) / cell)`` clipped to `dims`.

    `flat` (2-D index) puts every point in z layer 0. Same arithmetic as NumPy's
    ``np.floor(local / cell).astype(np.int64)`` so the keys are identical.
    """
    for i in range(points.shape[0]):
        ix = min(np.int64(np.floor((points[i, 0] - origin[0]) / cell)), dims[0] - 1)
        iy = min(np.int64(np.floor((points[i, 1] - origin[1]) / cell)), dims[1] - 1)
        iz = 0
        if not flat:
            iz = min(np.int64(np.floor((points[i, 2] - origin[2]) / cell)), dims[2] - 1)
        keys[i] = (ix * dims[1] + iy) * dims[2] + iz


@njit_parallel
def counting_scatter(points, origin, keys, start, parts, order, sorted_points):
    """Stable counting sort by key: ``order`` and ``sorted_points = points[order] - origin``.

    ``start[key]`` is the first sorted position of each key (exclusive prefix sum of the
    key counts); it is advanced in place. The keys are split into `parts` ranges (one
    per thread) of about equal point counts: each range's task reads every key in input
    order and places the points of its own range, so the order is the serial sort's
    whatever `parts` is (the scattered writes, the sort's cost, are shared).
    """
    n = points.shape[0]
    nk = start.size
    parts = max(1, parts)
    bounds = np.empty(parts + 1, dtype=np.int64)
    bounds[0] = 0
    bounds[parts] = nk
    for t in range(1, parts):  # first key whose points start at or after t n / parts
        bounds[t] = max(bounds[t - 1], np.searchsorted(start, (t * n) // parts))
    for t in prange(parts):
        lo = bounds[t]
        hi = bounds[t + 1]
        for i in range(n):
            k = keys[i]
            if k < lo or k >= hi:
                continue
            p = start[k]
            start[k] = p + 1
            order[p] = i
            sorted_points[p, 0] = points[i, 0] - origin[0]
            sorted_points[p, 1] = points[i, 1] - origin[1]
            sorted_points[p, 2] = points[i, 2] - origin[2]


_RADIX_BITS = 11


#: Keys per block of :func:`radix_order` (at most `_RADIX_BLOCKS` blocks).
_RADIX_BLOCK = 1 << 18
_RADIX_BLOCKS = 64


@njit_parallel
def radix_order(keys, nbits):
    """Stable sort of non-negative `keys` below ``2**nbits``: ``(order, keys[order])``.

    LSD radix sort, `_RADIX_BITS` bits per pass: the same permutation as
    ``np.argsort(keys, kind="stable")`` in O(N) per pass (a few passes for the grid keys
    of a cloud, instead of the comparison sort's O(N log N)). Each pass counts the digits
    of consecutive blocks of keys in parallel, gives every (digit, block) its first
    position (digits ascending, blocks in order within a digit) and scatters the blocks
    in parallel: the positions do not depend on the threads, the order is the serial
    sort's.
    """
    n = keys.size
    nblk = min(max(n // _RADIX_BLOCK, 1), _RADIX_BLOCKS)
    order = np.empty(n, dtype=np.int64)
    cur = np.empty(n, dtype=np.int64)
    for i in prange(n):
        order[i] = i
        cur[i] = keys[i]
    nxt_order = np.empty(n, dtype=np.int64)
    nxt = np.empty(n, dtype=np.int64)
    nb = 1 << _RADIX_BITS
    mask = nb - 1
    count = np.empty((nblk, nb), dtype=np.int64)
    shift = 0
    while shift < nbits:
        for k in prange(nblk):
            count[k, :] = 0
            for i in range(k * n // nblk, (k + 1) * n // nblk):
                count[k, (cur[i] >> shift) & mask] += 1
        first = 0
        for d in range(nb):
            for k in range(nblk):
                c = count[k, d]
                count[k, d] = first
                first += c
        for k in prange(nblk):
            for i in range(k * n // nblk, (k + 1) * n // nblk):
                d = (cur[i] >> shift) & mask
                at = count[k, d]
                count[k, d] = at + 1
                nxt[at] = cur[i]
                nxt_order[at] = order[i]
        cur, nxt = nxt, cur
        order, nxt_order = nxt_order, order
        shift += _RADIX_BITS
    return order, cur


# ------------------------------------------------------------------ exact copies
_NEG_ZERO = np.uint64(0x8000000000000000)


#: Largest cell whose points :func:`cells_may_share` compares pairwise.
PAIRWISE_CELL = 256


@njit_parallel
def cells_may_share(pts, cell_start):
    """Cells (of a :class:`CellIndex`, sorted local coordinates `pts`) in which two points
    may share a location: pairs of equal coordinates, or more than `PAIRWISE_CELL` points
    (not compared). 0 proves the cloud has no copies: equal locations fall in one cell
    and stay equal once the index's origin is subtracted."""
    found = 0
    for c in prange(cell_start.size - 1):
        s = cell_start[c]
        e = cell_start[c + 1]
        hit = 0
        if e - s > PAIRWISE_CELL:
            hit = 1
        else:
            for i in range(s, e - 1):
                x = pts[i, 0]
                y = pts[i, 1]
                z = pts[i, 2]
                for j in range(i + 1, e):
                    if pts[j, 0] == x and pts[j, 1] == y and pts[j, 2] == z:
                        hit = 1
                        break
                if hit:
                    break
        found += hit
    return found


@njit
def column_hash(bx, by, bz, out):
    """64-bit hash of the bits of every location ``(bx[i], by[i], bz[i])`` (the float64
    coordinates viewed as uint64, three C-contiguous columns) into `out`, -0.0 taken as
    0.0: ``b0 * C0 ^ b1 * C1 ^ b2 * C2`` (wrapping), then two mixing rounds."""
    c0 = np.uint64(0x9E3779B97F4A7C15)
    c1 = np.uint64(0xC2B2AE3D27D4EB4F)
    c2 = np.uint64(0x165667B19E3779F9)
    c3 = np.uint64(0xBF58476D1CE4E5B9)
    for i in range(bz.size):
        b0 = bx[i]
        b1 = by[i]
        b2 = bz[i]
        if b0 == _NEG_ZERO:
            b0 = np.uint64(0)
        if b1 == _NEG_ZERO:
            b1 = np.uint64(0)
        if b2 == _NEG_ZERO:
            b2 = np.uint64(0)
        h = (b0 * c0) ^ (b1 * c1) ^ (b2 * c2)
        h ^= h >> np.uint64(29)
        h *= c3
        h ^= h >> np.uint64(32)
        out[i] = h


@njit
def unique_rows(pts, h):
    """Group equal rows of `pts` by open addressing on their hashes `h` (int64), in O(N).

    Returns ``(first, inverse, counts)``: the first index of each distinct row in input
    order, the group of every row and the group sizes. Rows compare as floats, so -0.0
    and 0.0 are equal (the hash must agree: callers hash ``pts + 0.0``).
    """
    n = pts.shape[0]
    size = 1
    while size < 2 * n:
        size <<= 1
    mask = size - 1
    table = np.full(size, -1, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    inverse = np.empty(n, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    ng = 0
    for i in range(n):
        slot = h[i] & mask
        while True:
            g = table[slot]
            if g < 0:
                table[slot] = ng
                first[ng] = i
                counts[ng] = 1
                inverse[i] = ng
                ng += 1
                break
            j = first[g]
            if pts[j, 0] == pts[i, 0] and pts[j, 1] == pts[i, 1] and pts[j, 2] == pts[i, 2]:
                inverse[i] = g
                counts[g] += 1
                break
            slot = (slot + 1) & mask
    return first[:ng], inverse, counts[:ng]
