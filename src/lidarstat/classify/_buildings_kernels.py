"""Numba kernels of the building test: local planes over CSR neighbourhoods, the residual
of each point to its neighbours' tested planes, and the planar patches (union-find)."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from .._shared._kernels import eigh3
from .._shared._kernels import uf_find as _find


@njit_parallel
def local_planes(pts, indptr, indices, rows, centroid, normal, rss):  # pragma: no cover
    """Orthogonal (total least squares) plane of every neighbourhood.

    Row ``r`` holds the neighbours of point ``rows[r]``; writes the centroid, the unit
    normal (smallest eigenvector of the scatter matrix, oriented up) and the residual sum
    of squares (the smallest eigenvalue of the scatter matrix) of row ``r``.
    """
    for r in prange(rows.size):
        a, b = indptr[r], indptr[r + 1]
        m = b - a
        c0 = c1 = c2 = 0.0
        for t in range(a, b):
            j = indices[t]
            c0 += pts[j, 0]
            c1 += pts[j, 1]
            c2 += pts[j, 2]
        c0 /= m
        c1 /= m
        c2 /= m
        s = np.zeros((3, 3))
        for t in range(a, b):
            j = indices[t]
            d0, d1, d2 = pts[j, 0] - c0, pts[j, 1] - c1, pts[j, 2] - c2
            s[0, 0] += d0 * d0
            s[0, 1] += d0 * d1
            s[0, 2] += d0 * d2
            s[1, 1] += d1 * d1
            s[1, 2] += d1 * d2
            s[2, 2] += d2 * d2
        s[1, 0], s[2, 0], s[2, 1] = s[0, 1], s[0, 2], s[1, 2]
        ev = np.empty(3)
        vec = np.empty((3, 3))
        eigh3(s, ev, vec)
        sign = 1.0 if vec[2, 0] >= 0 else -1.0
        centroid[r, 0], centroid[r, 1], centroid[r, 2] = c0, c1, c2
        for k in range(3):
            normal[r, k] = sign * vec[k, 0]
        rss[r] = max(ev[0], 0.0)


@njit_parallel
def nearest_plane_residual(pts, indptr, indices, centroid, normal, planar,
                           out, owner):  # pragma: no cover - compiled
    """Smallest absolute distance of each point to the plane of a neighbour whose own
    neighbourhood passed the planarity test (inf where no neighbour passed); `owner` is
    that neighbour (-1 for none). Rows are the points in order."""
    n = indptr.size - 1
    for i in prange(n):
        best = np.inf
        who = -1
        for t in range(indptr[i], indptr[i + 1]):
            j = indices[t]
            if not planar[j]:
                continue
            d = abs((pts[i, 0] - centroid[j, 0]) * normal[j, 0]
                    + (pts[i, 1] - centroid[j, 1]) * normal[j, 1]
                    + (pts[i, 2] - centroid[j, 2]) * normal[j, 2])
            if d < best:
                best = d
                who = j
        out[i] = best
        owner[i] = who


@njit
def planar_patches(indptr, indices, on_plane):  # pragma: no cover - compiled
    """Connected components of the points on a tested plane, joined along the
    neighbourhood graph (both ends on a plane); labels 1..m, 0 for the other points."""
    n = indptr.size - 1
    parent = np.arange(n)
    for i in range(n):
        if not on_plane[i]:
            continue
        for t in range(indptr[i], indptr[i + 1]):
            j = indices[t]
            if j != i and on_plane[j]:
                ri, rj = _find(parent, i), _find(parent, j)
                if ri != rj:
                    if ri < rj:
                        parent[rj] = ri
                    else:
                        parent[ri] = rj
    label = np.zeros(n, np.int64)
    root_label = np.zeros(n, np.int64)
    m = 0
    for i in range(n):
        if not on_plane[i]:
            continue
        r = _find(parent, i)
        if root_label[r] == 0:
            m += 1
            root_label[r] = m
        label[i] = root_label[r]
    return label
