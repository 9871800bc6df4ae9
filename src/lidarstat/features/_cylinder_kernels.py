"""Numba kernels of the cylinder test (:func:`lidarstat.features.cylinder_test`): is a
curved neighbourhood a smooth surface?

Where the plane test rejects, the neighbourhood is either a consistently curved surface
(a pipe, a tank wall) or it straddles an edge. Model: a circular cylinder whose axis is
the minimum-curvature direction of the point (``Normal x PrincipalDir`` of the covariance
features, section 5). The neighbours are projected on the plane perpendicular to the
axis and a circle is fitted there (algebraic fit, then Gauss-Newton on the geometric
residuals weighted by the per-neighbour noise). Under "a cylinder with independent
noise", the weighted residual sum of squares is ``chi2(n - 3)`` (3 circle parameters;
with the true axis the measured mean is n - 3.0 on noisy cylinders and planes, k = 20
and 50). The axis from the neighbours' normals is off by a degree or two (more beside a
border, where the neighbours' PCA normals tilt), and a tilt epsilon moves a neighbour at
axial offset t by epsilon t in the projection - 5 mm at t = 0.15 m for 2 degrees, above
the noise - so with ``refine_axis`` (the classification's default) the tilt is fitted
too: Gauss-Newton on (centre, radius, two tilt components) from the 3-parameter circle,
the projection of neighbour j moving by ``(b, g) t_j``; the statistic is the smaller of
the two weighted RSS (the 5-parameter minimum, or an upper bound of it if the refinement
fails) and is referred to ``chi2(n - 5)``. On tls_plant this takes the pipe and tank
points labelled edge from 1.1 % to 0.14 %.
A plane is the limit of large radius (a straight line in
the projection); a crease projects to a V, which no circle fits.

Per-neighbour noise: with a sensor, the range noise ``sigma_r(r) = a + b r`` runs along the
ray ``d``; its radial (residual) component is ``sigma_r |d . rho|`` with ``rho`` the
radial direction at that neighbour, floored at 0.1 ``sigma_r`` (at the silhouette of a
pipe the ray is tangent and the first-order radial noise vanishes; the second-order term
``eps^2 / 2R`` remains). Without a sensor the given (or estimated) sigma across the
surface.
"""

from __future__ import annotations

import numba
import numpy as np

from .._shared._jit import njit, njit_parallel

_FLOOR = 0.1  # smallest |cos| of the ray against the radial direction (see module doc)
_ITERS = 8
_TILT_ITERS = 4  # from the converged circle the tilt is nearly linear
_AXIS_ROUNDS = 3  # turns of the axis by the fitted tilt, each followed by a new fit
_TILT_DONE = 1e-3  # a tilt below this (radians) is not worth another round
_TILT_GAIN = 0.5  # nor a round that left more than this share of the RSS


@njit
def _basis(a):
    ax, ay, az = a[0], a[1], a[2]
    if abs(ax) < 0.9:
        t0, t1, t2 = 1.0, 0.0, 0.0
    else:
        t0, t1, t2 = 0.0, 1.0, 0.0
    # e1 = normalise(t - (t.a) a), e2 = a x e1
    d = t0 * ax + t1 * ay + t2 * az
    e10, e11, e12 = t0 - d * ax, t1 - d * ay, t2 - d * az
    nn = np.sqrt(e10 * e10 + e11 * e11 + e12 * e12)
    e10, e11, e12 = e10 / nn, e11 / nn, e12 / nn
    e20 = ay * e12 - az * e11
    e21 = az * e10 - ax * e12
    e22 = ax * e11 - ay * e10
    return e10, e11, e12, e20, e21, e22


@njit
def _radial(ux, uy, dx, dy, has_sensor, sr, scale):
    """Distance from the circle centre, radial unit vector and the point's radial noise
    (scaled coordinates) for the offset (ux, uy) and the projected ray (dx, dy)."""
    dist = np.sqrt(ux * ux + uy * uy)
    if dist > 0:
        ux, uy = ux / dist, uy / dist
    c = abs(dx * ux + dy * uy) if has_sensor else 1.0
    return dist, ux, uy, sr * max(c, _FLOOR) / scale


@njit
def _solve3(A, b):
    """Solve a 3x3 system by Cramer's rule; returns (x, ok)."""
    det = (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
           - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
           + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))
    x = np.zeros(3)
    scale = abs(A[0, 0] * A[1, 1] * A[2, 2]) + 1e-300
    if abs(det) <= 1e-14 * scale:
        return x, False
    for c in range(3):
        M = A.copy()
        for r in range(3):
            M[r, c] = b[r]
        x[c] = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
                - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
                + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0])) / det
    return x, True


