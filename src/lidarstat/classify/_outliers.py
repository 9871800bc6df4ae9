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
def _lowest(key, z, m):  # pragma: no cover - compiled
    z1 = np.full(m, np.inf)
    arg = np.full(m, -1, np.int64)
    for i in range(key.size):
        k = key[i]
        if z[i] < z1[k]:  # strict: the first of equal lows is kept, as np.lexsort((z, key))
            z1[k] = z[i]
            arg[k] = i
    return z1, arg


def _cell_lowest(ij, z, shape):
    """Per cell: the lowest z and the index of that point (inf / -1 where empty); O(N)."""
    key = np.ascontiguousarray(ij[:, 0] * shape[1] + ij[:, 1])
    z1, arg = _lowest(key, np.ascontiguousarray(z, dtype=np.float64), shape[0] * shape[1])
    return z1.reshape(shape), arg.reshape(shape)


def _second_lowest_neighbour(z1):
    """Second-lowest value among the eight neighbours of every cell (inf if < 2 filled)."""
    p = np.pad(z1, 1, constant_values=np.inf)
    nx, ny = z1.shape
    stack = np.stack([p[1 + dx:1 + dx + nx, 1 + dy:1 + dy + ny]
                      for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy])
    return np.partition(stack, 1, axis=0)[1]


def low_outliers(xy, z, *, points_per_cell: float = 4.0, k: float = 5.0,
                 min_depth: float = 0.5, iterations: int = 3) -> np.ndarray:
    """Flag isolated points far below their neighbourhood's lowest points.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates (any origin).
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
    lo = column_min(xy)
    span = np.maximum(column_max(xy) - lo, 1e-9)
    cell = float(np.sqrt(points_per_cell * span[0] * span[1] / n))
    if not cell > 0:
        return out
    ij_all = np.floor((xy - lo) / cell).astype(np.int64)
    shape = tuple(column_max(ij_all) + 1)
    for _ in range(iterations):
        live = np.flatnonzero(~out)
        z1, arg = _cell_lowest(ij_all[live], z[live], shape)
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
        out[live[arg[ok][bad]]] = True
    return out
