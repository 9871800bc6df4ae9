"""The terrain step of the moments classification: grow the ground, test every point.

The moments cut decides ground window by window on heights above a lower envelope, so
ground that stands well above that envelope (an embankment, a ramp, the top of a steep
bank narrower than the envelope's opening) is cut away with the objects, and the ground
surface refitted to the cut runs under it. This step takes the ground the moments left
and:

1. **grid**: the lowest point and the lowest ground point of every ``cell`` square; a
   ground cell rising steeply above most of its ground neighbours (a low object the cut
   kept) leaves the seeds;
   **opening**: so does a ground cell standing more than ``open_slope * r`` above the
   progressive opening of the seeds with a window of radius ``r`` (SMRF's test, Pingel
   et al. 2013, up to ``open_radius``): a roof the cut kept. Steep ground leaves the
   seeds too; the growth puts it back;
2. **growth**: a cell without ground joins the ground when its lowest point continues a
   neighbouring ground cell smoothly: within ``step`` of the linear extrapolation of two
   ground cells in a row and rising at most ``max_rise`` per unit distance from the
   neighbour; repeated until no cell joins (an embankment is climbed band by band,
   a wall never);
3. **walls**: every connected region the growth added is kept only when at most
   ``wall_fraction`` of its border to cells not in it are walls (the region higher by
   more than the smooth-join bound): a bridge deck or a roof reached over a ramp has walls
   along most of its border, an embankment has none;
   **plateaus**: the surface's cells are joined into parts by smooth continuation; a
   part other than the largest whose border (its uphill side left out) is mostly walls,
   with more walls than uphill border, is taken back (a roof the cut kept, a roof on
   the data's edge) (:func:`reject_plateaus`);
   **platforms**: the growth once more over steps up to ``low_step``; a region it adds
   of at least ``low_cells`` cells standing on such low steps almost all round is kept
   (a plinth, a raised square: :func:`grow_platforms`);
4. **surface**: the TIN of the ground cells' lowest points at their own positions (a
   grid of cell centres would lie under a slope by ``slope * cell / 2``), empty cells
   filled by linear interpolation (nearest cell outside their hull), those near the
   points its vertices too;
5. **test**: a point is ground when its height above the surface lies within
   ``[-(below + s * slope), tolerance + s * slope]``, ``slope`` the surface's gradient
   at the point (Pingel et al. 2013's slope-dependent elevation threshold);
6. **noise fence**: and when its height is within ``fence`` robust standard deviations
   (plus ``s * slope``) of the median height of the ground around it, both taken over the
   ground points of a block of cells that are not vertices of the surface
   (:func:`noise_fence`): on smooth, dense ground the fixed tolerance takes low objects
   (cars, kerbs, low walls 0.2-0.5 m high) as ground, the ground's own spread does not.

Each of these is a raster operation (vectorised over cells) or a compiled loop over the
points (:mod:`._terrain_kernels`).
The grid leaves out the empty bands of the plane (:mod:`._terrain_frame`): its memory
follows the points, not their bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..neighbors import delaunay_triangles
from ._terrain_frame import MAX_EDGE, BandFrame, near_points, terrain_cell
from ._terrain_grid import (
    drop_bumps,
    drop_opened,
    grow_ground,
    grow_platforms,
    reject_plateaus,
    reject_walled,
)
from ._terrain_kernels import (block_spread, cell_lowest, cell_values, fence_test,
                               fill_triangles, first_on_surface, gather_cells, grid_bilinear,
                               height_test)

__all__ = ["TERRAIN_DEFAULTS", "TerrainModel", "TerrainRefinement", "drop_bumps",
           "drop_opened", "grow_ground", "grow_platforms", "noise_fence", "refine_terrain",
           "reject_plateaus", "reject_walled", "terrain_step"]

#: The terrain step's lengths in metres (slopes are dimensionless): the grid cell, the
#: tolerance on flat ground and its growth per unit slope (the values of Pingel et al.
#: 2013's elevation threshold and scaler), the smooth-continuation bounds of the growth
#: (a step of 0.3 m from the extrapolated terrain, a rise of at most 45 degrees from a
#: neighbour), the depth allowed under the surface, and the largest share of walls on the
#: border of a grown region, and how many of its 8 neighbours a seed cell must rise
#: above steeply to be dropped as a bump; the largest share of walls on the border of a
#: part of the surface; the slope and largest radius of the seeds' progressive opening
#: (steeper than SMRF's 0.15: the growth, not the opening, decides on steep ground); the
#: highest step up onto a low platform and the fewest cells of one (:func:`grow_platforms`);
#: the noise fence in robust standard deviations, the fewest ground points it is taken
#: over and the largest half-width of their block (:func:`noise_fence`).
TERRAIN_DEFAULTS = {"cell": 2.0, "tolerance": 0.5, "slope_tolerance": 1.25, "step": 0.3,
                    "max_slope": 1.0, "below": 1.0, "wall_fraction": 0.2, "bump_sides": 5,
                    "plateau_fraction": 0.5, "open_slope": 0.5, "open_radius": 18.0,
                    "low_step": 1.0, "low_cells": 16, "fence": 7.0, "fence_points": 64,
                    "fence_radius": 16.0}


@dataclass(frozen=True)
class TerrainModel:
    """A gridded ground surface: cell-centre elevations and their slope.

    Attributes
    ----------
    grid : (nx, ny) ndarray
        Elevation at the cell centres (no gaps).
    slope : (nx, ny) ndarray
        Gradient magnitude of `grid` (rise per coordinate unit).
    cell : float
        Cell side (coordinate units); cell ``(i, j)`` covers
        ``[i cell, (i + 1) cell) x [j cell, (j + 1) cell)``.
    tin : callable, optional
        The surface as a TIN (``f(xy / cell) -> z``): the lowest ground point of every surface
        cell at its own position, the filled cells near the points at their centres. A
        cell-centre grid of lowest points lies under a slope by about ``slope * cell / 2``;
        the TIN passes through the ground points themselves.
    frame : BandFrame, optional
        The grid's rows and columns without the empty bands: `xy` is moved into it first
        (:class:`~._terrain_frame.BandFrame`).
    """

    grid: np.ndarray
    slope: np.ndarray
    cell: float
    tin: object = None
    frame: object = None

    def __call__(self, xy) -> np.ndarray:
        """Elevation of the surface at `xy`: linear on the TIN of the cells' lowest
        ground points at their own positions when there is one, else bilinear between
        cell centres."""
        if self.tin is not None:  # built in cell units (see _tin)
            xy = self._framed(xy)
            return self.tin(xy / self.cell)
        return self.at(xy, self.grid)

    def slope_at(self, xy) -> np.ndarray:
        """Slope of the surface at `xy` (bilinear between cell centres)."""
        return self.at(xy, self.slope)

    def _framed(self, xy):
        xy = np.ascontiguousarray(xy, dtype=np.float64)
        return xy if self.frame is None else self.frame(xy)

    def at(self, xy, grid) -> np.ndarray:
        """Bilinear interpolation of a grid of this model's cells at `xy`."""
        xy = self._framed(xy)
        out = np.empty(len(xy))
        if len(xy):
            grid_bilinear(xy, np.ascontiguousarray(grid, dtype=np.float64), float(self.cell),
                          out)
        return out