@njit
def _circle_rss(x, y, ta, dx, dy, sr, n, cx, cy, R, bt, gm, has_sensor, scale):
    """Weighted RSS of the circle (cx, cy, R) with the axis tilt (bt, gm)."""
    q = 0.0
    for t in range(n):
        dist, ux, uy, sg = _radial(x[t] - bt * ta[t] - cx, y[t] - gm * ta[t] - cy,
                                   dx[t], dy[t], has_sensor, sr[t], scale)
        rr = dist - R
        q += rr * rr / (sg * sg)
    return q


@njit
def _solve_spd(J, g, out):
    """Solve the symmetric positive definite 5x5 system J out = g (Cholesky, in place on
    J); returns False when J is not positive definite."""
    m = J.shape[0]
    for c in range(m):
        d = J[c, c]
        for k in range(c):
            d -= J[c, k] * J[c, k]
        if not d > 0:
            return False
        d = np.sqrt(d)
        J[c, c] = d
        for r in range(c + 1, m):
            v = J[r, c]
            for k in range(c):
                v -= J[r, k] * J[c, k]
            J[r, c] = v / d
    for r in range(m):  # forward: L y = g
        v = g[r]
        for k in range(r):
            v -= J[r, k] * out[k]
        out[r] = v / J[r, r]
    for r in range(m - 1, -1, -1):  # backward: L' x = y
        v = out[r]
        for k in range(r + 1, m):
            v -= J[k, r] * out[k]
        out[r] = v / J[r, r]
    return True


@njit
def _tilt_refine(x, y, ta, dx, dy, sr, n, cx, cy, R, has_sensor, scale):
    """Gauss-Newton on (cx, cy, R, bt, gm) from the 3-parameter circle: the projection of
    a neighbour moves by (bt, gm) per unit of its offset ``ta`` along the axis (the
    first-order effect of tilting the axis). Returns the parameters and success."""
    c = np.array([cx, cy, R, 0.0, 0.0])
    J = np.empty((5, 5))
    g = np.empty(5)
    jac = np.empty(5)
    step = np.empty(5)
    for _ in range(_TILT_ITERS):
        J[:] = 0.0
        g[:] = 0.0
        for t in range(n):
            dist, ux, uy, sg = _radial(x[t] - c[3] * ta[t] - c[0], y[t] - c[4] * ta[t] - c[1],
                                       dx[t], dy[t], has_sensor, sr[t], scale)
            w = 1.0 / (sg * sg)
            res = dist - c[2]
            jac[0] = -ux
            jac[1] = -uy
            jac[2] = -1.0
            jac[3] = -ux * ta[t]
            jac[4] = -uy * ta[t]
            for p0 in range(5):
                wj = w * jac[p0]
                g[p0] -= wj * res
                for p1 in range(p0 + 1):
                    J[p0, p1] += wj * jac[p1]
        tr = 0.0
        for p0 in range(5):
            tr += J[p0, p0]
        if not tr > 0:
            return c, False
        for p0 in range(5):  # a neighbourhood thin along the axis fixes no tilt
            J[p0, p0] += 1e-9 * tr
        if not _solve_spd(J, g, step):
            return c, False
        for p0 in range(5):
            c[p0] += step[p0]
        if not (c[2] > 0 and c[2] < 1e4):
            return c, False
    return c, True


