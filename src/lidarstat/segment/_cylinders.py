"""Cylinder models of curved segments, and the merge of pieces of one cylinder (seed 003).

A segment's axis is the direction its normals are perpendicular to: the eigenvector of
the smallest eigenvalue of ``sum n n'`` over its points (for a plane every in-plane
direction qualifies, and the projected circle degenerates to a line). The points are
projected on the plane perpendicular to the axis and a circle is fitted as in the
consistent-curvature test (:func:`lidarstat.features.cylinder_test`: algebraic start,
Gauss-Newton on the geometric residuals weighted by the per-point noise). A segment is a
*cylinder* when the circle explains significantly more than a straight line does (the
plane), ``F = ((RSS_line - RSS_circle) / 1) / (RSS_circle / (n - 3))`` against
``F(1, n - 3)`` at 0.001, the circle's weighted RSS is at most half the
line's (a plane with a small misfit of the noise model passes the F test alone when it has
thousands of points), and its radius is below the segment's extent times 10.

Pieces of one cylinder (a tank cut by the shadow of a pipe in front of it, a pipe split
at a support) merge when one cylinder fitted to their union explains them about as well
as the separate fits: the noise-normalised RMS of the union, ``sqrt(RSS_u / (n - 3))``,
is at most ``tolerance`` (1.5) times the larger of 1 (the noise itself) and the pooled
RMS of the two fits, for every pair of cylinder segments whose axes are within
``max_angle`` and whose radii agree within 50 %. This is a tolerance, not a test: with
thousands of points the F test of the union against the two fits,
``((RSS_u - RSS_a - RSS_b) / 3) / ((RSS_a + RSS_b) / (n - 6))``, rejects for millimetre
differences between the pieces' fits (measured F = 1260 for two pieces of the synthetic
tank, whose fitted radii agree to 0.2 mm), which come from the noise model, not from
two surfaces.
"""

from __future__ import annotations

import numpy as np

from ..features import cylinder_test
from ..stats import f_pvalue


