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
from ._frame_kernels import _local_frame, _tricube, cholesky_inverse_n

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
    # Pass 1: weighted moment sums of the 15 monomials U^i V^j (i + j <= 4) for w, w^2, w^3
    # (the entries of X'WX, X'W^2X, X'W^3X) and of w h U^i V^j (i + j <= 2) for X'Wh.
    # scalar accumulators (kept in registers): s{p}_{k} = sum w^(p+1) * monomial k,
    # g{k} = sum w h * monomial k (k < 6)
    s0_0 = s0_1 = s0_2 = s0_3 = s0_4 = s0_5 = s0_6 = s0_7 = s0_8 = s0_9 = s0_10 = s0_11 = s0_12 = s0_13 = s0_14 = 0.0
    s1_0 = s1_1 = s1_2 = s1_3 = s1_4 = s1_5 = s1_6 = s1_7 = s1_8 = s1_9 = s1_10 = s1_11 = s1_12 = s1_13 = s1_14 = 0.0
    s2_0 = s2_1 = s2_2 = s2_3 = s2_4 = s2_5 = s2_6 = s2_7 = s2_8 = s2_9 = s2_10 = s2_11 = s2_12 = s2_13 = s2_14 = 0.0
    g0 = g1 = g2 = g3 = g4 = g5 = 0.0
    inv_b = 1.0 / b
    r00 = R[0, 0]
    r01 = R[0, 1]
    r02 = R[0, 2]
    r10 = R[1, 0]
    r11 = R[1, 1]
    r12 = R[1, 2]
    r20 = R[2, 0]
    r21 = R[2, 1]
    r22 = R[2, 2]
    for t in range(nk):  # the offsets and weights of pass 0, in local coordinates
        d0 = buf[t, 0]
        d1 = buf[t, 1]
        d2 = buf[t, 2]
        w = buf[t, 3]
        u = (r00 * d0 + r01 * d1 + r02 * d2) * inv_b
        v = (r10 * d0 + r11 * d1 + r12 * d2) * inv_b
        h = r20 * d0 + r21 * d1 + r22 * d2
        buf[t, 0] = u
        buf[t, 1] = v
        buf[t, 2] = h
        uu = u * u
        uv = u * v
        vv = v * v
        wh = w * h
        g0 += wh
        g1 += wh * u
        g2 += wh * v
        g3 += wh * uu
        g4 += wh * uv
        g5 += wh * vv
        w2 = w * w
        w3 = w2 * w
        s0_0 += w
        s1_0 += w2
        s2_0 += w3
        mk = u
        s0_1 += w * mk
        s1_1 += w2 * mk
        s2_1 += w3 * mk
        mk = v
        s0_2 += w * mk
        s1_2 += w2 * mk
        s2_2 += w3 * mk
        mk = uu
        s0_3 += w * mk
        s1_3 += w2 * mk
        s2_3 += w3 * mk
        mk = uv
        s0_4 += w * mk
        s1_4 += w2 * mk
        s2_4 += w3 * mk
        mk = vv
        s0_5 += w * mk
        s1_5 += w2 * mk
        s2_5 += w3 * mk
        mk = uu * u
        s0_6 += w * mk
        s1_6 += w2 * mk
        s2_6 += w3 * mk
        mk = uu * v
        s0_7 += w * mk
        s1_7 += w2 * mk
        s2_7 += w3 * mk
        mk = u * vv
        s0_8 += w * mk
        s1_8 += w2 * mk
        s2_8 += w3 * mk
        mk = vv * v
        s0_9 += w * mk
        s1_9 += w2 * mk
        s2_9 += w3 * mk
        mk = uu * uu
        s0_10 += w * mk
        s1_10 += w2 * mk
        s2_10 += w3 * mk
        mk = uu * uv
        s0_11 += w * mk
        s1_11 += w2 * mk
        s2_11 += w3 * mk
        mk = uu * vv
        s0_12 += w * mk
        s1_12 += w2 * mk
        s2_12 += w3 * mk
        mk = uv * vv
        s0_13 += w * mk
        s1_13 += w2 * mk
        s2_13 += w3 * mk
        mk = vv * vv
        s0_14 += w * mk
        s1_14 += w2 * mk
        s2_14 += w3 * mk
    mom[0, 0] = s0_0
    mom[0, 1] = s0_1
    mom[0, 2] = s0_2
    mom[0, 3] = s0_3
    mom[0, 4] = s0_4
    mom[0, 5] = s0_5
    mom[0, 6] = s0_6
    mom[0, 7] = s0_7
    mom[0, 8] = s0_8
    mom[0, 9] = s0_9
    mom[0, 10] = s0_10
    mom[0, 11] = s0_11
    mom[0, 12] = s0_12
    mom[0, 13] = s0_13
    mom[0, 14] = s0_14
    mom[1, 0] = s1_0
    mom[1, 1] = s1_1
    mom[1, 2] = s1_2
    mom[1, 3] = s1_3
    mom[1, 4] = s1_4
    mom[1, 5] = s1_5
    mom[1, 6] = s1_6
    mom[1, 7] = s1_7
    mom[1, 8] = s1_8
    mom[1, 9] = s1_9
    mom[1, 10] = s1_10
    mom[1, 11] = s1_11
    mom[1, 12] = s1_12
    mom[1, 13] = s1_13
    mom[1, 14] = s1_14
    mom[2, 0] = s2_0
    mom[2, 1] = s2_1
    mom[2, 2] = s2_2
    mom[2, 3] = s2_3
    mom[2, 4] = s2_4
    mom[2, 5] = s2_5
    mom[2, 6] = s2_6
    mom[2, 7] = s2_7
    mom[2, 8] = s2_8
    mom[2, 9] = s2_9
    mom[2, 10] = s2_10
    mom[2, 11] = s2_11
    mom[2, 12] = s2_12
    mom[2, 13] = s2_13
    mom[2, 14] = s2_14
    rhs[0] = g0
    rhs[1] = g1
    rhs[2] = g2
    rhs[3] = g3
    rhs[4] = g4
    rhs[5] = g5
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
