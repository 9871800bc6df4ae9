"""Terrain models: a raster of the ground surface from classified points.

The surface is the linear interpolation on the Delaunay triangulation (a TIN) of the
ground points (ASPRS 2 and 11 unless told otherwise), sampled at the centres of a grid
whose cell edges are multiples of the resolution, so that the rasters of neighbouring
tiles share one grid and mosaic without resampling. Cells outside the convex hull of the
ground points have no value (NaN); under buildings and other objects the TIN bridges the
gap between the surrounding ground points, as lidR's ``rasterize_terrain(tin())`` and
PDAL's ``filters.delaunay`` + ``writers.raster`` do.

In a catalogue each tile's model is computed from the ground points of the tile *and its
buffer* and covers the tile's extent, so the triangles near the tile's border are those of
the whole area whenever the buffer holds the ground points they are made of.

The triangulation is :func:`lidarstat.neighbors.delaunay_triangles` (the sweep-hull
insertion, about 140 bytes a point while it is built). Above
:data:`TIN_BLOCK_POINTS` ground points the raster is built block by block, each
block from the ground within a margin of it; a cell takes its value only from a triangle
whose circumcircle lies inside the margin, which is a triangle of the whole
triangulation, and the other cells are done again with twice the margin. The raster is
the whole triangulation's (for ground points in general position: four points on one
circle can be triangulated either way), with the memory of one block.
"""

from __future__ import annotations

import math

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidPointsError
from ..io import Raster
from ..neighbors import delaunay_triangles, find_duplicates
from ._terrain_kernels import rasterize_tin

__all__ = ["GROUND_CODES_DTM", "TIN_BLOCK_POINTS", "terrain_model"]

#: ASPRS classes taken as ground: bare earth (2) and road surface (11).
GROUND_CODES_DTM = (2, 11)

#: Ground points above which :func:`terrain_model` triangulates block by block.
TIN_BLOCK_POINTS = 250_000


def _grid(bounds, resolution):
    x0, y0, x1, y1 = bounds
    left = math.floor(x0 / resolution) * resolution
    bottom = math.floor(y0 / resolution) * resolution
    right = max(math.ceil(x1 / resolution) * resolution, left + resolution)
    top = max(math.ceil(y1 / resolution) * resolution, bottom + resolution)
    cols = round((right - left) / resolution)
    rows = round((top - bottom) / resolution)
    return left, top, rows, cols


def terrain_model(xyz, classification, *, resolution: float, bounds=None,
                  ground_codes=GROUND_CODES_DTM, crs: str | None = None,
                  block_points: int = TIN_BLOCK_POINTS) -> Raster:
    """A raster of the ground surface (TIN of the ground points) at `resolution`.

    Parameters
    ----------
    xyz : array_like, shape (N, 3)
    classification : array_like of int, shape (N,)
        ASPRS classes.
    resolution : float
        Cell size, in the units of `xyz`.
    bounds : (xmin, ymin, xmax, ymax), optional
        Area the raster covers (snapped outward to the grid); default: the points' extent.
    ground_codes : sequence of int
        Classes taken as ground.
    crs : str, optional
        Recorded in the raster.
    block_points : int
        Ground points above which the TIN is built block by block (each block from the
        ground within a margin of it, the margin doubled where a triangle of the block
        may not be one of the whole triangulation): the same raster, with the memory of
        one block's triangulation (about 140 bytes a point while it is built).

    Returns
    -------
    Raster

    Raises
    ------
    InvalidPointsError
        When fewer than three ground points, or all on one line, are found.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 10, (500, 2))
    >>> xyz = np.c_[xy, 0.1 * xy[:, 0] + 2.0]
    >>> dtm = terrain_model(xyz, np.full(500, 2), resolution=1.0, bounds=(0, 0, 10, 10))
    >>> dtm.shape, round(float(dtm.values[5, 4]), 6)  # the cell centred at x = 4.5
    ((10, 10), 2.45)
    """
    xyz = check_points(xyz, name="xyz")
    resolution = check_scalar(resolution, "resolution", func="terrain_model", low=0)
    block_points = check_scalar(block_points, "block_points", func="terrain_model", low=3,
                                closed="left", integer=True)
    cls = np.asarray(classification)
    if cls.shape != (len(xyz),):
        raise InvalidPointsError(f"classification has {cls.shape[0] if cls.ndim else 0} "
                                 f"values for {len(xyz)} points")
    ground = xyz[np.isin(cls, np.asarray(ground_codes))]
    if bounds is None:
        bounds = (xyz[:, 0].min(), xyz[:, 1].min(), xyz[:, 0].max(), xyz[:, 1].max())
    left, top, rows, cols = _grid(bounds, resolution)
    if len(ground) < 3:
        raise InvalidPointsError(f"{len(ground)} ground points (classes "
                                 f"{', '.join(map(str, ground_codes))}): a terrain model "
                                 "needs at least 3")
    origin = np.array([left, top])
    # one height per planimetric location (the lowest), so the triangulation is defined
    xy = ground[:, :2] - origin
    z = ground[:, 2]
    copies = find_duplicates(np.c_[xy, np.zeros(len(xy))])
    if copies.any:
        lowest = np.full(copies.n_unique, np.inf)
        np.minimum.at(lowest, copies.inverse, z)
        xy, z = xy[copies.first], lowest
    del ground, copies
    if len(xy) <= block_points:
        values = rasterize_tin(xy, z, _triangulate(xy, strict=True), float(resolution),
                               rows, cols)
    else:
        values = _blocked_tin(xy, z, float(resolution), rows, cols, block_points)
    return Raster(values, left, top, resolution, crs)


