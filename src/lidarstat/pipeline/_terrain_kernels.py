"""Numba kernel of the terrain model: rasterising the triangles of a TIN onto a grid."""

from __future__ import annotations

import math

import numpy as np

from .._shared._jit import njit


@njit
def rasterize_tin(xy, z, simplices, resolution, rows, cols):  # pragma: no cover - compiled
    """Linear interpolation of `z` on the triangles at the grid's cell centres.

    `xy` is relative to the grid's top-left corner (x to the east, y to the north, so
    rows go to negative y); cell (r, c) has its centre at ``((c + 0.5) res,
    -(r + 0.5) res)``. Each triangle visits the cells of its bounding box and writes the
    barycentric interpolation where the centre lies inside it (edges included, so a
    centre on a shared edge gets the same value from either triangle). NaN elsewhere.
    """
    out = np.full((rows, cols), np.nan)
    eps = 1e-12
    for t in range(simplices.shape[0]):
        a, b, c = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        xa, ya, xb, yb, xc, yc = xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]
        det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
        if det == 0.0:
            continue
        c0 = max(int(math.ceil(min(xa, xb, xc) / resolution - 0.5)), 0)
        c1 = min(int(math.floor(max(xa, xb, xc) / resolution - 0.5)), cols - 1)
        r0 = max(int(math.ceil(-max(ya, yb, yc) / resolution - 0.5)), 0)
        r1 = min(int(math.floor(-min(ya, yb, yc) / resolution - 0.5)), rows - 1)
        tol = eps * abs(det)
        for r in range(r0, r1 + 1):
            py = -(r + 0.5) * resolution
            for col in range(c0, c1 + 1):
                px = (col + 0.5) * resolution
                w0 = ((yb - yc) * (px - xc) + (xc - xb) * (py - yc)) / det
                w1 = ((yc - ya) * (px - xc) + (xa - xc) * (py - yc)) / det
                w2 = 1.0 - w0 - w1
                if w0 >= -tol and w1 >= -tol and w2 >= -tol:
                    out[r, col] = w0 * z[a] + w1 * z[b] + w2 * z[c]
    return out
