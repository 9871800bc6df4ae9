"""Numba kernel of region growing with a tested merge: union-find over the accepted edges
(most similar first), where the union of two units is refused when it fails the model
test that each part passes: the plane test for planar units, the quadric test
(:mod:`._quadric_merge_kernels`) for curved ones."""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit
from .._shared._kernels import eigh3
from .._shared._kernels import uf_find as _find
from . import _quadric_merge_kernels as _qk


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
def _slot_fill(members_head, nxt, xyz, dirs, use_d, M, G, Gd, c, m, J, g):
    """Add the points of a member list to a unit's quadric sums."""
    i = members_head
    while i >= 0:
        _qk.slot_add_point(M, G, Gd, c, xyz[i], dirs[i], use_d, m, J, g)
        i = nxt[i]


@njit
def grow_tested(src, dst, xyz, dirs, noise_normal, testable, curved, sigma2, crit, min_test,
                quad_min, parent):
    """Union the edges in order; refuse a union of two units when both pass their model
    test and their union does not: the plane test for `testable` units of at least
    `min_test` points each, the quadric test for `curved` units of at least `quad_min`
    points each (``crit[df]`` the chi-square critical value at `df` degrees of freedom).

    `parent` (N,) is filled with the union-find forest (``parent[i] = i`` on entry);
    returns the numbers of refused unions of planar and of curved units.
    """
    n_pts = xyz.shape[0]
    use_d = not noise_normal
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
    # quadric sums of the curved units of at least quad_min points ("slots"), with the
    # member lists that fill a slot when its unit reaches that size
    n_curved = 0
    for i in range(n_pts):
        if curved[i]:
            n_curved += 1
    n_slots = n_curved // max(quad_min, 1) + 2
    NM = _qk.NM
    QM = np.zeros((n_slots, NM, NM))
    QG = np.zeros((n_slots, NM, NM))
    QGd = np.zeros((n_slots, NM, NM))
    Qc = np.zeros((n_slots, 3))
    Qst = np.full(n_slots, np.nan)
    free = np.arange(n_slots - 1, -1, -1)
    n_free = n_slots
    slot = np.full(n_pts, -1, dtype=np.int64)
    nxt = np.full(n_pts, -1, dtype=np.int64)
    head = np.arange(n_pts)
    tail = np.arange(n_pts)
    uM = np.empty((NM, NM))
    uG = np.empty((NM, NM))
    uGd = np.empty((NM, NM))
    T = np.empty((NM, NM))
    m = np.empty(NM)
    J = np.empty((NM, 3))
    g = np.empty(NM)
    lim = crit.size - 1
    refused_plane = 0
    refused_quad = 0
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
            ca = crit[min(int(na) - 3, lim)]
            cb = crit[min(int(nb) - 3, lim)]
            cu = crit[min(int(na + nb) - 3, lim)]
            if qa <= ca and qb <= cb and qu > cu:
                refused_plane += 1
                continue
        if curved[ra] and na >= quad_min and nb >= quad_min:
            ka = slot[ra]
            kb = slot[rb]
            for k in (ka, kb):
                if np.isnan(Qst[k]):
                    Qst[k] = _qk.quadric_statistic(QM[k], QG[k], QGd[k], use_d, sigma2, T)
            uM[:] = QM[ka]
            uG[:] = QG[ka]
            uGd[:] = QGd[ka]
            _qk.slot_merge(uM, uG, uGd, Qc[ka], QM[kb], QG[kb], QGd[kb], Qc[kb], use_d, T)
            qu = _qk.quadric_statistic(uM, uG, uGd, use_d, sigma2, T)
            dof = _qk.QUADRIC_DOF
            ca = crit[min(int(na) - dof, lim)]
            cb = crit[min(int(nb) - dof, lim)]
            cu = crit[min(int(na + nb) - dof, lim)]
            if Qst[ka] <= ca and Qst[kb] <= cb and qu > cu:
                refused_quad += 1
                continue
        if na < nb:
            ra, rb = rb, ra
        if curved[ra]:
            ka = slot[ra]
            kb = slot[rb]
            if ka >= 0 and kb >= 0:
                _qk.slot_merge(QM[ka], QG[ka], QGd[ka], Qc[ka], QM[kb], QG[kb], QGd[kb],
                               Qc[kb], use_d, T)
                Qst[ka] = np.nan
                free[n_free] = kb
                n_free += 1
                slot[rb] = -1
            elif ka >= 0 or kb >= 0:
                if ka < 0:  # the slot of the smaller unit moves to the new root
                    ka = kb
                    slot[ra] = ka
                    slot[rb] = -1
                    other = ra
                else:
                    other = rb
                _slot_fill(head[other], nxt, xyz, dirs, use_d, QM[ka], QG[ka], QGd[ka],
                           Qc[ka], m, J, g)
                Qst[ka] = np.nan
            elif na + nb >= quad_min:
                n_free -= 1
                ka = free[n_free]
                QM[ka] = 0.0
                QG[ka] = 0.0
                QGd[ka] = 0.0
                Qc[ka] = xyz[head[ra]]
                Qst[ka] = np.nan
                slot[ra] = ka
                _slot_fill(head[ra], nxt, xyz, dirs, use_d, QM[ka], QG[ka], QGd[ka], Qc[ka],
                           m, J, g)
                _slot_fill(head[rb], nxt, xyz, dirs, use_d, QM[ka], QG[ka], QGd[ka], Qc[ka],
                           m, J, g)
            nxt[tail[ra]] = head[rb]
            tail[ra] = tail[rb]
        parent[rb] = ra
        cnt[ra] += cnt[rb]
        for a in range(3):
            s[ra, a] += s[rb, a]
            for c in range(3):
                S[ra, a, c] += S[rb, a, c]
                D[ra, a, c] += D[rb, a, c]
    for i in range(n_pts):
        parent[i] = _find(parent, i)
    return refused_plane, refused_quad
