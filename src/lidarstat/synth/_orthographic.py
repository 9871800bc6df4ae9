"""Orthographic range scans of CSG solids: vertical rays cast along -z on an XY grid.

Every ray starts above the scene at (x, y) and travels along d = (0, 0, -1); the ray
parameter is ``t = -z``; the solids and their interval lists are in
:mod:`lidarstat.synth._csg`.

``edge_distance`` of a scan is the 3-D distance from a sample to the nearest *boundary
sample*, where boundary samples come from 8-neighbour pairs of grid samples:

* a sample next to a grid node whose ray misses the object (silhouette) is a boundary
  sample itself;
* a pair on different faces whose depths differ by more than ``jump_factor`` times their
  XY separation (an occlusion / depth jump) makes both samples boundary samples;
* any other pair on different faces (a crease or a face boundary) contributes the 3-D
  midpoint of the pair.

The result is accurate to about one grid step.  Faces of these scenes never occlude
themselves, so pairs on the same face are never boundaries.
"""

from __future__ import annotations

import numpy as np

from ._csg import _face_truth

__all__ = ["scan_orthographic"]


def _edge_distance(img_face, img_z, x0, y0, dx, dy, jump_factor, chunk=1024):
    """3-D distance of each valid pixel to the nearest boundary sample (module docstring)."""
    ny, nx = img_face.shape
    valid = img_face >= 0
    X = x0 + dx * np.arange(nx)[None, :] + np.zeros((ny, 1))
    Y = y0 + dy * np.arange(ny)[:, None] + np.zeros((1, nx))
    P = np.stack([X, Y, np.where(valid, img_z, 0.0)], axis=-1)
    is_boundary = np.zeros((ny, nx), bool)
    mids = []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        # pair (i, j) with (i + di, j + dj)
        i0, i1 = 0, ny - di
        j0, j1 = max(0, -dj), nx - max(0, dj)
        a = (slice(i0, i1), slice(j0, j1))
        b = (slice(i0 + di, i1 + di), slice(j0 + dj, j1 + dj))
        va, vb = valid[a], valid[b]
        # silhouette: a valid pixel next to background
        is_boundary[a] |= va & ~vb
        is_boundary[b] |= vb & ~va
        both = va & vb & (img_face[a] != img_face[b])
        sep = np.hypot(di * dy, dj * dx)
        jump = both & (np.abs(img_z[a] - img_z[b]) > jump_factor * sep)
        is_boundary[a] |= jump
        is_boundary[b] |= jump
        crease = both & ~jump
        mids.append(0.5 * (P[a][crease] + P[b][crease]))
    # pixels on the border of the grid count as next to background
    for sl in (np.s_[0, :], np.s_[-1, :], np.s_[:, 0], np.s_[:, -1]):
        is_boundary[sl] |= valid[sl]
    Bset = np.concatenate([P[is_boundary]] + mids, axis=0)
    pts = P[valid]
    out = np.full(pts.shape[0], np.inf)
    if Bset.shape[0] == 0:
        return out
    b2 = np.einsum("ij,ij->i", Bset, Bset)
    # centre the coordinates to limit cancellation in |p|^2 + |b|^2 - 2 p.b
    cen = pts.mean(0)
    Bc = Bset - cen
    b2 = np.einsum("ij,ij->i", Bc, Bc)
    for s in range(0, pts.shape[0], chunk):
        pc = pts[s:s + chunk] - cen
        d2 = np.einsum("ij,ij->i", pc, pc)[:, None] + b2[None, :] - 2.0 * (pc @ Bc.T)
        out[s:s + chunk] = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
    out[is_boundary[valid]] = 0.0
    return out


def scan_orthographic(solid, faces, *, spacing, margin=3, jump_factor=3.0):
    """Cast vertical rays (along -z) on an XY grid through `solid`; keep the first hits.

    Parameters
    ----------
    solid : Cylinder, Box or the result of :func:`union` / :func:`difference`
        The scene.
    faces : FaceRegistry
        Registry the primitives of `solid` were created with.
    spacing : (float, float)
        Grid steps (dx, dy).  Grid nodes lie at integer multiples of the steps.
    margin : int
        Extra empty grid nodes around the XY bounding box of the solid.
    jump_factor : float
        Depth difference, in units of the XY separation of two neighbouring samples on
        different faces, above which the pair is an occlusion jump (not a crease).

    Returns
    -------
    dict
        ``xyz`` (N, 3), ``normal``, ``K``, ``H``, ``kmin``, ``kmax``, ``face`` (int32),
        ``flipped`` (bool), ``edge_distance``, ``ij`` (N, 2) grid (row, col) indices,
        ``grid_origin`` (x0, y0) and ``grid_shape`` (ny, nx).
    """
    dx, dy = float(spacing[0]), float(spacing[1])
    lo, hi = solid.xy_bounds()
    i_lo = np.floor(lo / (dx, dy)).astype(int) - margin
    i_hi = np.ceil(hi / (dx, dy)).astype(int) + margin
    nx, ny = i_hi[0] - i_lo[0] + 1, i_hi[1] - i_lo[1] + 1
    x0, y0 = i_lo[0] * dx, i_lo[1] * dy
    X = x0 + dx * np.arange(nx)
    Y = y0 + dy * np.arange(ny)
    XX, YY = np.meshgrid(X, Y)
    iv = solid.intervals(XX.ravel(), YY.ravel())
    t = iv.t0[:, 0]  # intervals are sorted: the first column is the first entry
    code = iv.f0[:, 0]
    hit = np.isfinite(t) & (code != 0)
    fid = np.abs(code) - 1
    flipped = code < 0
    pts = np.stack([XX.ravel(), YY.ravel(), -t], axis=1)[hit]
    fid, flipped = fid[hit], flipped[hit]
    normal, K, H, kmin, kmax = _face_truth(faces.faces, fid, flipped, pts)
    # grazing hits with a normal not facing the viewer (rounding) are dropped
    front = normal[:, 2] > 1e-12
    hit[hit] = front
    pts, fid, flipped = pts[front], fid[front], flipped[front]
    normal, K, H, kmin, kmax = normal[front], K[front], H[front], kmin[front], kmax[front]
    img_face = np.full(ny * nx, -1, dtype=np.int64)
    img_face[hit] = fid
    img_face = img_face.reshape(ny, nx)
    img_z = np.where(hit, -t, np.nan).reshape(ny, nx)
    edge = _edge_distance(img_face, img_z, x0, y0, dx, dy, jump_factor)
    II, JJ = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    ij = np.stack([II.ravel(), JJ.ravel()], axis=1)[hit].astype(np.int32)
    return {
        "xyz": pts, "normal": normal, "K": K, "H": H, "kmin": kmin, "kmax": kmax,
        "face": fid.astype(np.int32), "flipped": flipped,
        "edge_distance": edge, "ij": ij, "grid_origin": (x0, y0), "grid_shape": (ny, nx),
    }
