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
from .._shared._kernels import mirror3
from ..neighbors import make_drivers
from ._frame_kernels import FRAME_Z, frame_from_covariance, to_frame
from ._frame_kernels import _tricube  # noqa: F401 (the plane kernels import it from here)

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


#: Neighbours per lane block of the moment sums (:func:`_moment_sums`)
LANES = 8


@njit
def _lane_total(acc, k):
    """Sum of the LANES partial sums of accumulator `k`, in a fixed order."""
    a = k * LANES
    return (((acc[a] + acc[a + 1]) + (acc[a + 2] + acc[a + 3]))
            + ((acc[a + 4] + acc[a + 5]) + (acc[a + 6] + acc[a + 7])))


@njit
def _moment_sums(U, V, Hh, W, nk, acc, mom, rhs):
    """The weighted moment sums of one neighbourhood: ``mom[p, k] = sum w^(p+1) m_k`` over
    the 15 monomials ``m_k = U^i V^j`` (i + j <= 4, order of ``_MONO``) and
    ``rhs[k] = sum w h m_k`` (k < 6).

    Neighbour t goes to lane ``t % LANES``: each lane sums its neighbours in their order
    and the lanes are added in a fixed order (:func:`_lane_total`), so the result does not
    depend on the processor; the loop over the lanes of a block is elementwise, which the
    compiler turns into vector instructions (it only reads the neighbours' columns: a
    store to them in the same loop keeps it scalar). `acc` (at least ``54 * LANES``) is
    scratch.
    """
    for a in range(54 * LANES):
        acc[a] = 0.0
    for t0 in range(0, nk, LANES):
        nl = min(LANES, nk - t0)
        for L in range(nl):
            t = t0 + L
            u = U[t]
            v = V[t]
            w = W[t]
            uu = u * u
            uv = u * v
            vv = v * v
            w2 = w * w
            w3 = w2 * w
            wh = w * Hh[t]
            m6 = uu * u
            m7 = uu * v
            m8 = u * vv
            m9 = vv * v
            m10 = uu * uu
            m11 = uu * uv
            m12 = uu * vv
            m13 = uv * vv
            m14 = vv * vv
            # rows 0-14: w m_k; 15-29: w^2 m_k; 30-44: w^3 m_k; 45-50: w h m_k
            acc[0 * LANES + L] += w
            acc[1 * LANES + L] += w * u
            acc[2 * LANES + L] += w * v
            acc[3 * LANES + L] += w * uu
            acc[4 * LANES + L] += w * uv
            acc[5 * LANES + L] += w * vv
            acc[6 * LANES + L] += w * m6
            acc[7 * LANES + L] += w * m7
            acc[8 * LANES + L] += w * m8
            acc[9 * LANES + L] += w * m9
            acc[10 * LANES + L] += w * m10
            acc[11 * LANES + L] += w * m11
            acc[12 * LANES + L] += w * m12
            acc[13 * LANES + L] += w * m13
            acc[14 * LANES + L] += w * m14
            acc[15 * LANES + L] += w2
            acc[16 * LANES + L] += w2 * u
            acc[17 * LANES + L] += w2 * v
            acc[18 * LANES + L] += w2 * uu
            acc[19 * LANES + L] += w2 * uv
            acc[20 * LANES + L] += w2 * vv
            acc[21 * LANES + L] += w2 * m6
            acc[22 * LANES + L] += w2 * m7
            acc[23 * LANES + L] += w2 * m8
            acc[24 * LANES + L] += w2 * m9
            acc[25 * LANES + L] += w2 * m10
            acc[26 * LANES + L] += w2 * m11
            acc[27 * LANES + L] += w2 * m12
            acc[28 * LANES + L] += w2 * m13
            acc[29 * LANES + L] += w2 * m14
            acc[30 * LANES + L] += w3
            acc[31 * LANES + L] += w3 * u
            acc[32 * LANES + L] += w3 * v
            acc[33 * LANES + L] += w3 * uu
            acc[34 * LANES + L] += w3 * uv
            acc[35 * LANES + L] += w3 * vv
            acc[36 * LANES + L] += w3 * m6
            acc[37 * LANES + L] += w3 * m7
            acc[38 * LANES + L] += w3 * m8
            acc[39 * LANES + L] += w3 * m9
            acc[40 * LANES + L] += w3 * m10
            acc[41 * LANES + L] += w3 * m11
            acc[42 * LANES + L] += w3 * m12
            acc[43 * LANES + L] += w3 * m13
            acc[44 * LANES + L] += w3 * m14
            acc[45 * LANES + L] += wh
            acc[46 * LANES + L] += wh * u
            acc[47 * LANES + L] += wh * v
            acc[48 * LANES + L] += wh * uu
            acc[49 * LANES + L] += wh * uv
            acc[50 * LANES + L] += wh * vv
    for p in range(3):
        for k in range(15):
            mom[p, k] = _lane_total(acc, 15 * p + k)
    for k in range(6):
        rhs[k] = _lane_total(acc, 45 + k)


