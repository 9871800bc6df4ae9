"""Numba kernels of jet fitting (Cazals and Pouget 2005); the Monge form is in ``_monge_kernels``.

Per query point i, with neighbours j, offsets d_j = x_j - x_i and weights w_j (tricube of
d_ij/b, or 1 for CGAL's unweighted fit), the four steps are:

1. PCA frame (``_frame_kernels._local_frame``): eigenvectors of the (weighted) covariance
   of the neighbourhood, e1 the largest, n the smallest, n oriented toward the sensor or up,
   (e1, e2, n) direct.
2. Polynomial fit of degree d in that frame, origin at the point: heights h_j on
   ``J(u, v) = sum_k sum_i A[k(k+1)/2 + i] u^(k-i) v^i / ((k-i)! i!)`` (CGAL's ordering
   and Taylor scaling: A holds the partial derivatives), by weighted least squares on
   coordinates scaled by 1/b. The normal matrix ``N = X'WX`` is assembled from weighted
   moment sums of the monomials ``U^a V^c`` (a + c <= 2d), equilibrated by its diagonal
   and inverted by Cholesky.
3. Monge basis: normal ``(-A1, -A2, 1)/s`` with ``s = sqrt(1 + A1^2 + A2^2)``; the second
   fundamental form in an orthonormal tangent basis, diagonalised: k1 >= k2 with directions
   d1, d2, (d1, d2, n) direct.
4. Monge coefficients: the surface ``J(x, y) - z = 0`` written in the Monge frame
   (origin at the fitted point (0, 0, A0)) is the graph ``Z(X, Y)``; its Taylor
   coefficients follow order by order from ``A + B Z + C Z^2 = 0`` (see ``_monge``).

Statistics as for the quadric: residual form ``Q = v'Wv``, ``tr(B)`` and ``tr(B^2)`` with
``B = W - W X N^-1 X'W`` for the Satterthwaite chi-square; cofactor of A the sandwich
``N^-1 X'W^2X N^-1``; the Monge coefficients' cofactors by first-order propagation with a
forward-difference Jacobian (the PCA frame held fixed).
"""

from __future__ import annotations

import math

import numpy as np

from .._shared._jit import njit
from ..neighbors import make_drivers
from ._frame_kernels import FRAME_PCA, _local_frame, cholesky_inverse_n, to_frame
from ._monge_kernels import (
    _MAXM,
    _MAXMOM,
    _N_MONGE_OF,
    COL_DEG,
    COL_FACT,
    NMONGE,
    PAIR,
    _monge,
    _monge_workspace,
)

OK = 0
TOO_FEW = 1
SINGULAR = 2
SKIPPED = 255

#: stats columns: Q, sum w, tr(B), tr(B^2), sqrt cond_1(equilibrated N), bandwidth, A0,
#: distance from the point to the (unweighted) centroid of its neighbours over the bandwidth
NSTAT = 8


@njit
def n_coef(d):
    return (d + 1) * (d + 2) // 2


#: Smallest ratio of the RMS spreads along the two tangent axes of a fitted neighbourhood
#: (smaller: collinear points, status DEGENERATE). Rounding leaves ~1e-16 across a line; a
#: real strip 1 mm wide in a 1 m neighbourhood has 1e-3.
_FLAT = 1e-8


@njit
def _monomials(u, v, nmom_deg, out):
    """out[k(k+1)/2 + i] = u^(k-i) v^i for k <= nmom_deg."""
    out[0] = 1.0
    t = 1
    for k in range(1, nmom_deg + 1):
        # row k from row k-1: multiply by u, the last one by v too
        s = t - k  # start of row k-1
        for i in range(k):
            out[t + i] = out[s + i] * u
        out[t + k] = out[s + k - 1] * v
        t += k + 1


@njit
def _norm1(a, m):
    """1-norm (largest absolute column sum) of the leading m x m block of `a`."""
    norm = 0.0
    for c in range(m):
        acc = 0.0
        for r in range(m):
            acc += abs(a[r, c])
        if acc > norm:
            norm = acc
    return norm


