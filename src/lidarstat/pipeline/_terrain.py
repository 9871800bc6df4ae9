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
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_points, check_scalar
from ..errors import InvalidPointsError
from ..io import Raster
from ._terrain_kernels import rasterize_tin

__all__ = ["GROUND_CODES_DTM", "terrain_model"]

#: ASPRS classes taken as ground: bare earth (2) and road surface (11).
GROUND_CODES_DTM = (2, 11)


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
                  ground_codes=GROUND_CODES_DTM, crs: str | None = None) -> Raster:
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
    from scipy.spatial import Delaunay, QhullError

    xyz = check_points(xyz, name="xyz")
    resolution = check_scalar(resolution, "resolution", func="terrain_model", low=0)
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
    order = np.lexsort((ground[:, 2], xy[:, 1], xy[:, 0]))
    xy, z = xy[order], ground[order, 2]
    keep = np.r_[True, np.any(np.diff(xy, axis=0) != 0, axis=1)]
    try:
        tri = Delaunay(xy[keep])
    except QhullError:
        raise InvalidPointsError("the ground points lie on one line: no terrain surface "
                                 "can be triangulated") from None
    values = rasterize_tin(tri.points, z[keep], tri.simplices.astype(np.int64),
                           float(resolution), rows, cols)
    return Raster(values, left, top, resolution, crs)
