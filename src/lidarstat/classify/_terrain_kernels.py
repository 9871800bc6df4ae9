"""Compiled per-point loops of the terrain step (:mod:`._terrain`)."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

__all__ = ["block_spread", "cell_lowest", "cell_values", "fence_test", "fill_triangles",
           "first_on_surface", "gather_cells", "grid_bilinear", "height_test"]


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
def _bilinear(grid, cell, x, y):  # pragma: no cover - compiled
    """Bilinear interpolation of a grid of cell-centre values at ``(x, y)`` (edges
    clamped)."""
    nx, ny = grid.shape
    u = x / cell - 0.5
    v = y / cell - 0.5
    u = min(max(u, 0.0), nx - 1.0)
    v = min(max(v, 0.0), ny - 1.0)
    i0 = min(np.int64(np.floor(u)), nx - 2) if nx > 1 else 0
    j0 = min(np.int64(np.floor(v)), ny - 2) if ny > 1 else 0
    i1 = min(i0 + 1, nx - 1)
    j1 = min(j0 + 1, ny - 1)
    fu = u - i0
    fv = v - j0
    return ((1 - fu) * (1 - fv) * grid[i0, j0] + fu * (1 - fv) * grid[i1, j0]
            + (1 - fu) * fv * grid[i0, j1] + fu * fv * grid[i1, j1])


@njit
def grid_bilinear(xy, grid, cell, out):  # pragma: no cover - compiled
    """Bilinear interpolation of a grid of cell-centre values at every point (edges
    clamped), written to `out`."""
    for i in range(xy.shape[0]):
        out[i] = _bilinear(grid, cell, xy[i, 0], xy[i, 1])


@njit_parallel
def height_test(xy, z, surface, slope, cell, slope_tolerance, tolerance, below, height,
                upper, keep):  # pragma: no cover - compiled
    """The terrain test of every point: ``height = round(z - surface, 6)``, ``upper =
    tolerance + s slope`` and ``keep = -(below + s slope) <= height <= upper``, ``slope``
    the bilinear interpolation of the `slope` grid at `xy` (``s = slope_tolerance``)."""
    for i in prange(z.size):
        extra = slope_tolerance * _bilinear(slope, cell, xy[i, 0], xy[i, 1])
        h = np.rint((z[i] - surface[i]) * 1e6) / 1e6  # np.round(., 6)
        u = tolerance + extra
        height[i] = h
        upper[i] = u
        keep[i] = h <= u and h >= -(below + extra)


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


@njit
def _select(a, lo, hi, k):  # pragma: no cover - compiled
    """Reorder ``a[lo:hi + 1]`` so that ``a[k]`` is its ``k - lo``-th smallest value, the
    smaller ones before it and the larger after (quickselect, median-of-three pivot)."""
    while hi > lo:
        mid = (lo + hi) >> 1
        if a[mid] < a[lo]:
            a[lo], a[mid] = a[mid], a[lo]
        if a[hi] < a[mid]:
            a[hi], a[mid] = a[mid], a[hi]
            if a[mid] < a[lo]:
                a[lo], a[mid] = a[mid], a[lo]
        pivot = a[mid]
        i = lo
        j = hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while pivot < a[j]:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return


@njit
def _median_of(a, s, below, n):  # pragma: no cover - compiled
    """Median of `n` values of which `below` are smaller than all of ``a[:s]`` and
    ``n - below - s`` larger (:func:`_holds_median`), as ``np.median`` gives it; `a`
    reordered."""
    half = n >> 1
    if n & 1:
        k = half - below
        _select(a, 0, s - 1, k)
        return a[k]
    k = half - 1 - below
    _select(a, 0, s - 1, k)
    hi = a[k + 1]
    for q in range(k + 2, s):
        hi = min(hi, a[q])
    return (a[k] + hi) / 2


@njit
def _holds_median(below, s, n):  # pragma: no cover - compiled
    """Whether the middle value(s) of `n` sorted values lie among ``s`` of them that
    follow the `below` smallest."""
    half = n >> 1
    first = half if n & 1 else half - 1
    return below <= first and half < below + s


@njit
def _scan_block(values, offsets, nx, ny, i, j, w, dist, origin, lo, hi,
                tmp):  # pragma: no cover - compiled
    """Over the values ``v`` of the block of radius `w` around cell ``(i, j)``, ``x =
    |v - origin|`` when `dist`, else ``v``: how many ``x < lo``, and the ``x`` within
    ``[lo, hi]`` copied to `tmp` (which holds the whole block): ``(below, inside)``."""
    below = 0
    s = 0
    for a in range(max(0, i - w), min(nx, i + w + 1)):
        for q in range(offsets[a * ny + max(0, j - w)], offsets[a * ny + min(ny - 1, j + w) + 1]):
            x = abs(values[q] - origin) if dist else values[q]
            below += x < lo
            tmp[s] = x  # kept when within the range (no branch to mispredict)
            s += (x >= lo) & (x <= hi)
    return below, s


@njit
def _block_median(values, offsets, nx, ny, i, j, w, n, dist, origin, guess, width,
                  buf):  # pragma: no cover - compiled
    """Median of the block's ``x`` (:func:`_scan_block`): first among those within
    `width` of `guess` (a neighbouring block's), all of them when that range misses it
    or `width` is NaN."""
    if not np.isnan(width):
        below, s = _scan_block(values, offsets, nx, ny, i, j, w, dist, origin,
                               guess - width, guess + width, buf)
        if _holds_median(below, s, n):
            return _median_of(buf, s, below, n)
    _, s = _scan_block(values, offsets, nx, ny, i, j, w, dist, origin, -np.inf, np.inf, buf)
    return _median_of(buf, s, 0, n)


#: Consecutive cells of :func:`block_spread` run by one thread, each guessing from the
#: one before.
_CHUNK = 64


@njit_parallel
def block_spread(offsets, values, nx, ny, cells, min_points, max_radius, centre,
                 spread):  # pragma: no cover - compiled
    """Median and robust standard deviation (1.4826 MAD) of the values of a block of
    cells around each cell of `cells`.

    ``values`` (finite) are sorted by cell (flat index ``i * ny + j``) with ``offsets``
    (``nx * ny + 1``) their CSR offsets. The block of cell ``(i, j)`` is the
    ``(2w + 1)``-cell square around it, ``w`` the smallest radius up to `max_radius`
    holding at least `min_points` values. ``centre[c]`` and ``spread[c]`` are written for
    every ``c`` of `cells` (NaN with fewer than 3 values within `max_radius`).

    Both medians are exact order statistics, selected first among the values near the
    previous cell's (a neighbour's block shares most of its values): the median within
    0.3 of the previous MAD of the previous median, the MAD within 0.15 of it. The count
    of the values under that range tells whether the middle ones lie in it; when they do
    not, they are selected among all the block's values.
    """
    for t in prange((cells.size + _CHUNK - 1) // _CHUNK):
        buf = np.empty(512)
        m_prev = np.nan
        mad_prev = np.nan
        for r in range(t * _CHUNK, min(cells.size, (t + 1) * _CHUNK)):
            c = cells[r]
            i = c // ny
            j = c % ny
            n = 0
            w = 1
            while True:
                n = 0
                for a in range(max(0, i - w), min(nx, i + w + 1)):
                    n += (offsets[a * ny + min(ny - 1, j + w) + 1]
                          - offsets[a * ny + max(0, j - w)])
                if n >= min_points or w >= max_radius:
                    break
                w += 1
            if n < 3:
                centre[c] = np.nan
                spread[c] = np.nan
                continue
            if n > buf.size:
                buf = np.empty(2 * n)
            m = _block_median(values, offsets, nx, ny, i, j, w, n, False, 0.0, m_prev,
                              0.3 * mad_prev, buf)
            mad = _block_median(values, offsets, nx, ny, i, j, w, n, True, m, mad_prev,
                                0.15 * mad_prev, buf)
            centre[c] = m
            spread[c] = 1.4826 * mad
            m_prev = m
            mad_prev = mad


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


@njit_parallel
def fence_test(xy, cell, ny, centre, spread, fence, slope, slope_tolerance, height, upper,
               keep):  # pragma: no cover - compiled
    """The noise fence over every point: ``upper = min(upper, bound + s slope)`` and
    ``keep &= height <= upper``, ``bound`` the point's cell's ``centre + fence * spread``
    (``inf`` where that is not finite, as :func:`gather_cells`) and ``slope`` the
    bilinear interpolation of the `slope` grid (``s = slope_tolerance``; NaN as
    ``np.minimum``)."""
    ncells = centre.size
    for i in prange(height.size):
        c = _flat_cell(xy[i, 0], xy[i, 1], cell, ny, ncells)
        b = centre[c] + fence * spread[c]
        if not np.isfinite(b):
            b = np.inf
        v = b + slope_tolerance * _bilinear(slope, cell, xy[i, 0], xy[i, 1])
        u = upper[i]
        if np.isnan(u) or np.isnan(v):
            u = np.nan
        elif v < u:
            u = v
        upper[i] = u
        keep[i] = keep[i] and height[i] <= u


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
