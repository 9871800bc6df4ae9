"""The terrain step of the moments classification: grow the ground, test every point.

The moments cut decides ground window by window on heights above a lower envelope, so
ground that stands well above that envelope (an embankment, a ramp, the top of a steep
bank narrower than the envelope's opening) is cut away with the objects, and the ground
surface refitted to the cut runs under it. This step takes the ground the moments left
and:

1. **grid**: the lowest point and the lowest ground point of every ``cell`` square; a
   ground cell rising steeply above most of its ground neighbours (a low object the cut
   kept) leaves the seeds;
2. **growth**: a cell without ground joins the ground when its lowest point continues a
   neighbouring ground cell smoothly: within ``step`` of the linear extrapolation of two
   ground cells in a row and rising at most ``max_rise`` per unit distance from the
   neighbour; repeated until no cell joins (an embankment is climbed band by band,
   a wall never);
3. **walls**: every connected region the growth added is kept only when at most
   ``wall_fraction`` of its border to cells not in it are walls (the region higher by
   more than the smooth-join bound): a bridge deck or a roof reached over a ramp has walls
   along most of its border, an embankment has none;
4. **surface**: the ground cells' lowest points, empty cells filled by linear
   interpolation (nearest cell outside their hull), bilinear between cell centres;
5. **test**: a point is ground when its height above the surface lies within
   ``[-(below + s * slope), tolerance + s * slope]``, ``slope`` the surface's gradient
   at the point (Pingel et al. 2013's slope-dependent elevation threshold).

Each of these is a raster operation (vectorised over cells) or a compiled loop over the
points (:mod:`._terrain_kernels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._terrain_kernels import cell_lowest, fill_triangles, grid_bilinear

__all__ = ["TERRAIN_DEFAULTS", "TerrainModel", "TerrainRefinement", "drop_bumps",
           "grow_ground", "refine_terrain", "reject_walled", "terrain_step"]

#: The terrain step's lengths in metres (slopes are dimensionless): the grid cell, the
#: tolerance on flat ground and its growth per unit slope (the values of Pingel et al.
#: 2013's elevation threshold and scaler), the smooth-continuation bounds of the growth
#: (a step of 0.3 m from the extrapolated terrain, a rise of at most 45 degrees from a
#: neighbour), the depth allowed under the surface, and the largest share of walls on the
#: border of a grown region, and how many of its 8 neighbours a seed cell must rise
#: above steeply to be dropped as a bump.
TERRAIN_DEFAULTS = {"cell": 2.0, "tolerance": 0.5, "slope_tolerance": 1.25, "step": 0.3,
                    "max_slope": 1.0, "below": 1.0, "wall_fraction": 0.2, "bump_sides": 5}

#: The eight neighbour offsets of a cell.
_DIRS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


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
    """

    grid: np.ndarray
    slope: np.ndarray
    cell: float

    def __call__(self, xy) -> np.ndarray:
        """Elevation of the surface at `xy` (bilinear between cell centres)."""
        return self.at(xy, self.grid)

    def slope_at(self, xy) -> np.ndarray:
        """Slope of the surface at `xy` (bilinear between cell centres)."""
        return self.at(xy, self.slope)

    def at(self, xy, grid) -> np.ndarray:
        """Bilinear interpolation of a grid of this model's cells at `xy`."""
        xy = np.ascontiguousarray(xy, dtype=np.float64)
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
        Upper bound of the test at each point (``tolerance + s * slope``).
    surface : TerrainModel
    grown_cells, rejected_cells : int
        Cells the growth added and kept, and cells it added but the wall test took back.
    """

    ground: np.ndarray
    height: np.ndarray
    tolerance: np.ndarray
    surface: TerrainModel
    grown_cells: int
    rejected_cells: int


def _shift(a, di, dj, fill=np.inf):
    """``out[i, j] = a[i - di, j - dj]`` (the neighbour at offset ``(-di, -dj)``), `fill`
    outside."""
    out = np.full_like(a, fill)
    h, w = a.shape
    out[max(di, 0):h + min(di, 0), max(dj, 0):w + min(dj, 0)] = \
        a[max(-di, 0):h + min(-di, 0), max(-dj, 0):w + min(-dj, 0)]
    return out


def grow_ground(lowest, ground_z, *, cell, step, max_rise, max_rounds=200):
    """Cells joining the ground by smooth continuation of their ground neighbours.

    Parameters
    ----------
    lowest : (nx, ny) ndarray
        Lowest point of every cell (``inf`` where empty).
    ground_z : (nx, ny) ndarray
        Lowest ground point of every cell (``inf`` where the cell holds no ground).
    cell : float
        Cell side.
    step : float
        Largest difference between a cell's lowest point and the linear extrapolation of
        a neighbouring pair of ground cells (the neighbour alone when the next one in the
        same direction is not ground).
    max_rise : float
        Largest rise from the neighbour per unit of horizontal distance.
    max_rounds : int
        Most rounds (each adds at most one ring of cells).

    Returns
    -------
    (nx, ny) ndarray
        `ground_z` with the grown cells set to their lowest point.
    """
    g = ground_z.copy()
    usable = np.isfinite(lowest)
    for _ in range(max_rounds):
        free = usable & ~np.isfinite(g)
        join = np.zeros(g.shape, bool)
        for di, dj in _DIRS:
            n1 = _shift(g, di, dj)
            n2 = _shift(g, 2 * di, 2 * dj)
            with np.errstate(invalid="ignore"):
                pred = np.where(np.isfinite(n2), 2 * n1 - n2, n1)
                join |= (free & np.isfinite(n1) & (np.abs(lowest - pred) <= step)
                         & (np.abs(lowest - n1) <= max_rise * cell * np.hypot(di, dj)))
        if not join.any():
            break
        g[join] = lowest[join]
    return g


def drop_bumps(ground_z, *, cell, step, max_rise, min_sides, rounds=2):
    """Ground cells standing above most of their ground neighbours become empty.

    A cell is a bump when its lowest ground point is higher than that of at least
    `min_sides` of its 8 neighbouring ground cells by more than ``step + max_rise *
    distance`` (a low object the moments cut kept: a car, a hedge, a shed on a slope); a
    terrace edge rises that steeply above its downhill side only. Repeated `rounds` times
    (a bump two cells wide loses its rim first).

    Returns
    -------
    (nx, ny) ndarray
        `ground_z` with the bumps set to ``inf``.
    """
    g = ground_z.copy()
    for _ in range(rounds):
        above = np.zeros(g.shape, np.int8)
        for di, dj in _DIRS:
            n1 = _shift(g, di, dj)
            with np.errstate(invalid="ignore"):
                above += (np.isfinite(n1)
                          & (g - n1 > step + max_rise * cell * np.hypot(di, dj)))
        bump = np.isfinite(g) & (above >= min_sides)
        if not bump.any():
            break
        g[bump] = np.inf
    return g


def reject_walled(grown_z, ground_z, lowest, *, cell, step, max_rise, wall_fraction):
    """Take back the grown regions whose border is mostly walls.

    A border pair is a grown cell and an 8-neighbour outside its region holding points;
    it is a wall when the grown cell is higher than the neighbour's lowest point by more
    than ``step + max_rise * distance``, smooth when their difference is within that
    bound. A region with more than `wall_fraction` walls among its wall and smooth pairs
    is removed (a bridge deck, a roof reached over a ramp).

    Returns
    -------
    surface_z : (nx, ny) ndarray
        `grown_z` without the rejected regions.
    rejected : int
        Cells taken back.
    """
    from scipy import ndimage as ndi

    grown = np.isfinite(grown_z) & ~np.isfinite(ground_z)
    label, n = ndi.label(grown, structure=np.ones((3, 3), bool))
    if n == 0:
        return grown_z, 0
    walls = np.zeros(n + 1)
    smooth = np.zeros(n + 1)
    for di, dj in _DIRS:
        n_low = _shift(lowest, di, dj)
        n_label = _shift(label, di, dj, fill=-1)
        bound = step + max_rise * cell * np.hypot(di, dj)
        pair = grown & (n_label != label) & np.isfinite(n_low)
        with np.errstate(invalid="ignore"):
            dz = grown_z - n_low
        walls += np.bincount(label[pair & (dz > bound)], minlength=n + 1)
        smooth += np.bincount(label[pair & (np.abs(dz) <= bound)], minlength=n + 1)
    bad = walls > wall_fraction * np.maximum(walls + smooth, 1)
    bad[0] = False
    drop = bad[label] & grown
    out = grown_z.copy()
    out[drop] = np.inf
    return out, int(drop.sum())


def _fill(grid):
    """Empty (``inf``) cells filled by linear interpolation in the Delaunay triangulation
    of the filled cells on their rims (the only cells a triangle over a hole joins), the
    nearest filled cell outside the rims' hull.

    The triangles are rasterised (:func:`~._terrain_kernels.fill_triangles`) rather than
    the holes located in them: on a grid the holes lie on triangle edges, where a point
    location falls back to a search of every triangle.
    """
    from scipy import ndimage as ndi
    from scipy.spatial import Delaunay

    empty = ~np.isfinite(grid)
    if not empty.any() or empty.all():
        return grid
    out = grid.copy()
    rim = ~empty & ndi.binary_dilation(empty, structure=np.ones((3, 3), bool))
    full = np.argwhere(rim).astype(np.float64)
    todo = empty.copy()
    if len(full) >= 3 and np.ptp(full[:, 0]) > 0 and np.ptp(full[:, 1]) > 0:
        try:
            tri = Delaunay(full).simplices.astype(np.int64)
        except Exception:  # noqa: BLE001 - degenerate (collinear) rims: nearest below
            tri = None
        if tri is not None:
            fill_triangles(tri, full, np.ascontiguousarray(grid[rim]), out, todo)
    if todo.any():
        idx = ndi.distance_transform_edt(empty, return_distances=False,
                                         return_indices=True)
        out[todo] = grid[tuple(idx)][todo]
    return out


def refine_terrain(xy, z, ground, *, cell, tolerance, slope_tolerance, step, max_rise,
                   below, wall_fraction=0.2, bump_sides=5) -> TerrainRefinement:
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
    nx = int(np.floor(xy[:, 0].max() / cell)) + 1
    ny = int(np.floor(xy[:, 1].max() / cell)) + 1
    lowest, ground_z = cell_lowest(xy, z, ground, float(cell), nx, ny)
    if not np.isfinite(ground_z).any():
        ground_z = lowest
    ground_z = drop_bumps(ground_z, cell=cell, step=step, max_rise=max_rise,
                          min_sides=bump_sides)
    grown_z = grow_ground(lowest, ground_z, cell=cell, step=step, max_rise=max_rise)
    surface_z, rejected = reject_walled(grown_z, ground_z, lowest, cell=cell, step=step,
                                        max_rise=max_rise, wall_fraction=wall_fraction)
    grown = int((np.isfinite(surface_z) & ~np.isfinite(ground_z)).sum())
    grid = _fill(surface_z)
    gx, gy = np.gradient(grid, cell) if min(grid.shape) > 1 else (np.zeros_like(grid),) * 2
    model = TerrainModel(grid=grid, slope=np.hypot(gx, gy), cell=float(cell))
    height = np.round(z - model(xy), 6)
    extra = slope_tolerance * model.slope_at(xy)
    upper = tolerance + extra
    keep = (height <= upper) & (height >= -(below + extra))
    return TerrainRefinement(ground=keep, height=height, tolerance=upper, surface=model,
                             grown_cells=grown, rejected_cells=rejected)


def terrain_step(xy, z, ground, *, ux=1.0, uz=1.0):
    """The terrain step with :data:`TERRAIN_DEFAULTS`, lengths converted to coordinate
    units (`ux`, `uz`: metres per horizontal and vertical unit).

    Returns ``(ground, height, surface, tolerance)``.
    """
    d = TERRAIN_DEFAULTS
    # a slope in coordinate units is rise (z units) per run (xy units); in metres per
    # metre it is that times uz / ux
    aspect = uz / ux
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    t = refine_terrain(xy, z, ground, cell=d["cell"] / ux, tolerance=d["tolerance"] / uz,
                       slope_tolerance=d["slope_tolerance"] * aspect / uz,
                       step=d["step"] / uz, max_rise=d["max_slope"] / aspect,
                       below=d["below"] / uz, wall_fraction=d["wall_fraction"],
                       bump_sides=d["bump_sides"])
    return t.ground, t.height, t.surface, t.tolerance
