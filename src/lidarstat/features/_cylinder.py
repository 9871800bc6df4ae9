"""Consistent-curvature test by a cylinder fit: is a curved neighbourhood a smooth surface?

The model, its statistic and the noise per neighbour are described in
``_cylinder_kernels`` (the Numba fit); this is the wrapper on NumPy arrays.
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import kernel_array
from ._cylinder_kernels import cylinder_rows


def cylinder_test(points, query, indptr, idx, axes, sigma, *, sensor=None,
                  return_centre=False, refine_axis=False):
    """Cylinder test of the rows of `query` (see the module doc).

    Parameters
    ----------
    points : (N, 3) ndarray
    query : (M,) ndarray of int
        The points tested; row r of the CSR (`indptr`, `idx`) lists the neighbours of
        ``query[r]`` (indices into `points`, the point itself included).
    axes : (M, 3) ndarray
        Unit axis direction per row (e.g. the point's minimum-curvature direction).
    sigma : float or (N,) array_like
        Noise std per point: along the rays with a `sensor`, else across the surface.
    sensor : (3,) array_like, optional
        Scanner position.
    refine_axis : bool
        Also fit the tilt of the axis (two more parameters, ``dof = n - 5``): the
        statistic is the smaller of the weighted RSS with the given axis and with the
        refined one; radius and centre stay those of the given axis.

    Returns
    -------
    stat, dof, radius : (M,) ndarray
        Weighted residual sum of squares (``~ chi2(dof)`` on a cylinder), ``n - 3`` and
        the fitted radius (inf: straight in the projection, i.e. planar).
    centre : (M, 3) ndarray
        A point of the fitted axis (NaN when straight); with ``return_centre`` only.
    """
    pts = np.asarray(points, dtype=np.float64)
    origin = pts.mean(axis=0)
    local = np.ascontiguousarray(pts - origin)
    m = len(query)
    stat, dof, radius = np.empty(m), np.empty(m), np.empty(m)
    centre = np.empty((m, 3))
    has_sensor = sensor is not None
    sens = (np.asarray(sensor, dtype=np.float64) - origin) if has_sensor else np.zeros(3)
    sig = kernel_array(np.broadcast_to(np.asarray(sigma, dtype=np.float64), (pts.shape[0],)))
    cylinder_rows(local, np.ascontiguousarray(query, dtype=np.int64),
                  np.ascontiguousarray(indptr, dtype=np.int64),
                  np.ascontiguousarray(idx, dtype=np.int64),  # one compiled variant
                  np.ascontiguousarray(axes, dtype=np.float64), sens, has_sensor, sig, stat,
                  dof, radius, centre, bool(refine_axis))
    if return_centre:
        return stat, dof, radius, centre + origin
    return stat, dof, radius
