"""Numba kernels of the building test: the ground sample of the noise estimate, local
planes over CSR neighbourhoods, the residual of each point to its neighbours' tested
planes, the planar patches (union-find) and the highest roof point around each cell."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from .._shared._kernels import eigh3
from .._shared._kernels import uf_find as _find

_CHUNK = 1024  # rows of a parallel task of the per-point kernels


@njit_parallel
def local_planes(pts, indptr, indices, rows, centroid, normal, rss):  # pragma: no cover
    """Orthogonal (total least squares) plane of every neighbourhood.

    Row ``r`` holds the neighbours of point ``rows[r]``; writes the centroid, the unit
    normal (smallest eigenvector of the scatter matrix, oriented up) and the residual sum
    of squares (the smallest eigenvalue of the scatter matrix) of row ``r``. The rows go
    in chunks of `_CHUNK`, each with one set of 3 x 3 work arrays.
    """
    n = rows.size
    for c in prange((n + _CHUNK - 1) // _CHUNK):
        s = np.empty((3, 3))
        ev = np.empty(3)
        vec = np.empty((3, 3))
        for r in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
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
            s00 = s01 = s02 = s11 = s12 = s22 = 0.0
            for t in range(a, b):
                j = indices[t]
                d0, d1, d2 = pts[j, 0] - c0, pts[j, 1] - c1, pts[j, 2] - c2
                s00 += d0 * d0
                s01 += d0 * d1
                s02 += d0 * d2
                s11 += d1 * d1
                s12 += d1 * d2
                s22 += d2 * d2
            s[0, 0], s[0, 1], s[0, 2] = s00, s01, s02
            s[1, 0], s[1, 1], s[1, 2] = s01, s11, s12
            s[2, 0], s[2, 1], s[2, 2] = s02, s12, s22
            eigh3(s, ev, vec)
            sign = 1.0 if vec[2, 0] >= 0 else -1.0
            centroid[r, 0], centroid[r, 1], centroid[r, 2] = c0, c1, c2
            for k in range(3):
                normal[r, k] = sign * vec[k, 0]
            rss[r] = max(ev[0], 0.0)


@njit_parallel
def nearest_plane_residual(pts, indptr, indices, centroid, normal, planar, multi,
                           out, owner, n_multi):  # pragma: no cover - compiled
    """Smallest absolute distance of each point to the plane of a neighbour whose own
    neighbourhood passed the planarity test (inf where no neighbour passed); `owner` is
    that neighbour (-1 for none), `n_multi` the number of its neighbours flagged in
    `multi` (non-last returns). Rows are the points in order."""
    n = indptr.size - 1
    for c in prange((n + _CHUNK - 1) // _CHUNK):
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            best = np.inf
            who = -1
            count = 0
            for t in range(indptr[i], indptr[i + 1]):
                j = indices[t]
                count += multi[j]
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
            n_multi[i] = count


@njit_parallel
def roof_top(key, seeds, zmax, width, top):  # pragma: no cover - compiled
    """Largest `zmax` of the cells ``key + dx * width + dy`` (dx, dy in -1, 0, 1) among
    the sorted cell keys `seeds`, for every point (-inf where none of the nine is a seed);
    each row of three cells is one binary search."""
    n = key.size
    for c in prange((n + _CHUNK - 1) // _CHUNK):
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            best = -np.inf
            for dx in range(-1, 2):
                lo = key[i] + dx * width - 1
                t = np.searchsorted(seeds, lo)
                while t < seeds.size and seeds[t] <= lo + 2:
                    best = max(best, zmax[t])
                    t += 1
            top[i] = best


@njit_parallel
def roof_top_dense(key, roof, z, ncells, width, top):  # pragma: no cover - compiled
    """:func:`roof_top` on a dense table of the `ncells` cells: the highest `z` of the
    `roof` points of each cell, then for every point the largest of its nine cells."""
    zc = np.full(ncells, -np.inf)
    for i in range(key.size):
        if roof[i] and z[i] > zc[key[i]]:
            zc[key[i]] = z[i]
    n = key.size
    for c in prange((n + _CHUNK - 1) // _CHUNK):
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            best = -np.inf
            for dx in range(-1, 2):
                row = key[i] + dx * width
                best = max(best, max(zc[row - 1], max(zc[row], zc[row + 1])))
            top[i] = best


@njit
def ground_sample(xy, z, mask, ux, uz, most, side):  # pragma: no cover - compiled
    """The rows `mask` of ``(xy * ux, z * uz)`` about their mean, in row order: all of
    them when they are at most `most`, else those of an even spread of `side`-wide
    blocks (block ``7 bx + 3 by`` of the x, y block indices from the lowest corner, kept
    when a multiple of ``ceil(count / most)``). The mean is the sequential sum of the
    rows over their count (as NumPy's ``mean(axis=0)`` of the rows), so the sample is
    the one the copied rows would give; nothing but the sample is allocated."""
    n = mask.size
    m = 0
    s0 = s1 = s2 = 0.0
    for i in range(n):
        if mask[i]:
            s0 += xy[i, 0] * ux
            s1 += xy[i, 1] * ux
            s2 += z[i] * uz
            m += 1
    m0, m1, m2 = s0 / m, s1 / m, s2 / m
    every = 1
    lo0 = lo1 = np.inf
    if m > most:
        every = int(np.ceil(m / most))
        for i in range(n):
            if mask[i]:
                lo0 = min(lo0, xy[i, 0] * ux - m0)
                lo1 = min(lo1, xy[i, 1] * ux - m1)
    keep = 0
    for _pass in range(2):
        out = np.empty((keep, 3))
        keep = 0
        for i in range(n):
            if not mask[i]:
                continue
            x = xy[i, 0] * ux - m0
            y = xy[i, 1] * ux - m1
            if every > 1:
                block = (np.int64(np.floor((x - lo0) / side)) * 7
                         + np.int64(np.floor((y - lo1) / side)) * 3)
                if block % every != 0:
                    continue
            if _pass == 1:
                out[keep, 0] = x
                out[keep, 1] = y
                out[keep, 2] = z[i] * uz - m2
            keep += 1
    return out


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
