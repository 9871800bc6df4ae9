"""Numba kernels of the scan-grid tests (:mod:`._scan_grid`, :mod:`._grid_boundary`): the
range continuity of a grid edge and the smoothness of the grid line on either side of it."""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

#: Grid neighbours kept per point (8-neighbourhood of a regular angular grid).
SLOTS = 8


@njit
def _continuation(dirs, adj, a, tx, ty, tz, tol2):
    """Neighbour of `a` nearest the direction (tx, ty, tz), within sqrt(tol2); else -1."""
    best = -1
    bd = tol2
    for k in range(adj.shape[1]):
        c = adj[a, k]
        if c < 0:
            continue
        x = dirs[c, 0] - tx
        y = dirs[c, 1] - ty
        z = dirs[c, 2] - tz
        q = x * x + y * y + z * z
        if q < bd:
            bd = q
            best = c
    return best


@njit
def _grid_step(dirs, a, b):
    """The direction step from a to b and the squared tolerance (half of it) within which
    a node continues the grid line."""
    ex = dirs[b, 0] - dirs[a, 0]
    ey = dirs[b, 1] - dirs[a, 1]
    ez = dirs[b, 2] - dirs[a, 2]
    return ex, ey, ez, 0.25 * (ex * ex + ey * ey + ez * ez)


#: Gauss-Legendre nodes and weights on [-1, 1] (the same-sign tail integral below).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)


@njit
def _phibar(x):
    return 0.5 * math.erfc(x / math.sqrt(2.0))


@njit
def same_sign_p(t, rho, gx, gw):
    """``P(min(Z1, Z2) > t) + P(max(Z1, Z2) < -t)`` for standard normals of correlation rho.

    ``2 int_t^inf phi(x) Phibar((t - rho x) / sqrt(1 - rho^2)) dx``, by Gauss-Legendre on
    [t, t + 9].
    """
    if t <= 0:
        return 1.0
    q = math.sqrt(max(1.0 - rho * rho, 1e-12))
    acc = 0.0
    for k in range(gx.size):
        x = t + 4.5 * (gx[k] + 1.0)
        acc += gw[k] * math.exp(-0.5 * x * x) * _phibar((t - rho * x) / q)
    return min(1.0, 2.0 * 4.5 * acc / math.sqrt(2.0 * math.pi))


@njit_parallel
def edge_jumps(dirs, s, sig, adj, z_out, p_out):
    """Range-continuity statistic ``z`` and its p-value for every grid edge (module doc).

    `s` is the inverse range and `sig` its noise std per point. `z_out`, `p_out` are
    (N, SLOTS): z and ``p = 1 - Phi(z)`` (z = 0, p = 1 where the second differences differ
    in sign or the grid line does not continue on both sides), NaN for empty slots.
    """
    n = adj.shape[0]
    for a in prange(n):
        for k in range(adj.shape[1]):
            b = adj[a, k]
            z_out[a, k] = np.nan
            p_out[a, k] = np.nan
            if b < 0:
                continue
            ex, ey, ez, tol2 = _grid_step(dirs, a, b)
            ap = _continuation(dirs, adj, a, dirs[a, 0] - ex, dirs[a, 1] - ey, dirs[a, 2] - ez,
                               tol2)
            bp = _continuation(dirs, adj, b, dirs[b, 0] + ex, dirs[b, 1] + ey, dirs[b, 2] + ez,
                               tol2)
            d = s[b] - s[a]
            va = sig[a] * sig[a]
            vb = sig[b] * sig[b]
            za = 0.0
            zb = 0.0
            ea = 0.0
            eb = 0.0
            if ap >= 0:
                ea = d - (s[a] - s[ap])
                za = abs(ea) / math.sqrt(vb + 4.0 * va + sig[ap] * sig[ap])
            if bp >= 0:
                eb = d - (s[bp] - s[b])
                zb = abs(eb) / math.sqrt(va + 4.0 * vb + sig[bp] * sig[bp])
            if ap >= 0 and bp >= 0 and ea * eb > 0:
                z = min(za, zb)
                z_out[a, k] = z
                p_out[a, k] = _phibar(z)
            else:
                # a crease between a and b, or no continuation on one side (a crease
                # cannot be told from a jump with one side only): not tested
                z_out[a, k] = 0.0
                p_out[a, k] = 1.0


