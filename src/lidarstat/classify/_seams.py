"""Window cuts interpolated between windows, so no class step appears at a window border.

Every (sub-)window of the progressive method decides one height cut. Applied as a step
function, two neighbouring windows with cuts of 0.4 m and 1.2 m split a hedge of 0.8 m
exactly along their common border. As in adaptive thresholding (local thresholds
interpolated bilinearly between tile centres, e.g. CLAHE, Zuiderveld 1994), the cut of a
point here is the bilinear interpolation of per-cell cuts between cell centres:

* the cells are the finest windows the progressive split can reach (16 m by default), on the
  grid of the root windows; a cell's cut is the cut of the points in it (the mean when the
  cell straddles windows with different cuts);
* a point's cut is ``sum_c w_c cut_c / sum_c w_c`` over the four cell centres around it
  (bilinear weights ``w_c``; empty cells and cells without a cut are left out and the
  weights renormalised), so the cut is continuous and piecewise bilinear. Inside a window
  more than half a cell from any border with another cut it is the window's own cut,
  exactly (equal values are not averaged, so no rounding moves a tie);
* a point whose window found no cut at all (a root window that does not separate: all of it
  ground) keeps that decision; those windows do not enter their neighbours' interpolation.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ._terrain_frame import BandFrame

__all__ = ["interpolate_cuts"]


def interpolate_cuts(xy, cut, cell: float, frame=False) -> np.ndarray:
    """Per-point cuts interpolated bilinearly between the centres of ``cell`` squares.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates, with the origin at the corner of the window grid.
    cut : (N,) ndarray
        Each point's window cut (``inf`` where the window found none).
    cell : float
        Side of the interpolation cells (the finest window size).
    frame : BandFrame or None, optional
        ``BandFrame.of(xy, cell)`` when the caller has it (None: `xy` is already in
        its frame, or the frame is the whole grid).

    Returns
    -------
    (N,) ndarray of float64
        Continuous cuts; ``inf`` kept where the point's own cut is ``inf``.

    Examples
    --------
    >>> xy = np.c_[[4.0, 12.0, 16.0, 20.0, 28.0], np.full(5, 4.0)]
    >>> cut = np.array([1.0, 1.0, 3.0, 3.0, 3.0])  # two 16 m windows, border at x = 16
    >>> interpolate_cuts(xy, cut, 16.0).tolist()
    [1.0, 1.5, 2.0, 2.5, 3.0]
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    cut = np.ascontiguousarray(cut, dtype=np.float64)
    out = np.empty(cut.size)
    if not cut.size:
        return out
    # the grid without the empty bands of cells (:class:`~._terrain_frame.BandFrame`):
    # a point reads the four cells around it, none across a narrowed gap
    if frame is False:
        frame = BandFrame.of(xy, cell)
    if frame is not None:
        xy = frame(xy)
    nx = int(np.floor(xy[:, 0].max() / cell)) + 1
    ny = int(np.floor(xy[:, 1].max() / cell)) + 1
    grid = _cell_cuts(xy, cut, float(cell), nx, ny)
    _bilinear(xy, cut, float(cell), grid, nx, ny, out)
    return out


@njit
def _cell_cuts(xy, cut, cell, nx, ny):  # pragma: no cover - compiled
    """Cut of every cell: the common cut of its points, their mean if they differ, NaN
    when the cell holds no finite cut."""
    total = np.zeros(nx * ny)
    count = np.zeros(nx * ny, np.int64)
    lo = np.full(nx * ny, np.inf)
    hi = np.full(nx * ny, -np.inf)
    for i in range(cut.size):
        c = cut[i]
        if not np.isfinite(c):
            continue
        ix = min(max(np.int64(np.floor(xy[i, 0] / cell)), 0), nx - 1)
        iy = min(max(np.int64(np.floor(xy[i, 1] / cell)), 0), ny - 1)
        k = ix * ny + iy
        total[k] += c
        count[k] += 1
        lo[k] = min(lo[k], c)
        hi[k] = max(hi[k], c)
    grid = np.full(nx * ny, np.nan)
    for k in range(nx * ny):
        if count[k] > 0:
            grid[k] = lo[k] if lo[k] == hi[k] else total[k] / count[k]
    return grid


@njit_parallel
def _bilinear(xy, cut, cell, grid, nx, ny, out):  # pragma: no cover - compiled
    for i in prange(cut.size):
        if not np.isfinite(cut[i]):
            out[i] = cut[i]
            continue
        fx = xy[i, 0] / cell - 0.5
        fy = xy[i, 1] / cell - 0.5
        i0 = np.int64(np.floor(fx))
        j0 = np.int64(np.floor(fy))
        tx = fx - i0
        ty = fy - j0
        acc = 0.0
        wsum = 0.0
        vmin = np.inf
        vmax = -np.inf
        for a in range(2):
            ii = i0 + a
            if ii < 0 or ii >= nx:
                continue
            wx = tx if a == 1 else 1.0 - tx
            for b in range(2):
                jj = j0 + b
                if jj < 0 or jj >= ny:
                    continue
                v = grid[ii * ny + jj]
                if not np.isfinite(v):
                    continue
                w = wx * (ty if b == 1 else 1.0 - ty)
                if w <= 0.0:
                    continue
                acc += w * v
                wsum += w
                vmin = min(vmin, v)
                vmax = max(vmax, v)
        if wsum <= 0.0:
            out[i] = cut[i]
        elif vmin == vmax:  # one value around: exactly it
            out[i] = vmin
        else:
            out[i] = acc / wsum