@njit
def _fit_about(pts, i, idx, s, n, a, sensor, has_sensor, sig_pt, x, y, ta, sr, dx, dy):
    """Circle fit of the neighbours ``idx[s:s + n]`` of point i projected along the axis
    `a`: fills the projected, centred and scaled coordinates (x, y), the axial offsets
    ta, the noise sr and the projected rays (dx, dy); returns (q, line, fit) with q the
    weighted RSS of the circle (or of a straight line, ``line`` True) and ``fit`` = (cx,
    cy in scaled units, radius in metres, scale, axis point in local coordinates); scale
    0 where every neighbour projects on one point."""
    fit = np.full(7, np.nan)
    e10, e11, e12, e20, e21, e22 = _basis(a)
    mx = 0.0
    my = 0.0
    mt = 0.0
    for t in range(n):
        j = idx[s + t]
        px, py, pz = pts[j, 0] - pts[i, 0], pts[j, 1] - pts[i, 1], pts[j, 2] - pts[i, 2]
        x[t] = px * e10 + py * e11 + pz * e12
        y[t] = px * e20 + py * e21 + pz * e22
        ta[t] = px * a[0] + py * a[1] + pz * a[2]
        mx += x[t]
        my += y[t]
        mt += ta[t]
        sr[t] = sig_pt[j]
        if has_sensor:
            rx, ry, rz = pts[j, 0] - sensor[0], pts[j, 1] - sensor[1], pts[j, 2] - sensor[2]
            rn = np.sqrt(rx * rx + ry * ry + rz * rz)
            if rn > 0:
                rx, ry, rz = rx / rn, ry / rn, rz / rn
            dx[t] = rx * e10 + ry * e11 + rz * e12
            dy[t] = rx * e20 + ry * e21 + rz * e22
    mx /= n
    my /= n
    mt /= n
    scale = 0.0
    for t in range(n):
        x[t] -= mx
        y[t] -= my
        ta[t] -= mt
        scale = max(scale, abs(x[t]), abs(y[t]))
    fit[3] = scale
    if not scale > 0:
        return np.nan, True, fit
    for t in range(n):
        x[t] /= scale
        y[t] /= scale
        ta[t] /= scale
    # algebraic (Kasa) circle: x^2 + y^2 + D x + E y + F = 0
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for t in range(n):
        z = x[t] * x[t] + y[t] * y[t]
        v0, v1 = x[t], y[t]
        A[0, 0] += v0 * v0
        A[0, 1] += v0 * v1
        A[0, 2] += v0
        A[1, 1] += v1 * v1
        A[1, 2] += v1
        A[2, 2] += 1.0
        b[0] -= z * v0
        b[1] -= z * v1
        b[2] -= z
    A[1, 0], A[2, 0], A[2, 1] = A[0, 1], A[0, 2], A[1, 2]
    sol, ok = _solve3(A, b)
    cx, cy = -0.5 * sol[0], -0.5 * sol[1]
    R2 = cx * cx + cy * cy - sol[2]
    line = (not ok) or (not R2 > 0) or np.sqrt(max(R2, 0.0)) > 1e4
    if not line:
        R = np.sqrt(R2)
        for _ in range(_ITERS):  # Gauss-Newton on (cx, cy, R), weighted
            J = np.zeros((3, 3))
            g = np.zeros(3)
            for t in range(n):
                dist, ux, uy, sg = _radial(x[t] - cx, y[t] - cy, dx[t], dy[t],
                                           has_sensor, sr[t], scale)
                w = 1.0 / (sg * sg)
                res = dist - R
                j0, j1, j2 = -ux, -uy, -1.0
                J[0, 0] += w * j0 * j0
                J[0, 1] += w * j0 * j1
                J[0, 2] += w * j0 * j2
                J[1, 1] += w * j1 * j1
                J[1, 2] += w * j1 * j2
                J[2, 2] += w * j2 * j2
                g[0] -= w * j0 * res
                g[1] -= w * j1 * res
                g[2] -= w * j2 * res
            J[1, 0], J[2, 0], J[2, 1] = J[0, 1], J[0, 2], J[1, 2]
            step, ok2 = _solve3(J, g)
            if not ok2:
                break
            cx += step[0]
            cy += step[1]
            R += step[2]
            if not (R > 0 and R < 1e4):
                line = True
                break
    if not line:
        fit[0], fit[1], fit[2] = cx, cy, R * scale
        ccx, ccy = cx * scale + mx, cy * scale + my
        for d3 in range(3):
            e1d = e10 if d3 == 0 else (e11 if d3 == 1 else e12)
            e2d = e20 if d3 == 0 else (e21 if d3 == 1 else e22)
            fit[4 + d3] = pts[i, d3] + ccx * e1d + ccy * e2d
        return _circle_rss(x, y, ta, dx, dy, sr, n, cx, cy, R, 0.0, 0.0, has_sensor,
                           scale), False, fit
    # straight line in the projection: total least squares, 2 parameters
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for t in range(n):
        sxx += x[t] * x[t]
        sxy += x[t] * y[t]
        syy += y[t] * y[t]
    tr = sxx + syy
    det = sxx * syy - sxy * sxy
    lmin = 0.5 * tr - np.sqrt(max(0.25 * tr * tr - det, 0.0))
    # normal of the line: eigenvector of lmin
    nx, ny = sxy, lmin - sxx
    nn = np.sqrt(nx * nx + ny * ny)
    if nn == 0:
        nx, ny = (1.0, 0.0) if sxx <= syy else (0.0, 1.0)
    else:
        nx, ny = nx / nn, ny / nn
    q = 0.0
    for t in range(n):
        rr = x[t] * nx + y[t] * ny
        c = abs(dx[t] * nx + dy[t] * ny) if has_sensor else 1.0
        sg = sr[t] * max(c, _FLOOR) / scale
        q += rr * rr / (sg * sg)
    return q, True, fit