@dataclass(frozen=True)
class TerrainRefinement:
    """What the terrain step decided.

    Attributes
    ----------
    ground : (N,) ndarray of bool
        Ground after the test.
    height : (N,) ndarray of float64
        Height above the terrain surface.
    tolerance : (N,) ndarray of float64
        Upper bound of the test at each point (``tolerance + s * slope``, or the noise
        fence plus ``s * slope`` where that is lower).
    surface : TerrainModel
    grown_cells, rejected_cells : int
        Cells the growth added and kept, and cells it added but the wall test took back.
    plateau_cells : int
        Cells of the moments' ground taken back as walled parts (:func:`reject_plateaus`).
    """

    ground: np.ndarray
    height: np.ndarray
    tolerance: np.ndarray
    surface: TerrainModel
    grown_cells: int
    rejected_cells: int
    plateau_cells: int = 0


def _fill(grid):
    """Empty (``inf``) cells filled by linear interpolation in the Delaunay triangulation
    of the filled cells on their rims (the only cells a triangle over a hole joins), the
    nearest filled cell outside the rims' hull.

    The triangles are rasterised (:func:`~._terrain_kernels.fill_triangles`) rather than
    the holes located in them: on a grid the holes lie on triangle edges, where a point
    location falls back to a search of every triangle.
    """
    from scipy import ndimage as ndi

    empty = ~np.isfinite(grid)
    if not empty.any() or empty.all():
        return grid
    out = grid.copy()
    rim = ~empty & ndi.binary_dilation(empty, structure=np.ones((3, 3), bool))
    full = np.argwhere(rim).astype(np.float64)
    todo = empty.copy()
    if len(full) >= 3 and np.ptp(full[:, 0]) > 0 and np.ptp(full[:, 1]) > 0:
        tri = delaunay_triangles(full)  # none when the rims are collinear: nearest below
        if len(tri):
            fill_triangles(tri, full, np.ascontiguousarray(grid[rim]), out, todo)
    if todo.any():
        idx = ndi.distance_transform_edt(empty, return_distances=False,
                                         return_indices=True)
        out[todo] = grid[tuple(idx)][todo]
    return out


