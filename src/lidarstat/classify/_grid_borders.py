"""Where the visible surface of a scan-grid node ends: the grid directions no node
answers (:func:`direction_coverage`) and the end of a curved surface on its cylinder
(:func:`cylinder_border`, :func:`shadow_border`); used by :mod:`._grid_boundary`."""

from __future__ import annotations

import numpy as np

from ._scan_grid import _grid_rays

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
