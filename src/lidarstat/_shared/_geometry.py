"""Geometry helpers shared by several subpackages (features, classify)."""

from __future__ import annotations

import numpy as np

__all__ = ["mean_spacing", "scan_angles"]


def scan_angles(pts, sensor):
    """(N, 2) azimuth and elevation of every point seen from `sensor` (same origin)."""
    q = pts - sensor
    h = np.hypot(q[:, 0], q[:, 1])
    return np.ascontiguousarray(np.stack([np.arctan2(q[:, 1], q[:, 0]),
                                          np.arctan2(q[:, 2], h)], axis=1))


def mean_spacing(points):
    """Mean planimetric point spacing: sqrt(occupied area / N), the area from a coarse grid.

    Parameters
    ----------
    points : (N, 2+) ndarray
        Coordinates; the first two columns are used.

    Returns
    -------
    float
        The spacing (robust to holes and L-shaped clouds).
    """
    xy = points[:, :2]
    extent = np.ptp(xy, axis=0)
    # occupied area from a coarse grid (robust to holes and L-shaped clouds)
    cell = max(float(np.sqrt(np.prod(np.maximum(extent, 1e-9)) / max(points.shape[0], 1))) * 4,
               1e-9)
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    occupied = np.unique(ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]).size
    return float(np.sqrt(occupied * cell * cell / points.shape[0]))
