"""Where the terrain step's grid lies (:mod:`._terrain`): its cell on sparse points, the
empty bands it leaves out, and the filled cells that become vertices of its TIN.

The step's tests compare a cell with its neighbours, so what they need of the plane is
the cells holding points and a few rings of cells around them; a grid over the whole
bounding box would cost memory in proportion to the area, empty or not. Three rules keep
it in proportion to the points:

* **cell** (:func:`terrain_cell`): coarser only where the grid would pass 16 cells a
  point (and 262,144 cells): points four cells apart or more leave almost every cell
  alone among empty neighbours, and the neighbour tests have nothing to compare;
* **bands** (:class:`BandFrame`): rows and columns of cells farther than
  :data:`BAND_HALO` cells from every row (column) holding a point are taken out, so two
  clumps of points kilometres apart lie :data:`BAND_HALO` cells from the gap's sides.
  Every operation of the step reads at most 90 cells around a cell holding a point (the
  seeds' progressive opening, radii 1 to 9) and, for those, their nearest seed (under
  ``90 sqrt(2)`` cells away); a seed across a narrowed gap stays farther than that;
* **vertices** (:func:`near_points`): where the cells farther than :data:`VERTEX_RING`
  from every cell holding a point outnumber those (inside their box), the filled cells
  are vertices of the TIN only within that ring. Every cell holds a vertex, so a
  Delaunay triangle's empty circumcircle has a radius under ``sqrt(2)`` cells and a
  triangle holding a point has its vertices within ``2 sqrt(2)`` cells of it: the far
  vertices change no triangle under a point (but for the diagonal Qhull takes in a
  square of four co-circular centres). The triangles longer than :data:`MAX_EDGE` over
  far cells then span the empty areas, hold no point and are left out.
"""

from __future__ import annotations

import numpy as np

from .._shared._columns import column_max

__all__ = ["BAND_HALO", "CELLS_PER_POINT", "MAX_EDGE", "MIN_CELLS", "VERTEX_RING",
           "BandFrame", "near_points", "terrain_cell"]

#: Cells kept on either side of the rows and columns holding points: a narrowed gap of
#: ``2 BAND_HALO`` cells keeps a seed across it farther (``2 BAND_HALO - 90``) from the
#: cells the opening reads than their nearest seed (``90 sqrt(2)`` = 127.3).
BAND_HALO = 128
#: Rings of filled cells around the cells holding points that are vertices of the TIN
#: (a triangle holding a point reaches ``2 sqrt(2)`` cells from it).
VERTEX_RING = 3
#: Longest triangle edge of a TIN without the far cells (cells) unless its centroid lies
#: near the points: with a vertex in every cell a triangle's circumradius is under
#: ``sqrt(2)``, so its edges under ``2 sqrt(2)``, but at the grid's edge (slivers along
#: the hull); the longer ones over far cells span the empty areas the far cells left.
MAX_EDGE = 6.0
#: Most cells of the grid a point (:func:`terrain_cell`), and the fewest that are always
#: allowed.
CELLS_PER_POINT = 16
MIN_CELLS = 1 << 18


def terrain_cell(xy, cell, halo=BAND_HALO) -> float:
    """The terrain grid's cell: `cell`, or larger where the grid would pass
    :data:`CELLS_PER_POINT` cells a point (and :data:`MIN_CELLS` cells).

    The grid counted is the one the step uses (:class:`BandFrame`: the empty bands taken
    out); the cell grows by a quarter at a time until the grid fits. A grid that fine
    has points :data:`CELLS_PER_POINT` ** 0.5 cells apart or more: almost every cell
    holding a point has none among its 8 neighbours, so the neighbour tests have nothing
    to compare at either cell and the surface is the TIN of the ground points.
    """
    n = len(xy)
    cell = float(cell)
    limit = max(CELLS_PER_POINT * n, MIN_CELLS)
    if n < 2 or np.prod(np.floor(column_max(xy) / cell) + 1) <= limit:
        return cell
    while _grid_cells(xy, cell, halo) > limit:
        cell *= 1.25
    return cell