@njit
def _workspace(m):
    return (np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(_MAXMOM),
            np.empty((3, _MAXMOM)), np.empty((m, m)), np.empty((m, m)), np.empty((m, m)),
            np.empty((m, m)), np.empty((m, m)), np.empty(m), np.empty(m), np.empty(m),
            np.empty(NMONGE), np.empty((3, 3)), _monge_workspace(), np.empty((NMONGE, _MAXM)),
            np.empty((3, 3)))


@njit
def _jet_one(i, pts, idx, dist, s, e, bw, d, dm, weighted, sensor, has_sensor, min_nb, want_se,
             ws, buf, jet_out, monge_out, frame_out, stats_out, mcof_out):
    """Fit the jet at point i. Returns (status, p).

    frame_out rows: d1, d2, n in file coordinates. stats_out: see NSTAT. mcof_out: diagonal
    cofactors of the Monge coefficients (times sigma^2: variances), NaN if not wanted.
    """
    (cov, ev, evec, mono, mom, N, N2, N3, L, Ninv, rhs, beta, dsc, mtmp, mbasis, mws,
     jac, R) = ws
    # buf as four columns of its size, row t the neighbour's (d0, d1, d2, w): the layout
    # the frame kernels read (as the quadric kernel's)
    rows = buf.reshape((4, buf.shape[0])).T
    m = n_coef(d)
    nmd = 2 * d
    nmom = (nmd + 1) * (nmd + 2) // 2
    b = bw
    if b <= 0.0:
        for t in range(s, e):
            if dist[t] > b:
                b = dist[t]
    if not b > 0.0:
        return TOO_FEW, 0
    # pass 1: offsets and weights into buf
    p = 0
    sw = 0.0
    px0 = pts[i, 0]
    py0 = pts[i, 1]
    pz0 = pts[i, 2]
    for t in range(s, e):
        if weighted:
            q = dist[t] / b
            if q >= 1.0:
                continue
            q = 1.0 - q * q * q
            w = q * q * q
        else:
            w = 1.0
        j = idx[t]
        dx = pts[j, 0] - px0
        dy = pts[j, 1] - py0
        dz = pts[j, 2] - pz0
        rows[p, 0] = dx
        rows[p, 1] = dy
        rows[p, 2] = dz
        rows[p, 3] = w
        sw += w
        p += 1
    if p < min_nb or p <= m:
        return TOO_FEW, p
    ux = 0.0
    uy = 0.0
    uz = 0.0
    for t in range(p):
        ux += rows[t, 0]
        uy += rows[t, 1]
        uz += rows[t, 2]
    stats_out[7] = math.sqrt(ux * ux + uy * uy + uz * uz) / (p * b)
    # PCA frame (rows e, f, n of R) from the offsets and weights in buf
    if not (_local_frame(rows, p, px0, py0, pz0, FRAME_PCA, sensor, has_sensor, R, cov, ev, evec,
                         False) and ev[1] > 0.0):
        return SINGULAR, p
    # pass 2: local coordinates (U, V scaled by 1/b), moments of the monomials
    inv_b = 1.0 / b
    weighted_stats = weighted
    for k in range(nmom):
        mom[0, k] = 0.0
        mom[1, k] = 0.0
        mom[2, k] = 0.0
    for a in range(m):
        rhs[a] = 0.0
    to_frame(rows, p, R, inv_b)
    for t in range(p):
        w = rows[t, 3]
        _monomials(rows[t, 0], rows[t, 1], nmd, mono)
        wh = w * rows[t, 2]
        for a in range(m):
            rhs[a] += wh * mono[a]
        if weighted_stats:
            w2 = w * w
            w3 = w2 * w
            for k in range(nmom):
                mk = mono[k]
                mom[0, k] += w * mk
                mom[1, k] += w2 * mk
                mom[2, k] += w3 * mk
        else:
            for k in range(nmom):
                mom[0, k] += mono[k]
    # normal matrices with the Taylor factorials, equilibrated by the diagonal of N
    for a in range(m):
        dsc[a] = math.sqrt(mom[0, PAIR[a, a]]) / COL_FACT[a]
        if not dsc[a] > 0.0:
            return SINGULAR, p
    # collinear neighbours: the spread across the line is rounding error, which the
    # equilibration below would scale up to a well-conditioned (meaningless) system
    if m > 2 and (dsc[2] < _FLAT * dsc[1] or dsc[1] < _FLAT * dsc[2]):
        return SINGULAR, p
    for a in range(m):
        for c in range(a, m):
            f = 1.0 / (COL_FACT[a] * COL_FACT[c])
            k = PAIR[a, c]
            sc = dsc[a] * dsc[c]
            N[a, c] = f * mom[0, k] / sc
            N[c, a] = N[a, c]
            if weighted_stats:
                N2[a, c] = f * mom[1, k] / sc
                N3[a, c] = f * mom[2, k] / sc
                N2[c, a] = N2[a, c]
                N3[c, a] = N3[a, c]
    # 1-norm of the equilibrated N (for the condition number)
    norm1 = _norm1(N, m)
    if not cholesky_inverse_n(N, m, 1e-13, L, Ninv):
        return SINGULAR, p
    ninv1 = _norm1(Ninv, m)
    # beta (scaled, equilibrated) = Ninv D^-1 rhs / fact
    for a in range(m):
        rhs[a] = rhs[a] / (COL_FACT[a] * dsc[a])
    for a in range(m):
        acc = 0.0
        for c in range(m):
            acc += Ninv[a, c] * rhs[c]
        beta[a] = acc / dsc[a]  # coefficient of U^(k-i) V^i / ((k-i)! i!)
    # pass 3: explicit weighted residual sum of squares
    q = 0.0
    for t in range(p):
        _monomials(rows[t, 0], rows[t, 1], d, mono)
        fit = 0.0
        for a in range(m):
            fit += beta[a] * mono[a] / COL_FACT[a]
        r = rows[t, 2] - fit
        q += rows[t, 3] * r * r
    # traces and the cofactor (in equilibrated units: cof = D^-1 S D^-1)
    if weighted_stats:
        sw2 = mom[1, 0]
        t2 = 0.0
        t3 = 0.0
        for a in range(m):
            for c in range(m):
                t2 += Ninv[a, c] * N2[c, a]
                t3 += Ninv[a, c] * N3[c, a]
        for a in range(m):  # L := Ninv N2
            for c in range(m):
                acc = 0.0
                for k in range(m):
                    acc += Ninv[a, k] * N2[k, c]
                L[a, c] = acc
        trsn2 = 0.0  # tr((Ninv N2)^2) = tr(S N2)
        for a in range(m):
            for c in range(m):
                trsn2 += L[a, c] * L[c, a]
        if want_se:
            for a in range(m):  # N3 := S = (Ninv N2) Ninv (N3 no longer needed)
                for c in range(m):
                    acc = 0.0
                    for k in range(m):
                        acc += L[a, k] * Ninv[k, c]
                    N3[a, c] = acc
        stats_out[2] = sw - t2
        stats_out[3] = sw2 - 2.0 * t3 + trsn2
    else:
        for a in range(m):
            for c in range(m):
                N3[a, c] = Ninv[a, c]
        stats_out[2] = p - m
        stats_out[3] = p - m
    stats_out[0] = q
    stats_out[1] = sw
    stats_out[4] = math.sqrt(norm1 * ninv1)
    stats_out[5] = b
    # physical units: A = beta / b^k; cofactor scaled with D and b
    for a in range(m):
        sa = inv_b ** COL_DEG[a]
        jet_out[a] = beta[a] * sa
        dsc[a] = sa / dsc[a]  # now maps equilibrated -> physical
    for a in range(m, _MAXM):
        jet_out[a] = 0.0
    stats_out[6] = jet_out[0]
    for a in range(m):
        for c in range(m):
            N3[a, c] *= dsc[a] * dsc[c]  # physical cofactor of A
    if not _monge(jet_out, d, dm, mws, monge_out, mbasis):
        return SINGULAR, p
    # Monge basis to file coordinates: rows d1, d2, n
    for r in range(3):
        x0 = mbasis[r, 0]
        x1 = mbasis[r, 1]
        x2 = mbasis[r, 2]
        for c in range(3):
            frame_out[r, c] = x0 * R[0, c] + x1 * R[1, c] + x2 * R[2, c]
    for t in range(_N_MONGE_OF[dm], NMONGE):
        monge_out[t] = np.nan
    if not want_se:
        for t in range(NMONGE):
            mcof_out[t] = np.nan
        return OK, p
    # first-order propagation: forward differences of the Monge map in A (frame fixed)
    for t in range(NMONGE):
        mcof_out[t] = 0.0
    for a in range(m):
        sd = math.sqrt(max(N3[a, a], 0.0))
        if not sd > 0.0:
            for t in range(NMONGE):
                jac[t, a] = 0.0
            continue
        step = 1e-4 * sd
        keep = jet_out[a]
        jet_out[a] = keep + step
        _monge(jet_out, d, dm, mws, mtmp, mbasis)
        jet_out[a] = keep
        for t in range(NMONGE):
            jac[t, a] = (mtmp[t] - monge_out[t]) / step
    for t in range(NMONGE):
        acc = 0.0
        for a in range(m):
            ja = jac[t, a]
            if ja == 0.0:
                continue
            inner = 0.0
            for c in range(m):
                inner += N3[a, c] * jac[t, c]
            acc += ja * inner
        mcof_out[t] = acc
    for t in range(_N_MONGE_OF[dm], NMONGE):
        mcof_out[t] = np.nan
    return OK, p


