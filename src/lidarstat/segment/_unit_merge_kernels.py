"""Numba kernel of region growing with a tested merge: union-find over the accepted edges
(most similar first), where the union of two planar units is refused when it fails the
plane test that each part passes."""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit
from .._shared._kernels import eigh3
from .._shared._kernels import uf_find as _find


@njit
def _plane_statistic(n, s, S, D, noise_normal, sigma2, A, evals, evecs):
    """Orthogonal-regression RSS of a unit over its expected value per degree of freedom:
    ``lambda_min / (sigma^2 mean_i (d_i . n)^2)``, to compare with chi2(n - 3)."""
    for a in range(3):
        for c in range(3):
            A[a, c] = S[a, c] - s[a] * s[c] / n
    eigh3(A, evals, evecs)
    lam = max(evals[0], 0.0)
    if noise_normal:
        f = 1.0
    else:
        f = 0.0
        for a in range(3):
            for c in range(3):
                f += evecs[a, 0] * D[a, c] * evecs[c, 0]
        f /= n
    f = max(f, 1e-6)
    return lam / (sigma2 * f)


@njit
def grow_tested(src, dst, xyz, dirs, noise_normal, testable, sigma2, crit, min_test, parent):
    """Union the edges in order; refuse a union of two testable units of at least
    `min_test` points each when both pass the plane test and their union does not.

    `parent` (N,) is filled with the union-find forest (``parent[i] = i`` on entry);
    returns the number of refused unions.
    """
    n_pts = xyz.shape[0]
    cnt = np.ones(n_pts)
    s = xyz.copy()
    S = np.empty((n_pts, 3, 3))
    D = np.empty((n_pts, 3, 3))
    for i in range(n_pts):
        for a in range(3):
            for c in range(3):
                S[i, a, c] = xyz[i, a] * xyz[i, c]
                D[i, a, c] = dirs[i, a] * dirs[i, c]
    A = np.empty((3, 3))
    evals = np.empty(3)
    evecs = np.empty((3, 3))
    s_u = np.empty(3)
    S_u = np.empty((3, 3))
    D_u = np.empty((3, 3))
    refused = 0
    for t in range(src.size):
        ra = _find(parent, src[t])
        rb = _find(parent, dst[t])
        if ra == rb:
            continue
        na = cnt[ra]
        nb = cnt[rb]
        if testable[ra] and na >= min_test and nb >= min_test:
            for a in range(3):
                s_u[a] = s[ra, a] + s[rb, a]
                for c in range(3):
                    S_u[a, c] = S[ra, a, c] + S[rb, a, c]
                    D_u[a, c] = D[ra, a, c] + D[rb, a, c]
            qa = _plane_statistic(na, s[ra], S[ra], D[ra], noise_normal, sigma2, A, evals, evecs)
            qb = _plane_statistic(nb, s[rb], S[rb], D[rb], noise_normal, sigma2, A, evals, evecs)
            qu = _plane_statistic(na + nb, s_u, S_u, D_u, noise_normal, sigma2, A, evals,
                                  evecs)
            lim = crit.size - 1
            ca = crit[min(int(na) - 3, lim)]
            cb = crit[min(int(nb) - 3, lim)]
            cu = crit[min(int(na + nb) - 3, lim)]
            if qa <= ca and qb <= cb and qu > cu:
                refused += 1
                continue
        if na < nb:
            ra, rb = rb, ra
        parent[rb] = ra
        cnt[ra] += cnt[rb]
        for a in range(3):
            s[ra, a] += s[rb, a]
            for c in range(3):
                S[ra, a, c] += S[rb, a, c]
                D[ra, a, c] += D[rb, a, c]
    for i in range(n_pts):
        parent[i] = _find(parent, i)
    return refused
