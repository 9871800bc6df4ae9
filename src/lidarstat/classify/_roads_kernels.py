"""Numba kernel of the roads' cells (:mod:`._roads`): the bounds of a subset of rows."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit_parallel


@njit_parallel
def row_bounds(xy, rows, nblocks, out):  # pragma: no cover - compiled
    """Column minima and maxima of ``xy[rows]`` (M, 2) into ``out = (min x, min y, max
    x, max y)``, read in place (no copy of the rows), `nblocks` blocks in parallel."""
    m = rows.size
    step = (m + nblocks - 1) // nblocks
    part = np.empty((nblocks, 4))
    for b in prange(nblocks):
        l0 = l1 = np.inf
        h0 = h1 = -np.inf
        for t in range(b * step, min(m, (b + 1) * step)):
            i = rows[t]
            l0 = min(l0, xy[i, 0])
            l1 = min(l1, xy[i, 1])
            h0 = max(h0, xy[i, 0])
            h1 = max(h1, xy[i, 1])
        part[b, 0], part[b, 1], part[b, 2], part[b, 3] = l0, l1, h0, h1
    out[0], out[1] = part[:, 0].min(), part[:, 1].min()
    out[2], out[3] = part[:, 2].max(), part[:, 3].max()
