"""Numba kernels of the weighted local quadric (second-order Taylor) fit.

One call fits every query point of a block. Per point, with offsets d_j = x_j - x_i of the
neighbours, tricube weights w_j = (1 - (d_ij/b)^3)^3 and a local frame R (rows e1, e2, n):

* local coordinates (u, v, h) = R d_j, scaled U = u/b, V = v/b for conditioning;
* design row x_j = [1, U, V, U^2/2, U V, V^2/2] (eq. 4 of Crosilla et al. 2009);
* N = X'WX, N2 = X'W^2X, r = X'Wh; beta = N^-1 r (eq. 5) via Cholesky;
* residuals e_j = h_j - x_j'beta, Q = e'We (numerator of eq. 6);
* traces for the exact moments of Q under H0: tr(B) = sum w - tr(N^-1 N2) and
  tr(B^2) = sum w^2 - 2 tr(N^-1 N3) + tr((N^-1 N2)^2), with B = W - W X N^-1 X' W;
* cofactor of beta: N^-1 (the paper's) or the sandwich N^-1 N2 N^-1 (the WLS estimator's).

Everything is finally rescaled to physical units (a1, a2 by 1/b, a3..a5 by 1/b^2).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

# status codes (mirrored by FitStatus in _results.py)
OK = 0
TOO_FEW = 1
SINGULAR = 2

FRAME_Z = 0
FRAME_AUTO = 1
FRAME_PCA = 2

COV_PAPER = 0
COV_SANDWICH = 1

_CHUNK = 64


@njit
def _eigh3(a, evals, evecs):
    """Cyclic Jacobi eigen-decomposition of a symmetric 3x3 matrix (ascending order).

    `a` is overwritten. Columns of `evecs` are the eigenvectors.
    """
    for i in range(3):
        for j in range(3):
            evecs[i, j] = 1.0 if i == j else 0.0
    for _sweep in range(50):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= 1e-30 * diag or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(3):
                    akp = a[k, p]
                    akq = a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(3):
                    apk = a[p, k]
                    aqk = a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(3):
                    vkp = evecs[k, p]
                    vkq = evecs[k, q]
                    evecs[k, p] = c * vkp - s * vkq
                    evecs[k, q] = s * vkp + c * vkq
    for i in range(3):
        evals[i] = a[i, i]
    # sort ascending (insertion sort on 3 items, columns follow)
    for i in range(1, 3):
        j = i
        while j > 0 and evals[j - 1] > evals[j]:
            tmp = evals[j - 1]
            evals[j - 1] = evals[j]
            evals[j] = tmp
            for k in range(3):
                tv = evecs[k, j - 1]
                evecs[k, j - 1] = evecs[k, j]
                evecs[k, j] = tv
            j -= 1


@njit
def _tricube(d, b):
    if d >= b:
        return 0.0
    t = d / b
    t = 1.0 - t * t * t
    return t * t * t


@njit
def _local_frame(i, pts, idx, dist, s, e, b, frame, sensor, has_sensor, R, cov, evals, evecs):
    """Fill R (3x3, rows e1, e2, n) for point i. Returns False if the frame is degenerate."""
    if frame == FRAME_Z:
        for a in range(3):
            for c in range(3):
                R[a, c] = 1.0 if a == c else 0.0
        return True
    sw = 0.0
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        sw += w
        m0 += w * (pts[j, 0] - pts[i, 0])
        m1 += w * (pts[j, 1] - pts[i, 1])
        m2 += w * (pts[j, 2] - pts[i, 2])
    if sw <= 0.0:
        return False
    m0 /= sw
    m1 /= sw
    m2 /= sw
    for a in range(3):
        for c in range(3):
            cov[a, c] = 0.0
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        d0 = pts[j, 0] - pts[i, 0] - m0
        d1 = pts[j, 1] - pts[i, 1] - m1
        d2 = pts[j, 2] - pts[i, 2] - m2
        cov[0, 0] += w * d0 * d0
        cov[0, 1] += w * d0 * d1
        cov[0, 2] += w * d0 * d2
        cov[1, 1] += w * d1 * d1
        cov[1, 2] += w * d1 * d2
        cov[2, 2] += w * d2 * d2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    _eigh3(cov, evals, evecs)
    if evals[1] <= 0.0:
        return False
    n0 = evecs[0, 0]
    n1 = evecs[1, 0]
    n2 = evecs[2, 0]
    if frame == FRAME_AUTO:
        k = 0
        if abs(n1) > abs(n0):
            k = 1
        if abs(n2) > abs(n0) and abs(n2) > abs(n1):
            k = 2
        sign = 1.0
        if has_sensor and sensor[k] - pts[i, k] < 0.0:
            sign = -1.0
        for a in range(3):
            for c in range(3):
                R[a, c] = 0.0
        k1 = (k + 1) % 3
        k2 = (k + 2) % 3
        if sign > 0:
            R[0, k1] = 1.0
            R[1, k2] = 1.0
            R[2, k] = 1.0
        else:
            R[0, k2] = 1.0
            R[1, k1] = 1.0
            R[2, k] = -1.0
        return True
    # PCA frame: n = smallest eigenvector, oriented to the sensor or up
    flip = False
    if has_sensor:
        dot = n0 * (sensor[0] - pts[i, 0]) + n1 * (sensor[1] - pts[i, 1]) + n2 * (sensor[2] - pts[i, 2])
        flip = dot < 0.0
    else:
        flip = n2 < 0.0
    if flip:
        n0 = -n0
        n1 = -n1
        n2 = -n2
    e0 = evecs[0, 2]
    e1 = evecs[1, 2]
    e2 = evecs[2, 2]
    R[0, 0] = e0
    R[0, 1] = e1
    R[0, 2] = e2
    # e2 = n x e1
    R[1, 0] = n1 * e2 - n2 * e1
    R[1, 1] = n2 * e0 - n0 * e2
    R[1, 2] = n0 * e1 - n1 * e0
    R[2, 0] = n0
    R[2, 1] = n1
    R[2, 2] = n2
    return True


@njit
def _design(u, v, x):
    x[0] = 1.0
    x[1] = u
    x[2] = v
    x[3] = 0.5 * u * u
    x[4] = u * v
    x[5] = 0.5 * v * v


@njit
def _cholesky_inverse(a, L, li, inv):
    """Inverse of SPD 6x6 `a` via Cholesky; False if a pivot is not safely positive."""
    n = 6
    scale = 0.0
    for k in range(n):
        if a[k, k] > scale:
            scale = a[k, k]
    if scale <= 0.0:
        return False
    tol = 1e-12 * scale
    for j in range(n):
        sjj = a[j, j]
        for k in range(j):
            sjj -= L[j, k] * L[j, k]
        if not sjj > tol:
            return False
        L[j, j] = np.sqrt(sjj)
        for i in range(j + 1, n):
            sij = a[i, j]
            for k in range(j):
                sij -= L[i, k] * L[j, k]
            L[i, j] = sij / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    # inv(L) in place into inv (lower), then inv = Linv' Linv
    for i in range(n):
        for j in range(n):
            li[i, j] = 0.0
    for j in range(n):
        li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            acc = 0.0
            for k in range(j, i):
                acc -= L[i, k] * li[k, j]
            li[i, j] = acc / L[i, i]
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for k in range(j, n):
                acc += li[k, i] * li[k, j]
            inv[i, j] = acc
            inv[j, i] = acc
    return True


@njit
def _fit_one(i, pts, idx, dist, s, e, bw, frame, sensor, has_sensor, min_nb, cov_mode,
             R, cov3, ev, evec, x, N, N2, L, LI, Ninv, tmp, rhs,
             beta_out, cof_out, frame_out, stats_out):
    """Fit point i; returns (status, p). stats_out = [Q, sum w, trB, trB2]."""
    b = bw
    if b <= 0.0:  # kNN: the bandwidth is the farthest neighbour's distance (LOESS)
        for t in range(s, e):
            if dist[t] > b:
                b = dist[t]
    p = 0
    for t in range(s, e):
        if dist[t] < b:
            p += 1
    if p < min_nb or p < 6:
        return TOO_FEW, p
    if not _local_frame(i, pts, idx, dist, s, e, b, frame, sensor, has_sensor, R, cov3, ev, evec):
        return SINGULAR, p
    for a in range(3):
        for c in range(3):
            frame_out[a, c] = R[a, c]
    for a in range(6):
        rhs[a] = 0.0
        for c in range(6):
            N[a, c] = 0.0
            N2[a, c] = 0.0
    inv_b = 1.0 / b
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        d0 = pts[j, 0] - pts[i, 0]
        d1 = pts[j, 1] - pts[i, 1]
        d2 = pts[j, 2] - pts[i, 2]
        u = (R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2) * inv_b
        v = (R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2) * inv_b
        h = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2
        _design(u, v, x)
        w2 = w * w
        for a in range(6):
            wa = w * x[a]
            rhs[a] += wa * h
            for c in range(a, 6):
                N[a, c] += wa * x[c]
                N2[a, c] += w2 * x[a] * x[c]
    for a in range(6):
        for c in range(a):
            N[a, c] = N[c, a]
            N2[a, c] = N2[c, a]
    if not _cholesky_inverse(N, L, LI, Ninv):
        return SINGULAR, p
    for a in range(6):
        acc = 0.0
        for c in range(6):
            acc += Ninv[a, c] * rhs[c]
        tmp[a] = acc
    q = 0.0
    sw = 0.0
    sw2 = 0.0
    t2 = 0.0
    t3 = 0.0
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        d0 = pts[j, 0] - pts[i, 0]
        d1 = pts[j, 1] - pts[i, 1]
        d2 = pts[j, 2] - pts[i, 2]
        u = (R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2) * inv_b
        v = (R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2) * inv_b
        h = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2
        _design(u, v, x)
        fit = 0.0
        lev = 0.0
        for a in range(6):
            fit += x[a] * tmp[a]
            acc = 0.0
            for c in range(6):
                acc += Ninv[a, c] * x[c]
            lev += x[a] * acc
        r = h - fit
        q += w * r * r
        sw += w
        sw2 += w * w
        t2 += w * w * lev
        t3 += w * w * w * lev
    # S = Ninv N2 Ninv ; tr(S N2)
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


@njit_parallel
def fit_quadrics_block(pts, query, indptr, idx, dist, bandwidth, frame, sensor, has_sensor,
                       min_nb, cov_mode, status, npts, beta, cof, frames, stats):
    """Fit the quadric at every query point (positions into `pts`) of one block.

    Row r of the CSR arrays is the neighbourhood of ``pts[query[r]]``; outputs are indexed
    by r. Parallel over chunks of rows, one workspace per chunk (no per-point allocation).
    """
    m = query.size
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunks):
        R = np.empty((3, 3))
        cov3 = np.empty((3, 3))
        ev = np.empty(3)
        evec = np.empty((3, 3))
        x = np.empty(6)
        N = np.empty((6, 6))
        N2 = np.empty((6, 6))
        L = np.zeros((6, 6))
        LI = np.zeros((6, 6))
        Ninv = np.empty((6, 6))
        tmp = np.empty(6)
        rhs = np.empty(6)
        for r in range(ch * _CHUNK, min(m, (ch + 1) * _CHUNK)):
            st, p = _fit_one(query[r], pts, idx, dist, indptr[r], indptr[r + 1], bandwidth,
                             frame, sensor, has_sensor, min_nb, cov_mode, R, cov3, ev, evec, x,
                             N, N2, L, LI, Ninv, tmp, rhs, beta[r], cof[r], frames[r], stats[r])
            status[r] = st
            npts[r] = p
            if st != OK:
                for a in range(6):
                    beta[r, a] = np.nan
                for a in range(4):
                    stats[r, a] = np.nan