def _triangulate(xy, *, strict):
    """The Delaunay triangles of `xy` (vertex indices); None (or an error when
    `strict`) when the points lie on one line."""
    tri = delaunay_triangles(xy)
    if len(tri):
        return tri
    if strict:
        raise InvalidPointsError("the ground points lie on one line: no terrain surface "
                                 "can be triangulated")
    return None


class _Hull:
    """The convex hull of all the ground points, computed when first asked."""

    def __init__(self, xy):
        self.xy, self.eq = xy, None

    def contains(self, centres):
        """Which of `centres` lie in the hull (edges included)."""
        from scipy.spatial import ConvexHull, QhullError

        if self.eq is None:
            try:
                self.eq = ConvexHull(self.xy).equations
            except (QhullError, ValueError):  # on one line: the final pass decides
                return np.ones(len(centres), bool)
        scale = float(np.abs(self.xy).max()) + 1.0
        return np.all(centres @ self.eq[:, :2].T + self.eq[:, 2] <= 1e-9 * scale, axis=1)


def _blocked_tin(xy, z, resolution, rows, cols, block_points):
    """The TIN rasterised block by block, each block from the ground points within a
    margin of it; equal to the triangulation of all the points.

    A Delaunay triangle of a subset whose circumcircle lies inside the subset's window
    is a triangle of the whole triangulation (no point of the whole set lies in its
    circle: one would lie in the window, hence in the subset). A block's cells take the
    values of such triangles; the cells covered only by other triangles, or by none but
    inside the convex hull of all the points, are done again with twice the margin, the
    last time with every point. Memory holds one block's triangulation.
    """
    values = np.full((rows, cols), np.nan)
    side = max(8, int(math.sqrt(block_points / len(xy) * rows * cols)))  # cells
    hull = _Hull(xy)
    extent = (column_min(xy), column_max(xy))
    for r0 in range(0, rows, side):
        for c0 in range(0, cols, side):
            r1, c1 = min(r0 + side, rows), min(c0 + side, cols)
            values[r0:r1, c0:c1] = _tin_block(xy, z, resolution, (r0, r1, c0, c1),
                                              side * resolution / 8.0, hull, extent)
    return values


def _tin_block(xy, z, res, cells, margin, hull, extent):
    r0, r1, c0, c1 = cells
    # the block in grid coordinates (x east, y north from the top-left corner)
    bx0, bx1, by0, by1 = c0 * res, c1 * res, -r1 * res, -r0 * res
    out = np.full((r1 - r0, c1 - c0), np.nan)
    pending = np.ones(out.shape, bool)
    lo, hi = extent
    while True:
        w = (bx0 - margin, by0 - margin, bx1 + margin, by1 + margin)
        everything = w[0] <= lo[0] and w[1] <= lo[1] and w[2] >= hi[0] and w[3] >= hi[1]
        sel = np.flatnonzero((xy[:, 0] >= w[0]) & (xy[:, 0] <= w[2])
                             & (xy[:, 1] >= w[1]) & (xy[:, 1] <= w[3]))
        simp = _triangulate(xy[sel], strict=everything) if len(sel) >= 3 else None
        if simp is not None:
            # the block's own grid: cell centres relative to its top-left corner
            pts = xy[sel] - [bx0, by1]
            safe = np.ones(len(simp), bool) if everything else _circle_inside(pts, simp, (
                w[0] - bx0, w[1] - by1, w[2] - bx0, w[3] - by1))
            zz = z[sel]
            done = rasterize_tin(pts, zz, simp[safe], res, r1 - r0, c1 - c0)
            got = pending & np.isfinite(done)
            out[got] = done[got]
            pending &= ~got
            if not everything and pending.any():
                unsafe = np.isfinite(rasterize_tin(pts, zz, simp[~safe], res, r1 - r0,
                                                   c1 - c0))
                rr, cc = np.nonzero(pending & ~unsafe)
                if rr.size:  # outside the subset's hull: pending if inside the whole's
                    centres = np.c_[bx0 + (cc + 0.5) * res, by1 - (rr + 0.5) * res]
                    pending[rr, cc] = hull.contains(centres)
            del simp
        if everything or not pending.any():
            return out
        margin *= 2.0


def _circle_inside(pts, simp, window):
    """Triangles whose circumcircle lies inside `window` (xmin, ymin, xmax, ymax)."""
    a, b, c = pts[simp[:, 0]], pts[simp[:, 1]], pts[simp[:, 2]]
    b, c = b - a, c - a
    d = 2.0 * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        bb, cc = (b ** 2).sum(1), (c ** 2).sum(1)
        ux = (c[:, 1] * bb - b[:, 1] * cc) / d
        uy = (b[:, 0] * cc - c[:, 0] * bb) / d
    rad = np.hypot(ux, uy)
    ux, uy = ux + a[:, 0], uy + a[:, 1]
    ok = ((ux - rad >= window[0]) & (uy - rad >= window[1]) & (ux + rad <= window[2])
          & (uy + rad <= window[3]))
    return ok & np.isfinite(rad)
