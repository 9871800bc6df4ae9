"""Compiled per-point loops of the terrain step (:mod:`._terrain`)."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

__all__ = ["block_spread", "cell_lowest", "cell_values", "fill_triangles", "first_on_surface",
           "gather_cells", "grid_bilinear"]


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


@njit
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


@njit
def fill_triangles(tri, ij, val, grid, empty):  # pragma: no cover - compiled
    """Linear interpolation inside every triangle of a triangulation of grid cells.

    ``tri`` (T, 3) vertex indices into ``ij`` (integer cell indices, as float) holding
    ``val``; every cell of ``empty`` inside a triangle (edges included) gets the linear
    interpolation of the triangle's vertex values, written to ``grid``; cells outside every
    triangle are left as they are. Visits the cells of each triangle's bounding box, so
    the cost is the triangles' area, not (holes x triangles) as a point location is.
    """
    nx, ny = grid.shape
    for t in range(tri.shape[0]):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        x0, y0 = ij[a, 0], ij[a, 1]
        x1, y1 = ij[b, 0], ij[b, 1]
        x2, y2 = ij[c, 0], ij[c, 1]
        det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if det == 0.0:
            continue
        lo_i = max(np.int64(min(x0, x1, x2)), 0)
        hi_i = min(np.int64(max(x0, x1, x2)), nx - 1)
        lo_j = max(np.int64(min(y0, y1, y2)), 0)
        hi_j = min(np.int64(max(y0, y1, y2)), ny - 1)
        for i in range(lo_i, hi_i + 1):
            for j in range(lo_j, hi_j + 1):
                if not empty[i, j]:
                    continue
                l0 = ((y1 - y2) * (i - x2) + (x2 - x1) * (j - y2)) / det
                l1 = ((y2 - y0) * (i - x2) + (x0 - x2) * (j - y2)) / det
                l2 = 1.0 - l0 - l1
                eps = -1e-9
                if l0 >= eps and l1 >= eps and l2 >= eps:
                    grid[i, j] = l0 * val[a] + l1 * val[b] + l2 * val[c]
                    empty[i, j] = False


@njit_parallel
def block_spread(offsets, values, nx, ny, cells, min_points, max_radius, centre,
                 spread):  # pragma: no cover - compiled
    """Median and robust standard deviation (1.4826 MAD) of the values of a block of
    cells around each cell of `cells`.

    ``values`` are sorted by cell (flat index ``i * ny + j``) with ``offsets`` (``nx * ny
    + 1``) their CSR offsets. The block of cell ``(i, j)`` is the ``(2w + 1)``-cell square
    around it, ``w`` the smallest radius up to `max_radius` holding at least `min_points`
    values. ``centre[c]`` and ``spread[c]`` are written for every ``c`` of `cells`
    (NaN with fewer than 3 values within `max_radius`).
    """
    for t in prange(cells.size):
        c = cells[t]
        i = c // ny
        j = c % ny
        n = 0
        w = 1
        while True:
            n = 0
            for a in range(max(0, i - w), min(nx, i + w + 1)):
                n += offsets[a * ny + min(ny - 1, j + w) + 1] - offsets[a * ny + max(0, j - w)]
            if n >= min_points or w >= max_radius:
                break
            w += 1
        if n < 3:
            centre[c] = np.nan
            spread[c] = np.nan
            continue
        buf = np.empty(n)
        k = 0
        for a in range(max(0, i - w), min(nx, i + w + 1)):
            lo = offsets[a * ny + max(0, j - w)]
            hi = offsets[a * ny + min(ny - 1, j + w) + 1]
            for q in range(lo, hi):
                buf[k] = values[q]
                k += 1
        m = np.median(buf)
        centre[c] = m
        spread[c] = 1.4826 * np.median(np.abs(buf - m))


@njit
def _flat_cell(x, y, cell, ny, ncells):  # pragma: no cover - compiled
    """Flat cell ``floor(x / cell) * ny + floor(y / cell)`` clipped to ``[0, ncells)``."""
    c = np.int64(np.floor(x / cell)) * ny + np.int64(np.floor(y / cell))
    return min(max(c, 0), ncells - 1)


@njit
def cell_values(xy, height, ground, cell, nx, ny):  # pragma: no cover - compiled
    """The heights of the ground points that are not surface vertices (``height != 0``),
    sorted by flat cell (input order inside a cell), their CSR offsets (``nx * ny + 1``)
    and whether each cell holds a ground point: ``(offsets, values, has_ground)``.

    The counting sort of the flat keys ``floor(x / cell) * ny + floor(y / cell)``
    (clipped to the grid) without an array of keys.
    """
    ncells = nx * ny
    offsets = np.zeros(ncells + 1, np.int64)
    has_ground = np.zeros(ncells, np.bool_)
    for i in range(height.size):
        if ground[i]:
            c = _flat_cell(xy[i, 0], xy[i, 1], cell, ny, ncells)
            has_ground[c] = True
            if height[i] != 0:
                offsets[c + 1] += 1
    for c in range(ncells):
        offsets[c + 1] += offsets[c]
    values = np.empty(offsets[ncells])
    fill = offsets[:ncells].copy()
    for i in range(height.size):
        if ground[i] and height[i] != 0:
            c = _flat_cell(xy[i, 0], xy[i, 1], cell, ny, ncells)
            values[fill[c]] = height[i]
            fill[c] += 1
    return offsets, values, has_ground


@njit_parallel
def gather_cells(xy, cell, ny, centre, spread, fence, out):  # pragma: no cover - compiled
    """``centre + fence * spread`` of every point's flat cell (``inf`` where that is not
    finite), written to `out`."""
    ncells = centre.size
    for i in prange(out.size):
        c = _flat_cell(xy[i, 0], xy[i, 1], cell, ny, ncells)
        b = centre[c] + fence * spread[c]
        out[i] = b if np.isfinite(b) else np.inf


@njit
def first_on_surface(xy, z, surface, cell):  # pragma: no cover - compiled
    """In cell order, the first point of every cell of `surface` (``(nx, ny)``, ``inf``
    where empty) whose elevation is the cell's value (cell indices clamped to the grid).
    """
    nx, ny = surface.shape
    first = np.full(nx * ny, -1, np.int64)
    for i in range(z.size):
        ix = min(max(np.int64(np.floor(xy[i, 0] / cell)), 0), nx - 1)
        iy = min(max(np.int64(np.floor(xy[i, 1] / cell)), 0), ny - 1)
        c = ix * ny + iy
        if first[c] < 0 and z[i] == surface[ix, iy]:
            first[c] = i
    m = 0
    for c in range(first.size):
        if first[c] >= 0:
            m += 1
    out = np.empty(m, np.int64)
    m = 0
    for c in range(first.size):
        if first[c] >= 0:
            out[m] = first[c]
            m += 1
    return out
