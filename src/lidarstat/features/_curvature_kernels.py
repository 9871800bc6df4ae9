"""Numba kernel of the per-point curvature fields: noise model, statistics, tests, types.

Mirrors the vectorised reference formulas in ``_curvature_formulas.py`` (tested equal) so
the 2 x 5 Jacobian products, the 3 x 3 Wald solve and the 2 x 2 pseudo-inverse of the
paper's F test run without per-point temporaries. Each parallel task takes a chunk of 256
fits through four passes, each one function called once per chunk (not once per point
with a dozen array arguments): the height variance of each fit
(``_noise.fit_variance_and_spread``), the statistics, the p-values (erfc and the
Satterthwaite chi-square's tail in a loop of their own), then the decisions, the HK type
(``_hk.hk_surface_types``) and every field written into its output column.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ..stats import chi2_sf_scalar
from ._noise import FACTOR_FLOOR as _FACTOR_FLOOR
from ._noise import TRICUBE2_M2 as _TRICUBE2_M2
from ._noise import TRICUBE2_M4 as _TRICUBE2_M4
from ._noise import TRICUBE_M2 as _TRICUBE_M2

TEST_PAPER = 0
TEST_CALIBRATED = 1

# columns of the output matrix
(C_K, C_H, C_KMIN, C_KMAX, C_SDK, C_SDH, C_SDKMIN, C_SDKMAX, C_CHI2, C_CHI2DF, C_PLAN,
 C_PLANDF, C_S0, C_NX, C_NY, C_NZ, C_PLANP, C_KP, C_HP) = range(19)
NCOL = 19
C_RHO = NCOL  # scratch columns of curvature_fields: the spread (then the chi-square's
C_S2 = NCOL + 1  # p-value) and the height variance

_SQRT2 = math.sqrt(2.0)
_SQRT_2_OVER_PI = math.sqrt(2.0 / math.pi)
_CHUNK = 256  # points per parallel task of curvature_fields

# noise models of curvature_fields: the direction of sigma (``_noise``), or the height
# variance and the spread given per point
NOISE_Z = 0
NOISE_RANGE = 1
NOISE_NORMAL = 2
NOISE_GIVEN = 3

# rows of the float64 and uint8 output matrices of curvature_fields
(F_Z0, F_S0, F_K, F_H, F_KMIN, F_KMAX, F_DZ0, F_CHI2P, F_PLANP, F_KP, F_HP, F_NX, F_NY,
 F_NZ, F_KMIN_DET, F_HMIN_DET) = range(16)
NFLOAT = 14  # without the minimal detectable curvatures
(B_CHI2PASS, B_KSIG, B_HSIG, B_TYPE, B_STATUS) = range(5)
NBYTE = 5


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
def curvature_fields(status, npts, beta, cof, stats, frames, points, sensor, noise,
                     sigma2_given, spread_given, params, mode, dest, floats, flags, neighbors):
    """The curvature fields of a block of fits, point ``i`` into column ``dest[i]``.

    `params` is ``(sigma, radius, alpha, z_critical(alpha / 2), origin_z)``. `noise`
    (``NOISE_*``) gives each fit's height variance ``sigma^2 f`` and spread ``rho``
    (``_noise.fit_variance_and_spread``; `points`, the block's local coordinates, and
    `sensor` for the range; ``NOISE_GIVEN`` reads them from `sigma2_given`,
    `spread_given`). With `points` (not empty) z0 is the fitted height in file
    coordinates, else relative to the point. `floats` (at least NFLOAT rows) and `flags`
    (NBYTE rows) are the fields' rows (``F_*``, ``B_*``), `neighbors` the counts.
    """
    m = status.size
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunks):
        J = np.empty((4, 5))
        # a chunk's statistics (NCOL columns), then its spread and height variance
        rows = np.empty((_CHUNK, NCOL + 2))
        lo = ch * _CHUNK
        hi = min(m, lo + _CHUNK)
        # pass by pass over the chunk, each pass one function called once: no per-point
        # calls with a dozen array arguments, and the special functions (erfc, the
        # incomplete gamma) in a loop of their own
        if noise == NOISE_GIVEN:
            for i in range(lo, hi):
                rows[i - lo, C_RHO] = spread_given[i]
                rows[i - lo, C_S2] = sigma2_given[i]
        else:
            _height_variances(lo, hi, beta, frames, points, sensor, noise, params, rows)
        _statistics(lo, hi, status, npts, beta, cof, stats, frames, mode, J, rows)
        _p_values(lo, hi, status, mode, rows)
        _write_fields(lo, hi, status, npts, beta, frames, points, rows, params, dest, floats,
                      flags, neighbors)


@njit
def _height_variances(lo, hi, beta, frames, points, sensor, noise, params, rows):
    """``sigma^2 f`` and ``rho`` of fits lo..hi-1 into columns C_S2, C_RHO of `rows`
    (row ``i - lo``): ``_noise._factor_from_terms`` and ``_noise._spread_from_terms`` of
    their ``_noise._factor_terms``."""
    for i in range(lo, hi):
        s2, rho = _height_variance(i, beta, frames, points, sensor, noise, params)
        rows[i - lo, C_S2] = s2
        rows[i - lo, C_RHO] = rho


@njit(inline="always")
def _height_variance(i, beta, frames, points, sensor, noise, params):
    """``(sigma^2 f, rho)`` of fit i (:func:`_height_variances`)."""
    sigma = params[0]
    m2 = _TRICUBE_M2 * (params[1] * params[1])
    a1 = beta[i, 1]
    a2 = beta[i, 2]
    a3 = beta[i, 3]
    a4 = beta[i, 4]
    a5 = beta[i, 5]
    rho = 1.0
    if noise == NOISE_NORMAL:
        f = 1.0 + (a1 * a1 + a2 * a2) + m2 * (a3 * a3 + 2.0 * a4 * a4 + a5 * a5)
    else:
        d0 = 0.0
        d1 = 0.0
        d2 = 1.0
        if noise == NOISE_RANGE:
            d0 = points[i, 0] - sensor[0]
            d1 = points[i, 1] - sensor[1]
            d2 = points[i, 2] - sensor[2]
            nrm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if nrm > 0:
                d0 /= nrm
                d1 /= nrm
                d2 /= nrm
        t0 = frames[i, 0, 0] * d0 + frames[i, 0, 1] * d1 + frames[i, 0, 2] * d2
        t1 = frames[i, 1, 0] * d0 + frames[i, 1, 1] * d1 + frames[i, 1, 2] * d2
        te = frames[i, 2, 0] * d0 + frames[i, 2, 1] * d1 + frames[i, 2, 2] * d2
        a = te - (a1 * t0 + a2 * t1)
        gd0 = a3 * t0 + a4 * t1
        gd1 = a4 * t0 + a5 * t1
        g2 = gd0 * gd0 + gd1 * gd1
        f = a * a + m2 * g2
        b2 = params[1] * params[1]
        aa = a * a
        mean = aa + _TRICUBE_M2 * b2 * g2
        fourth = (aa * aa + 6.0 * aa * g2 * _TRICUBE2_M2 * b2
                  + g2 * g2 * _TRICUBE2_M4 * b2 * b2)
        rho = fourth / (mean * mean) if mean != 0.0 else np.nan
        if not np.isfinite(rho):
            rho = 1.0
        rho = max(rho, 1.0)
    if not np.isfinite(f):
        f = 1.0
    return sigma * sigma * max(f, _FACTOR_FLOOR), rho


@njit
def _write_fields(lo, hi, status, npts, beta, frames, points, rows, params, dest, floats,
                  flags, neighbors):
    """Fits lo..hi-1's fields from their statistics and p-values (rows ``i - lo`` of
    `rows`, the chi-square's in column C_RHO) into columns ``dest[i]``
    (``curvature_tests``)."""
    alpha = params[2]
    for i in range(lo, hi):
        row = rows[i - lo]
        j = dest[i]
        fitted = status[i] == 0
        chi2_p = row[C_RHO]
        chi2_pass = fitted and chi2_p == chi2_p and not chi2_p < alpha
        planar = not row[C_PLANP] < alpha
        K_sig = row[C_KP] < 0.5 * alpha
        H_sig = row[C_HP] < 0.5 * alpha
        K = row[C_K]
        H = row[C_H]
        kind = 0  # hk_surface_types
        if chi2_pass:
            if planar or not (K_sig or H_sig):
                kind = 1
            elif not K_sig:
                kind = 2 if H < 0 else (3 if H > 0 else 0)
            elif K > 0:
                kind = 4 if H < 0 else 5
            elif K < 0:
                if not H_sig:
                    kind = 8
                elif H < 0:
                    kind = 6
                elif H > 0:
                    kind = 7
        z0 = beta[i, 0] * frames[i, 2, 2]
        if points.shape[0] > 0:
            z0 = (z0 + points[i, 2]) + params[4]
        neighbors[j] = npts[i]
        floats[F_Z0, j] = z0
        floats[F_S0, j] = row[C_S0]
        floats[F_K, j] = K
        floats[F_H, j] = H
        floats[F_KMIN, j] = row[C_KMIN]
        floats[F_KMAX, j] = row[C_KMAX]
        floats[F_DZ0, j] = beta[i, 0]
        floats[F_CHI2P, j] = chi2_p
        floats[F_PLANP, j] = row[C_PLANP]
        floats[F_KP, j] = row[C_KP]
        floats[F_HP, j] = row[C_HP]
        floats[F_NX, j] = row[C_NX]
        floats[F_NY, j] = row[C_NY]
        floats[F_NZ, j] = row[C_NZ]
        if floats.shape[0] > NFLOAT:  # eq. 19, two-sided at alpha/2 (Bonferroni)
            floats[F_KMIN_DET, j] = params[3] * row[C_SDK]
            floats[F_HMIN_DET, j] = params[3] * row[C_SDH]
        flags[B_CHI2PASS, j] = chi2_pass
        flags[B_KSIG, j] = chi2_pass and K_sig
        flags[B_HSIG, j] = chi2_pass and H_sig
        flags[B_TYPE, j] = kind
        flags[B_STATUS, j] = 3 if fitted and not chi2_pass else status[i]


@njit
def _statistics(lo, hi, status, npts, beta, cof, stats, frames, mode, J, rows):
    """Fits lo..hi-1 of :func:`curvature_statistics` into rows ``i - lo`` of `rows`
    (NCOL columns), at the height variances of column C_S2; `J` (4, 5) is scratch."""
    for i in range(lo, hi):
        row = rows[i - lo]
        s2i = row[C_S2]
        for c in range(NCOL):
            row[c] = np.nan
        if status[i] != 0:
            continue
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
        row[C_K] = K
        row[C_H] = H
        row[C_KMIN] = H - disc
        row[C_KMAX] = H + disc
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
            row[C_CHI2] = q / s2i
            row[C_CHI2DF] = p - 6.0
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
                row[C_PLAN] = stat / (rank * s0)
                row[C_PLANDF] = rank
        else:
            trb = stats[i, 2]
            trb2 = stats[i, 3]
            s0 = q / trb
            s2 = s2i
            c = trb2 / trb
            row[C_CHI2] = q / (c * s2)
            row[C_CHI2DF] = trb * trb / trb2
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
                row[C_PLAN] = w / (dt * s2)
                row[C_PLANDF] = 3.0
        row[C_S0] = s0
        # the four variances J[r] . cof[i, 1:, 1:] . J[r] in one pass over the cofactor (each
        # sum in the order of _quad)
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        v3 = 0.0
        for a in range(5):
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            t3 = 0.0
            for b in range(5):
                cab = cof[i, a + 1, b + 1]
                t0 += cab * J[0, b]
                t1 += cab * J[1, b]
                t2 += cab * J[2, b]
                t3 += cab * J[3, b]
            v0 += J[0, a] * t0
            v1 += J[1, a] * t1
            v2 += J[2, a] * t2
            v3 += J[3, a] * t3
        row[C_SDK] = np.sqrt(max(s2 * v0, 0.0))
        row[C_SDH] = np.sqrt(max(s2 * v1, 0.0))
        if disc > 0:
            row[C_SDKMIN] = np.sqrt(max(s2 * v2, 0.0))
            row[C_SDKMAX] = np.sqrt(max(s2 * v3, 0.0))
        nx = -a1
        ny = -a2
        nn = np.sqrt(a1 * a1 + a2 * a2 + 1.0)
        for k in range(3):
            row[C_NX + k] = (frames[i, 0, k] * nx + frames[i, 1, k] * ny + frames[i, 2, k]) / nn


@njit
def _p_values(lo, hi, status, mode, rows):
    """The p-values of fits lo..hi-1 from their statistics (rows ``i - lo`` of `rows`):
    planarity, H, K in closed form, the chi-square's in column C_RHO (over the spread)."""
    for i in range(lo, hi):
        row = rows[i - lo]
        if status[i] == 0:
            row[C_PLANP] = chi2_sf_small_df(row[C_PLAN] * (row[C_PLANDF] if mode == TEST_PAPER
                                                           else 1.0), row[C_PLANDF])
            row[C_HP] = normal_two_sided(row[C_H], row[C_SDH])
            if mode == TEST_PAPER:
                row[C_KP] = normal_two_sided(row[C_K], row[C_SDK])
            else:
                # K = kmin kmax differs from 0 iff both principal curvatures do
                # (intersection-union test: each at alpha/2 gives a level-alpha/2 test of K = 0)
                p_min = normal_two_sided(row[C_KMIN], row[C_SDKMIN])
                p_max = normal_two_sided(row[C_KMAX], row[C_SDKMAX])
                if p_min != p_min:  # undefined (umbilic): the other decides, as np.fmax
                    row[C_KP] = p_max
                elif p_max != p_max:
                    row[C_KP] = p_min
                else:
                    row[C_KP] = max(p_min, p_max)
        # v'Wv against its Satterthwaite chi-square, scale and degrees of freedom by the
        # spread
        rho = row[C_RHO]
        df = row[C_CHI2DF] / rho if row[C_CHI2DF] > 0 else np.nan
        row[C_RHO] = chi2_sf_scalar(row[C_CHI2] / rho, df)
