"""Numba kernel of the optimal neighbourhood size (minimum eigenentropy, Weinmann et al. 2015).

One pass per point over its k_max nearest neighbours sorted by distance: the first and
second moments of the offsets from the point are accumulated neighbour by neighbour, and
at every prefix size k in ``[k_min, k_max]`` the covariance eigenvalues (closed form of a
symmetric 3x3 matrix) give the eigenentropy of the normalised eigenvalues
``-sum e_i ln e_i``, ``e_i = lambda_i / sum lambda``. The smallest entropy wins (the
first k on ties) among the prefixes whose middle eigenvalue is at least `min_spread` times
the largest (a surface patch, not a piece of one scan line); with none, the whole row. Offsets from the point itself keep the moments small, so the
one-pass covariance of a prefix loses no precision at the neighbourhood's scale.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel


@njit
def _eigvals3(a00, a01, a02, a11, a12, a22):
    """Eigenvalues of a symmetric 3x3 matrix, ascending (trigonometric closed form)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 <= 1e-30 * (q * q + 1e-300):
        e = np.empty(3)
        e[0], e[1], e[2] = a00, a11, a22
        e.sort()
        return e[0], e[1], e[2]
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
           + a02 * (a01 * a12 - b11 * a02))
    r = det / (2.0 * p * p * p)
    if r <= -1.0:
        phi = math.pi / 3.0
    elif r >= 1.0:
        phi = 0.0
    else:
        phi = math.acos(r) / 3.0
    e2 = q + 2.0 * p * math.cos(phi)
    e0 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    e1 = 3.0 * q - e0 - e2
    return e0, e1, e2


#: The running sums of :func:`_add_offset` before the first neighbour.
_NO_MOMENTS = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit
def _add_offset(mom, dx, dy, dz):
    """The running sums ``(sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)`` of the offsets
    with offset ``(dx, dy, dz)`` added (a tuple: kept in registers, no allocation)."""
    return (mom[0] + dx, mom[1] + dy, mom[2] + dz, mom[3] + dx * dx, mom[4] + dx * dy,
            mom[5] + dx * dz, mom[6] + dy * dy, mom[7] + dy * dz, mom[8] + dz * dz)


@njit
def _prefix_covariance(mom, k):
    """Covariance ``(c00, c01, c02, c11, c12, c22)`` (divided by k) of the k offsets whose
    running sums are `mom`."""
    inv = 1.0 / k
    mx, my, mz = mom[0] * inv, mom[1] * inv, mom[2] * inv
    return (mom[3] * inv - mx * mx, mom[4] * inv - mx * my, mom[5] * inv - mx * mz,
            mom[6] * inv - my * my, mom[7] * inv - my * mz, mom[8] * inv - mz * mz)


@njit
def _xlogx(x):
    return x * math.log(x) if x > 0.0 else 0.0


@njit_parallel
def optimal_k_rows(pts, indptr, idx, k_min, k_max, min_spread, out_k, out_entropy):
    """Per row (sorted by distance, the point itself first): the prefix size in
    ``[k_min, min(k_max, row length)]`` of minimum eigenentropy among those with
    ``lambda1 >= min_spread lambda2``, and that entropy (NaN when none qualifies)."""
    m = indptr.size - 1
    for r in prange(m):
        s = indptr[r]
        n = min(indptr[r + 1] - s, k_max)
        out_k[r] = n
        out_entropy[r] = np.nan
        if n < 3:
            continue
        i = idx[s]
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        mom = _NO_MOMENTS
        best = np.inf
        kbest = n
        for t in range(n):
            j = idx[s + t]
            mom = _add_offset(mom, pts[j, 0] - px, pts[j, 1] - py, pts[j, 2] - pz)
            k = t + 1
            if k < k_min and k < n:
                continue
            l0, l1, l2 = _eigvals3(*_prefix_covariance(mom, k))
            l0 = max(l0, 0.0)
            l1 = max(l1, 0.0)
            l2 = max(l2, 0.0)
            tot = l0 + l1 + l2
            if not tot > 0.0 or l1 < min_spread * l2:
                continue
            ent = -(_xlogx(l0 / tot) + _xlogx(l1 / tot) + _xlogx(l2 / tot))
            if ent < best:
                best = ent
                kbest = k
        if best == np.inf:
            kbest = n
        out_k[r] = kbest
        out_entropy[r] = best


