"""Numba kernels of the neighbourhood covariance features (Bae, Lichti et al. 2005/2007).

Two kernels do the work:

* :func:`knn_cells` - exact k nearest neighbours on the uniform grid of a
  :class:`lidarstat.neighbors.CellIndex` (the search kernels of
  :mod:`lidarstat.neighbors`, driven here so that each point's covariance is computed
  while its neighbours are in cache). The candidates of all points of one cell are the
  points of the (2R+1)^3 cells around it (R = 1 first); a point whose k-th candidate is
  farther than the distance from the point to the faces of that block is searched again
  with R + 1, so the result is exact. A quickselect keeps the k best, insertion-sorted
  so rows are ordered by distance (the region growing of Fig. 4 walks them from
  the closest). Working per cell in the grid's sorted order keeps the candidates in cache;
  this is several times faster than a KD-tree query for k = 50.
* :func:`covariance_rows` - per query point, the centred covariance of its neighbourhood
  (two passes: centroid, then the sum of outer products of the centred offsets, divided by
  n - 1), its eigen-decomposition by cyclic Jacobi (``_eigh3``), the normal (smallest
  eigenvector) oriented toward the sensor or up, and the index point's offset from the
  centroid in the plane of the two largest eigenvectors (the boundary test, eq. 6-8).

Coordinates are local (a grid origin is subtracted) and the covariance is accumulated from
centred offsets, so UTM-sized coordinates lose no precision.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from .._shared._kernels import eigh3 as _eigh3
from ..neighbors import GRID_CELL_CHUNK as _CELL_CHUNK
from ..neighbors import grid_cell_block as _cell_block
from ..neighbors import grid_knn_found as _knn_found
from ..neighbors import grid_knn_scratch as _scratch
from ._frame_kernels import orient_normal

# columns of the per-point output of covariance_rows
C_L0 = 0  # eigenvalues, ascending (lambda0 <= lambda1 <= lambda2)
C_L1 = 1
C_L2 = 2
C_NX = 3  # normal = eigenvector of lambda0, oriented
C_NY = 4
C_NZ = 5
C_AX = 6  # eigenvector of lambda2 (largest)
C_AY = 7
C_AZ = 8
C_CX = 9  # neighbourhood centroid (local coordinates)
C_CY = 10
C_CZ = 11
C_U = 12  # offset of the index point from the centroid along e(lambda2)
C_V = 13  # ... along e(lambda1)
C_N = 14  # neighbours used
NCOL = 15

_ROW_CHUNK = 256


@njit_parallel
def knn_cells(c0, c1, pts, cell_keys, cell_start, dims, cell, k, tau0, sort, out_idx,
              order, nbr_idx, nbr_dist, sensor, has_sensor, out_feat):
    """Exact `k` nearest neighbours (self included) of the points of cells ``c0..c1-1``.

    `pts` are the grid's sorted local coordinates; output row r is sorted position
    ``cell_start[c0] + r``; ``out_idx`` (sorted positions, any integer dtype) gets the k
    neighbours, in ascending distance if `sort`. With `sort` the neighbourhoods are also
    written in input order as CSR entries of k per row: ``nbr_idx[order[p] k + t]`` (input
    indices, ``order`` maps sorted positions to input indices) and ``nbr_dist`` (the
    distances); they are not touched otherwise and may be empty. Requires
    ``k <= len(pts)``. `tau0` is
    a typical k-th neighbour distance: candidates farther than 1.15 times the previous
    point's k-th distance (tau0 for a cell's first point) are dropped before the
    selection, unless fewer than k remain (then all are kept), so the pre-filter changes
    the speed, never the result. The covariance features of each point
    (:func:`_covariance_one`) are computed at once into ``out_feat`` (rows as
    ``out_idx``) while its neighbours are in cache.
    """
    base = cell_start[c0]
    ncell = c1 - c0
    nchunks = (ncell + _CELL_CHUNK - 1) // _CELL_CHUNK
    for ch in prange(nchunks):
        work = _scratch(1024)
        ranges = np.empty((9, 2), dtype=np.int64)
        cov = np.empty((3, 3))
        evals = np.empty(3)
        evecs = np.empty((3, 3))
        for c in range(c0 + ch * _CELL_CHUNK, min(c1, c0 + (ch + 1) * _CELL_CHUNK)):
            ix0, iy0, iz0, nr, work = _cell_block(c, cell_keys, cell_start, dims, ranges, work)
            tau2 = tau0 * tau0
            for i in range(cell_start[c], cell_start[c + 1]):
                kth, _, work = _knn_found(pts[i, 0], pts[i, 1], pts[i, 2], ix0, iy0, iz0, pts,
                                          cell_keys, cell_start, dims, cell, k, sort, tau2,
                                          ranges, nr, work)
                td = work[2]
                ti = work[3]
                tau2 = kth * 1.3225  # (1.15 r_k)^2 for the next point of the cell
                r = i - base
                for t in range(k):
                    out_idx[r, t] = ti[t]
                if sort:
                    row = order[i] * k
                    for t in range(k):
                        nbr_idx[row + t] = order[ti[t]]
                        nbr_dist[row + t] = np.sqrt(td[t])
                # the row just written, not the int64 scratch: _covariance_one then has
                # the index dtype of covariance_rows' CSR and is compiled once
                _covariance_one(i, pts, out_idx[r], 0, k, sensor, has_sensor, cov, evals,
                                evecs, out_feat[r])


# ------------------------------------------------------------------ covariance per row
@njit
def _covariance_one(pos, pts, idx, s, e, sensor, has_sensor, cov, evals, evecs, out):
    """Features of one neighbourhood (rows s..e of `idx`) of the point at `pos`."""
    n = e - s
    out[C_N] = n
    if n < 3:
        for a in range(NCOL - 1):
            out[a] = np.nan
        return
    # pass 1: centroid relative to the index point
    px = pts[pos, 0]
    py = pts[pos, 1]
    pz = pts[pos, 2]
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for t in range(s, e):
        j = idx[t]
        m0 += pts[j, 0] - px
        m1 += pts[j, 1] - py
        m2 += pts[j, 2] - pz
    m0 /= n
    m1 /= n
    m2 /= n
    # pass 2: centred second moments
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(s, e):
        j = idx[t]
        d0 = pts[j, 0] - px - m0
        d1 = pts[j, 1] - py - m1
        d2 = pts[j, 2] - pz - m2
        c00 += d0 * d0
        c01 += d0 * d1
        c02 += d0 * d2
        c11 += d1 * d1
        c12 += d1 * d2
        c22 += d2 * d2
    f = 1.0 / (n - 1)
    cov[0, 0] = c00 * f
    cov[0, 1] = c01 * f
    cov[0, 2] = c02 * f
    cov[1, 0] = c01 * f
    cov[1, 1] = c11 * f
    cov[1, 2] = c12 * f
    cov[2, 0] = c02 * f
    cov[2, 1] = c12 * f
    cov[2, 2] = c22 * f
    _eigh3(cov, evals, evecs)
    for a in range(3):
        out[C_L0 + a] = max(evals[a], 0.0)
    n0, n1, n2 = orient_normal(evecs[0, 0], evecs[1, 0], evecs[2, 0], px, py, pz, sensor,
                               has_sensor)
    out[C_NX] = n0
    out[C_NY] = n1
    out[C_NZ] = n2
    out[C_AX] = evecs[0, 2]
    out[C_AY] = evecs[1, 2]
    out[C_AZ] = evecs[2, 2]
    out[C_CX] = px + m0
    out[C_CY] = py + m1
    out[C_CZ] = pz + m2
    # index point minus centroid, in the plane of the two largest eigenvectors (eq. 7, 8)
    out[C_U] = -(m0 * evecs[0, 2] + m1 * evecs[1, 2] + m2 * evecs[2, 2])
    out[C_V] = -(m0 * evecs[0, 1] + m1 * evecs[1, 1] + m2 * evecs[2, 1])


@njit_parallel
def covariance_rows(pts, query, indptr, idx, sensor, has_sensor, out):
    """Covariance features of every CSR row: row r is the neighbourhood of ``pts[query[r]]``.

    ``out`` is (M, NCOL); rows with fewer than 3 neighbours are NaN.
    """
    m = query.size
    nchunks = (m + _ROW_CHUNK - 1) // _ROW_CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        evals = np.empty(3)
        evecs = np.empty((3, 3))
        for r in range(ch * _ROW_CHUNK, min(m, (ch + 1) * _ROW_CHUNK)):
            _covariance_one(query[r], pts, idx, indptr[r], indptr[r + 1], sensor, has_sensor,
                            cov, evals, evecs, out[r])


@njit_parallel
def neighbourhood_variance(values, indptr, idx, mean_out, var_out):
    """Mean and population variance (eq. 5, 1/n) of `values` over each CSR row, NaN ignored."""
    m = indptr.size - 1
    for r in prange(m):
        n = 0
        acc = 0.0
        for t in range(indptr[r], indptr[r + 1]):
            v = values[idx[t]]
            if v == v:
                acc += v
                n += 1
        if n == 0:
            mean_out[r] = np.nan
            var_out[r] = np.nan
            continue
        mu = acc / n
        acc = 0.0
        for t in range(indptr[r], indptr[r + 1]):
            v = values[idx[t]]
            if v == v:
                acc += (v - mu) * (v - mu)
        mean_out[r] = mu
        var_out[r] = acc / n


@njit_parallel
def table_second_pass(raw, nbr, sv, normals, mean_out, var_out, spread):
    """The second pass over a dense (M, k) neighbour table of sorted positions, in one.

    First every row's surface variation ``sv`` (eq. 4, from the eigenvalue columns of the
    kernel output `raw`) and a compact copy of its normal (`normals`, (M, 3)), then per
    row the mean and population variance of `sv` over its neighbours (eq. 5, NaN
    ignored; as :func:`neighbourhood_variance`) and :func:`_normal_spread_one` of the
    normals into `spread` (M, 4). The same operations as the three separate passes it
    replaced (bit-identical), with one read of the table and no NumPy temporaries.
    """
    m = nbr.shape[0]
    k = nbr.shape[1]
    for r in prange(m):
        sv[r] = raw[r, C_L0] / (raw[r, C_L0] + raw[r, C_L1] + raw[r, C_L2])
        normals[r, 0] = raw[r, C_NX]
        normals[r, 1] = raw[r, C_NY]
        normals[r, 2] = raw[r, C_NZ]
    for r in prange(m):
        n = 0
        acc = 0.0
        for t in range(k):
            v = sv[nbr[r, t]]
            if v == v:
                acc += v
                n += 1
        if n == 0:
            mean_out[r] = np.nan
            var_out[r] = np.nan
        else:
            mu = acc / n
            acc = 0.0
            for t in range(k):
                v = sv[nbr[r, t]]
                if v == v:
                    acc += (v - mu) * (v - mu)
            mean_out[r] = mu
            var_out[r] = acc / n
        _normal_spread_one(r, normals, nbr[r], 0, k, spread[r])


# ------------------------------------------------------------------ principal directions
@njit
def _normal_spread_one(i, normals, idx, s, e, out):
    """Direction of largest change of the normal over one neighbourhood (section 5).

    The neighbours' normals, flipped to the index normal's side, are expressed in a basis
    (b1, b2) of its tangent plane; the larger eigenvector of their 2x2 covariance (closed
    form) is the direction in which the normal turns fastest: the maximum curvature
    direction. out = [dx, dy, dz, lmax].
    """
    n0 = normals[i, 0]
    n1 = normals[i, 1]
    n2 = normals[i, 2]
    if not (n0 == n0):
        for a in range(4):
            out[a] = np.nan
        return
    # tangent basis: b1 orthogonal to n from the coordinate axis least aligned with n
    if abs(n0) <= abs(n1) and abs(n0) <= abs(n2):
        b10, b11, b12 = 0.0, -n2, n1
    elif abs(n1) <= abs(n2):
        b10, b11, b12 = n2, 0.0, -n0
    else:
        b10, b11, b12 = -n1, n0, 0.0
    nb = np.sqrt(b10 * b10 + b11 * b11 + b12 * b12)
    b10 /= nb
    b11 /= nb
    b12 /= nb
    b20 = n1 * b12 - n2 * b11
    b21 = n2 * b10 - n0 * b12
    b22 = n0 * b11 - n1 * b10
    su = sv = suu = suv = svv = 0.0
    cnt = 0
    for t in range(s, e):
        j = idx[t]
        a0 = normals[j, 0]
        if not (a0 == a0):
            continue
        a1 = normals[j, 1]
        a2 = normals[j, 2]
        if a0 * n0 + a1 * n1 + a2 * n2 < 0.0:
            a0 = -a0
            a1 = -a1
            a2 = -a2
        u = a0 * b10 + a1 * b11 + a2 * b12
        v = a0 * b20 + a1 * b21 + a2 * b22
        su += u
        sv += v
        suu += u * u
        suv += u * v
        svv += v * v
        cnt += 1
    if cnt < 3:
        for a in range(4):
            out[a] = np.nan
        return
    # centred 2x2 covariance (the values are bounded by 1: no cancellation problem)
    cuu = (suu - su * su / cnt) / (cnt - 1)
    cuv = (suv - su * sv / cnt) / (cnt - 1)
    cvv = (svv - sv * sv / cnt) / (cnt - 1)
    half = 0.5 * (cuu - cvv)
    root = np.sqrt(half * half + cuv * cuv)
    lmax = 0.5 * (cuu + cvv) + root
    # eigenvector of lmax: (cuv, lmax - cuu) or (lmax - cvv, cuv), the better conditioned
    if half >= 0.0:
        x = lmax - cvv
        y = cuv
    else:
        x = cuv
        y = lmax - cuu
    nrm = np.sqrt(x * x + y * y)
    if nrm == 0.0:  # isotropic: any tangent direction
        x = 1.0
        y = 0.0
        nrm = 1.0
    x /= nrm
    y /= nrm
    out[0] = x * b10 + y * b20
    out[1] = x * b11 + y * b21
    out[2] = x * b12 + y * b22
    out[3] = max(lmax, 0.0)


@njit_parallel
def normal_spread_rows_offset(normals, row0, indptr, idx, out):
    """:func:`_normal_spread_one` for every CSR row; row r is point ``row0 + r``."""
    m = indptr.size - 1
    for r in prange(m):
        _normal_spread_one(row0 + r, normals, idx, indptr[r], indptr[r + 1], out[r])


# ------------------------------------------------------------------ output assembly
#: rows of the per-point field block written by :func:`assemble`, in ``FIELDS`` order
FIELD_ROWS = ("NormalX", "NormalY", "NormalZ", "Eigenvalue0", "Eigenvalue1", "Eigenvalue2",
              "SurfaceVariation", "CurvatureVariance", "Linearity", "Planarity", "Scattering",
              "Verticality", "Omnivariance", "Anisotropy", "Eigenentropy", "EigenvalueSum",
              "DemantkeVerticality", "PrincipalDirX", "PrincipalDirY", "PrincipalDirZ",
              "NormalVariation")
MODE_RAW = 0
MODE_SQRT = 1
MODE_NORMALIZED = 2


@njit
def _xlogx(x):
    return x * np.log(x) if x > 0 else 0.0


@njit_parallel
def assemble(raw, mean_sv, var_sv, spread, source, origin, mode, fields, centroid, major,
             offset_uv, mean_out, counts):
    """Every output array of a point in input order, from the per-row kernel outputs.

    Output point i takes row ``source[i]`` of `raw`, `mean_sv`, `var_sv` and `spread`
    (the grid's sorted order back to input order). The eigen features follow
    :func:`lidarstat.features.eigen_features` operation for operation (same rounding):
    ratios of the eigenvalues (`mode` raw), their square roots (sqrt) or the eigenvalues
    over their sum (normalized); ``SurfaceVariation`` and ``EigenvalueSum`` always raw.
    `fields` is (len(FIELD_ROWS), N).
    """
    n = source.size
    for i in prange(n):
        s = source[i]
        r0 = raw[s, C_L0]
        r1 = raw[s, C_L1]
        r2 = raw[s, C_L2]
        total = r0 + r1 + r2
        if mode == MODE_SQRT:
            l0 = np.sqrt(r0)
            l1 = np.sqrt(r1)
            l2 = np.sqrt(r2)
        elif mode == MODE_NORMALIZED:
            l0 = r0 / total
            l1 = r1 / total
            l2 = r2 / total
        else:
            l0 = r0
            l1 = r1
            l2 = r2
        n0 = raw[s, C_NX]
        n1 = raw[s, C_NY]
        n2 = raw[s, C_NZ]
        a0 = raw[s, C_AX]
        a1 = raw[s, C_AY]
        a2 = raw[s, C_AZ]
        m0 = n1 * a2 - n2 * a1  # middle eigenvector = normal x major
        m1 = n2 * a0 - n0 * a2
        m2 = n0 * a1 - n1 * a0
        u0 = l2 * abs(a0) + l1 * abs(m0) + l0 * abs(n0)
        u1 = l2 * abs(a1) + l1 * abs(m1) + l0 * abs(n1)
        u2 = l2 * abs(a2) + l1 * abs(m2) + l0 * abs(n2)
        fields[0, i] = n0
        fields[1, i] = n1
        fields[2, i] = n2
        fields[3, i] = r0
        fields[4, i] = r1
        fields[5, i] = r2
        fields[6, i] = r0 / total
        fields[7, i] = var_sv[s]
        fields[8, i] = (l2 - l1) / l2
        fields[9, i] = (l1 - l0) / l2
        fields[10, i] = l0 / l2
        fields[11, i] = u2 / np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        fields[12, i] = np.cbrt(l0 * l1 * l2)
        fields[13, i] = (l2 - l0) / l2
        fields[14, i] = -(_xlogx(l0) + _xlogx(l1) + _xlogx(l2))
        fields[15, i] = total
        fields[16, i] = 1.0 - abs(n2)
        for a in range(4):
            fields[17 + a, i] = spread[s, a]
        for a in range(3):
            centroid[i, a] = raw[s, C_CX + a] + origin[a]
        major[i, 0] = a0
        major[i, 1] = a1
        major[i, 2] = a2
        offset_uv[i, 0] = raw[s, C_U]
        offset_uv[i, 1] = raw[s, C_V]
        mean_out[i] = mean_sv[s]
        counts[i] = np.int32(raw[s, C_N])
