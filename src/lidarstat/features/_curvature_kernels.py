"""Numba kernel of the per-point curvature statistics (K, H, their variances, test statistics).

Mirrors the vectorised reference formulas in ``_curvature_formulas.py`` (tested equal) so
the 2 x 5 Jacobian products, the 3 x 3 Wald solve and the 2 x 2 pseudo-inverse of the
paper's F test run without per-point temporaries. p-values are left to SciPy's ufuncs.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

TEST_PAPER = 0
TEST_CALIBRATED = 1

# columns of the output matrix
(C_K, C_H, C_KMIN, C_KMAX, C_SDK, C_SDH, C_SDKMIN, C_SDKMAX, C_CHI2, C_CHI2DF, C_PLAN,
 C_PLANDF, C_S0, C_NX, C_NY, C_NZ, C_PLANP, C_KP, C_HP) = range(19)
NCOL = 19

_SQRT2 = math.sqrt(2.0)
_SQRT_2_OVER_PI = math.sqrt(2.0 / math.pi)
_CHUNK = 256  # points per parallel task of curvature_statistics


@njit
def chi2_sf_small_df(x, df):
    """Upper tail of chi2(df) for df in {1, 2, 3} in closed form (NaN otherwise)."""
    if not x >= 0.0:
        return np.nan
    if df == 1:
        return math.erfc(math.sqrt(0.5 * x))
    if df == 2:
        return math.exp(-0.5 * x)
    if df == 3:
        return math.erfc(math.sqrt(0.5 * x)) + _SQRT_2_OVER_PI * math.sqrt(x) * math.exp(-0.5 * x)
    return np.nan


@njit
def normal_two_sided(est, sd):
    """Two-sided normal p-value of est/sd (NaN where sd is not positive)."""
    if not sd > 0.0:
        return np.nan
    return math.erfc(abs(est / sd) / _SQRT2)


@njit
def _quad(J, cof, s2, i, r1, r2):
    """s2 * J[r1] . cof[i, 1:, 1:] . J[r2]."""
    acc = 0.0
    for a in range(5):
        t = 0.0
        for b in range(5):
            t += cof[i, a + 1, b + 1] * J[r2, b]
        acc += J[r1, a] * t
    return s2 * acc


@njit_parallel
def curvature_statistics(status, npts, beta, cof, stats, frames, sigma2, mode, out):
    """Fill `out` (M, NCOL) with curvature, standard deviations and test statistics."""
    m = status.size
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunks):
        J = np.empty((4, 5))  # Jacobian rows of K, H, kmin, kmax (one per chunk of points)
        for i in range(ch * _CHUNK, min(m, (ch + 1) * _CHUNK)):
            _statistics_one(i, status, npts, beta, cof, stats, frames, sigma2, mode, J, out)


@njit
def _statistics_one(i, status, npts, beta, cof, stats, frames, sigma2, mode, J, out):
    """Row i of :func:`curvature_statistics`; `J` (4, 5) is scratch."""
    for c in range(NCOL):
        out[i, c] = np.nan
    if status[i] != 0:
        return
    a1 = beta[i, 1]
    a2 = beta[i, 2]
    a3 = beta[i, 3]
    a4 = beta[i, 4]
    a5 = beta[i, 5]
    g = 1.0 + a1 * a1 + a2 * a2
    det = a3 * a5 - a4 * a4
    num = a3 * (1.0 + a2 * a2) + a5 * (1.0 + a1 * a1) - 2.0 * a1 * a2 * a4
    g2 = g * g
    g3 = g2 * g
    sg = np.sqrt(g)
    g15 = 2.0 * g * sg  # 2 g^1.5
    g25 = g2 * sg  # g^2.5
    K = det / g2
    H = num / g15
    disc = np.sqrt(max(H * H - K, 0.0))
    out[i, C_K] = K
    out[i, C_H] = H
    out[i, C_KMIN] = H - disc
    out[i, C_KMAX] = H + disc
    J[0, 0] = -4.0 * a1 * det / g3
    J[0, 1] = -4.0 * a2 * det / g3
    J[0, 2] = a5 / g2
    J[0, 3] = -2.0 * a4 / g2
    J[0, 4] = a3 / g2
    J[1, 0] = (2.0 * a1 * a5 - 2.0 * a2 * a4) / g15 - 1.5 * num * a1 / g25
    J[1, 1] = (2.0 * a2 * a3 - 2.0 * a1 * a4) / g15 - 1.5 * num * a2 / g25
    J[1, 2] = (1.0 + a2 * a2) / g15
    J[1, 3] = -2.0 * a1 * a2 / g15
    J[1, 4] = (1.0 + a1 * a1) / g15
    for b in range(5):  # principal curvatures
        t = (2.0 * H * J[1, b] - J[0, b]) / (2.0 * disc) if disc > 0 else np.nan
        J[2, b] = J[1, b] - t
        J[3, b] = J[1, b] + t
    q = stats[i, 0]
    p = npts[i]
    if mode == TEST_PAPER:
        s0 = q / (p - 6.0)
        s2 = s0
        out[i, C_CHI2] = q / sigma2[i]
        out[i, C_CHI2DF] = p - 6.0
        # eq. 17: w' Q^-1 w / r with a 2x2 pseudo-inverse, r its rank
        qkk = _quad(J, cof, 1.0, i, 0, 0)
        qkh = _quad(J, cof, 1.0, i, 0, 1)
        qhh = _quad(J, cof, 1.0, i, 1, 1)
        tr = 0.5 * (qkk + qhh)
        dd = np.sqrt(max(0.25 * (qkk - qhh) ** 2 + qkh * qkh, 0.0))
        l1 = tr + dd
        l2 = tr - dd
        stat = 0.0
        rank = 0
        if l1 > 0:
            # eigenvectors of [[qkk, qkh], [qkh, qhh]]
            for lam in (l1, l2):
                if lam <= 1e-10 * l1:
                    continue
                vx = qkh
                vy = lam - qkk
                if abs(vx) + abs(vy) == 0.0:
                    vx = lam - qhh
                    vy = qkh
                if abs(vx) + abs(vy) == 0.0:
                    vx = 1.0 if lam == l1 else 0.0
                    vy = 0.0 if lam == l1 else 1.0
                nrm = np.sqrt(vx * vx + vy * vy)
                proj = (vx * K + vy * H) / nrm
                stat += proj * proj / lam
                rank += 1
        if rank > 0 and s0 > 0:
            out[i, C_PLAN] = stat / (rank * s0)
            out[i, C_PLANDF] = rank
    else:
        trb = stats[i, 2]
        trb2 = stats[i, 3]
        s0 = q / trb
        s2 = sigma2[i]
        c = trb2 / trb
        out[i, C_CHI2] = q / (c * s2)
        out[i, C_CHI2DF] = trb * trb / trb2
        # Wald test of a3 = a4 = a5 = 0 with covariance s2 * cof[3:, 3:]
        m00 = cof[i, 3, 3]
        m01 = cof[i, 3, 4]
        m02 = cof[i, 3, 5]
        m11 = cof[i, 4, 4]
        m12 = cof[i, 4, 5]
        m22 = cof[i, 5, 5]
        c00 = m11 * m22 - m12 * m12
        c01 = m02 * m12 - m01 * m22
        c02 = m01 * m12 - m02 * m11
        dt = m00 * c00 + m01 * c01 + m02 * c02
        if dt > 0:
            c11 = m00 * m22 - m02 * m02
            c12 = m01 * m02 - m00 * m12
            c22 = m00 * m11 - m01 * m01
            w = (a3 * a3 * c00 + a4 * a4 * c11 + a5 * a5 * c22
                 + 2.0 * (a3 * a4 * c01 + a3 * a5 * c02 + a4 * a5 * c12))
            out[i, C_PLAN] = w / (dt * s2)
            out[i, C_PLANDF] = 3.0
    out[i, C_S0] = s0
    out[i, C_SDK] = np.sqrt(max(_quad(J, cof, s2, i, 0, 0), 0.0))
    out[i, C_SDH] = np.sqrt(max(_quad(J, cof, s2, i, 1, 1), 0.0))
    if disc > 0:
        out[i, C_SDKMIN] = np.sqrt(max(_quad(J, cof, s2, i, 2, 2), 0.0))
        out[i, C_SDKMAX] = np.sqrt(max(_quad(J, cof, s2, i, 3, 3), 0.0))
    # p-values with closed forms (the Satterthwaite chi-square is left to SciPy)
    out[i, C_PLANP] = chi2_sf_small_df(out[i, C_PLAN] * (out[i, C_PLANDF] if mode == TEST_PAPER
                                                         else 1.0), out[i, C_PLANDF])
    out[i, C_HP] = normal_two_sided(H, out[i, C_SDH])
    if mode == TEST_PAPER:
        out[i, C_KP] = normal_two_sided(K, out[i, C_SDK])
    else:
        # K = kmin kmax differs from 0 iff both principal curvatures do
        # (intersection-union test: each at alpha/2 gives a level-alpha/2 test of K = 0)
        p_min = normal_two_sided(H - disc, out[i, C_SDKMIN])
        p_max = normal_two_sided(H + disc, out[i, C_SDKMAX])
        if p_min != p_min:  # undefined (umbilic): the other decides, as np.fmax
            out[i, C_KP] = p_max
        elif p_max != p_max:
            out[i, C_KP] = p_min
        else:
            out[i, C_KP] = max(p_min, p_max)
    nx = -a1
    ny = -a2
    nn = np.sqrt(a1 * a1 + a2 * a2 + 1.0)
    for k in range(3):
        out[i, C_NX + k] = (frames[i, 0, k] * nx + frames[i, 1, k] * ny + frames[i, 2, k]) / nn
