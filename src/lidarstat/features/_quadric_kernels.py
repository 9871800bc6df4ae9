"""Numba kernels of the weighted local quadric (second-order Taylor) fit.

One call fits every query point of a block. Per point, with offsets d_j = x_j - x_i of the
neighbours, tricube weights w_j = (1 - (d_ij/b)^3)^3 and a local frame R (rows e1, e2, n):

* local coordinates (u, v, h) = R d_j, scaled U = u/b, V = v/b for conditioning;
* design row x_j = [1, U, V, U^2/2, U V, V^2/2] (eq. 4 of Crosilla et al. 2009);
* N = X'WX, N2 = X'W^2X, N3 = X'W^3X assembled from weighted moment sums of the 15
  monomials U^i V^j, i + j <= 4 (two passes over the neighbours, no per-point design
  matrix); r = X'Wh; beta = N^-1 r (eq. 5) via Cholesky;
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


# The per-neighbour sums below are the fit's hot loops: 10 (frame), 24 + 27 (moments),
# 1 (residual) running sums over the neighbours' columns. Each is its own function compiled with the
# one fast-math flag that lets the compiler split a running sum into vector lanes
# (``reassoc``: partial sums of every lane in registers, added at the end); no other
# flag (no contraction into fused multiply-adds, NaN and infinity semantics kept), so
# every term is rounded as written and only the order of the additions is the
# compiler's (it follows the processor's vector width: the last bits of a sum may
# differ between processors, never between runs on one). A function has at most about
# 27 sums so that they stay in the 32 vector registers.
_SUMS = {"reassoc"}


@njit(fastmath=_SUMS)
def frame_sums(D0, D1, D2, W, nk):
    """``(sum w, sum w d, sum w d d')`` of the first `nk` offsets ``(D0, D1, D2)`` and
    weights `W`: ``sw, s0, s1, s2, c00, c01, c02, c11, c12, c22`` (what the frame's
    weighted covariance needs; see :func:`_fit_local`)."""
    sw = s0 = s1 = s2 = 0.0
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(nk):
        w = W[t]
        d0 = D0[t]
        d1 = D1[t]
        d2 = D2[t]
        w0 = w * d0
        w1 = w * d1
        w2 = w * d2
        sw += w
        s0 += w0
        s1 += w1
        s2 += w2
        c00 += w0 * d0
        c01 += w0 * d1
        c02 += w0 * d2
        c11 += w1 * d1
        c12 += w1 * d2
        c22 += w2 * d2
    return sw, s0, s1, s2, c00, c01, c02, c11, c12, c22


@njit(fastmath=_SUMS)
def _low_moments(U, V, Hh, W, nk, mom, rhs):
    """Columns 0-5 of `mom` (monomials 1 U V U^2 UV V^2) and `rhs`."""
    a0 = a1 = a2 = a3 = a4 = a5 = 0.0
    b0 = b1 = b2 = b3 = b4 = b5 = 0.0
    c0 = c1 = c2 = c3 = c4 = c5 = 0.0
    r0 = r1 = r2 = r3 = r4 = r5 = 0.0
    for t in range(nk):
        u = U[t]
        v = V[t]
        w = W[t]
        uu = u * u
        uv = u * v
        vv = v * v
        w2 = w * w
        w3 = w2 * w
        wh = w * Hh[t]
        a0 += w
        a1 += w * u
        a2 += w * v
        a3 += w * uu
        a4 += w * uv
        a5 += w * vv
        b0 += w2
        b1 += w2 * u
        b2 += w2 * v
        b3 += w2 * uu
        b4 += w2 * uv
        b5 += w2 * vv
        c0 += w3
        c1 += w3 * u
        c2 += w3 * v
        c3 += w3 * uu
        c4 += w3 * uv
        c5 += w3 * vv
        r0 += wh
        r1 += wh * u
        r2 += wh * v
        r3 += wh * uu
        r4 += wh * uv
        r5 += wh * vv
    for p, (m0, m1, m2, m3, m4, m5) in enumerate(((a0, a1, a2, a3, a4, a5),
                                                   (b0, b1, b2, b3, b4, b5),
                                                   (c0, c1, c2, c3, c4, c5))):
        mom[p, 0] = m0
        mom[p, 1] = m1
        mom[p, 2] = m2
        mom[p, 3] = m3
        mom[p, 4] = m4
        mom[p, 5] = m5
    rhs[0] = r0
    rhs[1] = r1
    rhs[2] = r2
    rhs[3] = r3
    rhs[4] = r4
    rhs[5] = r5


@njit(fastmath=_SUMS)
def _high_moments(U, V, W, nk, mom):
    """Columns 6-14 of `mom` (monomials U^3 U^2V UV^2 V^3 U^4 U^3V U^2V^2 UV^3 V^4)."""
    a6 = a7 = a8 = a9 = a10 = a11 = a12 = a13 = a14 = 0.0
    b6 = b7 = b8 = b9 = b10 = b11 = b12 = b13 = b14 = 0.0
    c6 = c7 = c8 = c9 = c10 = c11 = c12 = c13 = c14 = 0.0
    for t in range(nk):
        u = U[t]
        v = V[t]
        w = W[t]
        uu = u * u
        uv = u * v
        vv = v * v
        w2 = w * w
        w3 = w2 * w
        m6 = uu * u
        m7 = uu * v
        m8 = u * vv
        m9 = vv * v
        m10 = uu * uu
        m11 = uu * uv
        m12 = uu * vv
        m13 = uv * vv
        m14 = vv * vv
        a6 += w * m6
        a7 += w * m7
        a8 += w * m8
        a9 += w * m9
        a10 += w * m10
        a11 += w * m11
        a12 += w * m12
        a13 += w * m13
        a14 += w * m14
        b6 += w2 * m6
        b7 += w2 * m7
        b8 += w2 * m8
        b9 += w2 * m9
        b10 += w2 * m10
        b11 += w2 * m11
        b12 += w2 * m12
        b13 += w2 * m13
        b14 += w2 * m14
        c6 += w3 * m6
        c7 += w3 * m7
        c8 += w3 * m8
        c9 += w3 * m9
        c10 += w3 * m10
        c11 += w3 * m11
        c12 += w3 * m12
        c13 += w3 * m13
        c14 += w3 * m14
    for p, (m6, m7, m8, m9, m10, m11, m12, m13, m14) in enumerate((
            (a6, a7, a8, a9, a10, a11, a12, a13, a14),
            (b6, b7, b8, b9, b10, b11, b12, b13, b14),
            (c6, c7, c8, c9, c10, c11, c12, c13, c14))):
        mom[p, 6] = m6
        mom[p, 7] = m7
        mom[p, 8] = m8
        mom[p, 9] = m9
        mom[p, 10] = m10
        mom[p, 11] = m11
        mom[p, 12] = m12
        mom[p, 13] = m13
        mom[p, 14] = m14


@njit
def _moment_sums(U, V, Hh, W, nk, mom, rhs):
    """The weighted moment sums of one neighbourhood: ``mom[p, k] = sum w^(p+1) m_k`` over
    the 15 monomials ``m_k = U^i V^j`` (i + j <= 4, order of ``_MONO``) and
    ``rhs[k] = sum w h m_k`` (k < 6), over the first `nk` entries of the columns.

    Two passes over the columns (monomials of degree up to 2 with `rhs`, then those of
    degree 3 and 4), each running sum in vector lanes (see ``_SUMS``).
    """
    _low_moments(U, V, Hh, W, nk, mom, rhs)
    _high_moments(U, V, W, nk, mom)


@njit(fastmath=_SUMS)
def _residual_ss(U, V, H, W, nk, beta):
    """``sum w (h - x'beta)^2`` over the first `nk` neighbours (scaled beta), explicitly (no
    cancellation), in vector lanes (see ``_SUMS``)."""
    b0 = beta[0]
    b1 = beta[1]
    b2 = beta[2]
    b3 = 0.5 * beta[3]
    b4 = beta[4]
    b5 = 0.5 * beta[5]
    q = 0.0
    for t in range(nk):
        u = U[t]
        v = V[t]
        r = H[t] - (b0 + u * (b1 + b3 * u + b4 * v) + v * (b2 + b5 * v))
        q += W[t] * r * r
    return q


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
    """Per-thread scratch arrays of ``_fit_local`` (allocated once per chunk or cell)."""
    return (np.empty((3, 3)), np.empty((3, 3)), np.empty(3), np.empty((3, 3)),
            np.empty((3, 15)), np.empty((6, 6)), np.empty((6, 6)), np.zeros((6, 6)),
            np.zeros((6, 6)), np.empty((6, 6)), np.empty(6), np.empty(6), np.empty((6, 6)))


@njit
def _fit_one(i, pts, idx, dist, s, e, bw, frame, sensor, has_sensor, min_nb, cov_mode, ws, buf,
             row, beta_out, cof_out, frame_out, stats_out):
    """Fit point i from its neighbours ``idx[s:e]`` at distances ``dist[s:e]`` into row
    `row` of the outputs; returns (status, p) (see :func:`_fit_local`).

    `buf` (at least e - s rows, 4 columns) is scratch for the neighbours: pass 0 puts the
    offsets d_j = x_j - x_i and the weights of those with positive weight into its four
    columns of its size (as :func:`_fit_local` takes them).
    """
    cols = buf.reshape((4, buf.shape[0]))  # columns d0, d1, d2, w
    b = bw
    if b <= 0.0:  # kNN: the bandwidth is the farthest neighbour's distance (LOESS)
        for t in range(s, e):
            if dist[t] > b:
                b = dist[t]
    px = pts[i, 0]
    py = pts[i, 1]
    pz = pts[i, 2]
    inv_b = 1.0 / b
    p = 0
    nk = 0
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
        cols[0, nk] = pts[j, 0] - px
        cols[1, nk] = pts[j, 1] - py
        cols[2, nk] = pts[j, 2] - pz
        cols[3, nk] = w
        nk += 1
    return _fit_local(cols, nk, p, px, py, pz, b, frame, sensor, has_sensor, min_nb, cov_mode,
                      ws, row, beta_out, cof_out, frame_out, stats_out)


@njit
def _fit_local(cols, nk, p, px, py, pz, b, frame, sensor, has_sensor, min_nb, cov_mode, ws,
               row, beta_out, cof_out, frame_out, stats_out):
    """Fit the point at (px, py, pz) into row `row` of the outputs; returns (status, p).
    stats_out[row] = [Q, sum w, trB, trB2]. (Rows, not views of them: a view per point
    costs reference counting on the arrays that every thread shares.)

    `cols` (4 rows of at least `nk`) holds the offsets d_j = x_j - x_i and the tricube
    weights (rows 0-3) of `nk` neighbours, in their order (a weight may be 0: such a
    neighbour adds exact zeros to every sum); `p` counts the neighbours within the
    bandwidth `b`. Its first three rows become the local
    coordinates u, v, h (pass 1), read contiguously by the moment and residual passes.
    """
    R, cov3, ev, evec, mom, N, N2, L, LI, Ninv, tmp, rhs, N3 = ws
    inv_b = 1.0 / b
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
        sw, s0, s1, s2, c00, c01, c02, c11, c12, c22 = frame_sums(cols[0], cols[1], cols[2],
                                                                  cols[3], nk)
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
    # Pass 1: local coordinates (u, v, h), then the weighted moment sums of the 15
    # monomials U^i V^j (i + j <= 4) for w, w^2, w^3 (the entries of X'WX, X'W^2X, X'W^3X)
    # and of w h U^i V^j (i + j <= 2) for X'Wh
    to_frame(cols.T, nk, R, inv_b)  # rows t: (u, v, h, w), as to_frame reads them
    _moment_sums(cols[0], cols[1], cols[2], cols[3], nk, mom, rhs)
    rhs[3] *= 0.5
    rhs[5] *= 0.5
    # N's lower triangle (all the Cholesky reads), N2 and N3 whole (for M = N2 Ninv and
    # the traces)
    for a in range(6):
        for c in range(a + 1):
            k = _MONO[a * 6 + c]
            f = _COEF[a * 6 + c]
            N[a, c] = f * mom[0, k]
            N2[a, c] = f * mom[1, k]
            N2[c, a] = N2[a, c]
            N3[a, c] = f * mom[2, k]
            N3[c, a] = N3[a, c]
    if not _spd_inverse6(N, 1e-12, L, LI, Ninv):
        return SINGULAR, p
    for a in range(6):
        acc = 0.0
        for c in range(6):
            acc += Ninv[a, c] * rhs[c]
        tmp[a] = acc
    # Pass 2: the weighted residual sum of squares, explicitly (no cancellation)
    q = _residual_ss(cols[0], cols[1], cols[2], cols[3], nk, tmp)
    sw = mom[0, 0]
    sw2 = mom[1, 0]
    # traces: tr(Ninv N2), tr(Ninv N3) and, with M = N2 Ninv, tr(S N2) = tr(M M) for the
    # sandwich S = Ninv N2 Ninv = Ninv M; the three summed in one loop over the 36 products
    # in row order (three independent running sums)
    for a in range(6):  # L reused: M = N2 Ninv
        L[a, 0], L[a, 1], L[a, 2], L[a, 3], L[a, 4], L[a, 5] = _row_product(N2, a, Ninv)
    t2 = 0.0
    t3 = 0.0
    trSN2 = 0.0
    for a in range(6):
        for c in range(6):
            t2 += Ninv[a, c] * N2[c, a]
            t3 += Ninv[a, c] * N3[c, a]
            trSN2 += L[a, c] * L[c, a]
    cof = Ninv
    if cov_mode != COV_PAPER:  # LI reused: S, its upper triangle (sums in k order), mirrored
        for a in range(6):
            for c in range(a, 6):
                acc = 0.0
                for k in range(6):
                    acc += Ninv[a, k] * L[k, c]
                LI[a, c] = acc
                LI[c, a] = acc
        cof = LI
    # beta and the cofactor, rescaled to physical units as they are stored
    for a in range(6):
        da = 1.0 if a == 0 else (inv_b if a < 3 else inv_b * inv_b)
        beta_out[row, a] = tmp[a] * da
        for c in range(6):
            dc = 1.0 if c == 0 else (inv_b if c < 3 else inv_b * inv_b)
            cof_out[row, a, c] = cof[a, c] * (da * dc)
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
    finish_row(r, st, p, outs)


@njit
def finish_row(r, st, p, outs):
    """Status `st` and neighbour count `p` into output row r; NaN beta and statistics
    unless the fit is OK."""
    status, npts, beta, cof, frames, stats = outs
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
#: (positions into `pts`) of CSR rows, ``params`` and ``outs`` as :func:`_quadric_point`'s
#: (the fused search and fit over grid cells is ``_quadric_cells.fit_quadrics_cells``)
fit_quadrics_block = make_drivers(_quadric_point, _quadric_workspace, _quadric_skip).block
