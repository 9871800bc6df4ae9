"""Raster operations of the terrain step (:mod:`._terrain`) on grids of cell elevations.

Seeds (:func:`drop_bumps`, :func:`drop_opened`), growth by smooth continuation
(:func:`grow_ground`), the wall tests of grown regions and of parts of the surface
(:func:`reject_walled`, :func:`reject_plateaus`) and the growth onto low platforms
(:func:`grow_platforms`). A grid holds one elevation per cell, ``inf`` where the cell has
none; every operation is vectorised over the cells.
"""

from __future__ import annotations

import numpy as np

__all__ = ["drop_bumps", "drop_opened", "grow_ground", "grow_platforms", "reject_plateaus",
           "reject_walled"]

#: The eight neighbour offsets of a cell.
_DIRS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def _shift(a, di, dj, fill=np.inf):
    """``out[i, j] = a[i - di, j - dj]`` (the neighbour at offset ``(-di, -dj)``), `fill`
    outside."""
    out = np.full_like(a, fill)
    h, w = a.shape
    out[max(di, 0):h + min(di, 0), max(dj, 0):w + min(dj, 0)] = \
        a[max(-di, 0):h + min(-di, 0), max(-dj, 0):w + min(-dj, 0)]
    return out


def drop_opened(ground_z, *, cell, slope, max_radius):
    """Seed cells standing above a progressive opening of the seeds become empty.

    The progressive morphological filter of SMRF (Pingel et al. 2013) on the seed grid:
    openings with square windows of radius 1, 2, ... cells up to `max_radius`
    (coordinate units), each of the previous one; a cell is dropped when it stands more
    than ``slope * radius`` above an opening. It removes roofs narrower than the largest
    window that the moments cut kept; it also removes steep ground, which the growth puts
    back by smooth continuation (a roof it reaches that way is walled).
    """
    from scipy import ndimage as ndi

    have = np.isfinite(ground_z)
    if have.sum() < 3:
        return ground_z
    idx = ndi.distance_transform_edt(~have, return_distances=False, return_indices=True)
    last = ground_z[tuple(idx)]
    drop = np.zeros(ground_z.shape, bool)
    for r in range(1, max(1, int(round(max_radius / cell))) + 1):
        opened = ndi.grey_opening(last, size=(2 * r + 1, 2 * r + 1))
        drop |= have & (ground_z - opened > slope * r * cell)
        last = opened
    out = ground_z.copy()
    out[drop] = np.inf
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
    for dist, pair, dz in _border_steps(grown, label, lowest, grown_z):
        bound = step + max_rise * cell * dist
        walls += np.bincount(label[pair & (dz > bound)], minlength=n + 1)
        smooth += np.bincount(label[pair & (np.abs(dz) <= bound)], minlength=n + 1)
    bad = walls > wall_fraction * np.maximum(walls + smooth, 1)
    bad[0] = False
    drop = bad[label] & grown
    out = grown_z.copy()
    out[drop] = np.inf
    return out, int(drop.sum())


def _border_steps(region, label, lowest, z):
    """For each of the 8 directions, the border pairs of the labelled regions (a `region`
    cell and its neighbour in that direction, outside the cell's region, holding points)
    and the step down across them: yields ``(distance in cells, pair mask, z - lowest of
    the neighbour)``."""
    for di, dj in _DIRS:
        n_low = _shift(lowest, di, dj)
        n_label = _shift(label, di, dj, fill=-1)
        pair = region & (n_label != label) & np.isfinite(n_low)
        with np.errstate(invalid="ignore"):
            dz = z - n_low
        yield np.hypot(di, dj), pair, dz


def grow_platforms(surface_z, lowest, *, cell, max_rise, low_step, min_cells, wall_fraction):
    """Low platforms joined to the ground over a step no higher than `low_step`.

    A raised terrace, a plinth or a podium stands on a kerb-like wall a few decimetres
    high all round, so the smooth growth (within `step` of the extrapolated terrain) does
    not climb it. The growth is repeated with `low_step` instead of `step`; a connected
    region it adds is kept when it has at least `min_cells` cells (a car or a hedge is
    smaller) and at most `wall_fraction` of its border pairs (a region cell and an
    8-neighbour outside it holding points) step down by more than `low_step`: a platform
    is lower than `low_step` above the ground all round, a roof stands on walls higher
    than any platform's.

    Returns
    -------
    surface_z : (nx, ny) ndarray
        With the kept regions set to their lowest points.
    added : int
        Cells added.
    """
    from scipy import ndimage as ndi

    grown = grow_ground(lowest, surface_z, cell=cell, step=low_step, max_rise=max_rise)
    new = np.isfinite(grown) & ~np.isfinite(surface_z)
    label, n = ndi.label(new, structure=np.ones((3, 3), bool))
    if n == 0:
        return surface_z, 0
    walls = np.zeros(n + 1)
    pairs = np.zeros(n + 1)
    for _, pair, dz in _border_steps(new, label, lowest, grown):
        walls += np.bincount(label[pair & (dz > low_step)], minlength=n + 1)
        pairs += np.bincount(label[pair], minlength=n + 1)
    size = np.bincount(label.ravel(), minlength=n + 1)
    ok = (size >= min_cells) & (walls <= wall_fraction * np.maximum(pairs, 1))
    ok[0] = False
    keep = ok[label] & new
    out = surface_z.copy()
    out[keep] = grown[keep]
    return out, int(keep.sum())


