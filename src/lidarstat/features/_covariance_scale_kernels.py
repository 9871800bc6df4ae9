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
        sx = sy = sz = 0.0
        sxx = sxy = sxz = syy = syz = szz = 0.0
        best = np.inf
        kbest = n
        for t in range(n):
            j = idx[s + t]
            dx, dy, dz = pts[j, 0] - px, pts[j, 1] - py, pts[j, 2] - pz
            sx += dx
            sy += dy
            sz += dz
            sxx += dx * dx
            sxy += dx * dy
            sxz += dx * dz
            syy += dy * dy
            syz += dy * dz
            szz += dz * dz
            k = t + 1
            if k < k_min and k < n:
                continue
            inv = 1.0 / k
            mx, my, mz = sx * inv, sy * inv, sz * inv
            l0, l1, l2 = _eigvals3(sxx * inv - mx * mx, sxy * inv - mx * my,
                                   sxz * inv - mx * mz, syy * inv - my * my,
                                   syz * inv - my * mz, szz * inv - mz * mz)
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