@njit
def _fail(r, st, p, status, npts, jet, monge, frames, stats, mcof):
    status[r] = st
    npts[r] = p
    for a in range(_MAXM):
        jet[r, a] = np.nan
    for a in range(NMONGE):
        monge[r, a] = np.nan
        mcof[r, a] = np.nan
    for a in range(3):
        for c in range(3):
            frames[r, a, c] = np.nan
    for a in range(NSTAT):
        stats[r, a] = np.nan


@njit
def _jet_workspace(params):
    return _workspace(n_coef(params[1]))


@njit
def _jet_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs):
    """Fit the jet of point i from ``idx[s:e]`` into output row r (generic-driver protocol,
    ``neighbors/_drivers.py``). params: bandwidth (<= 0: farthest neighbour), degree,
    Monge degree, weighted, sensor, has_sensor, min_neighbors, want_se."""
    bw, d, dm, weighted, sensor, has_sensor, min_nb, want_se = params
    status, npts, jet, monge, frames, stats, mcof = outs
    st, p = _jet_one(i, pts, idx, dist, s, e, bw, d, dm, weighted, sensor, has_sensor, min_nb,
                     want_se, ws, buf, jet[r], monge[r], frames[r], stats[r], mcof[r])
    if st != OK:
        _fail(r, st, p, status, npts, jet, monge, frames, stats, mcof)
    else:
        status[r] = st
        npts[r] = p


@njit
def _jet_skip(r, outs):
    status, npts, jet, monge, frames, stats, mcof = outs
    _fail(r, SKIPPED, 0, status, npts, jet, monge, frames, stats, mcof)


#: ``fit_jets_block(pts, query, indptr, idx, dist, params, outs)`` (CSR rows) and
#: ``fit_jets_cells(c0, c1, pts, cell_keys, cell_start, dims, radius, active, params, outs)``
#: (fused radius search), with ``params`` and ``outs`` as :func:`_jet_point`'s.
fit_jets_block, fit_jets_cells = make_drivers(_jet_point, _jet_workspace, _jet_skip)