def reject_plateaus(surface_z, lowest, *, cell, step, max_rise, fraction, rounds=3):
    """:func:`_reject_plateaus_once` repeated `rounds` times (a roof in steps loses its
    lowest level first, which walls the next level). Returns ``(surface_z, rejected)``."""
    total = 0
    for _ in range(rounds):
        surface_z, rejected = _reject_plateaus_once(surface_z, lowest, cell=cell, step=step,
                                                    max_rise=max_rise, fraction=fraction)
        total += rejected
        if not rejected:
            break
    return surface_z, total


def _reject_plateaus_once(surface_z, lowest, *, cell, step, max_rise, fraction):
    """Take back the parts of the surface standing on walls along most of their border.

    The surface cells are joined into parts by smooth 4-neighbour pairs (either cell
    within `step` of the extrapolation of the other and the cell beyond it, as the
    growth, and at most ``step + max_rise * cell`` apart). A border pair of a part is one
    of its cells and an 8-neighbour outside it holding points, compared with where the
    part would continue (the extrapolation of the cell and the part's cell behind it,
    the cell itself when that is not in the part): a wall when the neighbour's lowest
    point lies more than ``3 step`` under it, uphill when more than that above it,
    smooth otherwise. Every part but the largest with walls on more than `fraction` of
    its non-uphill border and more walls than uphill pairs is removed: a roof the
    moments cut kept as ground (a roof on the data's edge, a large flat roof, a flat
    roof set into a slope), which :func:`reject_walled` does not see because the growth
    did not add it. The data's edge is no border, so a roof cut by the edge is judged on
    its inner sides; a terrace is walled on its downhill side only.

    Returns
    -------
    surface_z : (nx, ny) ndarray
        Without the rejected parts.
    rejected : int
        Cells taken back.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    have = np.isfinite(surface_z)
    if have.sum() < 2:
        return surface_z, 0
    nx, ny = surface_z.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    rows, cols = [], []
    for di, dj in ((0, 1), (1, 0)):  # 4-neighbours, each unordered pair once
        n_z = _shift(surface_z, di, dj)
        n_i = _shift(index, di, dj, fill=-1)
        # the pair joins when either cell continues the other smoothly: within `step`
        # of the extrapolation of the other and the cell beyond it (as the growth)
        back = _shift(surface_z, -di, -dj)   # beyond this cell, away from the neighbour
        far = _shift(surface_z, 2 * di, 2 * dj)  # beyond the neighbour
        bound = step + max_rise * cell
        with np.errstate(invalid="ignore"):
            fwd = np.where(np.isfinite(back), 2 * surface_z - back, surface_z)
            bwd = np.where(np.isfinite(far), 2 * n_z - far, n_z)
            ok = (have & np.isfinite(n_z) & (np.abs(surface_z - n_z) <= bound)
                  & ((np.abs(n_z - fwd) <= step) | (np.abs(surface_z - bwd) <= step)))
        rows.append(index[ok])
        cols.append(n_i[ok])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    graph = coo_matrix((np.ones(r.size, np.int8), (r, c)), shape=(nx * ny, nx * ny))
    _, lab = connected_components(graph, directed=False)
    label = np.where(have, lab.reshape(nx, ny), -1)
    # parts numbered 0..n-1 over the surface cells only
    uniq, part = np.unique(label[have], return_inverse=True)
    n = uniq.size
    if n < 2:
        return surface_z, 0
    part_grid = np.full((nx, ny), -1, np.int64)
    part_grid[have] = part
    walls = np.zeros(n)
    smooth = np.zeros(n)
    uphill = np.zeros(n)
    for di, dj in _DIRS:
        n_low = np.minimum(_shift(lowest, di, dj), _shift(surface_z, di, dj))
        n_part = _shift(part_grid, di, dj, fill=-2)
        back = _shift(surface_z, -di, -dj)
        b_part = _shift(part_grid, -di, -dj, fill=-2)
        # where the part would continue: the extrapolation of the cell and the one
        # behind it when that is in the part, the cell itself otherwise
        with np.errstate(invalid="ignore"):
            pred = np.where(b_part == part_grid, 2 * surface_z - back, surface_z)
        bound = 3 * step
        border = have & (n_part != part_grid) & np.isfinite(n_low)
        with np.errstate(invalid="ignore"):
            dz = pred - n_low
        walls += np.bincount(part_grid[border & (dz > bound)], minlength=n)
        smooth += np.bincount(part_grid[border & (np.abs(dz) <= bound)], minlength=n)
        uphill += np.bincount(part_grid[border & (dz < -bound)], minlength=n)
    size = np.bincount(part, minlength=n)
    # walls on most of the border that is not uphill of the part (a roof set into a
    # slope has a higher neighbour on one side, as a terrace under a retaining wall
    # has), and more walls than uphill border (a terrace is walled on its downhill side
    # only)
    bad = (walls > fraction * np.maximum(walls + smooth, 1)) & (walls > uphill)
    bad[np.argmax(size)] = False
    drop = have & bad[np.maximum(part_grid, 0)]
    out = surface_z.copy()
    out[drop] = np.inf
    return out, int(drop.sum())
