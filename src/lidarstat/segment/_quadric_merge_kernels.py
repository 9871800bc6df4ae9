"""Numba kernels of the quadric model test of a merge: a Taubin fit of a unit's points
from its moments, so that testing the union of two units costs O(1), not a refit.

A unit keeps, about an anchor point ``c``, three 10 x 10 sums over its points of the
monomials ``m(y) = (1, y_x, y_y, y_z, y_x^2, y_x y_y, y_x y_z, y_y^2, y_y y_z, y_z^2)`` of
``y = x - c``: ``M = sum m m^T`` (the moments up to degree 4), ``G = sum J J^T`` and
``G_d = sum (J d)(J d)^T`` with ``J = dm/dy`` (10 x 3) and ``d`` the point's noise
direction. Moving the anchor is a linear map of the monomials, ``m(y - delta) = T m(y)``,
so the sums of two units add after ``T . T^T`` (:func:`slot_merge`).

The fit ``f(x) = a^T m`` minimises ``a^T M a / a^T G a`` (Taubin 1991: the algebraic
residual over the mean squared gradient, about the mean squared distance to the
surface); the constant is eliminated (Schur complement of ``M``) and the 9 x 9 generalised
eigenproblem solved through a Cholesky factor of ``G`` and Jacobi rotations (plain loops:
no LAPACK call to compile). A point moved by ``e`` along ``d``
changes ``f`` by ``e (d . grad f)``, so under the model ``sum f^2 / (sigma^2 mean (d .
grad f)^2)`` is chi-square with ``n - 9`` degrees of freedom (10 coefficients up to scale).
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit
from .._shared._kernels import cholesky_lower, lower_inverse

#: Number of monomials of degree <= 2 in three variables.
NM = 10
#: Free parameters of a quadric (10 coefficients up to scale).
QUADRIC_DOF = 9
#: Floor of ``mean (d . grad f)^2 / mean |grad f|^2`` (noise direction inside the surface).
FACTOR_FLOOR = 1e-6

# index of y_a y_b among the monomials
_QA = np.array([0, 0, 0, 1, 1, 2], dtype=np.int64)
_QB = np.array([0, 1, 2, 1, 2, 2], dtype=np.int64)


@njit
def _mono_jac(p, c, d, use_d, m, J, g):
    """Monomials `m` (10), Jacobian `J` (10 x 3) and ``g = J d`` at point `p` about `c`."""
    y0 = p[0] - c[0]
    y1 = p[1] - c[1]
    y2 = p[2] - c[2]
    y = (y0, y1, y2)
    m[0] = 1.0
    m[1] = y0
    m[2] = y1
    m[3] = y2
    for r in range(NM):
        for k in range(3):
            J[r, k] = 0.0
    J[1, 0] = 1.0
    J[2, 1] = 1.0
    J[3, 2] = 1.0
    for q in range(6):
        a = _QA[q]
        b = _QB[q]
        m[4 + q] = y[a] * y[b]
        J[4 + q, a] += y[b]
        J[4 + q, b] += y[a]
    if use_d:
        for r in range(NM):
            g[r] = J[r, 0] * d[0] + J[r, 1] * d[1] + J[r, 2] * d[2]


@njit
def slot_add_point(M, G, Gd, c, p, d, use_d, m, J, g):
    """Add point `p` (noise direction `d`) to a unit's sums about anchor `c`."""
    _mono_jac(p, c, d, use_d, m, J, g)
    for r in range(NM):
        for s in range(NM):
            M[r, s] += m[r] * m[s]
            G[r, s] += J[r, 0] * J[s, 0] + J[r, 1] * J[s, 1] + J[r, 2] * J[s, 2]
            if use_d:
                Gd[r, s] += g[r] * g[s]


@njit
def _shift_matrix(delta, T):
    """``T`` with ``m(y - delta) = T m(y)``."""
    for r in range(NM):
        for s in range(NM):
            T[r, s] = 0.0
        T[r, r] = 1.0
    for a in range(3):
        T[1 + a, 0] = -delta[a]
    for q in range(6):
        a = _QA[q]
        b = _QB[q]
        T[4 + q, 0] = delta[a] * delta[b]
        T[4 + q, 1 + b] -= delta[a]
        T[4 + q, 1 + a] -= delta[b]


@njit
def _congruence(T, A, out, add):
    """``out = T A T^T`` (``out +=`` when `add`); plain loops (no BLAS call to compile)."""
    k = T.shape[0]
    tmp = np.zeros((k, k))
    for r in range(k):
        for q in range(k):
            t = T[r, q]
            if t != 0.0:
                for c in range(k):
                    tmp[r, c] += t * A[q, c]
    for r in range(k):
        for c in range(k):
            v = 0.0
            for q in range(k):
                v += tmp[r, q] * T[c, q]
            if add:
                out[r, c] += v
            else:
                out[r, c] = v