@njit_parallel
def cylinder_rows(pts, query, indptr, idx, axes, sensor, has_sensor, sig_pt, stat, dof,
                  radius, centre, refine_axis):
    """Weighted circle fit perpendicular to `axes[r]` over each query row r (module doc).

    `pts` local coordinates; row r lists the neighbours of point ``query[r]``. Noise of
    neighbour j: ``sig_pt[j] * max(|d . rho|, 0.1)`` with a sensor (`sig_pt` along the
    rays), else ``sig_pt[j]`` (across the surface). Writes the weighted RSS, its degrees
    of freedom (n - 3; n - 5 for a circle with `refine_axis`, the tilt fitted too) and the
    fitted radius (inf for a straight line) and a point of the axis (the circle centre
    lifted to 3-D, local coordinates; NaN for a line); NaN where fewer than 7 neighbours.
    """
    m = query.size
    for r in numba.prange(m):
        i = query[r]
        s, e = indptr[r], indptr[r + 1]
        n = e - s
        stat[r] = np.nan
        dof[r] = n - 3
        radius[r] = np.nan
        centre[r, 0] = np.nan
        centre[r, 1] = np.nan
        centre[r, 2] = np.nan
        if n < 7:
            continue
        x = np.empty(n)
        y = np.empty(n)
        ta = np.empty(n)
        sr = np.empty(n)
        dx = np.zeros(n)
        dy = np.zeros(n)
        a = axes[r].copy()
        q, line, fit = _fit_about(pts, i, idx, s, n, a, sensor, has_sensor, sig_pt,
                                  x, y, ta, sr, dx, dy)
        if fit[3] == 0.0:  # all neighbours on the axis
            continue
        if not line:
            radius[r] = fit[2]
            for d3 in range(3):
                centre[r, d3] = fit[4 + d3]
            if refine_axis:
                # refine with the axis tilt (2 more parameters, dof n - 5): the axis
                # comes from the neighbours' normals and is off by a degree or two (up
                # to 7 on a thin pipe whose neighbourhood wraps it), which along a pipe
                # moves the projected points by tilt x axial offset, far above the noise.
                # The tilt's Gauss-Newton is first order in the tilt, so the axis is
                # turned by the fitted tilt and the fit repeated about the new axis
                # (_AXIS_ROUNDS times, the projection redone each time); every round's
                # RSS is that of one axis and one circle, so their minimum bounds the
                # 5-parameter minimum. The radius and centre stay the given axis's: with
                # the tilt free a short patch trades tilt for radius (k = 20 on a 0.3 m
                # pipe: radii 0.15-1.7 m); the minimum itself is well defined
                dof[r] = n - 5
                if q > n - 5:  # below the null mean q changes no decision
                    for _ in range(_AXIS_ROUNDS):
                        prev = q
                        c5, ok5 = _tilt_refine(x, y, ta, dx, dy, sr, n, fit[0], fit[1],
                                               fit[2] / fit[3], has_sensor, fit[3])
                        if not ok5:
                            break
                        q = min(q, _circle_rss(x, y, ta, dx, dy, sr, n, c5[0], c5[1], c5[2],
                                               c5[3], c5[4], has_sensor, fit[3]))
                        tilt = np.sqrt(c5[3] * c5[3] + c5[4] * c5[4])
                        # another round only while the tilt explains the misfit (a crease
                        # keeps most of its RSS: it is no cylinder about any axis)
                        if not (tilt > _TILT_DONE and tilt < 1.0) or q <= n - 5 \
                                or q > _TILT_GAIN * prev:
                            break
                        e10, e11, e12, e20, e21, e22 = _basis(a)
                        a[0] += c5[3] * e10 + c5[4] * e20
                        a[1] += c5[3] * e11 + c5[4] * e21
                        a[2] += c5[3] * e12 + c5[4] * e22
                        na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
                        a /= na
                        q2, line2, fit = _fit_about(pts, i, idx, s, n, a, sensor, has_sensor,
                                                    sig_pt, x, y, ta, sr, dx, dy)
                        if line2:
                            break
                        q = min(q, q2)
            stat[r] = q
        else:
            stat[r] = q
            radius[r] = np.inf