def _grid_cells(xy, cell, halo, block=1 << 20):
    """Cells of the grid of `xy` at `cell` without its empty bands."""
    sizes = (np.floor(column_max(xy) / cell).astype(np.int64) + 1).tolist()
    occupied = [np.zeros(m, bool) for m in sizes]
    for s in range(0, len(xy), block):
        for a in (0, 1):
            occupied[a][np.floor(xy[s:s + block, a] / cell).astype(np.int64)] = True
    return int(np.prod([_keep_near(o, halo).sum() for o in occupied]))


def near_points(lowest, ring=VERTEX_RING):
    """The cells that are vertices of the TIN when filled: within `ring` cells
    (Chebyshev) of a cell holding a point (finite `lowest`) when the others inside the
    box of the cells holding points outnumber those, else every cell (the far ones cost
    little then, and leaving them out would change which diagonal Qhull takes in
    squares of co-circular filled centres elsewhere)."""
    from scipy import ndimage as ndi

    have = np.isfinite(lowest)
    if have.all():
        return have
    near = ndi.maximum_filter(have, size=2 * ring + 1, mode="constant", cval=False)
    rows, cols = np.flatnonzero(have.any(axis=1)), np.flatnonzero(have.any(axis=0))
    box = near[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1] if rows.size else near
    if box.size - np.count_nonzero(box) <= np.count_nonzero(have):
        return np.ones(have.shape, bool)
    return near


def _keep_near(occupied, halo):
    """Indices within `halo` of an occupied one (1-D)."""
    c = np.r_[0, np.cumsum(occupied)]
    n = occupied.size
    i = np.arange(n)
    return c[np.minimum(i + halo + 1, n)] - c[np.maximum(i - halo, 0)] > 0


class BandFrame:
    """The grid's columns and rows without the empty bands (:data:`BAND_HALO`).

    ``shift[0][i]`` (``shift[1][j]``) is the number of columns (rows) taken out before
    column ``i`` (row ``j``); :meth:`__call__` moves a point left (down) by that many
    cells, so its cell is ``i - shift[0][i]``.

    Parameters
    ----------
    shift : tuple of two (n,) ndarrays of int64
    cell : float
    """

    def __init__(self, shift, cell):
        self.shift = shift
        self.cell = float(cell)

    @classmethod
    def of(cls, xy, cell, halo=BAND_HALO, block=1 << 20):
        """The frame of `xy` (all >= 0), or ``None`` when no band is wider than
        ``2 halo`` cells or a moved point would change cell by rounding."""
        n = len(xy)
        if n == 0:
            return None
        sizes = (np.floor(column_max(xy) / cell).astype(np.int64) + 1).tolist()
        occupied = [np.zeros(m, bool) for m in sizes]
        for s in range(0, n, block):
            for a in (0, 1):
                occupied[a][np.floor(xy[s:s + block, a] / cell).astype(np.int64)] = True
        shift = []
        for occ in occupied:
            out = ~_keep_near(occ, halo)
            shift.append(np.cumsum(out) - out)
        if not any(s[-1] for s in shift):
            return None
        frame = cls(tuple(shift), cell)
        for s in range(0, n, block):  # the cells the moved points fall in
            ij = np.floor(xy[s:s + block] / cell).astype(np.int64)
            moved = np.floor(frame(xy[s:s + block]) / cell).astype(np.int64)
            want = np.c_[ij[:, 0] - frame.shift[0][ij[:, 0]], ij[:, 1] - frame.shift[1][ij[:, 1]]]
            if not np.array_equal(moved, want):
                return None
        return frame

    def __call__(self, xy) -> np.ndarray:
        """`xy` moved into the frame (a point in a band taken out lands on the next kept
        row or column)."""
        xy = np.asarray(xy, dtype=np.float64)
        out = np.empty_like(xy)
        for a in (0, 1):
            s = self.shift[a]
            i = np.clip(np.floor(xy[:, a] / self.cell), 0, s.size - 1).astype(np.int64)
            out[:, a] = xy[:, a] - self.cell * s[i]
        return out