def group_outer(vectors, groups, m):
    """Per group g < m: the sum of ``v v'`` over the rows v of `vectors` in group g (NaN
    rows count as zero). Returns (m, 3, 3)."""
    v = np.nan_to_num(np.asarray(vectors, dtype=np.float64))
    M = np.zeros((m, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            w = np.bincount(groups, weights=v[:, a] * v[:, b], minlength=m)
            M[:, a, b] = w
            M[:, b, a] = w
    return M


def _axes_of(normals, rows_idx, indptr):
    """Per row: eigenvector of the smallest eigenvalue of the normals' second moments."""
    m = indptr.size - 1
    seg = np.repeat(np.arange(m), np.diff(indptr))
    return np.linalg.eigh(group_outer(normals[rows_idx], seg, m))[1][:, :, 0]


def _dominant(axes, rows_idx, indptr):
    """Per row: the dominant direction of the members' axes (largest eigenvector)."""
    m = indptr.size - 1
    seg = np.repeat(np.arange(m), np.diff(indptr))
    return np.linalg.eigh(group_outer(axes[rows_idx], seg, m))[1][:, :, 2]


def _fit_rows(points, normals, rows_idx, indptr, sigma, sensor, point_axes=None):
    """Cylinder fit of each CSR row of point indices: (stat, n, radius, axis, centre, line).

    Axis candidates: the direction the members' normals are perpendicular to and, with
    `point_axes`, the dominant direction of the members' own axes (minimum-curvature
    directions); the one whose circle fits better is kept.
    """
    q = rows_idx[indptr[:-1]]  # the fit is centred on a member of the row
    axes_row = _axes_of(normals, rows_idx, indptr)
    stat, dof, radius, centre = cylinder_test(points, q, indptr, rows_idx, axes_row, sigma,
                                              sensor=sensor, return_centre=True)
    if point_axes is not None:
        alt = _dominant(point_axes, rows_idx, indptr)
        s2, _, r2, c2 = cylinder_test(points, q, indptr, rows_idx, alt, sigma,
                                      sensor=sensor, return_centre=True)
        better = np.isfinite(s2) & ~(s2 >= stat)
        stat, radius = np.where(better, s2, stat), np.where(better, r2, radius)
        centre = np.where(better[:, None], c2, centre)
        axes_row = np.where(better[:, None], alt, axes_row)
    # the straight-line (plane) fit of the same projection, for the model choice
    lstat = _line_stat(points, rows_idx, indptr, axes_row, sigma, sensor)
    return stat, dof + 3, radius, axes_row, centre, lstat


def _line_stat(points, rows_idx, indptr, axes_row, sigma, sensor):
    """Weighted RSS of the best plane containing the axis direction (a straight line in
    the projection; total least squares), weighted as the circle fit."""
    m = indptr.size - 1
    seg = np.repeat(np.arange(m), np.diff(indptr))
    p = points[rows_idx]
    a = axes_row[seg]
    # plane normal: smallest eigenvector of the covariance of the projected points
    cnt = np.diff(indptr).astype(np.float64)
    cen = np.stack([np.bincount(seg, weights=p[:, j], minlength=m) for j in range(3)], 1)
    cen /= cnt[:, None]
    d = p - cen[seg]
    d = d - np.einsum("ij,ij->i", d, a)[:, None] * a
    C = group_outer(d, seg, m)
    # the axis direction has zero variance after projection: take the smallest eigenvector
    # orthogonal to it (the middle one when the axis is the smallest)
    w, vec = np.linalg.eigh(C)
    n0 = vec[:, :, 0]
    par = np.abs(np.einsum("ij,ij->i", n0, axes_row)) > 0.5
    normal = np.where(par[:, None], vec[:, :, 1], n0)
    r = np.einsum("ij,ij->i", d, normal[seg])
    sig = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (points.shape[0],))[rows_idx]
    if sensor is not None:
        ray = points[rows_idx] - np.asarray(sensor, dtype=np.float64)
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        sig = sig * np.maximum(np.abs(np.einsum("ij,ij->i", ray, normal[seg])), 0.1)
    return np.bincount(seg, weights=(r / sig) ** 2, minlength=m)


def _csr(labels, ids):
    """CSR of the members of segments `ids` (1-based labels)."""
    order = np.argsort(labels, kind="stable")
    lab = labels[order]
    start = np.searchsorted(lab, ids, side="left")
    stop = np.searchsorted(lab, ids, side="right")
    counts = stop - start
    indptr = np.zeros(ids.size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    pos = np.repeat(start - indptr[:-1], counts) + np.arange(indptr[-1])
    return indptr, order[pos]


def segment_cylinders(points, labels, normals, sigma, *, sensor=None, alpha=0.001,
                      point_axes=None):
    """Cylinder model of every segment (see the module doc).

    `point_axes` (N, 3), optional: per-point axis directions (NaN where none) offered as
    a second axis candidate.

    Returns
    -------
    dict of str -> (S,) ndarray
        ``model`` (1 plane, 2 cylinder), ``radius`` (NaN for planes), ``axis_x/y/z``,
        ``axis_point_x/y/z`` (a point of the axis), ``cylinder_p`` (p-value of the F test
        of the cylinder against the plane), and the internals ``stat`` (weighted RSS of
        the circle), ``n``.
    """
    s = int(labels.max()) if labels.size else 0
    ids = np.arange(1, s + 1)
    indptr, idx = _csr(labels, ids)
    ok = np.diff(indptr) >= 7
    out = {k: np.full(s, np.nan) for k in ("radius", "axis_x", "axis_y", "axis_z",
                                            "axis_point_x", "axis_point_y", "axis_point_z",
                                            "cylinder_p", "stat")}
    out["model"] = np.ones(s, dtype=np.uint8)
    out["n"] = np.diff(indptr).astype(np.float64)
    if not ok.any():
        return out
    sel = np.flatnonzero(ok)
    counts = np.diff(indptr)[sel]
    sub_ptr = np.zeros(sel.size + 1, dtype=np.int64)
    np.cumsum(counts, out=sub_ptr[1:])
    sub_idx = np.concatenate([idx[indptr[i]:indptr[i + 1]] for i in sel]) if sel.size else \
        np.empty(0, np.int64)
    stat, n, radius, axis, centre, lstat = _fit_rows(points, normals, sub_idx, sub_ptr, sigma,
                                                     sensor, point_axes)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = (lstat - stat) / (stat / np.maximum(n - 3, 1))
        p = f_pvalue(np.maximum(f, 0.0), 1.0, np.maximum(n - 3, 1))  # F(1, n - 3), upper tail
    ext = np.array([np.ptp(points[sub_idx[a:b]], axis=0).max() for a, b in
                    zip(sub_ptr[:-1], sub_ptr[1:])])
    # significant and large: with thousands of points the F test alone calls a plane with
    # a small misfit of the noise model a cylinder of radius 40 m (a door recess)
    cyl = np.isfinite(radius) & (p < alpha) & (lstat >= 2.0 * stat) & (radius < 10 * ext)
    out["cylinder_p"][sel] = p
    out["stat"][sel] = stat
    out["model"][sel[cyl]] = 2
    out["radius"][sel[cyl]] = radius[cyl]
    for j, c in enumerate("xyz"):
        out[f"axis_{c}"][sel[cyl]] = axis[cyl, j]
        out[f"axis_point_{c}"][sel[cyl]] = centre[cyl, j]
    return out


def merge_cylinders(points, labels, normals, sigma, *, sensor=None, tolerance=1.5,
                    max_angle=5.0, max_pairs=20000, point_axes=None):
    """Merge segments that are pieces of one cylinder (see the module doc).

    Returns
    -------
    labels : (N,) ndarray of int32
        Relabelled by size (unchanged when nothing merges).
    table : dict
        :func:`segment_cylinders` of the returned labels.
    """
    from ._grow import relabel

    t = segment_cylinders(points, labels, normals, sigma, sensor=sensor, point_axes=point_axes)
    cyl = np.flatnonzero(t["model"] == 2)
    if cyl.size < 2:
        return labels, t
    ax = np.c_[t["axis_x"], t["axis_y"], t["axis_z"]][cyl]
    rad = t["radius"][cyl]
    a, b = np.triu_indices(cyl.size, 1)
    cos = np.abs(np.einsum("ij,ij->i", ax[a], ax[b]))
    close = (cos >= np.cos(np.radians(max_angle))) & \
        (np.abs(rad[a] - rad[b]) <= 0.5 * np.maximum(rad[a], rad[b]))
    a, b = a[close][:max_pairs], b[close][:max_pairs]
    if not a.size:
        return labels, t
    sa, sb = cyl[a] + 1, cyl[b] + 1
    ia, pa = _csr(labels, sa)
    ib, pb = _csr(labels, sb)
    na, nb = np.diff(ia), np.diff(ib)
    uptr = np.zeros(a.size + 1, dtype=np.int64)
    np.cumsum(na + nb, out=uptr[1:])
    uidx = np.concatenate([np.r_[pa[ia[r]:ia[r + 1]], pb[ib[r]:ib[r + 1]]]
                           for r in range(a.size)])
    su, nu, ru, _, _, _ = _fit_rows(points, normals, uidx, uptr, sigma, sensor, point_axes)
    sep = t["stat"][sa - 1] + t["stat"][sb - 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        rms_u = np.sqrt(su / np.maximum(nu - 3, 1))
        rms_ab = np.sqrt(sep / np.maximum(nu - 6, 1))
    ok = np.isfinite(ru) & (rms_u <= tolerance * np.maximum(rms_ab, 1.0))
    if not ok.any():
        return labels, t
    parent = np.arange(labels.max() + 1)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for u, v in zip(sa[ok], sb[ok]):  # a few pairs of segments, not points
        ru_, rv_ = find(u), find(v)
        if ru_ != rv_:
            parent[max(ru_, rv_)] = min(ru_, rv_)
    root = np.array([find(x) for x in range(parent.size)])
    new = relabel(root[labels] * (labels > 0))
    return new, segment_cylinders(points, new, normals, sigma, sensor=sensor,
                                  point_axes=point_axes)


def _noise_scale(points, idx, e, sigma, sensor):
    """Noise std in the radial directions `e` at the points `idx` (floored at 0.1 sigma)."""
    sig = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (points.shape[0],))[idx]
    if sensor is None:
        return sig
    ray = points[idx] - np.asarray(sensor, dtype=np.float64)
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    return sig * np.maximum(np.abs(np.einsum("ij,ij->i", ray, e)), 0.1)


def _perp_basis(a):
    t = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    b1 = np.cross(a, t)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(a, b1)


def fit_cylinder(points, idx, axis, axis_point, radius, sigma, *, sensor=None,
                 iterations=15, max_points=20000):
    """Weighted Gauss-Newton fit of all five cylinder parameters to the points `idx`.

    The segment fit of :func:`segment_cylinders` fixes the axis to the direction its
    normals are perpendicular to and fits a circle across it; a small tilt of that axis
    (the normals of 50-neighbourhoods on a half-seen pipe) displaces the cylinder by
    ``tilt * distance`` at the pipe's ends, where its creases are. Here the axis direction
    (two angles), the axis position (two offsets) and the radius are refined together on
    the residuals ``d_i = |(p_i - c) - ((p_i - c) . a) a| - R``, weighted by the noise in
    the radial direction, with the analytic Jacobian (``dd/dc = -e``, ``dd/da = -h e``,
    ``dd/dR = -1``, e the unit radial direction, h the height along the axis). Points are
    thinned evenly to `max_points`.

    Returns
    -------
    axis, axis_point : (3,) ndarray
    radius : float
    rms : float
        RMS of the weighted residuals (1 when the noise model holds).
    """
    idx = np.asarray(idx)
    if idx.size > max_points:
        idx = idx[np.linspace(0, idx.size - 1, max_points).astype(np.int64)]
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    c = np.asarray(axis_point, dtype=np.float64).copy()
    r = float(radius)
    p = points[idx]
    c = c + ((p.mean(axis=0) - c) @ a) * a  # axis point at the points' middle
    rms = np.nan
    for _ in range(iterations):
        b1, b2 = _perp_basis(a)
        w = p - c
        h = w @ a
        e = w - np.outer(h, a)
        rho = np.linalg.norm(e, axis=1)
        e /= np.maximum(rho, 1e-300)[:, None]
        d = rho - r
        s = _noise_scale(points, idx, e, sigma, sensor)
        eb1, eb2 = e @ b1, e @ b2
        J = np.c_[-h * eb1, -h * eb2, -eb1, -eb2, -np.ones(idx.size)] / s[:, None]
        f = d / s
        step, *_ = np.linalg.lstsq(J, -f, rcond=None)
        a = a + step[0] * b1 + step[1] * b2
        a /= np.linalg.norm(a)
        c = c + step[2] * b1 + step[3] * b2
        r += step[4]
        rms = float(np.sqrt(np.mean(f * f)))
        if np.abs(step).max() < 1e-9:
            break
    return a, c, r, rms


def refine_cylinder_table(points, labels, table, sigma, *, sensor=None):
    """:func:`fit_cylinder` for every cylinder segment of `table` (a copy is returned)."""
    out = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in table.items()}
    cyl = np.flatnonzero(np.asarray(table["model"]) == 2)
    if not cyl.size:
        return out
    indptr, idx = _csr(np.asarray(labels), cyl + 1)
    for k, s in enumerate(cyl):  # one fit per cylinder segment (a few), not per point
        ax = np.array([table["axis_x"][s], table["axis_y"][s], table["axis_z"][s]])
        ap = np.array([table["axis_point_x"][s], table["axis_point_y"][s],
                       table["axis_point_z"][s]])
        a, c, r, _ = fit_cylinder(points, idx[indptr[k]:indptr[k + 1]], ax, ap,
                                  table["radius"][s], sigma, sensor=sensor)
        if not (np.isfinite(r) and r > 0 and abs(a @ ax) > np.cos(np.radians(10))):
            continue  # keep the segment fit when the refinement runs away
        for j, q in enumerate("xyz"):
            out[f"axis_{q}"][s] = a[j]
            out[f"axis_point_{q}"][s] = c[j]
        out["radius"][s] = r
    return out


def cylinder_units(points, idx, table, s, sigma, *, sensor=None):
    """Residuals of the points `idx` from the cylinder of segment index `s` (0-based), in
    noise units."""
    a = np.array([table["axis_x"][s], table["axis_y"][s], table["axis_z"][s]])
    c = np.array([table["axis_point_x"][s], table["axis_point_y"][s], table["axis_point_z"][s]])
    w = points[idx] - c
    e = w - np.outer(w @ a, a)
    rho = np.linalg.norm(e, axis=1)
    e /= np.maximum(rho, 1e-300)[:, None]
    return np.abs(rho - table["radius"][s]) / _noise_scale(points, idx, e, sigma, sensor)


def absorb_into_cylinders(points, labels, nbh, table, sigma, *, sensor=None, nsigma=3.0,
                          min_fraction=0.9, width=None):
    """Merge a segment into a touching, larger cylinder segment whose cylinder it lies on.

    A band of a tank next to the ground, grown through small planar prefixes and cut off
    from the tank's own segment by edge points, gets a cylinder fit of its own (a strip is
    a poor cylinder: radius 0.23 m on the synthetic tank of radius 3 m) and is not merged
    by :func:`merge_cylinders` (radii differ). Here a segment whose points are at least
    `min_fraction` inliers (within `nsigma` noise units) of a touching larger cylinder
    segment's fitted cylinder joins it. Segments touch through the first `width`
    entries of each row of `nbh` (every entry when None).

    Returns
    -------
    labels : (N,) ndarray of int32
        Relabelled by size (unchanged when nothing is absorbed).
    changed : bool
    """
    from ._edge_kernels import label_pairs
    from ._grow import adjacency_of_pairs, relabel

    model = np.asarray(table["model"])
    if not (model == 2).any():
        return labels, False
    pairs, _ = adjacency_of_pairs(labels, *label_pairs(nbh, labels, different_only=True,
                                                       width=width))
    if not len(pairs):
        return labels, False
    size = np.bincount(labels, minlength=model.size + 1)[1:]
    target = np.arange(model.size + 1)
    for a, b in pairs:  # touching segment pairs with a cylinder: a few per segment
        for small, big in ((a, b), (b, a)):
            if model[big - 1] != 2 or size[small - 1] >= size[big - 1]:
                continue
            idx = np.flatnonzero(labels == small)
            u = cylinder_units(points, idx, table, big - 1, sigma, sensor=sensor)
            if np.mean(u <= nsigma) >= min_fraction:
                target[small] = big
    if (target == np.arange(target.size)).all():
        return labels, False
    for _ in range(target.size):  # follow chains small -> big
        nxt = target[target]
        if (nxt == target).all():
            break
        target = nxt
    return relabel(target[labels] * (labels > 0)), True
