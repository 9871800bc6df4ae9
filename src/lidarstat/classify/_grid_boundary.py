"""The ``'grid'`` boundary test of the covariance classification (terrestrial scans).

A boundary point is one whose neighbourhood is cut by the end of its visible surface. The
test does not look for a symptom of the cut in the neighbourhood (an off-centre centroid,
the paper's eq. 6-8) but estimates where the visible surface ends, on the scan grid, and
measures the distance:

* a grid direction of a node that leaves the scanned window: the node itself is the
  border (nothing was observed beyond it);
* a grid direction no node answers (no return), unless it is an isolated dropout on a
  surface that goes on (:func:`._grid_borders.direction_coverage`), and
* a grid edge the range-continuity test rejects (:mod:`._scan_grid`) between two surfaces
  the grid resolves on both sides (:func:`._scan_grid_kernels.border_edges`), unless a
  recess face the grid did not sample explains the step (the jamb rule,
  :func:`._jamb_kernels.visible_jambs`):

the surface ends between the node's ray and the next one, and the estimate is the mid
ray's intersection with the node's tangent plane, or with its fitted cylinder on a
consistently curved surface (the silhouette of a pipe, :func:`._grid_borders.cylinder_border`).
A point closer than ``border_band`` times its neighbourhood's reach to the nearest estimated
border point is a boundary.
"""

from __future__ import annotations

import numpy as np

from ._grid_borders import (_DIRS8, BORDER_JUMP, BORDER_MISSING, BORDER_WINDOW,
                            cylinder_border, direction_coverage, shadow_border)
from ._jamb_kernels import JAMB_HOPS, JAMB_REACH, visible_jambs
from ._scan_grid import _grid_rays, _rays, grid_coordinates
from ._scan_grid_kernels import border_edges

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


def grid_boundary(points, sensor, normals, ray_sigma, *, grid, jump_alpha, smooth_alpha=0.05,
                  cylinders=None, jamb_reach=None, return_borders=False):
    """Distance from every point to the nearest estimated end of the visible surface.

    Parameters
    ----------
    points : (N, 3) ndarray
    sensor : (3,) ndarray
    normals : (N, 3) ndarray
    ray_sigma : float or (N,) ndarray
        Range noise std along the rays.
    grid : dict
        The output of :func:`._scan_grid.grid_edges` (grid adjacency, steps, edge
        p-values).
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
    adj = grid["adjacency"]
    pe = grid["edge_p"]
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
                                              grid["step"], edges, cylinders=cylinders,
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