@njit
def _min_eigvec(a00, a01, a02, a11, a12, a22, lam):
    """Unit eigenvector of a symmetric 3x3 matrix for its eigenvalue `lam` (the largest
    cross product of two rows of ``A - lam I``)."""
    r0x, r0y, r0z = a00 - lam, a01, a02
    r1x, r1y, r1z = a01, a11 - lam, a12
    r2x, r2y, r2z = a02, a12, a22 - lam
    cax, cay, caz = r0y * r1z - r0z * r1y, r0z * r1x - r0x * r1z, r0x * r1y - r0y * r1x
    cbx, cby, cbz = r0y * r2z - r0z * r2y, r0z * r2x - r0x * r2z, r0x * r2y - r0y * r2x
    ccx, ccy, ccz = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
    na = cax * cax + cay * cay + caz * caz
    nb = cbx * cbx + cby * cby + cbz * cbz
    nc = ccx * ccx + ccy * ccy + ccz * ccz
    if na >= nb and na >= nc:
        x, y, z, q = cax, cay, caz, na
    elif nb >= nc:
        x, y, z, q = cbx, cby, cbz, nb
    else:
        x, y, z, q = ccx, ccy, ccz, nc
    if not q > 0.0:
        return 0.0, 0.0, 1.0
    s = 1.0 / math.sqrt(q)
    return x * s, y * s, z * s


@njit_parallel
def tested_k_rows(pts, indptr, idx, k_min, k_max, sigma2, dirs, crit, min_share2, out_k):
    """Per row (sorted by distance, the point itself first): the smallest prefix size in
    ``[k_min, min(k_max, row length)]`` whose plane test rejects at the stopping level,
    ``k lambda0 / (sigma^2 max((d . n)^2, min_share2)) > crit[k]`` (``lambda0`` the
    smallest eigenvalue of the prefix's covariance divided by k, n its normal, d the
    noise direction: ``dirs`` row r, or row 0 when it has one row, or the normal itself
    when it has none); the whole row when none does. `sigma2` has one value per row or
    one for all."""
    m = indptr.size - 1
    per_dir = dirs.shape[0] > 1
    along_normal = dirs.shape[0] == 0
    per_sigma = sigma2.size > 1
    for r in prange(m):
        s = indptr[r]
        n = min(indptr[r + 1] - s, k_max)
        out_k[r] = n
        if n < 4:
            continue
        s2 = sigma2[r] if per_sigma else sigma2[0]
        dr = r if per_dir else r - r
        i = idx[s]
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        mom = _NO_MOMENTS
        for t in range(n):
            j = idx[s + t]
            mom = _add_offset(mom, pts[j, 0] - px, pts[j, 1] - py, pts[j, 2] - pz)
            k = t + 1
            if k < k_min or k < 4 or k == n:
                continue
            c00, c01, c02, c11, c12, c22 = _prefix_covariance(mom, k)
            l0, l1, l2 = _eigvals3(c00, c01, c02, c11, c12, c22)
            l0 = max(l0, 0.0)
            share2 = 1.0
            if not along_normal:
                nx, ny, nz = _min_eigvec(c00, c01, c02, c11, c12, c22, l0)
                dn = nx * dirs[dr, 0] + ny * dirs[dr, 1] + nz * dirs[dr, 2]
                share2 = max(dn * dn, min_share2)
            if k * l0 > crit[k] * s2 * share2:
                out_k[r] = k
                break
