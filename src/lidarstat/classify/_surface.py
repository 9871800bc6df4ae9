"""Ground surface model from ground points: cell medians joined by a Delaunay TIN."""

from __future__ import annotations

import numpy as np

__all__ = ["ground_surface", "cell_keys"]


def cell_keys(xy: np.ndarray, cell: float, origin=None) -> np.ndarray:
    """One int64 key per point naming its ``cell x cell`` square (row-major, collision-free)."""
    o = xy.min(axis=0) if origin is None else np.asarray(origin, dtype=float)
    ij = np.floor((xy - o) / cell).astype(np.int64)
    ncol = int(ij[:, 1].max()) + 1 if ij.size else 1
    return ij[:, 0] * ncol + ij[:, 1]


def _cell_pick(xy, z, cell, which):
    key = cell_keys(xy, cell)
    o = np.lexsort((z, key))
    ks = key[o]
    b = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True])
    if which == "min":
        return o[b[:-1]]
    return o[(b[:-1] + b[1:] - 1) // 2]


def _extrapolate(P, V, tree, q, k=8):
    """Value at `q` of the least-squares plane through the `k` vertices nearest to it.

    Falls back to the nearest vertex where those vertices are (nearly) collinear.
    """
    k = min(k, len(P))
    d, nb = tree.query(q, k=k)
    nb = nb.reshape(len(q), k)
    if k < 3:
        return V[nb[:, 0]]
    dx = P[nb] - q[:, None, :]                      # (m, k, 2), q at the origin
    A = np.concatenate([np.ones((len(q), k, 1)), dx], axis=2)
    AtA = np.einsum("mki,mkj->mij", A, A)
    Atb = np.einsum("mki,mk->mi", A, V[nb])
    det = np.linalg.det(AtA)
    scale = np.einsum("mkj,mkj->m", dx, dx) / k
    ok = det > 1e-9 * np.maximum(scale, 1e-12) ** 2 * k ** 3
    out = V[nb[:, 0]].astype(float)
    if ok.any():
        out[ok] = np.linalg.solve(AtA[ok], Atb[ok][..., None])[:, 0, 0]
    return out


def ground_surface(xy_ground, z_ground, *, cell: float, which: str = "median"):
    """Return ``f(xy) -> z`` interpolating ground points (one per cell) linearly on a TIN.

    Parameters
    ----------
    xy_ground : (M, 2) ndarray
        Planimetric coordinates of ground points (local origin).
    z_ground : (M,) ndarray
        Their elevations.
    cell : float
        Thinning cell: one point per cell (the median or the lowest) becomes a TIN vertex,
        so the model costs O(cells) whatever the density.
    which : {'median', 'min'}

    Returns
    -------
    callable
        Linear interpolation inside the hull; outside it, the plane fitted to the nearest
        vertices (a terrain slope continues to the border of the cloud instead of
        stopping at the last cell's median point, which would lift the heights of a
        whole border strip of a sloped scene).
    """
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import Delaunay, QhullError, cKDTree

    sel = _cell_pick(xy_ground, z_ground, cell, which)
    P = np.ascontiguousarray(xy_ground[sel])
    V = z_ground[sel]
    tree = cKDTree(P)
    try:
        lin = LinearNDInterpolator(Delaunay(P), V) if len(P) >= 3 else None
    except QhullError:  # collinear vertices
        lin = None

    def f(q):
        q = np.asarray(q, dtype=float)
        if lin is None:
            return V[tree.query(q)[1]]
        v = lin(q)
        bad = np.isnan(v)
        if bad.any():
            v[bad] = _extrapolate(P, V, tree, q[bad])
        return v

    return f
