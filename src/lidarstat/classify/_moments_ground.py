"""The ground of the moments classification: lower envelope, window cuts, one surface.

1. a lower envelope (grey opening of the lowest-point grid) gives first heights;
2. every analysis window cuts its heights (:mod:`._moments_analysis`); the cuts are
   interpolated between the centres of the finest windows, so no class step appears at a
   window border (:func:`~._seams.interpolate_cuts`);
3. one TIN of the ground of all windows (:func:`~._surface.ground_surface`) gives new
   heights, and 2-3 repeat ``iterations`` times;
4. ground patches standing above their surroundings on (almost) every side (a roof the
   surface ran over) become objects (:func:`~._continuity.raised_patches`).
"""

from __future__ import annotations

import numpy as np

from .._shared._columns import column_max, column_min
from ._continuity import raised_patches
from ._moments_options import MomentsOptions
from ._moments_windows import window_pass
from ._seams import interpolate_cuts
from ._surface import ground_surface
from ._terrain_frame import BandFrame, terrain_cell

__all__ = ["drop_raised_patches", "ground_cut", "heights", "opening_surface"]

#: Bytes a cell of the opening's raster costs at its peak (grid, nearest-filled indices,
#: opening and masks).
_RASTER_CELL_BYTES = 48


def opening_surface(xy, z, *, window: float, cell: float = 1.0, frame=False) -> np.ndarray:
    """Lower envelope of the cloud: grey opening of the lowest-point grid (per point).

    The opening (erosion then dilation with a ``window x window`` square) removes every
    object narrower than the window and keeps planar slopes exactly (the opening of a
    linear function is itself), so ``z - opening`` is a height above ground that is not
    biased by the terrain trend. Empty cells take the value of the nearest filled cell.

    The raster leaves out the empty bands of rows and columns farther than
    :data:`~._terrain_frame.BAND_HALO` cells from every point
    (:class:`~._terrain_frame.BandFrame`): the opening of a cell holding a point reads
    the cells within ``k - 1`` of it, whose nearest filled cells lie within
    ``(k - 1) sqrt(2)`` (under 30 cells for the 20 m window), and a cell across a
    narrowed gap stays farther than that, so the envelope under the points is the one
    of the whole raster. `frame` is ``BandFrame.of(xy, cell)`` when the caller has it.
    """
    from scipy import ndimage as ndi

    if frame is False:
        frame = BandFrame.of(xy, cell)
    if frame is not None:  # the raster follows the points, not their bounding box
        xy = frame(xy)
    # cells on multiples of `cell` (not on the points' corner): every tile of an area
    # sees the same raster
    ij = np.floor(xy / cell).astype(np.int64)
    ij -= column_min(ij)
    shape = tuple(column_max(ij) + 1)
    _check_raster(shape, cell)
    g = np.full(shape, np.inf)
    np.minimum.at(g, (ij[:, 0], ij[:, 1]), z)
    empty = ~np.isfinite(g)
    if empty.any():
        ind = ndi.distance_transform_edt(empty, return_distances=False, return_indices=True)
        g = g[tuple(ind)]
    k = max(3, int(round(window / cell)) | 1)
    op = ndi.grey_opening(g, size=(k, k))
    return op[ij[:, 0], ij[:, 1]]


def _check_raster(shape, cell):
    """Refuse a ground raster larger than a quarter of the physical memory (a cloud
    whose occupied rows and columns are that many: a wide area densely spread)."""
    from .._shared._memory import physical_memory
    from ..errors import InvalidPointsError

    cells = int(shape[0]) * int(shape[1])
    limit = (physical_memory() or 8 << 30) // 4
    if cells * _RASTER_CELL_BYTES > limit:
        raise InvalidPointsError(
            f"the cloud spans {shape[0] * cell:,.0f} x {shape[1] * cell:,.0f} coordinate "
            f"units: its ground raster of {cell:g}-unit cells would hold {cells:,} cells "
            f"({cells * _RASTER_CELL_BYTES / 1e9:,.1f} GB), more than a quarter of the "
            "memory; split the cloud into its separate areas, or check its units "
            "(--units, --scale)")


