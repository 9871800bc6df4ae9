"""Compiled kernels of the ground surface's cell picks on a subset of the points, in
parallel over blocks of points and blocks of cells (:func:`~._surface.ground_surface`),
and of its TIN's bins, in parallel over blocks of triangles.

Each gives what its serial counterpart in :mod:`._surface` gives: the same keys (the same
arithmetic), the same stable order of the points by key (a counting sort whose blocks of
points keep their order inside each key) and the same pick in every cell (each cell is
worked by one thread alone); each bin lists its triangles in ascending order whatever the
blocks.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ._surface import pick_one

__all__ = ["bin_triangles", "cell_keys_where", "order_where", "pick_cells"]


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


@njit_parallel
def bin_triangles(P, simplices, ox, oy, g, nx, ny, nblocks):  # pragma: no cover - compiled
    """CSR of the triangles that meet each grid cell (``i * ny + j``, cells of side `g`
    from ``(ox, oy)``), each cell's in ascending order.

    A triangle enters the cells of its bounding box that no edge's line separates from
    it (the separating-axis test), each cell widened by a margin: 1e-6 of the
    triangle's box side plus the coordinates' rounding. A point is accepted by a
    triangle only within ``3 eps_broad`` (4.5e-8) of its diameter
    (:func:`~._surface._tin_eval`), so a triangle left out of a cell accepts no point
    located in that cell: the first triangle of a cell's list that accepts a point is
    the one the bounding boxes alone give, with fewer tried. Blocks of triangles are
    counted and filled in parallel, block after block inside each cell.
    """
    nt = simplices.shape[0]
    nc = nx * ny
    step = (nt + nblocks - 1) // nblocks
    at = np.zeros((nblocks, nc), np.int64)  # counts, then each block's next slot
    grain = 64 * np.finfo(np.float64).eps * (abs(ox) + abs(oy) + g * (nx + ny))
    indptr = np.zeros(nc + 1, np.int64)
    tri = np.empty(0, np.int64)
    for fill_in in range(2):  # count, then fill
        if fill_in:
            run = 0
            for c in range(nc):
                indptr[c] = run
                for b in range(nblocks):
                    n = at[b, c]
                    at[b, c] = run
                    run += n
            indptr[nc] = run
            tri = np.empty(run, np.int64)
        for b in prange(nblocks):
            for t in range(b * step, min(nt, (b + 1) * step)):
                _bin_one(P, simplices, t, ox, oy, g, nx, ny, grain, at[b], tri, fill_in)
    return indptr, tri


@njit
def _bin_one(P, simplices, t, ox, oy, g, nx, ny, grain, at, tri,
             fill_in):  # pragma: no cover - compiled
    """Count (or, with `fill_in`, write at ``at[c]``) triangle t in the cells it meets."""
    ax = P[simplices[t, 0], 0]
    ay = P[simplices[t, 0], 1]
    bx = P[simplices[t, 1], 0]
    by = P[simplices[t, 1], 1]
    cx = P[simplices[t, 2], 0]
    cy = P[simplices[t, 2], 1]
    xmin = min(ax, bx, cx)
    xmax = max(ax, bx, cx)
    ymin = min(ay, by, cy)
    ymax = max(ay, by, cy)
    d = 1e-6 * max(xmax - xmin, ymax - ymin) + grain
    i0 = max(0, int(np.floor((xmin - ox) / g)))
    i1 = min(nx - 1, int(np.floor((xmax - ox) / g)))
    j0 = max(0, int(np.floor((ymin - oy) / g)))
    j1 = min(ny - 1, int(np.floor((ymax - oy) / g)))
    for i in range(i0, i1 + 1):
        x0 = ox + i * g - d
        x1 = ox + (i + 1) * g + d
        for j in range(j0, j1 + 1):
            y0 = oy + j * g - d
            y1 = oy + (j + 1) * g + d
            if (_beyond(ax, ay, bx, by, cx, cy, x0, x1, y0, y1)
                    or _beyond(bx, by, cx, cy, ax, ay, x0, x1, y0, y1)
                    or _beyond(cx, cy, ax, ay, bx, by, x0, x1, y0, y1)):
                continue
            c = i * ny + j
            if fill_in:
                tri[at[c]] = t
            at[c] += 1


@njit
def _beyond(px, py, qx, qy, rx, ry, x0, x1, y0, y1):  # pragma: no cover - compiled
    """Whether the box ``[x0, x1] x [y0, y1]`` lies wholly on the far side of the line
    through p and q from r (False for a degenerate triangle: no side)."""
    nx = py - qy
    ny = qx - px
    side = nx * (rx - px) + ny * (ry - py)
    if side == 0.0 or side != side:
        return False
    if side < 0.0:
        nx = -nx
        ny = -ny
    # the corner farthest toward r's side
    far = nx * ((x1 if nx > 0.0 else x0) - px) + ny * ((y1 if ny > 0.0 else y0) - py)
    return far < 0.0
