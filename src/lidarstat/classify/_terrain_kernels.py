"""Compiled per-point loops of the terrain step (:mod:`._terrain`)."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

__all__ = ["cell_lowest", "grid_bilinear"]


@njit
def cell_lowest(xy, z, ground, cell, nx, ny):  # pragma: no cover - compiled
    """Lowest point of every cell and lowest ground point of every cell (``inf`` if none).

    Returns ``(lowest, lowest_ground)``, two ``(nx, ny)`` arrays.
    """
    low = np.full((nx, ny), np.inf)
    low_g = np.full((nx, ny), np.inf)
    for i in range(z.size):
        ix = min(max(np.int64(np.floor(xy[i, 0] / cell)), 0), nx - 1)
        iy = min(max(np.int64(np.floor(xy[i, 1] / cell)), 0), ny - 1)
        low[ix, iy] = min(low[ix, iy], z[i])
        if ground[i] and z[i] < low_g[ix, iy]:
            low_g[ix, iy] = z[i]
    return low, low_g


@njit_parallel
def grid_bilinear(xy, grid, cell, out):  # pragma: no cover - compiled
    """Bilinear interpolation of a grid of cell-centre values at every point (edges
    clamped), written to `out`."""
    nx, ny = grid.shape
    for i in prange(xy.shape[0]):
        u = xy[i, 0] / cell - 0.5
        v = xy[i, 1] / cell - 0.5
        u = min(max(u, 0.0), nx - 1.0)
        v = min(max(v, 0.0), ny - 1.0)
        i0 = min(np.int64(np.floor(u)), nx - 2) if nx > 1 else 0
        j0 = min(np.int64(np.floor(v)), ny - 2) if ny > 1 else 0
        i1 = min(i0 + 1, nx - 1)
        j1 = min(j0 + 1, ny - 1)
        fu = u - i0
        fv = v - j0
        out[i] = ((1 - fu) * (1 - fv) * grid[i0, j0] + fu * (1 - fv) * grid[i1, j0]
                  + (1 - fu) * fv * grid[i0, j1] + fu * fv * grid[i1, j1])
