"""Numba kernels of the fused neighbour search and quadric fit over the cells of a grid.

The neighbours of a point of an occupied cell are among the points of the 27 cells around
it, the same candidates for every point of the cell. So each cell gathers its candidates
once into contiguous columns (x, y, z), and each of its points then

1. computes the squared distance to every candidate in one elementwise loop over those
   columns (vector lanes: no branch, no indirect load);
2. keeps the positions and squared distances of the candidates within the search
   radius, branch-free (each is stored, the count advances only for those inside);
3. forms the tricube weights of those neighbours (square roots included) in one
   elementwise loop, then their offsets, into the four columns that
   :func:`._quadric_kernels._fit_local` fits from, in the candidates' order (the grid's
   order of the 27 cells, as the CSR search gives them).

The offsets and distances are those the CSR path computes from the same coordinates, bit
for bit; the fit is :func:`._quadric_kernels._fit_local`, as for CSR neighbourhoods.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ..neighbors import grid_candidate_count, grid_cell_ranges
from ._quadric_kernels import _fit_local, _quadric_skip, _workspace, finish_row

#: Occupied cells per parallel iteration (threads take them as they are free)
_CELL_CHUNK = 64


@njit
def gather(pts, ranges, nr, cand):
    """The points of the sorted-position `ranges` into rows 0-2 of `cand` (x, y, z), in
    order; returns their number."""
    m = 0
    for t in range(nr):
        for j in range(ranges[t, 0], ranges[t, 1]):
            cand[0, m] = pts[j, 0]
            cand[1, m] = pts[j, 1]
            cand[2, m] = pts[j, 2]
            m += 1
    return m


@njit
def within(px, py, pz, cand, m, r2, sel, d2s):
    """The candidates of `cand` within sqrt(`r2`) of the point (px, py, pz): row 3 of
    `cand` receives the squared distances of its `m` candidates, `sel` the positions of
    those inside and `d2s` their squared distances, in order; returns their number."""
    X = cand[0]
    Y = cand[1]
    Z = cand[2]
    D = cand[3]
    for k in range(m):  # elementwise: vector lanes
        dx = X[k] - px
        dy = Y[k] - py
        dz = Z[k] - pz
        d2 = dx * dx + dy * dy
        d2 += dz * dz
        D[k] = d2
    n = 0
    for k in range(m):  # branch-free: the test's outcome is never mispredicted
        d2 = D[k]
        sel[n] = k
        d2s[n] = d2
        n += d2 <= r2
    return n


@njit
def neighbour_columns(px, py, pz, cand, sel, n, bw, cols):
    """The offsets (rows 0-2 of `cols`) and tricube weights (row 3, which holds their
    squared distances from :func:`within`) of the `n` neighbours ``sel[:n]``, for the
    bandwidth `bw` (<= 0: the farthest neighbour's distance); a neighbour at the
    bandwidth or beyond gets weight 0 (it adds nothing to any sum of the fit). Returns
    (p, b): the neighbours closer than the bandwidth and the bandwidth."""
    X = cand[0]
    Y = cand[1]
    Z = cand[2]
    W = cols[3]
    b = bw
    if b <= 0.0:
        for t in range(n):
            d = np.sqrt(W[t])
            if d > b:
                b = d
    inv_b = 1.0 / b
    p = 0
    for t in range(n):  # elementwise: vector lanes (square roots included)
        d = np.sqrt(W[t])
        g = d * inv_b  # the tricube weight, by a product (no division)
        g = 1.0 - g * g * g
        w = g * g * g
        inside = d < b
        W[t] = w if inside & (w > 0.0) else 0.0
        p += inside
    D0 = cols[0]
    D1 = cols[1]
    D2 = cols[2]
    for t in range(n):
        k = sel[t]
        D0[t] = X[k] - px
        D1[t] = Y[k] - py
        D2[t] = Z[k] - pz
    return p, b


@njit_parallel
def fit_quadrics_cells(c0, c1, pts, cell_keys, cell_start, dims, radius, active, params, outs):
    """Fused neighbour search (3-D sphere of `radius`) and quadric fit of the points of
    the occupied cells ``c0..c1-1`` of a :class:`lidarstat.neighbors.CellIndex`.

    Output row r is sorted position ``cell_start[c0] + r``; points with ``active[i] == 0``
    get status SKIPPED and NaN outputs. ``params`` (bandwidth, frame, sensor, has_sensor,
    min_neighbors, covariance mode) and ``outs`` (status, npts, beta, cof, frames, stats)
    as ``_quadric_kernels._quadric_point``'s.
    """
    bw, frame, sensor, has_sensor, min_nb, cov_mode = params
    base = cell_start[c0]
    r2 = radius * radius
    ncell = c1 - c0
    nchunks = (ncell + _CELL_CHUNK - 1) // _CELL_CHUNK
    for ch in prange(nchunks):
        ws = _workspace()
        ranges = np.empty((9, 2), dtype=np.int64)
        cap = 256
        cand = np.empty((4, cap))
        cols = np.empty((4, cap))
        sel = np.empty(cap, dtype=np.int32)
        for c in range(c0 + ch * _CELL_CHUNK, min(c1, c0 + (ch + 1) * _CELL_CHUNK)):
            nr = grid_cell_ranges(c, cell_keys, cell_start, dims, 3, ranges)
            need = grid_candidate_count(ranges, nr)
            if need > cap:
                cap = max(need, 2 * cap)
                cand = np.empty((4, cap))
                cols = np.empty((4, cap))
                sel = np.empty(cap, dtype=np.int32)
            m = gather(pts, ranges, nr, cand)
            for i in range(cell_start[c], cell_start[c + 1]):
                r = i - base
                if active[i] == 0:
                    _quadric_skip(r, outs)
                    continue
                px = pts[i, 0]
                py = pts[i, 1]
                pz = pts[i, 2]
                n = within(px, py, pz, cand, m, r2, sel, cols[3])
                p, b = neighbour_columns(px, py, pz, cand, sel, n, bw, cols)
                st, p = _fit_local(cols, n, p, px, py, pz, b, frame, sensor, has_sensor,
                                   min_nb, cov_mode, ws, r, outs[2], outs[3], outs[4], outs[5])
                finish_row(r, st, p, outs)
