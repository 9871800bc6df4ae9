"""Numba kernels of :func:`lidarstat.neighbors.knn_indices`: the `k` nearest of every
point of a :class:`~._query.CellIndex`, cell by cell.

The 27 cells around a cell are copied once into contiguous work arrays; each point of the
cell takes the squared distances to all of them in one pass, keeps those within a
radius from its predecessor's ``k + 1``-th distance (widened until ``k + 1`` are within
it) and inserts them into a sorted list of ``k + 1``. While the list's last distance
exceeds the radius the searched block is guaranteed to cover
(:func:`._grid_kernels._guaranteed`), the next shell of cells is inserted, so the list
is exact: the ``k + 1`` smallest squared distances, computed as
:func:`._grid_kernels._gather` computes them, equal distances in the order the cells
were visited.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ._grid_kernels import _CELL_CHUNK, _count, _guaranteed, cell_ranges

_WIDEN = 1.6  # factor of the squared radius when fewer than k + 1 candidates lie within
_TRIES = 3  # radii tried before every candidate of the block is inserted


@njit
def _block_arrays(cap):
    """Work arrays of a cell's block: x, y, z, sorted position, squared distance and the
    candidates within the radius (indices into the block)."""
    return (np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap, dtype=np.int64),
            np.empty(cap), np.empty(cap, dtype=np.int64))


@njit(inline="always")
def _insert(d, j, td, ti, s, kk):
    """Insert squared distance `d` of position `j` into the ascending list ``td[:s]``
    (with ``ti``) of at most `kk` entries, after the entries equal to it; returns the new
    length. A full list keeps its entries when `d` is not below its last."""
    if s == kk:
        if d >= td[kk - 1]:
            return s
        p = kk - 1
    else:
        p = s
        s += 1
    while p > 0 and td[p - 1] > d:
        td[p] = td[p - 1]
        ti[p] = ti[p - 1]
        p -= 1
    td[p] = d
    ti[p] = j
    return s


@njit
def _insert_cells(px, py, pz, ix, iy, z0, z1, pts, cell_keys, cell_start, dims, td, ti, s,
                  kk):  # pragma: no cover - compiled
    """:func:`_insert` every point of the cells ``z0..z1`` of column (ix, iy)."""
    base = (ix * dims[1] + iy) * dims[2]
    a = np.searchsorted(cell_keys, base + z0)
    b = np.searchsorted(cell_keys, base + z1, side="right")
    for j in range(cell_start[a], cell_start[b]):
        dx = pts[j, 0] - px
        dy = pts[j, 1] - py
        dz = pts[j, 2] - pz
        s = _insert(dx * dx + dy * dy + dz * dz, j, td, ti, s, kk)
    return s


@njit
def _shell(px, py, pz, ix0, iy0, iz0, rad, pts, cell_keys, cell_start, dims, td, ti, s,
           kk):  # pragma: no cover - compiled
    """:func:`_insert` the points of the cells at Chebyshev distance `rad` from
    (ix0, iy0, iz0): whole columns on the shell's sides, the top and bottom layers
    inside them. Returns the list's length."""
    lo = max(iz0 - rad, 0)
    hi = min(iz0 + rad, dims[2] - 1)
    for ix in range(max(ix0 - rad, 0), min(ix0 + rad, dims[0] - 1) + 1):
        for iy in range(max(iy0 - rad, 0), min(iy0 + rad, dims[1] - 1) + 1):
            if abs(ix - ix0) == rad or abs(iy - iy0) == rad:
                s = _insert_cells(px, py, pz, ix, iy, lo, hi, pts, cell_keys, cell_start,
                                  dims, td, ti, s, kk)
                continue
            if iz0 - rad >= 0:
                s = _insert_cells(px, py, pz, ix, iy, iz0 - rad, iz0 - rad, pts, cell_keys,
                                  cell_start, dims, td, ti, s, kk)
            if iz0 + rad <= dims[2] - 1:
                s = _insert_cells(px, py, pz, ix, iy, iz0 + rad, iz0 + rad, pts, cell_keys,
                                  cell_start, dims, td, ti, s, kk)
    return s


@njit_parallel
def grid_rows(c0, c1, pts, cell_keys, cell_start, dims, cell, k, tau0, order, out,
              tie):  # pragma: no cover - compiled
    """The `k` nearest (ascending distance) of the points of cells ``c0..c1-1`` into
    ``out[order[i] k:(order[i] + 1) k]`` (input indices); ``tie[order[i]]`` is 1 where two
    of the point's ``k + 1`` nearest distances are equal, else 0 (module docstring).
    `tau0` is a typical k-th neighbour distance (the first radius of a cell: speed only).
    """
    ncell = c1 - c0
    nchunks = (ncell + _CELL_CHUNK - 1) // _CELL_CHUNK
    kk = k + 1
    maxrad = max(dims[0], max(dims[1], dims[2]))
    for ch in prange(nchunks):
        ranges = np.empty((9, 2), dtype=np.int64)
        td = np.empty(kk)
        ti = np.empty(kk, dtype=np.int64)
        bx, by, bz, bj, bd, bc = _block_arrays(256)
        for c in range(c0 + ch * _CELL_CHUNK, min(c1, c0 + (ch + 1) * _CELL_CHUNK)):
            ix0, iy0, iz0, nr = cell_ranges(c, cell_keys, cell_start, dims, ranges)
            m = _count(ranges, nr)
            if m > bx.size:
                bx, by, bz, bj, bd, bc = _block_arrays(2 * m)
            q = 0
            for r in range(nr):
                for j in range(ranges[r, 0], ranges[r, 1]):
                    bx[q] = pts[j, 0]
                    by[q] = pts[j, 1]
                    bz[q] = pts[j, 2]
                    bj[q] = j
                    q += 1
            tau2 = tau0 * tau0
            for i in range(cell_start[c], cell_start[c + 1]):
                px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
                for t in range(m):
                    dx = bx[t] - px
                    dy = by[t] - py
                    dz = bz[t] - pz
                    bd[t] = dx * dx + dy * dy + dz * dz
                nq = 0
                if m >= kk:  # the candidates within the radius, widened until kk are
                    r2 = tau2
                    for _try in range(_TRIES):
                        nq = 0
                        for t in range(m):
                            bc[nq] = t
                            nq += bd[t] <= r2
                        if nq >= kk:
                            break
                        r2 *= _WIDEN
                if nq < kk:
                    for t in range(m):
                        bc[t] = t
                    nq = m
                s = 0
                for u in range(nq):
                    t = bc[u]
                    s = _insert(bd[t], bj[t], td, ti, s, kk)
                rad = 1
                while s < kk or td[kk - 1] > _guaranteed(px, py, pz, ix0, iy0, iz0, rad,
                                                         cell, dims) ** 2:
                    if rad > maxrad:
                        break
                    rad += 1
                    s = _shell(px, py, pz, ix0, iy0, iz0, rad, pts, cell_keys, cell_start,
                               dims, td, ti, s, kk)
                row = order[i] * k
                same = 0
                for t in range(k):
                    out[row + t] = order[ti[t]]
                    if td[t] == td[t + 1]:
                        same = 1
                tie[order[i]] = same
                tau2 = td[kk - 1] * 1.3225  # (1.15 r_k)^2 for the next point of the cell
