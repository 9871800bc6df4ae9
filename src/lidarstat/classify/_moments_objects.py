"""Classes of the moments classification: ground, road, buildings, vegetation by height.

Buildings are decided by the tested local planes of :mod:`._buildings`
(:func:`building_step`); the cell rule :func:`vegetation_like` decides when no building
test is given.
"""

from __future__ import annotations

import numpy as np

from ._buildings import building_tests
from ._moments_result import ASPRS
from ._surface import cell_keys

__all__ = ["asprs_classes", "building_step", "vegetation_like"]


def building_step(xy, z, height, ground, multi, units, *, min_object_height, min_height,
                  options):
    """The building test (:func:`~._buildings.building_tests`) on the moments' objects.

    `xy`, `z`, `height` and `min_object_height` are in coordinate units, `units` the
    (horizontal, vertical) metres per unit, `min_height` in metres; `options` is the
    :class:`~._moments_options.MomentsOptions` (``building_alpha``, ``sigma`` in metres,
    ``min_points``).

    Returns ``(tests, rows)``: the test of the candidates alone (objects at least
    `min_object_height` high; its mask and fields are per candidate) and their rows. The
    noise estimate reads the ground's rows in place.
    """
    ux, uz = units
    rows = np.flatnonzero(~ground & (height >= min_object_height))

    def metres(at):  # (len(at), 3) in metres, column by column: no (N, 2) temporaries
        out = np.empty((at.size, 3))
        for j in range(2):
            np.multiply(xy[at, j], ux, out=out[:, j])
        np.multiply(z[at], uz, out=out[:, 2])
        return out

    h = height[rows] if uz == 1 else height[rows] * uz
    tests = building_tests(metres(rows), np.ones(rows.size, bool), None, multi[rows], h,
                           alpha=options.building_alpha, sigma=options.sigma,
                           min_points=options.min_points, min_height=min_height,
                           ground_columns=(xy, z, ground, units))
    return tests, rows


def vegetation_like(xy, height, obj, multi, cell, spread):
    """Objects whose cell shows vegetation: several returns, or heights spread like a canopy.

    A building cell holds a roof (heights within a few decimetres of a plane over the
    cell); a tree cell holds points at many heights and pulses with several echoes. Cells
    are ``cell / 2`` wide (2 m by default: small enough that a crown overhanging a roof
    does not turn the roof cells beside it into vegetation; 8 m cells did on the synthetic
    town, building recall 0.57-0.84 against 0.97-0.98 with 2 m cells). A cell is
    vegetation when more than half of its object points are non-last returns or its
    object heights span more than `spread` (``4 * surface_cell`` in height units); every
    non-last return is vegetation.
    """
    out = np.zeros(height.size, bool)
    idx = np.flatnonzero(obj)
    if idx.size == 0:
        return out
    key = cell_keys(xy[idx], 0.5 * cell)
    _, inv = np.unique(key, return_inverse=True)
    k = inv.max() + 1
    hmax = np.full(k, -np.inf)
    hmin = np.full(k, np.inf)
    np.maximum.at(hmax, inv, height[idx])
    np.minimum.at(hmin, inv, height[idx])
    cnt = np.bincount(inv, minlength=k)
    mfrac = np.bincount(inv, weights=multi[idx].astype(float), minlength=k) / np.maximum(cnt, 1)
    veg_cell = (hmax - hmin > spread) | (mfrac > 0.5)
    out[idx] = veg_cell[inv] | multi[idx]
    return out


def asprs_classes(xy, height, ground, road, multi, *, min_object_height, vegetation_heights,
                  surface_cell, height_spread, buildings=None):
    """ASPRS code of every point (lengths in coordinate units).

    Ground is 2, or 11 where it is road; a non-ground point closer than
    `min_object_height` to the ground surface is unclassified (1); the other objects are
    vegetation where their cell looks like it (:func:`vegetation_like`), low (3), medium
    (4) or high (5) by the `vegetation_heights`, and buildings (6) where they are not
    vegetation and at least as high as the upper vegetation height. With `buildings` (the
    mask of :func:`building_step`) the buildings are those objects and every other object
    is vegetation by height.
    """
    cls = np.full(height.size, ASPRS["unclassified"], np.uint8)
    cls[ground] = ASPRS["ground"]
    cls[ground & road] = ASPRS["road"]
    obj = ~ground & (height >= min_object_height)
    h0, h1 = vegetation_heights
    if buildings is None:
        veg = obj & vegetation_like(xy, height, obj, multi, surface_cell, height_spread)
        bld = obj & ~veg & (height >= h1)
    else:
        bld = obj & buildings
    cls[bld] = ASPRS["building"]
    vmask = obj & ~bld
    cls[vmask & (height < h0)] = ASPRS["low_vegetation"]
    cls[vmask & (height >= h0) & (height < h1)] = ASPRS["medium_vegetation"]
    cls[vmask & (height >= h1)] = ASPRS["high_vegetation"]
    return cls
