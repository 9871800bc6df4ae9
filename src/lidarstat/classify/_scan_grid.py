"""The scan grid of a terrestrial scan and the range-continuity test of its edges.

A terrestrial scanner samples a regular grid of directions; the *visible surface* of a
point is what its rays see without a break in range. Two things end it: a ray that returns
nothing (sky, the scan window) and a *depth jump* (an occlusion: the visible surface ends
and the ray passes to a background farther away). A crease does not end it: across a
crease the range is continuous, only its slope changes.

**Range continuity of a grid edge** (:func:`._scan_grid_kernels.edge_jumps`). For two
grid-adjacent points a, b take the points a', b' that continue the grid line beyond each of
them (a' = the neighbour of a nearest the direction ``2 d_a - d_b``, b' likewise; accepted
within half the step). In inverse range ``s = 1 / R`` a plane is exactly linear in the ray
direction (``n . (R d) = c`` gives ``1 / R = n . d / c``), so along a grid line the steps
``D_a = s_a - s_a'``, ``D = s_b - s_a``, ``D_b = s_b' - s_b`` are equal on a plane and,
across a crease between a and b, ``D`` lies *between* ``D_a`` and ``D_b`` (the profile is
piecewise linear, the step across the crease a convex combination of the two slopes). At a
depth jump ``D`` lies outside them by the depth. With the second differences
``E_a = D - D_a`` and ``E_b = D - D_b``,

    z_ab = min(|E_a| / sd(E_a), |E_b| / sd(E_b))    if E_a and E_b have the same sign, else 0

(``sd(E_a)^2 = sigma_b^2 + 4 sigma_a^2 + sigma_a'^2`` with ``sigma = sigma_r(R) / R^2`` the
noise of s). Null hypothesis: a, b and the points beyond them lie on one continuous
surface, linear in s along the grid line on either side of some point between a and b (a
plane, or two planes meeting at a crease; curved surfaces add second differences of order
``(R step)^2 / radius``, far below the noise). The null is composite: on a plane both E are
noise (correlation about 2/3) and ``P(z > t) = 2 P(Z1 > t, Z2 > t)``
(:func:`._scan_grid_kernels.same_sign_p`); at a crease beside a or b one E carries the
whole change of slope and the other is noise, so ``P(z > t) -> 1 - Phi(t)``, the largest
value over the null. The p-value is therefore ``p = 1 - Phi(z)``: exact at the least
favourable null (a sharp crease next to an endpoint), conservative on planes. An edge
whose grid line does not continue on both sides is not tested (p = 1: with one side, a
crease cannot be told from a jump). Per point, ``jump_z`` is the largest z of its grid
edges and ``jump_p`` the Bonferroni p-value over its m edges, ``min(1, m min p)``: "a
depth jump at this point".
"""

from __future__ import annotations

import numpy as np

from ._scan_grid_kernels import SLOTS, edge_jumps

#: A grid neighbour is farther than this many grid steps: not adjacent (a missing node).
ADJ_STEPS = 1.75


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


def grid_edges(points, sensor, ray_sigma):
    """The scan grid and the range-continuity test of every grid edge.

    Parameters
    ----------
    points : (N, 3) ndarray
    sensor : (3,) ndarray
    ray_sigma : float or (N,) ndarray
        Range noise std along the rays.

    Returns
    -------
    dict with ``jump_z``, ``jump_p`` (per point), ``step`` (azimuth and elevation steps),
    ``edge_z``, ``edge_p`` and ``adjacency`` (per grid edge, :func:`grid_adjacency`).
    """
    from .._shared._geometry import scan_angles

    _, pts, sens, rng, dirs, sig = _rays(points, sensor, ray_sigma)
    with np.errstate(divide="ignore"):
        s = 1.0 / rng
    adj, step = grid_adjacency(scan_angles(pts, sens))
    z = np.empty(adj.shape, dtype=np.float64)
    pe = np.empty(adj.shape, dtype=np.float64)
    edge_jumps(dirs, s, np.ascontiguousarray(sig), adj, z, pe)
    n_edges = np.count_nonzero(adj >= 0, axis=1)
    has = n_edges > 0
    jz = np.full(len(pts), np.nan)
    jp = np.full(len(pts), np.nan)
    jz[has] = np.max(np.where(adj[has] >= 0, z[has], -np.inf), axis=1)
    # Bonferroni over the point's grid edges (valid under any dependence between them)
    jp[has] = np.minimum(1.0, n_edges[has] * np.min(np.where(adj[has] >= 0, pe[has], np.inf),
                                                    axis=1))
    return {"jump_z": jz, "jump_p": jp, "step": step, "edge_z": z, "edge_p": pe,
            "adjacency": adj}