@njit
def _jacobi_min(K, v):
    """Smallest eigenvalue of the symmetric `K` (overwritten) and its eigenvector in `v`,
    by cyclic Jacobi rotations."""
    k = K.shape[0]
    V = np.eye(k)
    for _ in range(50):
        off = 0.0
        diag = 0.0
        for r in range(k):
            diag += K[r, r] * K[r, r]
            for q in range(r + 1, k):
                off += K[r, q] * K[r, q]
        if off <= 1e-30 * diag:
            break
        for p in range(k - 1):
            for q in range(p + 1, k):
                apq = K[p, q]
                if apq == 0.0:
                    continue
                theta = (K[q, q] - K[p, p]) / (2.0 * apq)
                t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * c
                for r in range(k):
                    krp = K[r, p]
                    krq = K[r, q]
                    K[r, p] = c * krp - sn * krq
                    K[r, q] = sn * krp + c * krq
                for r in range(k):
                    kpr = K[p, r]
                    kqr = K[q, r]
                    K[p, r] = c * kpr - sn * kqr
                    K[q, r] = sn * kpr + c * kqr
                for r in range(k):
                    vrp = V[r, p]
                    vrq = V[r, q]
                    V[r, p] = c * vrp - sn * vrq
                    V[r, q] = sn * vrp + c * vrq
    j = 0
    for r in range(1, k):
        if K[r, r] < K[j, j]:
            j = r
    for r in range(k):
        v[r] = V[r, j]
    return K[j, j]


@njit
def _cholesky_inverse(N, Li):
    """``Li = L^-1`` for the Cholesky factor ``N = L L^T``; False when `N` is not
    positive definite."""
    k = N.shape[0]
    L = np.zeros((k, k))
    if not cholesky_lower(N, k, 0.0, L):
        return False
    lower_inverse(L, k, Li)
    return True


@njit
def slot_merge(MA, GA, GdA, cA, MB, GB, GdB, cB, use_d, T):
    """Add unit B's sums (anchor `cB`) to unit A's (anchor `cA`)."""
    delta = np.empty(3)
    for a in range(3):
        delta[a] = cA[a] - cB[a]
    _shift_matrix(delta, T)
    _congruence(T, MB, MA, True)
    _congruence(T, GB, GA, True)
    if use_d:
        _congruence(T, GdB, GdA, True)


@njit
def quadric_statistic(M, G, Gd, use_d, sigma2, T):
    """Chi-square statistic (``n - 9`` degrees of freedom) of the Taubin quadric of a unit
    from its sums; ``inf`` when the moments are degenerate."""
    n = M[0, 0]
    if n <= QUADRIC_DOF:
        return np.inf
    mu = np.empty(3)
    for a in range(3):
        mu[a] = M[0, 1 + a] / n
    _shift_matrix(mu, T)  # about the centroid
    Mc = np.empty((NM, NM))
    Gc = np.empty((NM, NM))
    _congruence(T, M, Mc, False)
    _congruence(T, G, Gc, False)
    var = (Mc[1, 1] + Mc[2, 2] + Mc[3, 3]) / n
    if not var > 0.0:
        return np.inf
    s = 1.0 / np.sqrt(var)  # unit spread: conditioning only (the ratio is invariant)
    D = np.empty(NM)
    D[0] = 1.0
    for r in range(1, 4):
        D[r] = s
    for r in range(4, NM):
        D[r] = s * s
    k = NM - 1
    C = np.empty((k, k))
    N = np.empty((k, k))
    for r in range(k):
        for q in range(k):
            C[r, q] = D[r + 1] * D[q + 1] * (Mc[r + 1, q + 1] - Mc[r + 1, 0] * Mc[0, q + 1] / n)
            N[r, q] = D[r + 1] * D[q + 1] * Gc[r + 1, q + 1]
    tr = 0.0
    for r in range(k):
        tr += N[r, r]
    for r in range(k):
        N[r, r] += 1e-12 * tr
    Li = np.empty((k, k))
    if not _cholesky_inverse(N, Li):
        return np.inf
    K = np.empty((k, k))
    _congruence(Li, C, K, False)
    for r in range(k):
        for q in range(r + 1, k):
            K[r, q] = K[q, r] = 0.5 * (K[r, q] + K[q, r])
    v = np.empty(k)
    _jacobi_min(K, v)
    b = np.zeros(k)
    for r in range(k):
        for q in range(k):
            b[r] += Li[q, r] * v[q]
    rss = 0.0
    grad2 = 0.0  # sum |grad f|^2
    for r in range(k):
        for q in range(k):
            rss += b[r] * C[r, q] * b[q]
            grad2 += b[r] * N[r, q] * b[q]
    rss = max(rss, 0.0)
    if use_d:
        Gdc = np.empty((NM, NM))
        _congruence(T, Gd, Gdc, False)
        bd = np.empty(k)
        for r in range(k):
            bd[r] = D[r + 1] * b[r]
        dgrad2 = 0.0
        for r in range(k):
            for q in range(k):
                dgrad2 += bd[r] * Gdc[r + 1, q + 1] * bd[q]
        factor = max(dgrad2 / grad2, FACTOR_FLOOR) if grad2 > 0 else FACTOR_FLOOR
    else:
        factor = 1.0
    return n * rss / (sigma2 * factor * grad2)


@njit
def quadric_set_statistic(xyz, dirs, use_d, sigma2):
    """Statistic of the Taubin quadric of all points of `xyz` (a test's reference)."""
    M = np.zeros((NM, NM))
    G = np.zeros((NM, NM))
    Gd = np.zeros((NM, NM))
    m = np.empty(NM)
    J = np.empty((NM, 3))
    g = np.empty(NM)
    T = np.empty((NM, NM))
    c = xyz[0].copy()
    for i in range(xyz.shape[0]):
        slot_add_point(M, G, Gd, c, xyz[i], dirs[i], use_d, m, J, g)
    return quadric_statistic(M, G, Gd, use_d, sigma2, T)
