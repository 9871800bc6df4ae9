"""Range continuity on the scan grid and the ``'visible'`` boundary test (terrestrial scans).

A terrestrial scanner samples a regular grid of directions; the *visible surface* of a point
is what its rays see without a break in range. Two things end it: a ray that returns
nothing (sky, the scan window) and a *depth jump* (an occlusion: the visible surface ends and
the ray passes to a background farther away). A crease does not end it: across a crease the
range is continuous, only its slope changes.

**Range continuity of a grid edge.** For two grid-adjacent points a, b take the points a', b'
that continue the grid line beyond each of them (a' = the neighbour of a nearest the direction
``2 d_a - d_b``, b' likewise; accepted within half the step). In inverse range ``s = 1 / R``
a plane is exactly linear in the ray direction (``n . (R d) = c`` gives ``1 / R = n . d / c``),
so along a grid line the steps ``D_a = s_a - s_a'``, ``D = s_b - s_a``, ``D_b = s_b' - s_b`` are
equal on a plane and, across a crease between a and b, ``D`` lies *between* ``D_a`` and ``D_b``
(the profile is piecewise linear, the step across the crease a convex combination of the two
slopes). At a depth jump ``D`` lies outside them by the depth. With the second differences
``E_a = D - D_a`` and ``E_b = D - D_b``,

    z_ab = min(|E_a| / sd(E_a), |E_b| / sd(E_b))    if E_a and E_b have the same sign, else 0

(``sd(E_a)^2 = sigma_b^2 + 4 sigma_a^2 + sigma_a'^2`` with ``sigma = sigma_r(R) / R^2`` the
noise of s). Null hypothesis: a, b and the points beyond them lie on one continuous surface,
linear in s along the grid line on either side of some point between a and b (a plane, or
two planes meeting at a crease; curved surfaces add second differences of order
``(R step)^2 / radius``, far below the noise). The null is composite: on a plane both E are
noise (correlation ``(2 sigma_a^2 + 2 sigma_b^2) / (sd_a sd_b)``, about 2/3) and
``P(z > t) = 2 P(Z1 > t, Z2 > t)`` (:func:`same_sign_p`); at a crease beside a or b one E
carries the whole change of slope and the other is noise, so ``P(z > t) -> 1 - Phi(t)``,
the largest value over the null. The p-value is therefore ``p = 1 - Phi(z)``: exact at the
least favourable null (a sharp crease next to an endpoint), conservative on planes. An
edge whose grid line does not continue on both sides is not tested (p = 1: with one side,
a crease cannot be told from a jump). Per point, ``jump_z`` is the largest z of its grid
edges and ``jump_p`` the Bonferroni p-value over its m edges, ``min(1, m min p)``: "a depth
jump at this point".

**Resolved jumps.** A face narrower than two grid steps (a soffit or a window jamb seen at
grazing incidence) breaks the "one crease between a and b" null and looks like a jump; so
does a true depth jump, and one grid line cannot tell them apart (a jump *is* a face of
zero width seen along the ray). What a jump between two surfaces the grid *resolves* has
and a narrow face has not: on either side the grid line continues over two more nodes on
one plane. Per edge, both triples (a, a', a'') and (b, b', b'') are tested for linearity
in s (the second difference ``s_a - 2 s_a' + s_a''`` against its sd
``sqrt(sig_a^2 + 4 sig_a'^2 + sig_a''^2)``, two-sided, accepted at ``linear_alpha``); the
edges where both are accepted and the continuity test rejects are *resolved jumps*, and
``jump_resolved_p`` is the Bonferroni p-value over the point's edges of the continuity
test restricted to them (1 where there is none).

**The visible disc.** The ``'scan'`` test (:mod:`lidarstat.features._scan_kernels`) takes the
complete disc from the kNN table, whose 3-D ball loses grid nodes across a crease (the other
face bends away: holes, false boundaries at the foot of a wall) and gains nodes across a small
depth jump (a background within the ball fills the gap: missed boundaries). Here the disc is
gathered on the grid instead: starting at the point, a breadth-first walk over grid edges that
pass the continuity test, kept to the nodes whose linearised scan coordinates (the same map as
the ``'scan'`` test, on the point's tangent plane) lie within the radius rho of the point's
complete disc (the kNN reach r shrunk by the density gradient, ``rho = r / g``: on a curved
surface the linearised distance of a node underestimates its 3-D distance, by a factor 2 near
a pipe's silhouette, which without the shrink makes borders up to 1 r away look near).
For a point whose visible surface does not end within rho every node of that centrally
symmetric set of directions is reached, so their centroid is the point; where it ends, the
nodes beyond are missing (no return, or across a jump) and the centroid moves away from the
border. The statistic is the same Hotelling ``T2`` (F(2, m - 2) null, exact for a uniform
sample of the disc, conservative on a grid).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from .._shared._kernels import eigh3 as _eigh3

#: Grid neighbours kept per point (8-neighbourhood of a regular angular grid).
SLOTS = 8
#: A grid neighbour is farther than this many grid steps: not adjacent (a missing node).
ADJ_STEPS = 1.75
#: Cap on the nodes of one visible disc (a safety bound; a k = 50 disc holds 50-300).
MAX_NODES = 16384
_MIN_COS = 0.05


def grid_adjacency(angles, *, sample=20000):
    """Grid neighbours of every point from its (azimuth, elevation) seen from the scanner.

    A scanner's grid is regular in azimuth and elevation, with steps that need not be
    equal (the real pump scan: 1 : 3.4). The two steps are estimated (per axis, the median
    over up to `sample` points of the smallest step to a neighbour lying more along that
    axis than across it), the angles are divided by them and the 8 nearest nodes within
    ``ADJ_STEPS`` grid units are the neighbours. The azimuth is cut at its largest gap
    (a full turn is cut at one seam, which then looks like the end of the scan).

    Parameters
    ----------
    angles : (N, 2) ndarray
        Azimuth and elevation (radians).
    sample : int
        Points used to estimate the steps.

    Returns
    -------
    adj : (N, SLOTS) int64 ndarray
        Indices of the grid neighbours, -1 padded.
    steps : (float, float)
        The azimuth and elevation steps (radians).
    """
    from scipy.spatial import cKDTree

    n = angles.shape[0]
    adj = np.full((n, SLOTS), -1, dtype=np.int64)
    if n < 2:
        return adj, (0.0, 0.0)
    az = np.asarray(angles[:, 0], dtype=np.float64)
    el = np.asarray(angles[:, 1], dtype=np.float64)
    a = np.sort(az)
    gaps = np.diff(np.r_[a, a[0] + 2.0 * np.pi])
    g = int(np.argmax(gaps))
    az = np.mod(az - (a[g] + 0.5 * gaps[g]), 2.0 * np.pi)
    xy = np.c_[az, el]
    tree = cKDTree(xy)
    pick = np.unique(np.linspace(0, n - 1, min(n, sample)).astype(np.int64))
    kq = min(17, n)
    _, idx = tree.query(xy[pick], k=kq)
    d = np.abs(xy[np.asarray(idx).reshape(pick.size, kq)[:, 1:]] - xy[pick, None, :])
    with np.errstate(invalid="ignore"):
        s_az = np.nanmedian(_row_min(d[..., 0], d[..., 1]))
        s_el = np.nanmedian(_row_min(d[..., 1], d[..., 0]))
    if not (np.isfinite(s_az) and s_az > 0):
        s_az = s_el
    if not (np.isfinite(s_el) and s_el > 0):
        s_el = s_az
    if not (np.isfinite(s_az) and s_az > 0):
        return adj, (0.0, 0.0)
    grid = np.c_[az / s_az, el / s_el]
    kk = min(SLOTS + 1, n)
    dist, nb = cKDTree(grid).query(grid, k=kk, workers=-1)
    dist = np.asarray(dist).reshape(n, kk)[:, 1:]
    nb = np.asarray(nb).reshape(n, kk)[:, 1:]
    adj[:, :kk - 1] = np.where((dist <= ADJ_STEPS) & (dist > 0), nb, -1)
    return adj, (float(s_az), float(s_el))


def _row_min(along, across):
    """Per row, the smallest `along` step of the neighbours lying more along than across
    (NaN when there is none)."""
    v = np.where(along > across, along, np.inf).min(axis=1)
    return np.where(np.isfinite(v), v, np.nan)


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


@njit_parallel
def edge_resolved(dirs, s, sig, adj, zc, out):
    """Is each grid edge (a, b) between two *resolved* surfaces (module doc)?

    ``out[a, k]`` is True when the grid line continues for two more nodes beyond a and
    beyond b and both triples are linear in s (|second difference| / sd < `zc`, the plane
    accepted): a jump there separates two surfaces the grid resolves, not a face
    narrower than the grid.
    """
    n = adj.shape[0]
    for a in prange(n):
        for k in range(adj.shape[1]):
            b = adj[a, k]
            out[a, k] = False
            if b < 0:
                continue
            ex, ey, ez, tol2 = _grid_step(dirs, a, b)
            za = _linear_z(dirs, s, sig, adj, a, -ex, -ey, -ez, tol2)
            zb = _linear_z(dirs, s, sig, adj, b, ex, ey, ez, tol2)
            out[a, k] = za < zc and zb < zc


@njit
def _frame(pts, angles, sensor, normal, major, i):
    """Coefficients of the linearised scan map of point i (see _scan_kernels)."""
    px = pts[i, 0] - sensor[0]
    py = pts[i, 1] - sensor[1]
    pz = pts[i, 2] - sensor[2]
    ri = math.sqrt(px * px + py * py + pz * pz)
    f = np.empty(17)
    f[0] = ri
    if not ri > 0:
        return f
    d0, d1, d2 = px / ri, py / ri, pz / ri
    ce, se = math.cos(angles[i, 1]), math.sin(angles[i, 1])
    ca, sa = math.cos(angles[i, 0]), math.sin(angles[i, 0])
    n0, n1, n2 = normal[0], normal[1], normal[2]
    a0, a1, a2 = major[0], major[1], major[2]
    nd = n0 * d0 + n1 * d1 + n2 * d2
    if abs(nd) < _MIN_COS:
        nd = _MIN_COS if nd >= 0 else -_MIN_COS
    f[1], f[2], f[3] = d0, d1, d2
    f[4], f[5] = -ce * sa, ce * ca  # d(ray)/d(azimuth)
    f[6], f[7], f[8] = -se * ca, -se * sa, ce  # d(ray)/d(elevation)
    f[9], f[10], f[11] = n0 / nd, n1 / nd, n2 / nd
    f[12], f[13], f[14] = a0, a1, a2
    f[15], f[16] = angles[i, 0], angles[i, 1]
    return f


@njit
def _map(f, angles, j, bx):
    """Linearised scan coordinates (u, v) of node j in the frame f; bx = major x normal."""
    da = angles[j, 0] - f[15]
    if da > np.pi:
        da -= 2.0 * np.pi
    elif da < -np.pi:
        da += 2.0 * np.pi
    de = angles[j, 1] - f[16]
    e0 = da * f[4] + de * f[6]
    e1 = da * f[5] + de * f[7]
    e2 = de * f[8]
    k = f[9] * e0 + f[10] * e1 + f[11] * e2
    x0 = f[0] * (e0 - f[1] * k)
    x1 = f[0] * (e1 - f[2] * k)
    x2 = f[0] * (e2 - f[3] * k)
    return (x0 * f[12] + x1 * f[13] + x2 * f[14], x0 * bx[0] + x1 * bx[1] + x2 * bx[2])


@njit_parallel
def visible_disc(pts, angles, adj, cut, normals, major, sensor, radius, nchunk, out):
    """Hotelling T2 and node count of every point's visible disc (module doc).

    ``cut[a, k]``: the grid edge (a, adj[a, k]) failed the continuity test. ``radius`` is the
    disc radius per point in linearised scan coordinates. ``out`` is (N, 2): T2 (NaN where
    fewer than 4 nodes or a degenerate disc) and m.
    """
    n = pts.shape[0]
    for c in prange(nchunk):
        mark = np.full(n, -1, dtype=np.int64)
        queue = np.empty(MAX_NODES, dtype=np.int64)
        uu = np.empty(MAX_NODES)
        vv = np.empty(MAX_NODES)
        bx = np.empty(3)
        for i in range(c, n, nchunk):
            out[i, 0] = np.nan
            out[i, 1] = 0.0
            rad = radius[i]
            if not rad > 0:
                continue
            f = _frame(pts, angles, sensor, normals[i], major[i], i)
            if not f[0] > 0:
                continue
            n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
            bx[0] = n1 * f[14] - n2 * f[13]
            bx[1] = n2 * f[12] - n0 * f[14]
            bx[2] = n0 * f[13] - n1 * f[12]
            r2 = rad * rad
            mark[i] = i
            queue[0] = i
            head = 0
            tail = 1
            while head < tail:
                a = queue[head]
                head += 1
                for k in range(adj.shape[1]):
                    b = adj[a, k]
                    if b < 0 or mark[b] == i or cut[a, k]:
                        continue
                    mark[b] = i
                    u, v = _map(f, angles, b, bx)
                    if u * u + v * v >= r2 or tail >= MAX_NODES:
                        continue
                    queue[tail] = b
                    uu[tail] = u
                    vv[tail] = v
                    tail += 1
            su = 0.0
            sv = 0.0
            suu = 0.0
            suv = 0.0
            svv = 0.0
            m = 0
            for t in range(1, tail):
                u = uu[t]
                v = vv[t]
                su += u
                sv += v
                suu += u * u
                suv += u * v
                svv += v * v
                m += 1
            out[i, 1] = m
            if m < 4:
                continue
            cu = su / m
            cv = sv / m
            xx = suu - m * cu * cu
            xy = suv - m * cu * cv
            yy = svv - m * cv * cv
            det = xx * yy - xy * xy
            if not det > 1e-12 * (xx + yy) * (xx + yy):
                continue
            out[i, 0] = m * (m - 1) * (cu * cu * yy - 2.0 * cu * cv * xy + cv * cv * xx) / det


def _rays(points, sensor, ray_sigma):
    """The scan's rays in coordinates centred on the first point: the origin, the
    points and the sensor there, every point's range, unit ray direction and the noise
    std of its inverse range (``sigma_r / R^2``)."""
    origin = np.asarray(points[0], dtype=np.float64)
    pts = np.ascontiguousarray(points - origin)
    sens = np.asarray(sensor, dtype=np.float64) - origin
    ray = pts - sens
    rng = np.linalg.norm(ray, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        dirs = np.ascontiguousarray(ray / rng[:, None])
        sig = np.broadcast_to(np.asarray(ray_sigma, dtype=np.float64), rng.shape) / rng ** 2
    return origin, pts, sens, rng, dirs, sig


def visible_boundary(points, sensor, normals, major, ray_sigma, radius, *, jump_alpha,
                     linear_alpha=0.05):
    """The ``'visible'`` boundary statistic and the range-continuity fields of every point.

    Parameters
    ----------
    points : (N, 3) ndarray
    sensor : (3,) ndarray
    normals, major : (N, 3) ndarray
        Normal and largest eigenvector of every point's neighbourhood.
    ray_sigma : float or (N,) ndarray
        Range noise std along the rays.
    radius : (N,) ndarray
        Disc radius (the neighbourhood's reach).
    jump_alpha : float
        Level of the continuity test of a grid edge; failed edges are not crossed.
    linear_alpha : float
        Level of the linearity test of the three nodes on either side of a grid edge
        (:func:`edge_resolved`; accepted on both sides = two resolved surfaces).

    Returns
    -------
    dict with ``t2``, ``m`` (visible disc), ``jump_z``, ``jump_p``, ``jump_resolved_p``
    (per point), ``step``
    (azimuth and elevation steps), ``edge_z``, ``edge_p`` and ``adjacency`` (per grid edge).
    """
    from .._shared._geometry import scan_angles

    _, pts, sens, rng, dirs, sig = _rays(points, sensor, ray_sigma)
    with np.errstate(divide="ignore"):
        s = 1.0 / rng
    angles = scan_angles(pts, sens)
    adj, step = grid_adjacency(angles)
    z = np.empty(adj.shape, dtype=np.float64)
    pe = np.empty(adj.shape, dtype=np.float64)
    edge_jumps(dirs, s, np.ascontiguousarray(sig), adj, z, pe)
    cut = np.ascontiguousarray(pe < jump_alpha)
    from scipy.special import ndtri

    resolved = np.empty(adj.shape, dtype=np.bool_)
    edge_resolved(dirs, s, np.ascontiguousarray(sig), adj, float(ndtri(1.0 - linear_alpha / 2.0)),
                  resolved)
    out = np.empty((pts.shape[0], 2))
    import numba

    visible_disc(pts, angles, adj, cut, np.ascontiguousarray(normals, dtype=np.float64),
                 np.ascontiguousarray(major, dtype=np.float64), sens,
                 np.ascontiguousarray(radius, dtype=np.float64),
                 4 * numba.get_num_threads(), out)
    n_edges = np.count_nonzero(adj >= 0, axis=1)
    has = n_edges > 0
    jz = np.full(len(pts), np.nan)
    jp = np.full(len(pts), np.nan)
    jz[has] = np.max(np.where(adj[has] >= 0, z[has], -np.inf), axis=1)
    # Bonferroni over the point's grid edges (valid under any dependence between them)
    jp[has] = np.minimum(1.0, n_edges[has] * np.min(np.where(adj[has] >= 0, pe[has], np.inf),
                                                    axis=1))
    # the same, over the edges between two resolved surfaces only
    pr = np.where(resolved, pe, np.inf)
    jr = np.full(len(pts), np.nan)
    jr[has] = np.minimum(1.0, n_edges[has] * np.min(np.where(adj[has] >= 0, pr[has], np.inf),
                                                    axis=1))
    return {"t2": out[:, 0], "m": out[:, 1], "jump_z": jz, "jump_p": jp, "jump_resolved_p": jr, "step": step,
            "edge_z": z, "edge_p": pe, "adjacency": adj}


# ---------------------------------------------------------------------------------------
# The 'grid' boundary test: the distance to the end of the visible surface
# ---------------------------------------------------------------------------------------

#: The eight unit offsets of a grid node's neighbours, in (azimuth, elevation) steps.
_DIRS8 = np.array([(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)],
                  dtype=np.float64)
#: The slot of the opposite direction.
_OPPOSITE = np.array([1, 0, 3, 2, 7, 6, 5, 4])
#: Border kinds (``border_kind``): no border reached, the scan window, a missing return,
#: a depth jump found by the continuity test.
BORDER_NONE, BORDER_WINDOW, BORDER_MISSING, BORDER_JUMP = 0, 1, 2, 3
#: Half-width (grid steps, per axis) of the cell around ``node + direction`` in which a node
#: answers that grid direction (:func:`direction_coverage`).
COVER_STEPS = 0.75


def _ring_residual(g, s, v, ans, a, c):
    """Residual of ``s[c]`` from the plane ``s`` ~ grid position fitted at `a` to its
    answering nodes ``ans[a]`` that do not lie toward `c` (less than half a step along
    a -> c: the plane is not fitted across the gap; least squares through ``s[a]``), and
    its variance (`v`: the variances of s). 0 and inf where they do not span the plane."""
    nb = ans[a]
    nbc = np.maximum(nb, 0)
    x = g[nbc] - g[a, None, :]
    u = g[c] - g[a]
    m = (nb >= 0) & (np.einsum("pki,pi->pk", x, u) < 0.25 * np.einsum("pi,pi->p", u, u)[:, None])
    x = np.where(m[..., None], x, 0.0)
    xtx = np.einsum("pki,pkj->pij", x, x)
    det = xtx[:, 0, 0] * xtx[:, 1, 1] - xtx[:, 0, 1] ** 2
    good = det > 1e-6
    det = np.where(good, det, 1.0)
    inv = np.stack([np.stack([xtx[:, 1, 1], -xtx[:, 0, 1]], -1),
                    np.stack([-xtx[:, 0, 1], xtx[:, 0, 0]], -1)], 1) / det[:, None, None]
    w = np.einsum("pki,pij,pj->pk", x, inv, g[c] - g[a])      # pred = s_a + w . (s_nb - s_a)
    w = np.where(m, w, 0.0)
    sw = w.sum(axis=1)
    e = s[c] - (1.0 - sw) * s[a] - (w * s[nbc]).sum(axis=1)
    var = v[c] + (1.0 - sw) ** 2 * v[a] + (w * w * v[nbc]).sum(axis=1)
    return np.where(good, e, 0.0), np.where(good, var, np.inf)


def direction_coverage(g, s=None, sig=None, zc=np.inf):
    """Which of the eight grid directions of every node a node answers, and which of the
    unanswered ones are isolated dropouts.

    A real scanner's grid is not a lattice: the pump scan's columns (one azimuth each) are
    regular in elevation but each with its own elevation phase, so the nodes of the next
    column sit anywhere between the diagonal and the horizontal direction. Direction ``d``
    (a unit offset in (azimuth, elevation) steps) is *answered* when a node lies in the
    cell ``|g' - (g + d)| <= COVER_STEPS`` (per axis, Chebyshev): the cells of neighbouring
    directions overlap by half a step, so a node of the next column at any phase answers
    the horizontal direction and one of the diagonals and, with its column neighbour, the
    other. An unanswered direction is an isolated *dropout* (a missing return on a
    surface that goes on, not a border) when a node c answers ``2 d`` and the inverse range
    `s` is continuous across the gap: s[c] is predicted from the plane (in grid position)
    fitted at the node to the nodes answering it, s[node] from the plane at c, and the gap
    is a jump when both residuals exceed `zc` standard deviations (`sig`: the noise std of
    `s`) in the same sense (s[c] beyond both extrapolations; on a smoothly curved surface
    the two bracket it, as in the continuity test of a grid edge). Without `s` (or where
    the answers do not span a plane) the node beyond the gap alone makes a dropout.

    Parameters
    ----------
    g : (N, 2) ndarray
        Grid positions (azimuth and elevation divided by their steps).
    s, sig : (N,) ndarray, optional
        Inverse range and its noise std.
    zc : float
        Critical |z| of the continuity test across a gap.

    Returns
    -------
    covered, dropout : (N, 8) bool ndarrays

    Examples
    --------
    >>> az, el = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    >>> g = np.c_[az.ravel(), el.ravel() + 0.5 * (az.ravel() % 2)]  # columns offset 0.5
    >>> covered, _ = direction_coverage(g)
    >>> bool(covered[2 * 5 + 2].all())     # an inner node: all eight answered
    True
    >>> g = np.delete(np.c_[az.ravel(), el.ravel()], 3 * 5 + 2, axis=0)  # one dropout
    >>> covered, dropout = direction_coverage(g)
    >>> (~covered[2 * 5 + 2]).nonzero()[0], bool(dropout[2 * 5 + 2, 0])
    (array([0]), True)
    """
    from scipy.spatial import cKDTree

    n = g.shape[0]
    covered = np.zeros((n, 8), dtype=bool)
    dropout = np.zeros((n, 8), dtype=bool)
    if n == 0:
        return covered, dropout
    tree = cKDTree(g)

    def answer(at):
        _, j = tree.query(at, k=1, p=np.inf, distance_upper_bound=COVER_STEPS, workers=-1)
        return np.where(j < n, j, -1)

    ans = np.stack([answer(g + _DIRS8[d]) for d in range(8)], axis=1)
    covered[:] = ans >= 0
    v = None if s is None else np.asarray(sig, dtype=np.float64) ** 2
    for d in range(8):
        a = np.flatnonzero(~covered[:, d])
        if a.size == 0:
            continue
        dv = _DIRS8[d]
        c = answer(g[a] + 2.0 * dv)
        has = c >= 0
        a, c = a[has], c[has]
        ok = np.ones(a.size, dtype=bool)
        if s is not None:
            e1, v1 = _ring_residual(g, s, v, ans, a, c)
            e2, v2 = _ring_residual(g, s, v, ans, c, a)
            with np.errstate(invalid="ignore", divide="ignore"):
                z1 = e1 / np.sqrt(v1)
                z2 = -e2 / np.sqrt(v2)
            # a jump: the range across the gap is off both sides' planes in the same sense
            ok = ~((np.sign(z1) == np.sign(z2)) & (np.minimum(np.abs(z1), np.abs(z2)) >= zc))
        dropout[a[ok], d] = True
    return covered, dropout


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


#: Grid hops of the near surface's plane fit behind a jump (the jamb rule).
JAMB_HOPS = 3
#: A perpendicular connecting face whose image would span at most this many grid steps
#: can lie between two rays without a sample (the jamb rule: 1 = whenever it could).
JAMB_REACH = 1.0


@njit
def _grid_plane(pts, adj, cut, node, stamp, hops, tol, buf, mark):
    """Normal of the plane through the grid nodes within `hops` grid edges of `node` that
    are reached without crossing a cut edge, refitted once without the nodes farther than
    `tol` from the first plane; (0, 0, 0) with fewer than 6 nodes. ``mark`` holds the
    visit `stamp` (unique per call)."""
    buf[0] = node
    mark[node] = stamp
    head = 0
    tail = 1
    level_end = 1
    level = 0
    while head < tail and level < hops:
        while head < level_end:
            a = buf[head]
            head += 1
            for k in range(adj.shape[1]):
                b = adj[a, k]
                if b < 0 or cut[a, k] or mark[b] == stamp or tail >= buf.size:
                    continue
                mark[b] = stamp
                buf[tail] = b
                tail += 1
        level_end = tail
        level += 1
    cov = np.empty((3, 3))
    evals = np.empty(3)
    evecs = np.empty((3, 3))
    nx = 0.0
    ny = 0.0
    nz = 0.0
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for rnd in range(2):
        m = 0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for t in range(tail):
            j = buf[t]
            if rnd == 1 and abs((pts[j, 0] - cx) * nx + (pts[j, 1] - cy) * ny
                                + (pts[j, 2] - cz) * nz) > tol:
                continue
            sx += pts[j, 0]
            sy += pts[j, 1]
            sz += pts[j, 2]
            m += 1
        if m < 6:
            return 0.0, 0.0, 0.0
        cx = sx / m
        cy = sy / m
        cz = sz / m
        for u in range(3):
            for v in range(3):
                cov[u, v] = 0.0
        for t in range(tail):
            j = buf[t]
            dx = pts[j, 0] - cx
            dy = pts[j, 1] - cy
            dz = pts[j, 2] - cz
            if rnd == 1 and abs(dx * nx + dy * ny + dz * nz) > tol:
                continue
            cov[0, 0] += dx * dx
            cov[0, 1] += dx * dy
            cov[0, 2] += dx * dz
            cov[1, 1] += dy * dy
            cov[1, 2] += dy * dz
            cov[2, 2] += dz * dz
        cov[1, 0] = cov[0, 1]
        cov[2, 0] = cov[0, 2]
        cov[2, 1] = cov[1, 2]
        _eigh3(cov, evals, evecs)
        nx = evecs[0, 0]
        ny = evecs[1, 0]
        nz = evecs[2, 0]
    return nx, ny, nz


@njit_parallel
def visible_jambs(pts, sensor, dirs, rng, adj, cut, edges, sig_r, hops, reach, nchunk, out):
    """The jamb rule: which border edges a visible face narrower than the grid explains.

    For a border edge (a, b) let N be the nearer node and F the farther. The near surface's
    plane is fitted to the grid nodes within `hops` uncut grid edges of N (normal n toward
    the sensor; the kNN normal beside a recess is tilted by the recess back). A face
    perpendicular to it that runs from N's edge back to F's depth (a jamb, a sill, a
    lintel) ends at ``q = N - depth n``. It faces the scanner when q's image lies from N
    toward F (``proj > 0``, in grid steps along N -> F) and fits between the two rays
    without a sample when ``proj <= reach``: then the step is two creases around a visible
    face the grid did not sample, not a border, and ``out[a, k]`` is True.
    `rng` is every node's range (the nearer node of an edge is N); `sig_r` the range noise
    per point (the refit's tolerance is three of it).
    """
    n = adj.shape[0]
    for c in prange(nchunk):
        mark = np.full(n, -1, dtype=np.int64)
        buf = np.empty((2 * hops + 1) * (2 * hops + 1) + 8, dtype=np.int64)
        for a in range(c, n, nchunk):
            for k in range(adj.shape[1]):
                out[a, k] = False
                b = adj[a, k]
                if b < 0 or not edges[a, k]:
                    continue
                near = a if rng[a] <= rng[b] else b
                far = b if rng[a] <= rng[b] else a
                nx, ny, nz = _grid_plane(pts, adj, cut, near, a * adj.shape[1] + k, hops,
                                         3.0 * sig_r[near], buf, mark)
                if nx == 0.0 and ny == 0.0 and nz == 0.0:
                    continue
                if (nx * (sensor[0] - pts[near, 0]) + ny * (sensor[1] - pts[near, 1])
                        + nz * (sensor[2] - pts[near, 2])) < 0:
                    nx, ny, nz = -nx, -ny, -nz
                depth = -((pts[far, 0] - pts[near, 0]) * nx + (pts[far, 1] - pts[near, 1]) * ny
                          + (pts[far, 2] - pts[near, 2]) * nz)
                if not depth > 0:
                    continue
                qx = pts[near, 0] - depth * nx - sensor[0]
                qy = pts[near, 1] - depth * ny - sensor[1]
                qz = pts[near, 2] - depth * nz - sensor[2]
                qn = math.sqrt(qx * qx + qy * qy + qz * qz)
                # the image direction across the step: the mean offset of N's grid
                # neighbours beyond it (perpendicular to the step's image for a straight
                # step, whichever grid edge crosses it)
                ex = 0.0
                ey = 0.0
                ez = 0.0
                mc = 0
                for i in range(adj.shape[1]):
                    x = adj[near, i]
                    if x < 0 or not cut[near, i]:
                        continue
                    ex += dirs[x, 0] - dirs[near, 0]
                    ey += dirs[x, 1] - dirs[near, 1]
                    ez += dirs[x, 2] - dirs[near, 2]
                    mc += 1
                if mc == 0:
                    continue
                ex /= mc
                ey /= mc
                ez /= mc
                ee = ex * ex + ey * ey + ez * ez
                if not (qn > 0 and ee > 0):
                    continue
                proj = ((qx / qn - dirs[near, 0]) * ex + (qy / qn - dirs[near, 1]) * ey
                        + (qz / qn - dirs[near, 2]) * ez) / ee
                out[a, k] = 0.0 < proj <= reach


def grid_coordinates(angles):
    """Scan-grid coordinates (azimuth, elevation) in radians, the azimuth cut at its
    largest gap (as :func:`grid_adjacency`), and the azimuth of the cut."""
    az = np.asarray(angles[:, 0], dtype=np.float64)
    a = np.sort(az)
    gaps = np.diff(np.r_[a, a[0] + 2.0 * np.pi])
    g = int(np.argmax(gaps))
    cut = float(a[g] + 0.5 * gaps[g])
    return np.c_[np.mod(az - cut, 2.0 * np.pi), angles[:, 1]], cut


def _grid_rays(gpos, steps, az_cut):
    """Unit ray directions at (fractional) grid positions `gpos` (in steps)."""
    az = gpos[:, 0] * steps[0] + az_cut
    el = gpos[:, 1] * steps[1]
    return np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]


def _ray_cylinder(sensor, ray, centre, axis, radius):
    """Coefficients of ``A t^2 + 2 B t + C = 0``, the ray ``sensor + t ray`` meeting the
    cylinder (point `centre` on the axis, unit `axis`, `radius`); it meets the
    cylinder where ``B^2 - A C >= 0``."""
    w = sensor - centre
    wp = w - np.einsum("ij,ij->i", w, axis)[:, None] * axis
    rp = ray - np.einsum("ij,ij->i", ray, axis)[:, None] * axis
    return (np.einsum("ij,ij->i", rp, rp), np.einsum("ij,ij->i", wp, rp),
            np.einsum("ij,ij->i", wp, wp) - radius * radius)


#: Bisection steps locating the silhouette ray within its grid step.
_SILHOUETTE_BISECT = 30
#: Grid steps on either side of a node within which its cylinder's silhouette is sought.
_SILHOUETTE_REACH = 2


def cylinder_border(sensor, nodes, gpos, direction, steps, az_cut, centre, axis, radius,
                    occluded, *, return_silhouette=False):
    """Where the visible surface of a node on a circular cylinder ends between its ray
    (grid position ``gpos``) and the next ray (``gpos + direction``).

    The rays ``u`` along the grid line (``u = 0`` the node's ray, ``u = 1`` the next)
    meet the cylinder while the discriminant ``B^2 - A C`` of :func:`_ray_cylinder` is
    non-negative. Where the surface is cut by a nearer surface in front (`occluded`),
    the end is the occluder's shadow, uniform between the node's ray and the next ray (or
    the silhouette, if nearer), and the estimate is the near intersection with the
    cylinder of the mid ray. Else the surface ends at its silhouette: the ray ``u*``
    where the discriminant vanishes (bisection), at the tangent point ``t = -B / A``.
    ``u*`` is searched within ``_SILHOUETTE_REACH`` grid steps on either side of the
    node: it moves by about a step for a radius error of ``range x step``, while the 3-D
    tangent point moves only by about the radius error. Without a silhouette there (the
    end of a pipe), the mid ray's intersection.

    Returns the border points and where the model applies (finite cylinder, the node on
    it within a quarter of the radius, the sensor outside it); with `return_silhouette`
    also where the point is a silhouette's tangent point.
    """
    m = nodes.shape[0]
    with np.errstate(invalid="ignore"):
        ok = (np.isfinite(radius) & np.isfinite(centre).all(axis=1)
              & np.isfinite(axis).all(axis=1))
    c = np.where(ok[:, None], centre, 0.0)
    a = np.where(ok[:, None], axis, (1.0, 0.0, 0.0))
    r = np.where(ok, radius, 1.0)
    rel = nodes - c
    dist = np.linalg.norm(rel - np.einsum("ij,ij->i", rel, a)[:, None] * a, axis=1)
    ok &= np.abs(dist - r) < 0.25 * r

    def disc(u):
        A, B, C = _ray_cylinder(sensor, _grid_rays(gpos + u[:, None] * direction, steps,
                                                   az_cut), c, a, r)
        return B * B - A * C

    ok &= _ray_cylinder(sensor, _grid_rays(gpos, steps, az_cut), c, a, r)[2] > 0
    # bracket the silhouette: the last ray meeting the cylinder before the first that
    # does not, on the integer rays -REACH .. 1 + REACH
    ks = np.arange(-_SILHOUETTE_REACH, _SILHOUETTE_REACH + 2, dtype=np.float64)
    hit = np.stack([disc(np.full(m, k)) >= 0 for k in ks], axis=1)
    z = _SILHOUETTE_REACH  # column of u = 0
    fwd = hit[:, z:]  # u = 0, 1, ...
    # forward from the node's ray when it meets the cylinder, else backward
    first_miss = np.where((~fwd).any(axis=1), np.argmax(~fwd, axis=1), -1)
    bwd = hit[:, z - 1::-1]  # u = -1, -2, ...
    first_hit = np.where(bwd.any(axis=1), np.argmax(bwd, axis=1), -1)
    on0 = hit[:, z]
    lo = np.where(on0, first_miss - 1.0, -first_hit - 1.0)
    sil = np.where(on0, first_miss > 0, first_hit >= 0)
    lo = np.where(sil, lo, 0.0)
    hi = lo + 1.0
    for _ in range(_SILHOUETTE_BISECT):
        mid = 0.5 * (lo + hi)
        h = disc(mid) >= 0
        lo = np.where(h, mid, lo)
        hi = np.where(h, hi, mid)
    # the mid ray (on the cylinder) for an occlusion, or where no silhouette is near
    mid_ray = occluded | ~sil
    ok &= sil | on0
    u_end = np.where(sil, np.clip(lo, 0.0, 1.0), 1.0)
    u = np.where(mid_ray, 0.5 * u_end, lo)
    ray = _grid_rays(gpos + u[:, None] * direction, steps, az_cut)
    A, B, C = _ray_cylinder(sensor, ray, c, a, r)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(mid_ray, (-B - np.sqrt(np.maximum(B * B - A * C, 0.0))) / A, -B / A)
    ok &= np.isfinite(t) & (t > 0)
    q = sensor + np.where(ok, t, 0.0)[:, None] * ray
    if return_silhouette:
        return q, ok, ok & ~mid_ray
    return q, ok


def shadow_border(sensor, nodes, normals, occluders, gpos_b, direction, steps, az_cut,
                  occ_cyl, node_cyl):
    """The end of a node's visible surface in the shadow of a nearer *curved* surface.

    `occluders` (coordinates of each node's grid neighbour in `direction`, nearer to the
    sensor, at grid position `gpos_b`) lie on the circular cylinders `occ_cyl` (centre,
    axis, radius per row). Their silhouette toward the node (:func:`cylinder_border`
    from the occluder back along ``-direction``) is the ray that grazes the occluder, and
    the shadow on the node's surface begins on that ray. The estimate is the ray's near
    intersection with the node's cylinder `node_cyl` (rows NaN: none) or else with the
    node's tangent plane (`normals`). Returns the points and where they apply: the
    occluder's silhouette is found and its ray lies between the node's ray and the
    occluder's (else the midpoint rule stands).
    """
    m = nodes.shape[0]
    qb, okb, sil = cylinder_border(sensor, occluders, gpos_b, -direction, steps, az_cut,
                                   *occ_cyl, np.zeros(m, dtype=bool), return_silhouette=True)
    ok = okb & sil

    def unit(v):
        return v / np.linalg.norm(v, axis=1)[:, None]

    with np.errstate(invalid="ignore", divide="ignore"):
        rs, ra, rb = unit(qb - sensor), unit(nodes - sensor), unit(occluders - sensor)
        u = np.einsum("ij,ij->i", rs - ra, rb - ra) / np.einsum("ij,ij->i", rb - ra, rb - ra)
        ok &= (u >= 0) & (u <= 1)
        c, ax, r = node_cyl
        on = np.isfinite(r) & np.isfinite(c).all(axis=1)
        A, B, C = _ray_cylinder(sensor, rs, np.where(on[:, None], c, 0.0),
                                np.where(on[:, None], ax, 0.0), np.where(on, r, 0.0))
        t = np.where(on, (-B - np.sqrt(B * B - A * C)) / A,
                     np.einsum("ij,ij->i", nodes - sensor, normals)
                     / np.einsum("ij,ij->i", rs, normals))
    ok &= np.isfinite(t) & (t > 0)
    return sensor + np.where(ok, t, 0.0)[:, None] * rs, ok


def grid_border_points(points, sensor, normals, angles, adj, steps, edges, *,
                       cylinders=None, ray_sigma=None, gap_alpha=0.001):
    """Estimated border points of the visible surfaces on a scan grid (``'grid'`` test).

    For every node and each of its eight grid directions: where the direction leaves the
    scanned window, the node itself is the border (nothing was observed beyond it); where
    no node answers in that direction (:func:`direction_coverage`: no return, and not an
    isolated dropout on a surface that goes on) or the edge there is a border edge
    (`edges`, from :func:`border_edges`), the surface ends somewhere between the node's
    ray and the next ray, and the estimate is the mid ray's intersection with the node's
    tangent plane (unbiased for a border uniformly placed between the rays; the node
    itself when the intersection is behind the sensor or farther than ten grid steps).

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates (any origin shared with `sensor`).
    sensor : (3,) ndarray
    normals : (N, 3) ndarray
    angles : (N, 2) ndarray
        Azimuth and elevation of every point seen from the sensor.
    adj : (N, SLOTS) ndarray
        Grid neighbours (:func:`grid_adjacency`).
    steps : (float, float)
        Azimuth and elevation steps (radians).
    edges : (N, SLOTS) bool ndarray
        Border edges.
    ray_sigma : float or (N,) ndarray, optional
        Range noise std along the rays; with it a single missing node is a dropout only
        where the range is continuous across it (test at `gap_alpha`, two-sided), without
        it wherever a node answers two steps on.
    gap_alpha : float
        Level of that continuity test.

    Returns
    -------
    border : (B, 3) ndarray
        Border points.
    node : (B,) int64 ndarray
        The node each border point belongs to.
    kind : (B,) uint8 ndarray
        ``BORDER_WINDOW``, ``BORDER_MISSING`` or ``BORDER_JUMP``.
    slot : (B,) int64 ndarray
        The adjacency slot of the border edge (-1 for the window and missing returns).
    """
    n = points.shape[0]
    s_az, s_el = steps
    if n == 0 or not (s_az > 0 and s_el > 0):
        return (np.empty((0, 3)), np.empty(0, np.int64), np.empty(0, np.uint8),
                np.empty(0, np.int64))
    xy, az_cut = grid_coordinates(angles)
    g = np.c_[xy[:, 0] / s_az, xy[:, 1] / s_el]
    rng = np.linalg.norm(points - sensor, axis=1)
    if ray_sigma is None:
        covered, dropout = direction_coverage(g)
    else:
        from scipy.special import ndtri

        sig = np.broadcast_to(np.asarray(ray_sigma, dtype=np.float64), rng.shape) / rng ** 2
        covered, dropout = direction_coverage(g, 1.0 / rng, sig,
                                              float(ndtri(1.0 - gap_alpha / 2.0)))
    # the direction of each slot's border edge (its neighbour's offset rounded, 0.6 steps)
    nb = np.maximum(adj, 0)
    off = g[nb] - g[:, None, :]
    dist = np.linalg.norm(off[:, :, None, :] - _DIRS8[None, None], axis=-1)
    best = np.argmin(dist, axis=2)
    ok = (adj >= 0) & (np.take_along_axis(dist, best[..., None], 2)[..., 0] < 0.6)
    rows = np.broadcast_to(np.arange(n)[:, None], adj.shape)
    jump = np.zeros((n, 8), dtype=bool)
    jslot = np.full((n, 8), -1, dtype=np.int64)
    sel = ok & edges
    jump[rows[sel], best[sel]] = True
    jslot[rows[sel], best[sel]] = np.broadcast_to(np.arange(adj.shape[1]), adj.shape)[sel]
    lo = g.min(axis=0) - 0.5
    hi = g.max(axis=0) + 0.5
    far = 10.0 * rng * max(s_az, s_el)
    out_p, out_n, out_k, out_s = [], [], [], []
    for d in range(8):
        nxt = g + _DIRS8[d]
        outside = ((nxt < lo) | (nxt > hi)).any(axis=1)
        win = ~covered[:, d] & outside
        miss = ~covered[:, d] & ~outside & ~dropout[:, d]
        node = np.flatnonzero(win)
        out_p.append(points[node])
        out_n.append(node)
        out_k.append(np.full(node.size, BORDER_WINDOW, np.uint8))
        out_s.append(np.full(node.size, -1, np.int64))
        node = np.flatnonzero(miss | jump[:, d])
        ray = _grid_rays(g[node] + 0.5 * _DIRS8[d], steps, az_cut)
        pa = points[node]
        nrm = normals[node]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", pa - sensor, nrm) / np.einsum("ij,ij->i", ray, nrm)
        q = sensor + t[:, None] * ray
        bad = ~(np.isfinite(t) & (t > 0)) | ~(np.linalg.norm(q - pa, axis=1) <= far[node])
        q[bad] = pa[bad]
        if cylinders is not None:
            # nodes on a consistently curved surface: the border on their circular cylinder
            js = adj[node, np.maximum(jslot[node, d], 0)]
            occluded = jump[node, d] & (rng[js] < rng[node])
            qc, ok = cylinder_border(sensor, pa, g[node], _DIRS8[d], steps, az_cut,
                                     *(c[node] for c in cylinders), occluded)
            ok &= np.linalg.norm(qc - pa, axis=1) <= far[node]
            q[ok] = qc[ok]
            # the shadow of a nearer curved surface begins on its silhouette ray
            oi = np.flatnonzero(occluded)
            b = js[oi]
            qs, oks = shadow_border(sensor, pa[oi], normals[node[oi]], points[b], g[b],
                                    _DIRS8[d], steps, az_cut, tuple(c[b] for c in cylinders),
                                    tuple(np.where(ok[oi, None] if c.ndim == 2 else ok[oi],
                                                   c[node[oi]], np.nan) for c in cylinders))
            oks &= np.linalg.norm(qs - pa[oi], axis=1) <= far[node[oi]]
            q[oi[oks]] = qs[oks]
        out_p.append(q)
        out_n.append(node)
        out_k.append(np.where(jump[node, d], BORDER_JUMP, BORDER_MISSING).astype(np.uint8))
        out_s.append(np.where(jump[node, d], jslot[node, d], -1))
    return (np.concatenate(out_p), np.concatenate(out_n), np.concatenate(out_k),
            np.concatenate(out_s))


def grid_boundary(points, sensor, normals, ray_sigma, *, vis, jump_alpha, smooth_alpha=0.05,
                  cylinders=None, jamb_reach=None, return_borders=False):
    """Distance from every point to the nearest estimated end of the visible surface.

    Parameters
    ----------
    points : (N, 3) ndarray
    sensor : (3,) ndarray
    normals : (N, 3) ndarray
    ray_sigma : float or (N,) ndarray
        Range noise std along the rays.
    vis : dict
        The output of :func:`visible_boundary` (grid adjacency, steps, edge p-values).
    jump_alpha : float
        Level of the continuity test of one grid edge.
    smooth_alpha : float
        Level of the smoothness tests on either side of a rejected edge.
    cylinders : tuple of (N, 3), (N, 3), (N,) ndarrays, optional
        Per point a circular cylinder (a point of its axis, the unit axis, the radius;
        NaN where the point is not on a consistently curved surface): the border of such
        a node is placed on its cylinder (:func:`cylinder_border`), else on its tangent
        plane.

    Returns
    -------
    dict with ``border_distance`` (m; inf where no border exists), ``border_kind``
    (uint8: ``BORDER_WINDOW``, ``BORDER_MISSING``, ``BORDER_JUMP``; 0 without a border)
    and ``border_p`` (the continuity test's p-value of the nearest border's grid edge; 0
    for the window and missing returns, which are observed, not tested; NaN without a
    border). With `return_borders`, also ``borders``: the border points, their nodes,
    kinds and adjacency slots (:func:`grid_border_points`), and ``nearest``: the index of
    each point's nearest border point.
    """
    from scipy.spatial import cKDTree
    from scipy.special import ndtri

    from .._shared._geometry import scan_angles

    origin, pts, sens, rng, dirs, sig = _rays(points, sensor, ray_sigma)
    adj = vis["adjacency"]
    pe = vis["edge_p"]
    cut = np.ascontiguousarray((adj >= 0) & (pe < jump_alpha))
    edges = np.empty(adj.shape, dtype=np.bool_)
    nrm = np.ascontiguousarray(normals, dtype=np.float64)
    border_edges(dirs, np.ascontiguousarray(1.0 / rng), np.ascontiguousarray(sig), adj, cut,
                 float(ndtri(1.0 - smooth_alpha / 2.0)), edges)
    if jamb_reach is None:
        jamb_reach = JAMB_REACH
    if jamb_reach > 0:
        import numba

        jamb = np.empty(adj.shape, dtype=np.bool_)
        visible_jambs(pts, sens, dirs, rng, adj, cut, edges,
                      np.ascontiguousarray(np.broadcast_to(np.asarray(ray_sigma, np.float64),
                                                           rng.shape)),
                      JAMB_HOPS, float(jamb_reach), 4 * numba.get_num_threads(), jamb)
        edges &= ~jamb
    if cylinders is not None:
        cylinders = (np.asarray(cylinders[0], dtype=np.float64) - origin,
                     np.asarray(cylinders[1], dtype=np.float64),
                     np.asarray(cylinders[2], dtype=np.float64))
    bp, node, kind, slot = grid_border_points(pts, sens, nrm, scan_angles(pts, sens), adj,
                                              vis["step"], edges, cylinders=cylinders,
                                              ray_sigma=ray_sigma, gap_alpha=jump_alpha)
    n = pts.shape[0]
    dist = np.full(n, np.inf)
    bkind = np.zeros(n, dtype=np.uint8)
    bpv = np.full(n, np.nan)
    if bp.shape[0]:
        dist, j = cKDTree(bp).query(pts, workers=-1)
        bkind = kind[j]
        bpv = np.where(kind[j] == BORDER_JUMP, pe[node[j], np.maximum(slot[j], 0)], 0.0)
    out = {"border_distance": dist, "border_kind": bkind, "border_p": bpv}
    if return_borders:
        out["borders"] = (bp, node, kind, slot)
        out["nearest"] = j if bp.shape[0] else np.full(n, -1, dtype=np.int64)
    return out