def heights(z, surface, overwrite=False):
    """Heights above a surface, rounded to 1e-6 of the coordinate unit.

    A cut often falls inside a mass of tied heights: the TIN vertices themselves (height
    exactly 0 in exact arithmetic) and points on flat ground. Without rounding, which of
    them fall below the cut would depend on the last bits of the interpolation (1e-15),
    i.e. on how the TIN is evaluated, not on the data. With `overwrite` the heights are
    written into `surface` (a float64 array made for this call: no second N-array).
    """
    h = np.subtract(z, surface, out=surface if overwrite else None)
    return np.round(h, 6, out=h)


def ground_cut(xy, z, rank, roots, p: MomentsOptions, inten, *, opening_window, opening_cell,
               surface_cell, iterations, scheduler, workers):
    """Window cuts on heights above a ground surface refitted ``iterations`` times.

    Parameters
    ----------
    xy, z : local coordinates in root-window order (coordinate units)
    rank : (N,) ndarray
        Input index of every point (breaks every tie independently of the order).
    roots : list of Tile
        Root windows (:func:`~._moments_windows.root_windows`).
    opening_window, opening_cell, surface_cell : float
        Window and grid cell of the lower envelope (coarser where its raster would pass
        16 cells a point: :func:`~._terrain_frame.terrain_cell`), cell of the ground
        surface (coordinate units).

    Returns
    -------
    ground, height, cut : (N,) ndarrays
        Ground mask, heights above the last surface, each point's interpolated cut.
    surface : callable or None
        The last ground surface (None when ``iterations == 0``), made in the frame of the
        1 m cells without their empty bands (:class:`~._terrain_frame.BandFrame`).
    fields, steps, windows
        The final pass's fields (``cluster_id``), analyses and windows.
    """
    # the envelope's raster follows the points as the terrain grid does: its cell
    # coarser only where it would pass 16 cells a point, its empty bands left out; the
    # surfaces' TINs use that frame too (a triangle across clumps 20 km apart would be
    # binned over the whole box: gigabytes)
    opening_cell = terrain_cell(xy, opening_cell)
    frame = BandFrame.of(xy, opening_cell)
    height = heights(z, opening_surface(xy, z, window=opening_window, cell=opening_cell,
                                        frame=frame), overwrite=True)
    surf = None
    # the cuts' grid and its frame are the same in every pass: moved once
    cut_frame = BandFrame.of(xy, p.finest_window)
    cut_xy = xy if cut_frame is None else cut_frame(xy)
    for it in range(iterations + 1):
        last = it == iterations
        fields, steps, windows = window_pass(xy, height, roots, p, inten, scheduler, workers,
                                             final=last)
        cut = interpolate_cuts(cut_xy, fields["cut"], p.finest_window, frame=None)
        ground = height <= cut
        if ground.sum() < 3:
            ground[:] = True
        if not last:
            fields = None  # this pass's window fields: the cut above holds what is needed
            surf = ground_surface(xy, z, cell=surface_cell, rank=rank,
                                  where=np.flatnonzero(ground), frame=frame)
            height = None  # the heights of this pass go before the next are made
            height = heights(z, surf(xy), overwrite=True)
    return ground, height, cut, surf, fields, steps, windows


def drop_raised_patches(xy, z, rank, ground, height, surf, *, surface_cell, step,
                        raised=None, refit=True):
    """Ground patches of the lowest-point grid standing above their surroundings on
    (almost) every side become objects; their heights are taken above the surface
    refitted without them. Returns ``(ground, height, surface)``.

    `raised`: ``raised_patches(xy, z, step=step, rank=rank)`` when the caller has it (the
    patches read only the coordinates, so they can be found beside the window passes).
    `refit` False: the ground alone, ``(ground, None, None)``, for a caller that replaces
    the surface and heights (the terrain step)."""
    if raised is None:
        raised = raised_patches(xy, z, step=step, rank=rank)
    raised = ground & raised
    if raised.any() and (ground & ~raised).sum() >= 3:
        ground = ground & ~raised
        if refit:
            surf = ground_surface(xy, z, cell=surface_cell, rank=rank,
                                  where=np.flatnonzero(ground),
                                  frame=(BandFrame.of(xy, surface_cell) if surf is None
                                         else surf.frame))
            height = heights(z, surf(xy), overwrite=True)
    return (ground, height, surf) if refit else (ground, None, None)