@njit
def _step_on(dirs, adj, a, ex, ey, ez, tol2):
    """The node continuing the grid line one step from `a` in the direction (ex, ey, ez);
    -1 when there is none or `a` is -1."""
    if a < 0:
        return -1
    return _continuation(dirs, adj, a, dirs[a, 0] + ex, dirs[a, 1] + ey, dirs[a, 2] + ez, tol2)


@njit
def _linear_z(dirs, s, sig, adj, a, ex, ey, ez, tol2):
    """|second difference| / sd of s over a and the two nodes continuing the grid line from
    `a` in the direction (ex, ey, ez): 0 on a plane; NaN when the line does not continue."""
    b = _step_on(dirs, adj, a, ex, ey, ez, tol2)
    c = _step_on(dirs, adj, b, ex, ey, ez, tol2)
    if c < 0:
        return np.nan
    e = s[a] - 2.0 * s[b] + s[c]
    return abs(e) / math.sqrt(sig[a] * sig[a] + 4.0 * sig[b] * sig[b] + sig[c] * sig[c])


@njit
def _cubic_z(dirs, s, sig, adj, a, ex, ey, ez, tol2):
    """|third difference| / sd of s over a and the three nodes continuing the grid line
    from `a` in the direction (ex, ey, ez): 0 on a surface of constant curvature along the
    line (to first order); NaN when the line does not continue."""
    b = _step_on(dirs, adj, a, ex, ey, ez, tol2)
    c = _step_on(dirs, adj, b, ex, ey, ez, tol2)
    d = _step_on(dirs, adj, c, ex, ey, ez, tol2)
    if d < 0:
        return np.nan
    e = s[a] - 3.0 * s[b] + 3.0 * s[c] - s[d]
    return abs(e) / math.sqrt(sig[a] * sig[a] + 9.0 * sig[b] * sig[b] + 9.0 * sig[c] * sig[c]
                              + sig[d] * sig[d])


@njit
def _smooth_side(dirs, s, sig, adj, a, ex, ey, ez, tol2, zc):
    """The grid line from `a` continues on one smooth surface: linear in s over three
    nodes, or of constant curvature over four (a pipe toward its silhouette)."""
    if _linear_z(dirs, s, sig, adj, a, ex, ey, ez, tol2) < zc:
        return True
    return _cubic_z(dirs, s, sig, adj, a, ex, ey, ez, tol2) < zc


@njit_parallel
def border_edges(dirs, s, sig, adj, cut, zc, out):
    """Which continuity-test rejections end a visible surface (the ``'grid'`` test).

    ``out[a, k]`` is True where the edge (a, adj[a, k]) failed the continuity test
    (``cut``), the grid line continues on one smooth surface on *both* sides of it
    (:func:`_smooth_side` at `zc`: a face narrower than the grid - a soffit row, a jamb
    seen at grazing incidence - is not resolved and is not a border), and no grid node is
    a continuous neighbour of both a and b (the jump is not bypassed: a diagonal edge that
    skips one row of a narrow face is cut, while the two edges over that row are not).
    """
    n = adj.shape[0]
    m = adj.shape[1]
    for a in prange(n):
        for k in range(m):
            out[a, k] = False
            b = adj[a, k]
            if b < 0 or not cut[a, k]:
                continue
            bypass = False
            for i in range(m):
                x = adj[a, i]
                if x < 0 or cut[a, i]:
                    continue
                for j in range(m):
                    if adj[b, j] == x and not cut[b, j]:
                        bypass = True
                        break
                if bypass:
                    break
            if bypass:
                continue
            ex, ey, ez, tol2 = _grid_step(dirs, a, b)
            out[a, k] = (_smooth_side(dirs, s, sig, adj, a, -ex, -ey, -ez, tol2, zc)
                         and _smooth_side(dirs, s, sig, adj, b, ex, ey, ez, tol2, zc))
