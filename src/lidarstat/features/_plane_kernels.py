"""Numba kernels of the local (Taylorised) plane regression of Crosilla, Visintini and Sepic (2005).

Per point i, over its planimetric (2-D) neighbours j with tricube weights
``w_ij = (1 - (d_ij / b_i)^3)^3``, the weighted least-squares fit of eq. 6,
``z_j = z0_i + sE (E_j - E_i) + sN (N_j - N_i) + e_j``, i.e. eq. 7
``beta = (A'QA)^-1 A'Qz``. Besides beta the kernel returns what the statistics need:

* the sandwich cofactor ``C = N^-1 A'Q^2A N^-1`` (``N = A'QA``): with independent noise
  of variance sigma^2 the covariance of beta is ``sigma^2 C``;
* ``q = r'Qr``, ``tr(B)`` and ``tr(B^2)`` for ``B = Q - QAN^-1A'Q`` (so that
  ``E[q] = sigma^2 tr(B)``, ``Var[q] = 2 sigma^4 tr(B^2)``);
* the leverage of the point itself ``h_ii = w_ii [N^-1]_00`` (``w_ii = 1``) and the
  resubstitution residual ``z_i - z0_i``: the leave-one-out residual is
  ``(z_i - z0_i) / (1 - h_ii)`` without refitting (PRESS).
"""

from __future__ import annotations

import numba
import numpy as np

from .._shared._jit import njit, njit_parallel
from ._quadric_kernels import _tricube

STATUS_OK = 0
STATUS_TOO_FEW = 1
STATUS_DEGENERATE = 2


@njit
def _inv3(a, out):
    """Inverse of a symmetric 3x3 matrix by cofactors; returns the determinant (0 = singular)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    scale = abs(a[0, 0] * a[1, 1] * a[2, 2])
    if det == 0.0 or not np.isfinite(det) or abs(det) <= 1e-13 * scale:
        return 0.0
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inv
    out[0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inv
    out[1, 0] = c01 * inv
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inv
    out[1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inv
    out[2, 0] = c02 * inv
    out[2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inv
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inv
    return det


@njit
def _fit_one(r, i, pts, indptr, idx, dist, b, min_nb, beta, cof, stats):
    """Fit row r (point i); fills beta[r], cof[r], stats[r] = (q, trB, trB2, h_ii, resid, p, sw)."""
    s = indptr[r]
    e = indptr[r + 1]
    n = np.zeros((3, 3))
    m2 = np.zeros((3, 3))
    m3 = np.zeros((3, 3))
    rhs = np.zeros(3)
    a = np.empty(3)
    p = 0
    sw = 0.0
    sw2 = 0.0
    zi = pts[i, 2]
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        a[0] = 1.0
        a[1] = pts[j, 0] - pts[i, 0]
        a[2] = pts[j, 1] - pts[i, 1]
        dz = pts[j, 2] - zi
        p += 1
        sw += w
        sw2 += w * w
        for u in range(3):
            rhs[u] += w * a[u] * dz
            for v in range(3):
                aa = a[u] * a[v]
                n[u, v] += w * aa
                m2[u, v] += w * w * aa
                m3[u, v] += w * w * w * aa
    stats[r, 5] = p
    stats[r, 6] = sw
    if p < min_nb:
        return STATUS_TOO_FEW
    ninv = np.empty((3, 3))
    if _inv3(n, ninv) == 0.0:
        return STATUS_DEGENERATE
    for u in range(3):
        acc = 0.0
        for v in range(3):
            acc += ninv[u, v] * rhs[v]
        beta[r, u] = acc
    beta[r, 0] += zi  # heights were taken relative to z_i
    # sandwich cofactor C = N^-1 M2 N^-1, traces of N^-1 M2, N^-1 M3, (N^-1 M2)^2
    t2 = np.zeros((3, 3))
    for u in range(3):
        for v in range(3):
            acc = 0.0
            for k in range(3):
                acc += ninv[u, k] * m2[k, v]
            t2[u, v] = acc
    for u in range(3):
        for v in range(3):
            acc = 0.0
            for k in range(3):
                acc += t2[u, k] * ninv[k, v]
            cof[r, u, v] = acc
    tr2 = 0.0
    tr3 = 0.0
    tr22 = 0.0
    for u in range(3):
        tr2 += t2[u, u]
        for k in range(3):
            tr3 += ninv[u, k] * m3[k, u]
            tr22 += t2[u, k] * t2[k, u]
    # weighted residual sum of squares
    q = 0.0
    for t in range(s, e):
        w = _tricube(dist[t], b)
        if w <= 0.0:
            continue
        j = idx[t]
        res = (pts[j, 2] - beta[r, 0] - beta[r, 1] * (pts[j, 0] - pts[i, 0])
               - beta[r, 2] * (pts[j, 1] - pts[i, 1]))
        q += w * res * res
    stats[r, 0] = q
    stats[r, 1] = sw - tr2
    stats[r, 2] = sw2 - 2.0 * tr3 + tr22
    stats[r, 3] = ninv[0, 0]  # leverage of the point itself (w_ii = 1, a_i = [1, 0, 0])
    stats[r, 4] = zi - beta[r, 0]
    return STATUS_OK


@njit_parallel
def fit_planes(pts, query, indptr, idx, dist, bandwidth, min_nb, beta, cof, stats, status):
    """Local plane fits of every CSR row r (query point ``query[r]``); outputs preallocated."""
    m = indptr.size - 1
    for r in numba.prange(m):
        status[r] = _fit_one(r, query[r], pts, indptr, idx, dist, bandwidth[r], min_nb, beta,
                             cof, stats)


@njit_parallel
def geary_local(z, query, indptr, idx, dist, bandwidth, m2, c):
    """Local Geary indicator c_i = sum_j d_ij (h_i - h_j)^2 / m2 per CSR row (tricube d_ij).

    `z` holds the deviations h = z - mean(z) of all points and ``m2 = n^-1 sum h^2``
    (Anselin 1995); row r is point ``query[r]``; the point itself contributes 0.
    """
    for r in numba.prange(indptr.size - 1):
        i = query[r]
        acc = 0.0
        for t in range(indptr[r], indptr[r + 1]):
            j = idx[t]
            if j == i:
                continue
            w = _tricube(dist[t], bandwidth)
            d = z[i] - z[j]
            acc += w * d * d
        c[r] = acc / m2


@njit_parallel
def geary_gamma(c, query, indptr, idx, dist, bandwidth, gamma):
    """gamma_i = c_i sum_j d_ij / sum_j d_ij c_j (Sclocco and Di Marzio 2004); 1 if undefined."""
    for r in numba.prange(indptr.size - 1):
        i = query[r]
        sw = 0.0
        swc = 0.0
        for t in range(indptr[r], indptr[r + 1]):
            j = idx[t]
            if j == i:
                continue
            w = _tricube(dist[t], bandwidth)
            sw += w
            swc += w * c[j]
        if swc > 0.0 and sw > 0.0:
            gamma[r] = c[i] * sw / swc
        else:
            gamma[r] = 1.0
