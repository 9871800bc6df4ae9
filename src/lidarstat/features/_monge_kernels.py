"""Numba kernels of the Monge form of a jet (Cazals and Pouget 2005), step 4 of the fit.

The surface ``J(x, y) - z = 0`` of a jet in its fitting frame, written in the Monge frame
(origin at the fitted point (0, 0, A0)), is the graph ``Z(X, Y)``; its Taylor coefficients
``k1, k2, b0..b3, c0..c4`` follow order by order from ``A + B Z + C Z^2 = 0`` (``_monge``).
Also the index tables of a jet's coefficients that the fit shares.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

#: Monge outputs: k1, k2, b0..b3, c0..c4
NMONGE = 11
_MAXD = 4
_MAXM = 15  # coefficients of a degree-4 jet
_MAXMOM = 45  # monomials of degree <= 8
_N_MONGE_OF = (0, 0, 2, 6, 11)  # Monge coefficients up to degree dm


def _tables():
    """Index tables: column (k, i) of the design <-> monomial U^(k-i) V^i; pair products."""
    mono_k, mono_i = [], []
    for k in range(2 * _MAXD + 1):
        for i in range(k + 1):
            mono_k.append(k)
            mono_i.append(i)
    col_fact = np.empty(_MAXM)
    col_deg = np.empty(_MAXM, np.int64)
    pair = np.empty((_MAXM, _MAXM), np.int64)
    for k in range(_MAXD + 1):
        for i in range(k + 1):
            a = k * (k + 1) // 2 + i
            col_fact[a] = math.factorial(k - i) * math.factorial(i)
            col_deg[a] = k
    for a in range(_MAXM):
        ka = int(col_deg[a])
        ia = a - ka * (ka + 1) // 2
        for c in range(_MAXM):
            kc = int(col_deg[c])
            ic = c - kc * (kc + 1) // 2
            kk = ka + kc
            pair[a, c] = kk * (kk + 1) // 2 + ia + ic
    return np.array(mono_k, np.int64), np.array(mono_i, np.int64), col_fact, col_deg, pair


MONO_K, MONO_I, COL_FACT, COL_DEG, PAIR = _tables()


@njit
def _hom_mul(p, dp, q, dq, out):
    """out (degree dp + dq) = p (degree dp) * q (degree dq); coefficients of X^(d-i) Y^i."""
    for t in range(dp + dq + 1):
        out[t] = 0.0
    for a in range(dp + 1):
        pa = p[a]
        if pa == 0.0:
            continue
        for c in range(dq + 1):
            out[a + c] += pa * q[c]


@njit
def _compose(A, kdeg, px, py, tmp, out):
    """Homogeneous part of degree kdeg of J(Lx, Ly) (plain coefficients).

    ``px[e]``, ``py[e]`` hold the powers Lx^e, Ly^e (degree e); A uses CGAL's ordering
    with Taylor scaling.
    """
    for t in range(kdeg + 1):
        out[t] = 0.0
    base = kdeg * (kdeg + 1) // 2
    for i in range(kdeg + 1):
        coef = A[base + i] / COL_FACT[base + i]
        if coef == 0.0:
            continue
        _hom_mul(px[kdeg - i], kdeg - i, py[i], i, tmp)
        for t in range(kdeg + 1):
            out[t] += coef * tmp[t]


@njit
def _monge(A, d, dm, ws, out, basis):
    """Monge form of the jet A (degree d) up to degree dm (2..4), in the fitting frame.

    out: k1, k2, b0..b3, c0..c4 (zeros above dm). basis rows: d1, d2, n (fitting frame).
    Returns False if the normal is undefined.
    """
    px, py, tmp, h2, h3, h4, b1p, b2p, z2, z3, z4 = ws
    for t in range(NMONGE):
        out[t] = 0.0
    a1 = A[1]
    a2 = A[2]
    s = math.sqrt(1.0 + a1 * a1 + a2 * a2)
    n0 = -a1 / s
    n1 = -a2 / s
    n2 = 1.0 / s
    # orthonormal tangent basis t1 = (1, 0, a1)/|.|, t2 = n x t1
    nt = math.sqrt(1.0 + a1 * a1)
    t10 = 1.0 / nt
    t11 = 0.0
    t12 = a1 / nt
    t20 = n1 * t12 - n2 * t11
    t21 = n2 * t10 - n0 * t12
    t22 = n0 * t11 - n1 * t10
    A3 = A[3] if d >= 2 else 0.0
    A4 = A[4] if d >= 2 else 0.0
    A5 = A[5] if d >= 2 else 0.0
    # second fundamental form in (t1, t2): P' H P / s, P = [[t10, t20], [t11, t21]]
    m00 = (t10 * (A3 * t10 + A4 * t11) + t11 * (A4 * t10 + A5 * t11)) / s
    m01 = (t10 * (A3 * t20 + A4 * t21) + t11 * (A4 * t20 + A5 * t21)) / s
    m11 = (t20 * (A3 * t20 + A4 * t21) + t21 * (A4 * t20 + A5 * t21)) / s
    tr = 0.5 * (m00 + m11)
    df = 0.5 * (m00 - m11)
    rad = math.sqrt(df * df + m01 * m01)
    k1 = tr + rad
    k2 = tr - rad
    # eigenvector of k1: angle theta with tan(2 theta) = 2 m01 / (m00 - m11)
    th = 0.5 * math.atan2(m01, df)
    c = math.cos(th)
    sn = math.sin(th)
    d10 = c * t10 + sn * t20
    d11 = c * t11 + sn * t21
    d12 = c * t12 + sn * t22
    # d2 = n x d1 makes (d1, d2, n) direct
    d20 = n1 * d12 - n2 * d11
    d21 = n2 * d10 - n0 * d12
    d22 = n0 * d11 - n1 * d10
    basis[0, 0] = d10
    basis[0, 1] = d11
    basis[0, 2] = d12
    basis[1, 0] = d20
    basis[1, 1] = d21
    basis[1, 2] = d22
    basis[2, 0] = n0
    basis[2, 1] = n1
    basis[2, 2] = n2
    out[0] = k1
    out[1] = k2
    if dm < 3:
        return True
    # powers of Lx = d10 X + d20 Y and Ly = d11 X + d21 Y
    px[0, 0] = 1.0
    py[0, 0] = 1.0
    px[1, 0] = d10
    px[1, 1] = d20
    py[1, 0] = d11
    py[1, 1] = d21
    for e in range(2, dm + 1):
        _hom_mul(px[e - 1], e - 1, px[1], 1, px[e])
        _hom_mul(py[e - 1], e - 1, py[1], 1, py[e])
    # A_k = J_k(L) (the degree-2 part is diagonal by construction: Z2 = (k1 X^2 + k2 Y^2)/2)
    z2[0] = 0.5 * k1
    z2[1] = 0.0
    z2[2] = 0.5 * k2
    if d >= 3:
        _compose(A, 3, px, py, tmp, h3)
    else:
        for t in range(4):
            h3[t] = 0.0
    # B'_1 = n_x (dJ/dx)_1(L) + n_y (dJ/dy)_1(L); (dJ/dx)_1 = A3 x + A4 y, (dJ/dy)_1 = A4 x + A5 y
    b1p[0] = n0 * (A3 * d10 + A4 * d11) + n1 * (A4 * d10 + A5 * d11)
    b1p[1] = n0 * (A3 * d20 + A4 * d21) + n1 * (A4 * d20 + A5 * d21)
    # Z3 = (A_3 + B'_1 Z2) / s
    _hom_mul(b1p, 1, z2, 2, tmp)
    for t in range(4):
        z3[t] = (h3[t] + tmp[t]) / s
    out[2] = 6.0 * z3[0]
    out[3] = 2.0 * z3[1]
    out[4] = 2.0 * z3[2]
    out[5] = 6.0 * z3[3]
    if dm < 4:
        return True
    if d >= 4:
        _compose(A, 4, px, py, tmp, h4)
    else:
        for t in range(5):
            h4[t] = 0.0
    # B'_2 = n_x (dJ/dx)_2(L) + n_y (dJ/dy)_2(L) with
    # (dJ/dx)_2 = (A6 x^2 + 2 A7 xy + A8 y^2)/2, (dJ/dy)_2 = (A7 x^2 + 2 A8 xy + A9 y^2)/2
    if d >= 3:
        A6 = A[6]
        A7 = A[7]
        A8 = A[8]
        A9 = A[9]
        # x^2, xy, y^2 of L as degree-2 polynomials: px[2], (px[1] py[1]), py[2]
        _hom_mul(px[1], 1, py[1], 1, tmp)
        cx2 = 0.5 * (n0 * A6 + n1 * A7)
        cxy = n0 * A7 + n1 * A8
        cy2 = 0.5 * (n0 * A8 + n1 * A9)
        for t in range(3):
            b2p[t] = cx2 * px[2, t] + cxy * tmp[t] + cy2 * py[2, t]
    else:
        for t in range(3):
            b2p[t] = 0.0
    # C0 = n_xy' H0 n_xy / 2
    c0 = 0.5 * (A3 * n0 * n0 + 2.0 * A4 * n0 * n1 + A5 * n1 * n1)
    # Z4 = (A_4 + B'_1 Z3 + B'_2 Z2 + C0 Z2^2) / s
    for t in range(5):
        z4[t] = h4[t]
    _hom_mul(b1p, 1, z3, 3, tmp)
    for t in range(5):
        z4[t] += tmp[t]
    _hom_mul(b2p, 2, z2, 2, tmp)
    for t in range(5):
        z4[t] += tmp[t]
    _hom_mul(z2, 2, z2, 2, tmp)
    for t in range(5):
        z4[t] = (z4[t] + c0 * tmp[t]) / s
    out[6] = 24.0 * z4[0]
    out[7] = 6.0 * z4[1]
    out[8] = 4.0 * z4[2]
    out[9] = 6.0 * z4[3]
    out[10] = 24.0 * z4[4]
    return True


@njit
def _monge_workspace():
    return (np.zeros((5, 5)), np.zeros((5, 5)), np.zeros(9), np.zeros(3), np.zeros(4),
            np.zeros(5), np.zeros(2), np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(5))


@njit_parallel
def monge_from_jets(A, d, dm, monge, basis):
    """Monge form of many jets (rows of A, fitting-frame coefficients); for tests/tools."""
    for r in prange(A.shape[0]):
        ws = _monge_workspace()
        _monge(A[r], d, dm, ws, monge[r], basis[r])
