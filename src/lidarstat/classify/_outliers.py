"""Low outliers: isolated points far below the surrounding lowest points (ASPRS class 7).

Ground filters that work from the lowest points (a lower envelope, a TIN of cell minima)
are pulled down by a single multipath echo metres under the terrain, and the sequential
moments of heights above such a surface are dominated by it.  Every practical filter
removes them first (Sithole & Vosselman 2004, section 2.2; SMRF and PDAL's
``filters.outlier``).  The rule here is local and data-scaled:

* the cloud is gridded with cells of about ``points_per_cell`` points (from the mean
  density), and each cell keeps its lowest point ``z1``;
* a cell's *reference* is the second-lowest of its eight neighbours' ``z1``: one or two
  low neighbours (a pair of outliers) cannot pull it down, and a ground cell at a
  building wall still has at least three ground neighbours;
* the gap ``g = reference - z1`` is about ``-slope x cell`` on a plane and small on rough
  terrain; the cells' gaps give a robust fence ``median(g) + k 1.4826 MAD(g)`` (k = 5 by
  default, about 1 false flag in 3.5 million cells for normal gaps), floored at
  ``min_depth`` so the fence never falls inside the ranging noise of very smooth scenes;
* points above the fence are flagged and the test is repeated (``iterations``) so a
  cluster of low echoes in one cell is peeled off point by point.
"""

from __future__ import annotations

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared._jit import njit

__all__ = ["low_outliers"]


@njit
def _cell_keys(xy, lo0, lo1, cell, ny):  # pragma: no cover - compiled
    """Flat cell number ``ix * ny + iy`` of every point, ``(ix, iy) = floor((xy - lo) / cell)``."""
    key = np.empty(xy.shape[0], np.int64)
    for i in range(xy.shape[0]):
        key[i] = (np.int64(np.floor((xy[i, 0] - lo0) / cell)) * ny
                  + np.int64(np.floor((xy[i, 1] - lo1) / cell)))
    return key


@njit
def _lowest_live(key, z, out, m):  # pragma: no cover - compiled
    """Per cell: the lowest z of the points not yet flagged in `out` and the index of that
    point (inf / -1 where empty); the first of equal lows is kept (in index order)."""
    z1 = np.full(m, np.inf)
    arg = np.full(m, -1, np.int64)
    for i in range(z.size):
        if out[i]:
            continue
        k = key[i]
        if z[i] < z1[k]:
            z1[k] = z[i]
            arg[k] = i
    return z1, arg


@njit
def _second_lowest_neighbour(z1):  # pragma: no cover - compiled
    """Second-lowest value among the eight neighbours of every cell (inf if < 2 filled)."""
    nx, ny = z1.shape
    out = np.empty((nx, ny))
    for i in range(nx):
        for j in range(ny):
            a = np.inf  # lowest
            b = np.inf  # second lowest
            for di in range(-1, 2):
                ii = i + di
                for dj in range(-1, 2):
                    jj = j + dj
                    if di == 0 and dj == 0:
                        continue
                    v = np.inf
                    if 0 <= ii < nx and 0 <= jj < ny:
                        v = z1[ii, jj]
                    if v < a:
                        b = a
                        a = v
                    elif v < b:
                        b = v
            out[i, j] = b
    return out


def low_outliers(xy, z, *, points_per_cell: float = 4.0, k: float = 5.0,
                 min_depth: float = 0.5, iterations: int = 3) -> np.ndarray:
    """Flag isolated points far below their neighbourhood's lowest points.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates (any origin); an (N, 3) array is read as its first two
        columns (the coordinates of a cloud without a copy of them).
    z : (N,) ndarray
        Elevations.
    points_per_cell : float, optional
        Mean points per grid cell; the cell side is ``sqrt(points_per_cell / density)``.
    k : float, optional
        Width of the robust fence in MAD-based standard deviations.
    min_depth : float, optional
        Smallest depth below the reference a flagged point must have (in z units).
    iterations : int, optional
        Passes; each pass removes at most the lowest point of each cell.

    Returns
    -------
    (N,) ndarray of bool
        True for a low outlier.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(1)
    >>> xy = g.uniform(0, 50, (5000, 2))
    >>> z = 0.1 * xy[:, 0] + g.normal(0, 0.03, 5000)
    >>> z[[10, 20]] -= [3.0, 6.0]
    >>> np.flatnonzero(low_outliers(xy, z)).tolist()
    [10, 20]
    """
    xy = np.asarray(xy, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    n = z.size
    out = np.zeros(n, bool)
    if n < 16:
        return out
    cols = xy if xy.ndim == 2 and xy.flags.c_contiguous else np.ascontiguousarray(xy)
    xy = xy[:, :2]
    lo = column_min(xy)
    span = np.maximum(column_max(xy) - lo, 1e-9)
    cell = float(np.sqrt(points_per_cell * span[0] * span[1] / n))
    if not cell > 0:
        return out
    # floor((v - lo) / cell) is monotone in v: the largest index is that of the maximum
    nx, ny = (int(np.floor((v - lo[j]) / cell)) + 1 for j, v in enumerate(column_max(xy)))
    key = _cell_keys(cols, float(lo[0]), float(lo[1]), cell, ny)  # reads columns 0 and 1
    z = np.ascontiguousarray(z)
    for _ in range(iterations):
        z1, arg = _lowest_live(key, z, out, nx * ny)
        z1, arg = z1.reshape(nx, ny), arg.reshape(nx, ny)
        ref = _second_lowest_neighbour(z1)
        ok = np.isfinite(z1) & np.isfinite(ref)
        if ok.sum() < 8:
            break
        gap = ref[ok] - z1[ok]
        med = np.median(gap)
        mad = 1.4826 * np.median(np.abs(gap - med))
        fence = max(med + k * mad, min_depth)
        bad = gap > fence
        if not bad.any():
            break
        out[arg[ok][bad]] = True
    return out
