"""Sampling of the analytic height fields of ``_surfaces``: the shared keywords, the
(jittered) XY grid, the Monge-patch truth (normal, K, H from exact derivatives) and the
assembly of the :class:`SyntheticCloud`."""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ._truth import _build

_EDGE_DOC = "XY distance to the border of the sampled domain (lower bound of the 3-D distance)"


def _pair(value, name, func):
    """A positive float or a pair of positive floats -> (float, float)."""
    if np.ndim(value) == 0:
        v = check_scalar(value, name, func=func, low=0.0)
        return v, v
    vals = list(np.asarray(value, dtype=object).ravel())
    if len(vals) != 2:
        raise InvalidParameterError(
            f"The '{name}' parameter of {func} must be a float or a pair of floats. "
            f"Got {value!r} instead."
        )
    return tuple(check_scalar(v, name, func=func, low=0.0) for v in vals)


def _common(func, spacing, sigma, jitter, n, area):
    """Validate the shared keywords; derive the spacing from `n` when given."""
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0, closed="left")
    jitter = check_scalar(jitter, "jitter", func=func, low=0.0, high=0.5, closed="left")
    if n is not None:
        n = check_scalar(n, "n", func=func, low=1, closed="left", integer=True)
        h = math.sqrt(area / n)
        return (h, h), sigma, jitter
    return _pair(spacing, "spacing", func), sigma, jitter


def _grid(half_x, half_y, spacing, jitter, rng):
    """Regular grid symmetric about the origin covering [-half_x, half_x] x [-half_y, half_y].

    With ``jitter > 0`` every node moves uniformly by up to ``jitter * spacing`` in x and y.
    Returns flattened x, y and the (row, col) indices.
    """
    dx, dy = spacing
    nx = int(math.floor(2 * half_x / dx + 1e-9)) + 1
    ny = int(math.floor(2 * half_y / dy + 1e-9)) + 1
    if nx * ny > 50_000_000:
        raise InvalidParameterError(
            f"the requested grid has {nx * ny} nodes; increase `spacing` or decrease `n`"
        )
    xs = (np.arange(nx) - (nx - 1) / 2.0) * dx
    ys = (np.arange(ny) - (ny - 1) / 2.0) * dy
    X, Y = np.meshgrid(xs, ys)  # rows = y, cols = x
    J, I = np.meshgrid(np.arange(nx), np.arange(ny))
    x, y = X.ravel(), Y.ravel()
    if jitter > 0:
        x = x + rng.uniform(-jitter * dx, jitter * dx, x.size)
        y = y + rng.uniform(-jitter * dy, jitter * dy, y.size)
    ij = np.stack([I.ravel(), J.ravel()], axis=1).astype(np.int32)
    return x, y, ij


def _monge(fx, fy, fxx, fxy, fyy):
    """Normal, K and H of the Monge patch from exact derivatives (normal up)."""
    w2 = 1.0 + fx * fx + fy * fy
    w = np.sqrt(w2)
    normal = np.stack([-fx / w, -fy / w, 1.0 / w], axis=1)
    K = (fxx * fyy - fxy * fxy) / (w2 * w2)
    H = ((1.0 + fy * fy) * fxx - 2.0 * fx * fy * fxy + (1.0 + fx * fx) * fyy) / (2.0 * w2 * w)
    return normal, K, H


def _finish(name, x, y, z, normal, K, H, edge, ij, sigma, rng, meta, kmin=None, kmax=None):
    xyz = np.stack([x, y, z], axis=1)
    meta = dict(meta)
    meta.setdefault("edge_distance", _EDGE_DOC)
    meta["ij"] = ij
    return _build(xyz_true=xyz, normal=normal, K=K, H=H, kmin=kmin, kmax=kmax,
                  face=np.zeros(x.size, np.int32), edge_distance=edge, sigma=sigma, rng=rng,
                  name=name, meta=meta)


def _unit2(axis, func):
    a = np.asarray(axis, dtype=np.float64).ravel()
    if a.size == 3:
        if a[2] != 0:
            raise InvalidParameterError(
                f"The 'axis' parameter of {func} must lie in the XY plane. Got {axis!r} instead."
            )
        a = a[:2]
    if a.size != 2 or not np.all(np.isfinite(a)) or np.hypot(*a) == 0:
        raise InvalidParameterError(
            f"The 'axis' parameter of {func} must be a non-zero 2-vector. Got {axis!r} instead."
        )
    return a / np.hypot(*a)




def _radius_slope(func, radius, max_slope):
    """Checked radius R and largest slope (degrees) of a cylinder or sphere patch, and the
    largest distance from the axis (or centre) kept, ``R sin(max_slope)``."""
    R = check_scalar(radius, "radius", func=func, low=0.0)
    slope = check_scalar(max_slope, "max_slope", func=func, low=0.0, high=89.0, closed="right")
    return R, slope, R * math.sin(math.radians(slope))
