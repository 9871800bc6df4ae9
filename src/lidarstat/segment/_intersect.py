"""Break lines between adjacent fitted surfaces by 3-D intersection (seed 000, "indirect
segmentation of the surface units").

For two adjacent units with surfaces ``z = f_a(E, N)`` and ``z = f_b(E, N)`` the break
line is the curve ``g = f_a - f_b = 0`` in plan, lifted to ``z = f_a``. When one unit is
a wall modelled over its own plane, both surfaces are written implicitly, ``F(x) = 0``,
and the touching points are projected onto ``F_a = F_b = 0`` in 3-D by Gauss-Newton
steps. It is placed from
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


def _implicit(unit, x):
    """``F(x) = 0`` on a unit's surface and the 3-D gradient of F at points `x` (k, 3):
    ``f(E, N) - z`` for a height field, ``h(u, v) - w`` in a wall's own frame."""
    if getattr(unit, "frame", None) is None:
        g = unit.basis.gradient(unit.surface, x[:, :2])
        return unit.height(x[:, :2]) - x[:, 2], np.c_[g, -np.ones(len(x))]
    origin, rot = unit.frame[0], unit.frame[1:]
    local = (x - origin) @ rot.T
    g = unit.basis.gradient(unit.surface, local[:, :2])
    f = unit.basis.evaluate(unit.surface, local[:, :2]) - local[:, 2]
    return f, np.c_[g, -np.ones(len(x))] @ rot


def _project3(ua, ub, x, iters=10):
    """Gauss-Newton projection of 3-D points onto the curve ``F_a = F_b = 0`` (minimum-
    norm steps ``J'(JJ')^-1 F``); returns the points, the largest ``|F|`` there and the
    unit gradients at them."""
    p = x.copy()
    for _ in range(iters):
        fa, ga = _implicit(ua, p)
        fb, gb = _implicit(ub, p)
        J = np.stack([ga, gb], axis=1)  # (k, 2, 3)
        JJ = J @ np.swapaxes(J, 1, 2)
        ok = np.abs(np.linalg.det(JJ)) > 1e-12
        JJ[~ok] = np.eye(2)
        lam = np.linalg.solve(JJ, np.c_[fa, fb][..., None])
        p = p - np.where(ok[:, None], (np.swapaxes(J, 1, 2) @ lam)[..., 0], 0.0)
    fa, ga = _implicit(ua, p)
    fb, gb = _implicit(ub, p)
    ga /= np.linalg.norm(ga, axis=1, keepdims=True)
    gb /= np.linalg.norm(gb, axis=1, keepdims=True)
    return p, np.maximum(np.abs(fa), np.abs(fb)), ga, gb


def _line3(ua, ub, points, touch, max_shift, min_angle, spacing):
    """The intersection line of two units when one is modelled in its own frame (a wall):
    the same rules as for height fields, in 3-D. Returns (line, angle, n_support,
    rms_gap) or None."""
    x = points[touch]
    p, gap, ga, gb = _project3(ua, ub, x)
    near = (np.linalg.norm(p - x, axis=1) <= max_shift) & (gap < 1e-3 * max_shift)
    if near.sum() < 2:
        return None
    p = p[near]
    cosang = float(np.median(np.abs(np.sum(ga[near] * gb[near], axis=1))))
    angle = float(np.degrees(np.arccos(min(cosang, 1.0))))
    if angle < min_angle:
        return None
    mid = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - mid, full_matrices=False)
    t = (p - mid) @ vt[0]
    if ua.degree == 1 and ub.degree == 1:
        line = _project3(ua, ub, mid + np.outer([t.min(), t.max()], vt[0]))[0]
    else:
        o = np.argsort(t)
        t, p = t[o], p[o]
        bins = np.floor((t - t[0]) / spacing).astype(np.int64)
        _, first = np.unique(bins, return_index=True)
        line = p[np.unique(np.r_[first, t.size - 1])]
    return line, angle, int(near.sum()), float(np.sqrt(np.mean(gap[near] ** 2)))


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
        touch = np.unique(contact_points[key == a * base + b])
        if touch.size < 2:
            continue
        if getattr(ua, "frame", None) is not None or getattr(ub, "frame", None) is not None:
            # a unit in its own frame (a wall) is not a height field z(E, N): 3-D
            found = _line3(ua, ub, points, touch, max_shift, min_angle, spacing)
            if found is None:
                continue
            line, angle, support, rms = found
            if len(line) < 2 or np.allclose(line[0], line[-1]):
                continue
            verts.append(line)
            for k, v in zip(attrs, (a, b, angle, support, rms)):
                attrs[k].append(v)
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


# --- curved creases of the covariance segmentation (seed 003, eq. 9-17 on cylinders) ---

