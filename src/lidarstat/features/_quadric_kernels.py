"""Numba kernels of the weighted local quadric (second-order Taylor) fit.

One call fits every query point of a block. Per point, with offsets d_j = x_j - x_i of the
neighbours, tricube weights w_j = (1 - (d_ij/b)^3)^3 and a local frame R (rows e1, e2, n):

* local coordinates (u, v, h) = R d_j, scaled U = u/b, V = v/b for conditioning;
* design row x_j = [1, U, V, U^2/2, U V, V^2/2] (eq. 4 of Crosilla et al. 2009);
* N = X'WX, N2 = X'W^2X, N3 = X'W^3X assembled from weighted moment sums of the 15
  monomials U^i V^j, i + j <= 4 (one pass); r = X'Wh; beta = N^-1 r (eq. 5) via Cholesky;
* residuals e_j = h_j - x_j'beta, Q = e'We (numerator of eq. 6);
* traces for the exact moments of Q under H0 (from the 6 x 6 matrices, no leverage
  pass): tr(B) = sum w - tr(N^-1 N2) and
  tr(B^2) = sum w^2 - 2 tr(N^-1 N3) + tr((N^-1 N2)^2), with B = W - W X N^-1 X' W;
* cofactor of beta: N^-1 (the paper's) or the sandwich N^-1 N2 N^-1 (the WLS estimator's).

Everything is finally rescaled to physical units (a1, a2 by 1/b, a3..a5 by 1/b^2).
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit
from ..neighbors import make_drivers
from ._frame_kernels import _local_frame, _tricube, cholesky_inverse_n, to_frame

# status codes (mirrored by FitStatus in _results.py)
OK = 0
TOO_FEW = 1
SINGULAR = 2
SKIPPED = 255  # not asked for (inactive in the fused driver); rows are discarded by callers

COV_PAPER = 0
COV_SANDWICH = 1

# x = [1, U, V, U^2/2, UV, V^2/2]: x_a x_c = _COEF * monomial number _MONO (row-major a, c)
# monomials: 1 U V U2 UV V2 U3 U2V UV2 V3 U4 U3V U2V2 UV3 V4
_MONO = (0, 1, 2, 3, 4, 5,
         1, 3, 4, 6, 7, 8,
         2, 4, 5, 7, 8, 9,
         3, 6, 7, 10, 11, 12,
         4, 7, 8, 11, 12, 13,
         5, 8, 9, 12, 13, 14)
_COEF = (1.0, 1.0, 1.0, 0.5, 1.0, 0.5,
         1.0, 1.0, 1.0, 0.5, 1.0, 0.5,
         1.0, 1.0, 1.0, 0.5, 1.0, 0.5,
         0.5, 0.5, 0.5, 0.25, 0.5, 0.25,
         1.0, 1.0, 1.0, 0.5, 1.0, 0.5,
         0.5, 0.5, 0.5, 0.25, 0.5, 0.25)


@njit
def _acc3(s0, s1, s2, w, w2, w3, mk):
    """One monomial's three moment sums advanced by a neighbour of weight w:
    ``(s0 + w mk, s1 + w^2 mk, s2 + w^3 mk)``."""
    return s0 + w * mk, s1 + w2 * mk, s2 + w3 * mk


@njit
def _put(a, values):
    """``a[:len(values)] = values`` from a tuple of scalar accumulators."""
    for k in range(len(values)):
        a[k] = values[k]


@njit
def _workspace():
    """Per-thread scratch arrays of ``_fit_one`` (allocated once per chunk or cell)."""
    return (np.empty((3, 3)), np.empty((3, 3)), np.empty(3), np.empty((3, 3)),
            np.empty((3, 15)), np.empty((6, 6)), np.empty((6, 6)), np.empty((6, 6)),
            np.zeros((6, 6)), np.zeros((6, 6)), np.empty((6, 6)), np.empty(6), np.empty(6))


@njit
def _fit_one(i, pts, idx, dist, s, e, bw, frame, sensor, has_sensor, min_nb, cov_mode, ws, buf,
             beta_out, cof_out, frame_out, stats_out):
    """Fit point i; returns (status, p). stats_out = [Q, sum w, trB, trB2].

    `buf` (at least e - s rows, 4 columns) receives the offsets and weight of the
    neighbours (pass 0), then their u, v, h (pass 1), so that the frame, moment and residual
    passes read them contiguously.
    """
    R, cov3, ev, evec, mom, N, N2, N3, L, LI, Ninv, tmp, rhs = ws
    b = bw
    if b <= 0.0:  # kNN: the bandwidth is the farthest neighbour's distance (LOESS)
        for t in range(s, e):
            if dist[t] > b:
                b = dist[t]
    # Pass 0: the offsets d_j = x_j - x_i and weights of the neighbours with positive
    # weight, once, into `buf` (read contiguously by the frame and the moment passes)
    px = pts[i, 0]
    py = pts[i, 1]
    pz = pts[i, 2]
    p = 0
    nk = 0
    for t in range(s, e):
        if dist[t] < b:
            p += 1
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        buf[nk, 0] = pts[j, 0] - px
        buf[nk, 1] = pts[j, 1] - py
        buf[nk, 2] = pts[j, 2] - pz
        buf[nk, 3] = w
        nk += 1
    if p < min_nb or p < 6:
        return TOO_FEW, p
    if not _local_frame(buf, nk, px, py, pz, frame, sensor, has_sensor, R, cov3, ev, evec):
        return SINGULAR, p
    for a in range(3):
        for c in range(3):
            frame_out[a, c] = R[a, c]
    # Pass 1: local coordinates (u, v, h) into buf, then the weighted moment sums of the 15
    # monomials U^i V^j (i + j <= 4) for w, w^2, w^3 (the entries of X'WX, X'W^2X, X'W^3X)
    # and of w h U^i V^j (i + j <= 2) for X'Wh, in scalar accumulators (kept in registers):
    # s{p}_{k} = sum w^(p+1) * monomial k, g{k} = sum w h * monomial k (k < 6)
    inv_b = 1.0 / b
    to_frame(buf, nk, R, inv_b)
    s0_0 = s0_1 = s0_2 = s0_3 = s0_4 = s0_5 = s0_6 = s0_7 = s0_8 = s0_9 = s0_10 = s0_11 = s0_12 = s0_13 = s0_14 = 0.0
    s1_0 = s1_1 = s1_2 = s1_3 = s1_4 = s1_5 = s1_6 = s1_7 = s1_8 = s1_9 = s1_10 = s1_11 = s1_12 = s1_13 = s1_14 = 0.0
    s2_0 = s2_1 = s2_2 = s2_3 = s2_4 = s2_5 = s2_6 = s2_7 = s2_8 = s2_9 = s2_10 = s2_11 = s2_12 = s2_13 = s2_14 = 0.0
    g0 = g1 = g2 = g3 = g4 = g5 = 0.0
    for t in range(nk):
        u = buf[t, 0]
        v = buf[t, 1]
        w = buf[t, 3]
        uu = u * u
        uv = u * v
        vv = v * v
        wh = w * buf[t, 2]
        g0 += wh
        g1 += wh * u
        g2 += wh * v
        g3 += wh * uu
        g4 += wh * uv
        g5 += wh * vv
        w2 = w * w
        w3 = w2 * w
        s0_0, s1_0, s2_0 = _acc3(s0_0, s1_0, s2_0, w, w2, w3, 1.0)
        s0_1, s1_1, s2_1 = _acc3(s0_1, s1_1, s2_1, w, w2, w3, u)
        s0_2, s1_2, s2_2 = _acc3(s0_2, s1_2, s2_2, w, w2, w3, v)
        s0_3, s1_3, s2_3 = _acc3(s0_3, s1_3, s2_3, w, w2, w3, uu)
        s0_4, s1_4, s2_4 = _acc3(s0_4, s1_4, s2_4, w, w2, w3, uv)
        s0_5, s1_5, s2_5 = _acc3(s0_5, s1_5, s2_5, w, w2, w3, vv)
        s0_6, s1_6, s2_6 = _acc3(s0_6, s1_6, s2_6, w, w2, w3, uu * u)
        s0_7, s1_7, s2_7 = _acc3(s0_7, s1_7, s2_7, w, w2, w3, uu * v)
        s0_8, s1_8, s2_8 = _acc3(s0_8, s1_8, s2_8, w, w2, w3, u * vv)
        s0_9, s1_9, s2_9 = _acc3(s0_9, s1_9, s2_9, w, w2, w3, vv * v)
        s0_10, s1_10, s2_10 = _acc3(s0_10, s1_10, s2_10, w, w2, w3, uu * uu)
        s0_11, s1_11, s2_11 = _acc3(s0_11, s1_11, s2_11, w, w2, w3, uu * uv)
        s0_12, s1_12, s2_12 = _acc3(s0_12, s1_12, s2_12, w, w2, w3, uu * vv)
        s0_13, s1_13, s2_13 = _acc3(s0_13, s1_13, s2_13, w, w2, w3, uv * vv)
        s0_14, s1_14, s2_14 = _acc3(s0_14, s1_14, s2_14, w, w2, w3, vv * vv)
    _put(mom[0], (s0_0, s0_1, s0_2, s0_3, s0_4, s0_5, s0_6, s0_7, s0_8, s0_9, s0_10, s0_11,
                  s0_12, s0_13, s0_14))
    _put(mom[1], (s1_0, s1_1, s1_2, s1_3, s1_4, s1_5, s1_6, s1_7, s1_8, s1_9, s1_10, s1_11,
                  s1_12, s1_13, s1_14))
    _put(mom[2], (s2_0, s2_1, s2_2, s2_3, s2_4, s2_5, s2_6, s2_7, s2_8, s2_9, s2_10, s2_11,
                  s2_12, s2_13, s2_14))
    _put(rhs, (g0, g1, g2, g3, g4, g5))
    rhs[3] *= 0.5
    rhs[5] *= 0.5
    for a in range(6):
        for c in range(a, 6):
            k = _MONO[a * 6 + c]
            f = _COEF[a * 6 + c]
            N[a, c] = f * mom[0, k]
            N2[a, c] = f * mom[1, k]
            N3[a, c] = f * mom[2, k]
            N[c, a] = N[a, c]
            N2[c, a] = N2[a, c]
            N3[c, a] = N3[a, c]
    if not cholesky_inverse_n(N, 6, 1e-12, L, Ninv):
        return SINGULAR, p
    for a in range(6):
        acc = 0.0
        for c in range(6):
            acc += Ninv[a, c] * rhs[c]
        tmp[a] = acc
    # Pass 2: the weighted residual sum of squares, explicitly (no cancellation)
    q = 0.0
    b0 = tmp[0]
    b1 = tmp[1]
    b2 = tmp[2]
    b3 = 0.5 * tmp[3]
    b4 = tmp[4]
    b5 = 0.5 * tmp[5]
    for t in range(nk):  # the neighbours' local coordinates and weights from pass 1
        u = buf[t, 0]
        v = buf[t, 1]
        h = buf[t, 2]
        w = buf[t, 3]
        r = h - (b0 + u * (b1 + b3 * u + b4 * v) + v * (b2 + b5 * v))
        q += w * r * r
    sw = mom[0, 0]
    sw2 = mom[1, 0]
    # traces: tr(Ninv N2), tr(Ninv N3); S = Ninv N2 Ninv and tr(S N2)
    t2 = 0.0
    t3 = 0.0
    for a in range(6):
        for c in range(6):
            t2 += Ninv[a, c] * N2[c, a]
            t3 += Ninv[a, c] * N3[c, a]
    for a in range(6):
        for c in range(6):
            acc = 0.0
            for k in range(6):
                acc += N2[a, k] * Ninv[k, c]
            L[a, c] = acc  # L reused: N2 Ninv
    trSN2 = 0.0
    for a in range(6):
        for c in range(6):
            acc = 0.0
            for k in range(6):
                acc += Ninv[a, k] * L[k, c]
            cof_out[a, c] = acc  # sandwich S
    for a in range(6):
        for c in range(6):
            trSN2 += cof_out[a, c] * N2[c, a]
    if cov_mode == COV_PAPER:
        for a in range(6):
            for c in range(6):
                cof_out[a, c] = Ninv[a, c]
    # rescale to physical units
    for a in range(6):
        da = 1.0 if a == 0 else (inv_b if a < 3 else inv_b * inv_b)
        beta_out[a] = tmp[a] * da
        for c in range(6):
            dc = 1.0 if c == 0 else (inv_b if c < 3 else inv_b * inv_b)
            cof_out[a, c] *= da * dc
    stats_out[0] = q
    stats_out[1] = sw
    stats_out[2] = sw - t2
    stats_out[3] = sw2 - 2.0 * t3 + trSN2
    return OK, p


@njit
def _quadric_workspace(params):
    return _workspace()


@njit
def _quadric_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs):
    """Fit the quadric of point i from ``idx[s:e]`` into output row r (generic-driver
    protocol, ``neighbors/_drivers.py``). params: bandwidth (<= 0: farthest neighbour),
    frame, sensor, has_sensor, min_neighbors, covariance mode; outs: status, npts, beta,
    cof, frames, stats."""
    bw, frame, sensor, has_sensor, min_nb, cov_mode = params
    status, npts, beta, cof, frames, stats = outs
    st, p = _fit_one(i, pts, idx, dist, s, e, bw, frame, sensor, has_sensor, min_nb, cov_mode,
                     ws, buf, beta[r], cof[r], frames[r], stats[r])
    status[r] = st
    npts[r] = p
    if st != OK:
        for a in range(6):
            beta[r, a] = np.nan
        for a in range(4):
            stats[r, a] = np.nan


@njit
def _quadric_skip(r, outs):
    status, npts, beta, cof, frames, stats = outs
    status[r] = SKIPPED
    npts[r] = 0
    for a in range(6):
        beta[r, a] = np.nan
    for a in range(4):
        stats[r, a] = np.nan


#: ``fit_quadrics_block(pts, query, indptr, idx, dist, params, outs)``: every query point
#: (positions into `pts`) of CSR rows; ``fit_quadrics_cells(c0, c1, pts, cell_keys,
#: cell_start, dims, radius, active, params, outs)``: fused neighbour search (3-D sphere of
#: `radius`) and fit of the points of cells ``c0..c1-1`` (output row r = sorted position
#: ``cell_start[c0] + r``; ``active[i] == 0``: SKIPPED, NaN outputs). ``params`` and ``outs``
#: as :func:`_quadric_point`'s.
fit_quadrics_block, fit_quadrics_cells = make_drivers(_quadric_point, _quadric_workspace,
                                                      _quadric_skip)