@njit
def _residual_ss(U, V, H, W, nk, beta, part):
    """``sum w (h - x'beta)^2`` over the first `nk` neighbours (scaled beta; `H` is
    overwritten by the terms ``w e^2``).

    The terms are formed in one elementwise loop (vector lanes) and summed in LANES
    partial sums added in a fixed order (:func:`_lane_total`): the result does not depend
    on the processor. `part` (at least LANES) is scratch.
    """
    b0 = beta[0]
    b1 = beta[1]
    b2 = beta[2]
    b3 = 0.5 * beta[3]
    b4 = beta[4]
    b5 = 0.5 * beta[5]
    for t in range(nk):
        u = U[t]
        v = V[t]
        r = H[t] - (b0 + u * (b1 + b3 * u + b4 * v) + v * (b2 + b5 * v))
        H[t] = W[t] * r * r
    for lane in range(LANES):
        part[lane] = 0.0
    n = nk - nk % LANES
    for t0 in range(0, n, LANES):
        for lane in range(LANES):
            part[lane] += H[t0 + lane]
    for t in range(n, nk):
        part[t - n] += H[t]
    return _lane_total(part, 0)


@njit
def _row_product(A, a, B):
    """Row `a` of the 6 x 6 product A B: six running sums over k in order (each entry as
    ``sum_k A[a, k] B[k, c]`` in one loop over k, which the compiler keeps in registers
    and vector lanes)."""
    m0 = m1 = m2 = m3 = m4 = m5 = 0.0
    for k in range(6):
        f = A[a, k]
        m0 += f * B[k, 0]
        m1 += f * B[k, 1]
        m2 += f * B[k, 2]
        m3 += f * B[k, 3]
        m4 += f * B[k, 4]
        m5 += f * B[k, 5]
    return m0, m1, m2, m3, m4, m5


@njit
def _spd_inverse6(a, rel_tol, L, LI, inv):
    """Inverse of the SPD 6 x 6 `a` (its lower triangle is read) into `inv` via its
    Cholesky factor `L`, whose inverse (lower) goes to `LI`: as :func:`cholesky_inverse_n`
    with m = 6, but dividing once per pivot (its reciprocal is the diagonal of `LI`) and
    with loops of fixed length that the compiler unrolls. False if a pivot is not above
    `rel_tol` times the largest diagonal.
    """
    scale = 0.0
    for k in range(6):
        if a[k, k] > scale:
            scale = a[k, k]
    if not scale > 0.0:
        return False
    tol = rel_tol * scale
    for j in range(6):
        sjj = a[j, j]
        for k in range(j):
            sjj -= L[j, k] * L[j, k]
        if not sjj > tol:
            return False
        ljj = np.sqrt(sjj)
        L[j, j] = ljj
        dj = 1.0 / ljj
        LI[j, j] = dj
        for r in range(j + 1, 6):
            acc = a[r, j]
            for k in range(j):
                acc -= L[r, k] * L[j, k]
            L[r, j] = acc * dj
    for j in range(6):  # forward substitution, column by column
        for r in range(j + 1, 6):
            acc = 0.0
            for k in range(j, r):
                acc -= L[r, k] * LI[k, j]
            LI[r, j] = acc * LI[r, r]
    for r in range(6):  # a^-1 = LI' LI
        for c in range(r, 6):
            acc = 0.0
            for k in range(c, 6):
                acc += LI[k, r] * LI[k, c]
            inv[r, c] = acc
            inv[c, r] = acc
    return True