def cylinder_tangent_planes(points, labels, table):
    """Tangent planes of the fitted cylinders at the points of cylinder segments.

    For a point p of a segment whose model is a cylinder (``table['model'] == 2``, axis
    point a, unit axis u, radius R), the radial direction ``e = (p - a) - ((p - a) . u) u``
    normalised is the surface normal there and ``a + ((p - a) . u) u + R e`` the foot of p
    on the cylinder: the local plane of eq. 10-15 for a curved surface, where the
    neighbourhood's own covariance plane is a secant, not a tangent.

    Returns
    -------
    on : (N,) ndarray of bool
        Points of cylinder segments.
    normal, foot : (M, 3) ndarray
        Normal and foot point of the M points of `on`, in index order.
    """
    labels = np.asarray(labels)
    model = np.asarray(table["model"])
    on = labels > 0
    on[on] = model[labels[on] - 1] == 2
    if not on.any():
        return on, np.zeros((0, 3)), np.zeros((0, 3))
    s = labels[on] - 1
    u = np.c_[table["axis_x"], table["axis_y"], table["axis_z"]][s]
    a = np.c_[table["axis_point_x"], table["axis_point_y"], table["axis_point_z"]][s]
    w = points[on] - a
    h = np.einsum("ij,ij->i", w, u)
    e = w - h[:, None] * u
    e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
    foot = a + h[:, None] * u + np.asarray(table["radius"])[s][:, None] * e
    return on, e, foot


def _onto_cylinder(x, axis_point, axis, radius):
    w = x - axis_point
    h = np.einsum("ij,ij->i", w, axis)
    e = w - h[:, None] * axis
    ln = np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
    return axis_point + h[:, None] * axis + radius[:, None] * e / ln


def snap_between_cylinders(x, cyl_a, cyl_b, iterations=20):
    """Alternating projections of `x` on two cylinders (each ``(axis_point, axis,
    radius)`` with one row per point); returns the points (on cylinder b) and their
    distance to cylinder a (about 0 where the cylinders cross, the gap where they do
    not)."""
    x = np.array(x, dtype=np.float64, copy=True)
    for _ in range(iterations):
        x = _onto_cylinder(_onto_cylinder(x, *cyl_a), *cyl_b)
    return x, np.linalg.norm(_onto_cylinder(x, *cyl_a) - x, axis=1)


def snap_to_cylinder(x, axis_point, axis, radius, normal, centre, iterations=20):
    """Points of the curve cylinder ∩ plane near `x`, by alternating projections.

    Each row: a cylinder (axis point, unit axis, radius) and a plane (unit normal, a
    point `centre`); `x` is alternately projected on the plane and radially on the
    cylinder. Where the two surfaces cross at a clear angle this converges linearly to
    the point of their intersection curve near the start (the eq. 17 point of the
    tangent plane, already within ``spacing^2 / (2 R)`` of it). Also returns each point's
    distance to the plane (about 0 where the two surfaces cross, the gap where they do
    not).
    """
    x = np.array(x, dtype=np.float64, copy=True)
    for _ in range(iterations):
        x -= np.einsum("ij,ij->i", x - centre, normal)[:, None] * normal
        x = _onto_cylinder(x, axis_point, axis, radius)
    return x, np.abs(np.einsum("ij,ij->i", x - centre, normal))


def chain_curve(pts, *, bin_angle=2.0, max_gap=None, tolerance=None):
    """Order the local intersection points of a curved crease into polylines.

    The points are projected on their best-fitting plane, a circle is fitted there
    (algebraic), and they are sorted by their angle about its centre, starting after the
    largest empty angle (the unseen part of the crease); each `bin_angle` degrees of arc
    gives one vertex, the component-wise median of its points. Consecutive vertices
    farther apart than `max_gap` (a shadow on the crease) start a new polyline; with a
    `tolerance`, also those whose chord would leave the fitted circle by more than it
    (``chord > sqrt(8 R tolerance)``), so a polyline never cuts across an unseen arc.

    Returns
    -------
    list of (m, 3) ndarray
        Polylines with at least two vertices.
    """
    pts = np.asarray(pts, dtype=np.float64)
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    uv = (pts - c) @ vt[:2].T
    A = np.c_[2 * uv, np.ones(len(uv))]
    sol, *_ = np.linalg.lstsq(A, (uv ** 2).sum(axis=1), rcond=None)
    ang = np.arctan2(uv[:, 1] - sol[1], uv[:, 0] - sol[0])
    if tolerance is not None:
        rad = np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0))
        chord = np.sqrt(8.0 * rad * tolerance)
        max_gap = chord if max_gap is None else min(max_gap, chord)
    o = np.argsort(ang)
    ang, pts = ang[o], pts[o]
    gaps = np.diff(np.r_[ang, ang[0] + 2 * np.pi])
    g = int(np.argmax(gaps))
    ang = np.mod(ang - ang[(g + 1) % ang.size], 2 * np.pi)
    o = np.argsort(ang, kind="stable")
    ang, pts = ang[o], pts[o]
    b = np.floor(ang / np.radians(bin_angle)).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
    verts = np.array([np.median(v, axis=0) for v in np.split(pts, starts[1:])])
    if max_gap is None or len(verts) < 2:
        pieces = [verts]
    else:
        step = np.linalg.norm(np.diff(verts, axis=0), axis=1)
        cut = np.flatnonzero(step > max_gap) + 1
        pieces = np.split(verts, cut)
    return [v for v in pieces if len(v) >= 2]
