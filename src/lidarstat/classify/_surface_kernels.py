"""Compiled kernels of the ground surface's cell picks on a subset of the points, in
parallel over blocks of points and blocks of cells (:func:`~._surface.ground_surface`).

Each gives what its serial counterpart in :mod:`._surface` gives: the same keys (the same
arithmetic), the same stable order of the points by key (a counting sort whose blocks of
points keep their order inside each key) and the same pick in every cell (each cell is
worked by one thread alone).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit_parallel
from ._surface import pick_one

__all__ = ["cell_keys_where", "order_where", "pick_cells"]


@njit_parallel
def cell_keys_where(xy, where, cell, nblocks, out):  # pragma: no cover - compiled
    """``cell_keys(xy[where], cell)`` into `out` (the origin at the subset's column
    minima, ``ix * ncol + iy``); returns the number of keys (the largest plus one)."""
    m = where.size
    step = (m + nblocks - 1) // nblocks
    lo0 = np.full(nblocks, np.inf)
    lo1 = np.full(nblocks, np.inf)
    hi1 = np.full(nblocks, -np.inf)
    for b in prange(nblocks):
        a0 = b * step
        a1 = min(m, a0 + step)
        l0 = np.inf
        l1 = np.inf
        h1 = -np.inf
        for t in range(a0, a1):
            i = where[t]
            l0 = min(l0, xy[i, 0])
            l1 = min(l1, xy[i, 1])
            h1 = max(h1, xy[i, 1])
        lo0[b] = l0
        lo1[b] = l1
        hi1[b] = h1
    ox = lo0.min()
    oy = lo1.min()
    ncol = np.int64(np.floor((hi1.max() - oy) / cell)) + 1
    top = np.zeros(nblocks, np.int64)
    for b in prange(nblocks):
        a0 = b * step
        a1 = min(m, a0 + step)
        km = np.int64(0)
        for t in range(a0, a1):
            i = where[t]
            k = (np.int64(np.floor((xy[i, 0] - ox) / cell)) * ncol
                 + np.int64(np.floor((xy[i, 1] - oy) / cell)))
            out[t] = k
            km = max(km, k)
        top[b] = km
    return top.max() + 1


@njit_parallel
def order_where(key, nkeys, where, nblocks):  # pragma: no cover - compiled
    """Stable counting sort of `key` (0 <= key < nkeys) carried to the rows `where`:
    ``(where[order], starts)`` with ``order``, ``starts`` as ``cell_order(key)``."""
    m = key.size
    step = (m + nblocks - 1) // nblocks
    at = np.zeros((nkeys, nblocks), np.int64)  # counts, then each block's next slot
    for b in prange(nblocks):
        a0 = b * step
        a1 = min(m, a0 + step)
        for t in range(a0, a1):
            at[key[t], b] += 1
    nz = 0
    run = 0
    for k in range(nkeys):
        first = run
        for b in range(nblocks):
            c = at[k, b]
            at[k, b] = run
            run += c
        if run > first:
            nz += 1
    starts = np.empty(nz + 1, np.int64)
    j = 0
    for k in range(nkeys):
        end = at[k + 1, 0] if k + 1 < nkeys else m
        if end > at[k, 0]:
            starts[j] = at[k, 0]
            j += 1
    starts[nz] = m
    rows = np.empty(m, np.int64)
    for b in prange(nblocks):
        a0 = b * step
        a1 = min(m, a0 + step)
        for t in range(a0, a1):
            k = key[t]
            p = at[k, b]
            rows[p] = where[t]
            at[k, b] = p + 1
    return rows, starts


@njit_parallel
def pick_cells(order, z, starts, which_median, rank, nblocks):  # pragma: no cover - compiled
    """``_pick_per_cell`` with the cells in `nblocks` blocks worked in parallel."""
    m = starts.size - 1
    out = np.empty(m, np.int64)
    step = (m + nblocks - 1) // nblocks
    for b in prange(nblocks):
        c0 = b * step
        c1 = min(m, c0 + step)
        big = 0
        for c in range(c0, c1):
            big = max(big, starts[c + 1] - starts[c])
        buf = np.empty(big, np.int64)
        for c in range(c0, c1):
            out[c] = pick_one(order, starts[c], starts[c + 1], z, which_median, rank, buf)
    return out