def _tin(xy, z, surface_z, grid, lowest, cell):
    """TIN of the surface cells' lowest points at their own positions and of the centres
    of the filled cells near the points (:func:`~._terrain_frame.near_points`;
    :class:`TerrainModel`)."""
    from ._surface import TinSurface

    ny = grid.shape[1]
    pick = first_on_surface(xy, z, np.ascontiguousarray(surface_z), float(cell))
    near = near_points(lowest)
    filled = np.flatnonzero((~np.isfinite(surface_z) & near).ravel())
    # in cell units rounded to 1e-9 cell: the vertices are often co-circular (the filled
    # cells' centres), and which diagonal the triangulation takes must not depend on the
    # last bits of the coordinates, i.e. on the file's unit
    centres = np.c_[filled // ny, filled % ny] + 0.5
    P = np.round(np.r_[xy[pick] / cell, centres], 9)
    V = np.r_[z[pick], grid.ravel()[filled]]
    if len(P) < 3:
        return None
    # without the far cells, triangles span the empty areas; none holds a point (one
    # holding a point reaches 2 sqrt(2) cells), and binning them would cost their area
    return TinSurface(P, V, 1.0, keep=None if near.all() else partial(_near_triangles, near))


def _near_triangles(near, corners):
    """Triangles (``(T, 3, 2)`` corners in cell units) no longer than
    :data:`~._terrain_frame.MAX_EDGE` or whose centroid lies in a `near` cell."""
    edge = np.max([np.hypot(*(corners[:, i] - corners[:, i - 1]).T) for i in range(3)],
                  axis=0)
    ij = np.floor(corners.mean(axis=1)).astype(np.int64)
    ij = np.clip(ij, 0, np.array(near.shape) - 1)
    return (edge <= MAX_EDGE) | near[ij[:, 0], ij[:, 1]]


def noise_fence(xy, height, ground, *, cell, fence, min_points=64, max_radius=8):
    """Upper bound of a ground point's height from the spread of the ground around it.

    The heights above the surface of the ground points that are not its vertices (a
    vertex's height is 0 by construction and says nothing of the noise) are gathered per
    ``cell`` square; for every cell the block of ``(2w + 1)^2`` cells around it, ``w``
    the smallest radius (up to `max_radius` cells) holding at least `min_points` of
    them, gives their median ``m`` and robust standard deviation ``s = 1.4826 MAD``
    (:func:`~._terrain_kernels.block_spread`). A point's bound is ``m + fence * s``
    (``inf`` where a block holds fewer than 3 heights): the residual of a point to the
    surface tested against the local ground's own noise rather than a fixed tolerance.
    The median and MAD ignore up to half of the block, so the low objects the fence is
    there to find do not widen it.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates, all >= 0.
    height : (N,) ndarray
        Heights above the surface (rounded: a vertex's height is exactly 0).
    ground : (N,) ndarray of bool
        The ground points whose heights give the spread.
    cell : float
        Cell side (coordinate units).
    fence : float
        Robust standard deviations above the median.
    min_points, max_radius : int
        Fewest heights of a block, largest block radius (cells).

    Returns
    -------
    (N,) ndarray of float64
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    centre, spread, ny = _fence_cells(xy, height, ground, cell=cell, min_points=min_points,
                                      max_radius=max_radius)
    bound = np.empty(len(height))
    gather_cells(xy, float(cell), ny, centre, spread, float(fence), bound)
    return bound


def _fence_cells(xy, height, ground, *, cell, min_points, max_radius):
    """The median and robust standard deviation of the ground heights of every cell's
    block (:func:`noise_fence`): ``(centre, spread, ny)``, flat over the ``(nx, ny)``
    cells of `xy` (C-contiguous), NaN where a cell holds no ground."""
    n = len(height)
    nx = int(np.floor(xy[:, 0].max() / cell)) + 1 if n else 1
    ny = int(np.floor(xy[:, 1].max() / cell)) + 1 if n else 1
    # the cells are found point by point in compiled loops: no per-point key arrays
    offsets, values, has_ground = cell_values(
        xy, np.ascontiguousarray(height, dtype=np.float64),
        np.ascontiguousarray(ground, dtype=np.bool_), float(cell), nx, ny)
    cells = np.flatnonzero(has_ground)
    centre = np.full(nx * ny, np.nan)
    spread = np.full(nx * ny, np.nan)
    if cells.size:
        block_spread(offsets, values, nx, ny, cells, int(min_points), int(max_radius),
                     centre, spread)
    return centre, spread, ny


#: Points tested against the surface at a time (bounds the temporaries of the test).
_BLOCK = 1 << 20


def _blocks(n):
    """``(start, stop)`` of consecutive blocks of at most :data:`_BLOCK` points."""
    return [(s, min(n, s + _BLOCK)) for s in range(0, n, _BLOCK)]


def _test_points(model, xy_in, xy, z, *, tolerance, slope_tolerance, below):
    """Heights above the surface, upper bounds and the ground test of every point:
    ``(height, upper, keep)`` (:func:`~._terrain_kernels.height_test`).

    ``height = round(z - surface, 6)``, ``upper = tolerance + s slope``, ground when
    ``-(below + s slope) <= height <= upper`` (``s = slope_tolerance``). The surface is
    evaluated at `xy_in` block by block (bounded temporaries), the slope at `xy` (`xy_in`
    in the model's frame).
    """
    n = len(z)
    height, upper, keep = np.empty(n), np.empty(n), np.empty(n, bool)
    slope = np.ascontiguousarray(model.slope, dtype=np.float64)
    for s, e in _blocks(n):
        height_test(xy[s:e], z[s:e], model(xy_in[s:e]), slope, model.cell,
                    float(slope_tolerance), float(tolerance), float(below), height[s:e],
                    upper[s:e], keep[s:e])
    return height, upper, keep


def refine_terrain(xy, z, ground, *, cell, tolerance, slope_tolerance, step, max_rise,
                   below, wall_fraction=0.2, bump_sides=5,
                   plateau_fraction=0.5, open_slope=0.5,
                   open_radius=0.0, low_step=0.0, low_cells=16, fence=0.0,
                   fence_points=64, fence_radius=8) -> TerrainRefinement:
    """Grow the ground over smooth continuations, then test every point against it.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates, all >= 0 (the moments' local frame).
    z : (N,) ndarray
        Elevations.
    ground : (N,) ndarray of bool
        Ground of the moments cut (the seeds).
    cell : float
        Cell of the terrain grid (coordinate units).
    tolerance : float
        Height above the surface a point of flat ground may have (vertical units).
    slope_tolerance : float
        Extra height allowed per unit of surface slope (vertical units).
    step, max_rise : float
        Smooth-continuation bounds of :func:`grow_ground` (vertical units, and vertical
        units per horizontal unit).
    below : float
        Depth under the surface a ground point may have on flat ground (vertical units;
        the slope term is added as above).
    wall_fraction : float
        Largest share of walls on the border of a grown region (:func:`reject_walled`).
    bump_sides : int
        Ground cells rising steeply above at least this many of their 8 ground
        neighbours leave the seeds first (:func:`drop_bumps`).
    plateau_fraction : float
        Largest share of walls on the border of a smooth part of the surface other than
        the largest (:func:`reject_plateaus`; 1 switches it off).
    open_slope, open_radius : float
        Slope (vertical units per horizontal unit) and largest window radius (horizontal
        units) of the progressive opening that seed cells must not stand above
        (:func:`drop_opened`; radius 0 switches it off).
    low_step, low_cells : float, int
        Highest step up onto a low platform (vertical units) and the fewest cells of one
        (:func:`grow_platforms`; a `low_step` not above `step` switches it off).
    fence, fence_points, fence_radius : float, int, int
        The noise fence in robust standard deviations, the fewest ground heights it is
        taken over and the largest radius of their block in cells (:func:`noise_fence`;
        `fence` 0 switches it off).

    Returns
    -------
    TerrainRefinement

    Examples
    --------
    >>> g = np.random.default_rng(1)
    >>> xy = g.uniform(0, 60, (8000, 2))
    >>> z = 0.2 * xy[:, 0] + g.normal(0, 0.03, 8000)     # a 20 % slope
    >>> seeds = xy[:, 0] < 40                            # the moments kept only part of it
    >>> t = refine_terrain(xy, z, seeds, cell=2.0, tolerance=0.5, slope_tolerance=1.25,
    ...                    step=0.3, max_rise=1.0, below=1.0)
    >>> bool(t.ground.mean() > 0.99)
    True
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    ground = np.ascontiguousarray(ground, dtype=np.bool_)
    frame = BandFrame.of(xy, cell)
    if frame is not None:  # the grid without its empty bands (the model moves xy itself)
        xy, xy_in = frame(xy), xy
    else:
        xy_in = xy
    nx = int(np.floor(xy[:, 0].max() / cell)) + 1
    ny = int(np.floor(xy[:, 1].max() / cell)) + 1
    lowest, ground_z = cell_lowest(xy, z, ground, float(cell), nx, ny)
    if not np.isfinite(ground_z).any():
        ground_z = lowest
    ground_z = drop_bumps(ground_z, cell=cell, step=step, max_rise=max_rise,
                          min_sides=bump_sides)
    seeds_z = ground_z
    if open_radius > 0:
        seeds_z = drop_opened(ground_z, cell=cell, slope=open_slope, max_radius=open_radius)
    grown_z = grow_ground(lowest, seeds_z, cell=cell, step=step, max_rise=max_rise)
    # the wall test judges what the growth added beyond the moments' ground: ground the
    # opening took away and the growth reached again (a wide terrace above a retaining
    # wall, joined by a ramp) is the cut's ground, not a deck
    surface_z, rejected = reject_walled(grown_z, ground_z, lowest, cell=cell, step=step,
                                        max_rise=max_rise, wall_fraction=wall_fraction)
    surface_z, plateaus = reject_plateaus(surface_z, lowest, cell=cell, step=step,
                                          max_rise=max_rise, fraction=plateau_fraction)
    if low_step > step:
        surface_z, _ = grow_platforms(surface_z, lowest, cell=cell, max_rise=max_rise,
                                      low_step=low_step, min_cells=low_cells,
                                      wall_fraction=wall_fraction)
    grown = int((np.isfinite(surface_z) & ~np.isfinite(ground_z)).sum())
    grid = _fill(surface_z)
    gx, gy = np.gradient(grid, cell) if min(grid.shape) > 1 else (np.zeros_like(grid),) * 2
    model = TerrainModel(grid=grid, slope=np.hypot(gx, gy), cell=float(cell),
                         tin=_tin(xy, z, surface_z, grid, lowest, cell), frame=frame)
    del lowest, ground_z, seeds_z, grown_z, surface_z
    height, upper, keep = _test_points(model, xy_in, xy, z, tolerance=tolerance,
                                       slope_tolerance=slope_tolerance, below=below)
    if fence > 0 and keep.any():
        centre, spread, ny = _fence_cells(xy, height, keep, cell=cell, min_points=fence_points,
                                          max_radius=fence_radius)
        fence_test(xy, float(cell), ny, centre, spread, float(fence),
                   np.ascontiguousarray(model.slope, dtype=np.float64), float(slope_tolerance),
                   height, upper, keep)
    return TerrainRefinement(ground=keep, height=height, tolerance=upper, surface=model,
                             grown_cells=grown, rejected_cells=rejected,
                             plateau_cells=plateaus)


def terrain_step(xy, z, ground, *, ux=1.0, uz=1.0):
    """The terrain step with :data:`TERRAIN_DEFAULTS`, lengths converted to coordinate
    units (`ux`, `uz`: metres per horizontal and vertical unit), the cell coarser only
    on points too sparse for it (:func:`~._terrain_frame.terrain_cell`).

    Returns ``(ground, height, surface, tolerance)``.
    """
    d = TERRAIN_DEFAULTS
    # a slope in coordinate units is rise (z units) per run (xy units); in metres per
    # metre it is that times uz / ux
    aspect = uz / ux
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    t = refine_terrain(xy, z, ground, cell=terrain_cell(xy, d["cell"] / ux),
                       tolerance=d["tolerance"] / uz,
                       slope_tolerance=d["slope_tolerance"] * aspect / uz,
                       step=d["step"] / uz, max_rise=d["max_slope"] / aspect,
                       below=d["below"] / uz, wall_fraction=d["wall_fraction"],
                       bump_sides=d["bump_sides"], plateau_fraction=d["plateau_fraction"],
                       open_slope=d["open_slope"] / aspect, open_radius=d["open_radius"] / ux,
                       low_step=d["low_step"] / uz, low_cells=d["low_cells"],
                       fence=d["fence"], fence_points=d["fence_points"],
                       fence_radius=max(1, round(d["fence_radius"] / d["cell"])))
    return t.ground, t.height, t.surface, t.tolerance
