"""Break lines between adjacent fitted surfaces by 3-D intersection (seed 000, "indirect
segmentation of the surface units").

For two adjacent units with surfaces ``z = f_a(E, N)`` and ``z = f_b(E, N)`` the break
line is the curve ``g = f_a - f_b = 0`` in plan, lifted to ``z = f_a``. It is placed from
the data only through its extent: the points of either unit that touch the other are
moved onto ``g = 0`` by Newton steps along the gradient of g, and the line runs between the
extreme projections (straight for two planes, a polyline through the projections for
quadrics). Where the scan has no points on the crease itself the line is still placed,
which is the point of the indirect segmentation.
"""

from __future__ import annotations

import numpy as np

from ._result import Polylines


def _project(ua, ub, xy, iters=8):
    """Newton projection of `xy` onto f_a - f_b = 0; returns points and a convergence mask."""
    p = xy.copy()
    for _ in range(iters):
        g = ua.height(p) - ub.height(p)
        grad = ua.basis.gradient(ua.surface, p) - ub.basis.gradient(ub.surface, p)
        nrm2 = np.sum(grad * grad, axis=1)
        step = np.where(nrm2 > 0, g / np.where(nrm2 > 0, nrm2, 1.0), 0.0)
        p = p - step[:, None] * grad
    g = np.abs(ua.height(p) - ub.height(p))
    return p, g


def _normal(unit, xy):
    g = unit.basis.gradient(unit.surface, xy)
    n = np.c_[-g, np.ones(len(xy))]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def intersection_lines(points, labels, units, contact_points, contact_segments, *, max_shift,
                       min_angle=5.0, min_contacts=4, spacing=None):
    """Intersect the fitted surfaces of adjacent units.

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    labels : (N,) ndarray of int
        Final segment ids (1..S); ``units[s - 1]`` is the unit of segment s.
    units : list of SurfaceUnit
        Fitted surfaces.
    contact_points, contact_segments : (K,) ndarray of int
        Point ``contact_points[k]`` (in a segment) touches segment ``contact_segments[k]``
        (for instance within two Delaunay edges); pairs with at least `min_contacts`
        contacts are intersected.
    max_shift : float
        Touching points farther than this (in plan) from the intersection are ignored:
        step edges (a roof over the ground) have no nearby intersection and get no line.
    min_angle : float
        Smallest angle in degrees between the surface normals for a line.
    spacing : float, optional
        Vertex spacing of curved lines (default: ``max_shift / 2``).

    Returns
    -------
    Polylines
        Attributes ``segment_a``, ``segment_b``, ``angle_deg`` (between normals at the
        line's midpoint), ``n_support`` (touching points used), ``rms_gap`` (RMS of
        ``|f_a - f_b|`` at the projected points).
    """
    la = np.asarray(labels)[contact_points].astype(np.int64)
    lb = np.asarray(contact_segments, dtype=np.int64)
    lo, hi = np.minimum(la, lb), np.maximum(la, lb)
    base = int(max(la.max(initial=0), lb.max(initial=0))) + 1
    key = lo * base + hi
    keys, counts = np.unique(key, return_counts=True)
    pairs = np.c_[keys // base, keys % base][counts >= min_contacts]
    spacing = spacing or max_shift / 2.0
    verts, attrs = [], {"segment_a": [], "segment_b": [], "angle_deg": [], "n_support": [],
                        "rms_gap": []}
    for a, b in pairs:
        ua, ub = units[a - 1], units[b - 1]
        if getattr(ua, "frame", None) is not None or getattr(ub, "frame", None) is not None:
            continue  # a unit in its own frame (a wall) is not a height field z(E, N)
        touch = np.unique(contact_points[key == a * base + b])
        if touch.size < 2:
            continue
        xy = points[touch, :2]
        p, gap = _project(ua, ub, xy)
        near = (np.hypot(*(p - xy).T) <= max_shift) & (gap < 1e-3 * max_shift)
        if near.sum() < 2:
            continue
        p = p[near]
        mid = p.mean(axis=0, keepdims=True)
        cosang = abs(float(np.sum(_normal(ua, mid) * _normal(ub, mid))))
        angle = float(np.degrees(np.arccos(min(cosang, 1.0))))
        if angle < min_angle:
            continue
        c = p - mid
        _, _, vt = np.linalg.svd(c, full_matrices=False)
        t = c @ vt[0]
        if ua.degree == 1 and ub.degree == 1:
            ends = mid + np.outer([t.min(), t.max()], vt[0])
            line = np.c_[ends, ua.height(ends)]
        else:
            o = np.argsort(t)
            t, p = t[o], p[o]
            bins = np.floor((t - t[0]) / spacing).astype(np.int64)
            _, first = np.unique(bins, return_index=True)
            keep = np.unique(np.r_[first, t.size - 1])
            q, _ = _project(ua, ub, p[keep])
            line = np.c_[q, ua.height(q)]
        if len(line) < 2 or np.allclose(line[0], line[-1]):
            continue
        verts.append(line)
        attrs["segment_a"].append(a)
        attrs["segment_b"].append(b)
        attrs["angle_deg"].append(angle)
        attrs["n_support"].append(int(near.sum()))
        attrs["rms_gap"].append(float(np.sqrt(np.mean(gap[near] ** 2))))
    return Polylines(verts, {k: np.asarray(v) for k, v in attrs.items()})