@njit
def _workspace():
    """Per-thread scratch arrays of ``_fit_one`` (allocated once per chunk or cell)."""
    return (np.empty((3, 3)), np.empty((3, 3)), np.empty(3), np.empty((3, 3)),
            np.empty((3, 15)), np.empty((6, 6)), np.empty((6, 6)), np.zeros((6, 6)),
            np.zeros((6, 6)), np.empty((6, 6)), np.empty(6), np.empty(6),
            np.empty(54 * LANES))


@njit
def _fit_one(i, pts, idx, dist, s, e, bw, frame, sensor, has_sensor, min_nb, cov_mode, ws, buf,
             row, beta_out, cof_out, frame_out, stats_out):
    """Fit point i into row `row` of the outputs; returns (status, p). stats_out[row] = [Q,
    sum w, trB, trB2]. (Rows, not views of them: a view per point costs reference counting on
    the arrays that every thread shares.)

    `buf` (at least e - s rows, 4 columns) is scratch for the neighbours, used as four
    columns of its size: their offsets and weights (pass 0, which also sums what the
    frame's covariance needs), then their u, v, h (pass 1), so that the moment and
    residual passes read each coordinate contiguously; the residual pass (2) leaves the
    terms w e^2 in the h column.
    """
    R, cov3, ev, evec, mom, N, N2, L, LI, Ninv, tmp, rhs, part = ws
    cols = buf.reshape((4, buf.shape[0]))  # columns d0 / u, d1 / v, d2 / h, w
    rows = cols.T  # row t: the neighbour's (u, v, h, w), as to_frame reads them
    b = bw
    if b <= 0.0:  # kNN: the bandwidth is the farthest neighbour's distance (LOESS)
        for t in range(s, e):
            if dist[t] > b:
                b = dist[t]
    # Pass 0: the offsets d_j = x_j - x_i and weights of the neighbours with positive
    # weight, once, into `buf` (read contiguously by the moment passes), and the weighted
    # sums of the offsets and of their products that give the frame's covariance
    px = pts[i, 0]
    py = pts[i, 1]
    pz = pts[i, 2]
    inv_b = 1.0 / b
    p = 0
    nk = 0
    sw = s0 = s1 = s2 = 0.0
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(s, e):
        d = dist[t]
        if not d < b:
            continue
        p += 1
        g = d * inv_b  # the tricube weight, by a product (no division)
        g = 1.0 - g * g * g
        w = g * g * g
        if w <= 0.0:
            continue
        j = idx[t]
        d0 = pts[j, 0] - px
        d1 = pts[j, 1] - py
        d2 = pts[j, 2] - pz
        cols[0, nk] = d0
        cols[1, nk] = d1
        cols[2, nk] = d2
        cols[3, nk] = w
        nk += 1
        w0 = w * d0
        w1 = w * d1
        sw += w
        s0 += w0
        s1 += w1
        s2 += w * d2
        c00 += w0 * d0
        c01 += w0 * d1
        c02 += w0 * d2
        c11 += w1 * d1
        c12 += w1 * d2
        c22 += w * d2 * d2
    if p < min_nb or p < 6:
        return TOO_FEW, p
    # the fit, hence every result, is the same for any direction of e1 in the tangent plane
    if frame == FRAME_Z:
        for a in range(3):
            for c in range(3):
                R[a, c] = 1.0 if a == c else 0.0
    else:
        # weighted covariance about the weighted mean, from the sums about the point:
        # sum w (d - m)(d - m)' = sum w d d' - m (sum w d)'; the offsets are within b of
        # the point, so the subtraction loses no more than the sums' own rounding
        if not sw > 0.0:
            return SINGULAR, p
        m0 = s0 / sw
        m1 = s1 / sw
        m2 = s2 / sw
        cov3[0, 0] = c00 - m0 * s0
        cov3[0, 1] = c01 - m0 * s1
        cov3[0, 2] = c02 - m0 * s2
        cov3[1, 1] = c11 - m1 * s1
        cov3[1, 2] = c12 - m1 * s2
        cov3[2, 2] = c22 - m2 * s2
        mirror3(cov3)
        if not frame_from_covariance(cov3, px, py, pz, frame, sensor, has_sensor, R, ev, evec,
                                     True):
            return SINGULAR, p
    for a in range(3):
        for c in range(3):
            frame_out[row, a, c] = R[a, c]
    # Pass 1: local coordinates (u, v, h) into buf, then the weighted moment sums of the 15
    # monomials U^i V^j (i + j <= 4) for w, w^2, w^3 (the entries of X'WX, X'W^2X, X'W^3X)
    # and of w h U^i V^j (i + j <= 2) for X'Wh
    to_frame(rows, nk, R, inv_b)
    _moment_sums(cols[0], cols[1], cols[2], cols[3], nk, part, mom, rhs)
    rhs[3] *= 0.5
    rhs[5] *= 0.5
    # N's lower triangle (all the Cholesky reads) and N2 whole (for M = N2 Ninv); N3 only
    # enters tr(Ninv N3), read from the moments
    for a in range(6):
        for c in range(a + 1):
            k = _MONO[a * 6 + c]
            f = _COEF[a * 6 + c]
            N[a, c] = f * mom[0, k]
            N2[a, c] = f * mom[1, k]
            N2[c, a] = N2[a, c]
    if not _spd_inverse6(N, 1e-12, L, LI, Ninv):
        return SINGULAR, p
    for a in range(6):
        acc = 0.0
        for c in range(6):
            acc += Ninv[a, c] * rhs[c]
        tmp[a] = acc
    # Pass 2: the weighted residual sum of squares, explicitly (no cancellation)
    q = _residual_ss(cols[0], cols[1], cols[2], cols[3], nk, tmp, part)
    sw = mom[0, 0]
    sw2 = mom[1, 0]
    # traces: tr(Ninv N2), tr(Ninv N3) (N3's entries read from the moments) and, with M =
    # N2 Ninv, tr(S N2) = tr(M M) for the sandwich S = Ninv N2 Ninv = Ninv M (symmetric:
    # its upper triangle, mirrored); each trace summed over all 36 products in row order
    t2 = 0.0
    t3 = 0.0
    for a in range(6):
        for c in range(6):
            t2 += Ninv[a, c] * N2[c, a]
            t3 += Ninv[a, c] * (_COEF[c * 6 + a] * mom[2, _MONO[c * 6 + a]])
    for a in range(6):  # L reused: M = N2 Ninv
        L[a, 0], L[a, 1], L[a, 2], L[a, 3], L[a, 4], L[a, 5] = _row_product(N2, a, Ninv)
    trSN2 = 0.0
    for a in range(6):
        for c in range(6):
            trSN2 += L[a, c] * L[c, a]
    # the cofactor's upper triangle, rescaled to physical units as it is stored, mirrored
    for a in range(6):
        da = 1.0 if a == 0 else (inv_b if a < 3 else inv_b * inv_b)
        beta_out[row, a] = tmp[a] * da
        if cov_mode == COV_PAPER:
            cof = (Ninv[a, 0], Ninv[a, 1], Ninv[a, 2], Ninv[a, 3], Ninv[a, 4], Ninv[a, 5])
        else:
            cof = _row_product(Ninv, a, L)
        for c in range(a, 6):
            dc = 1.0 if c == 0 else (inv_b if c < 3 else inv_b * inv_b)
            acc = cof[c] * (da * dc)
            cof_out[row, a, c] = acc
            cof_out[row, c, a] = acc
    stats_out[row, 0] = q
    stats_out[row, 1] = sw
    stats_out[row, 2] = sw - t2
    stats_out[row, 3] = sw2 - 2.0 * t3 + trSN2
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
                     ws, buf, r, beta, cof, frames, stats)
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
