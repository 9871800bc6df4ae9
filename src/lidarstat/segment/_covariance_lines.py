"""Intersection lines of a covariance segmentation (seed 003, eq. 9-17).

For neighbouring points of two segments whose normals differ by more than ``min_angle``,
the planes through their neighbourhood centroids meet in the line ``l(t) = x0 + t a`` with
``a = n1 x n2``; the point of the line that minimises ``|l(t) - p1|^2 + |l(t) - p2|^2``
(eq. 17) is the line's point closest to the midpoint of p1 and p2. Points farther than
``max_distance`` from p1 or p2 are rejected (parallel surfaces, step edges). Per segment
pair the points are fitted by a line (principal axis, one round of 3-MAD trimming) with
its extent. Where a cylinder segment meets a plane or another cylinder the eq. 17 point
is moved onto their intersection curve and the points are chained into polylines
(:mod:`lidarstat.segment._intersect`).
"""

from __future__ import annotations

import numpy as np

from . import _edge_kernels as _ek
from ._result import Polylines

def clean_plane_points(labels, clean, nbh):
    """For every point, the nearest neighbour in its own segment whose plane test passed.

    Points next to a crease have neighbourhoods that straddle it, so their normals and
    centroids are biased toward the other face; the local plane of the nearest clean
    point of the same segment (``clean``: surface or boundary class) is not. Rows must be
    sorted by distance (kNN); a point without such a neighbour keeps its own.
    """
    n = labels.size
    ref = np.arange(n)
    if nbh.kind != "knn" or nbh.k is None:
        return ref
    _ek.first_in_row(nbh.indptr, nbh.indices, nbh.query_indices(),
                     np.ascontiguousarray(clean, dtype=bool), _ek._compact(labels), ref)
    return ref


def local_intersections(points, labels, normals, centroids, nbh, *, min_angle=20.0,
                        max_distance, max_offset=np.inf, return_pairs=False):
    """Local intersection points of neighbouring points on different segments (eq. 9-17).

    Returns
    -------
    x0 : (P, 3) ndarray
        Intersection points (eq. 17), one per accepted pair.
    seg : (P, 2) ndarray of int
        The two segments (smaller id first).
    pairs : (P, 2) ndarray of int
        With `return_pairs`: the two points (in the order of `seg`).
    """
    i, j = _ek.label_pairs(nbh, labels)  # 0 < labels[i] < labels[j]
    n1, n2 = normals[i], normals[j]
    cosang = np.abs(np.einsum("ij,ij->i", n1, n2))
    ok = cosang < np.cos(np.radians(min_angle))  # eq. 9: not parallel
    i, j, n1, n2 = i[ok], j[ok], n1[ok], n2[ok]
    a = np.cross(n1, n2)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    origin = points.mean(axis=0) if len(points) else np.zeros(3)
    p1, p2 = points[i] - origin, points[j] - origin
    c1, c2 = centroids[i] - origin, centroids[j] - origin
    m = 0.5 * (p1 + p2)
    A = np.stack([n1, n2, a], axis=1)  # eq. 10-14 plus the line's closest point to m
    rhs = np.stack([np.einsum("ij,ij->i", n1, c1), np.einsum("ij,ij->i", n2, c2),
                    np.einsum("ij,ij->i", a, m)], axis=1)
    x0 = np.linalg.solve(A, rhs[:, :, None])[:, :, 0]
    far = np.maximum(np.linalg.norm(x0 - p1, axis=1), np.linalg.norm(x0 - p2, axis=1))
    # two faces that meet have their crease near the pair: the eq. 17 point is within
    # |p1 - p2| / (2 sin(theta / 2)) of the pair's midpoint for an interior angle theta,
    # at most |p1 - p2| from 60 degrees up; faces that do not meet (a roof and the soffit
    # under its fascia, a wall under the eaves) have theirs off in the air
    gap = np.linalg.norm(p1 - p2, axis=1)
    good = (far <= max_distance) & (np.linalg.norm(x0 - m, axis=1) <= gap + max_offset)
    seg = np.stack([labels[i[good]], labels[j[good]]], axis=1)
    if return_pairs:
        return x0[good] + origin, seg, np.stack([i[good], j[good]], axis=1)
    return x0[good] + origin, seg


def _pair_groups(x0, seg):
    """The local intersection points grouped by segment pair: yields ``(a, b, points)``."""
    if not len(seg):
        return
    key = seg[:, 0].astype(np.int64) * (int(seg.max()) + 1) + seg[:, 1]
    order = np.argsort(key, kind="stable")
    key, x0s, segs = key[order], x0[order], seg[order]
    bounds = np.flatnonzero(np.diff(key)) + 1
    for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, key.size]):
        yield segs[lo, 0], segs[lo, 1], x0s[lo:hi]


def _line_attributes(attr):
    return {"segment_a": np.asarray(attr["segment_a"], dtype=np.int32),
            "segment_b": np.asarray(attr["segment_b"], dtype=np.int32),
            "n_points": np.asarray(attr["n_points"], dtype=np.int64),
            "rms": np.asarray(attr["rms"], dtype=np.float64)}


def fit_lines(x0, seg, *, min_points=5):
    """A straight line per segment pair through its local intersection points.

    Principal axis of the points, one round of trimming at 3 MAD of the distances to the
    line, extent = the trimmed points' projections.

    Returns
    -------
    Polylines
        Attributes ``segment_a``, ``segment_b``, ``n_points``, ``rms`` (distance of the
        trimmed points to the line).
    """
    starts, ends, attr = [], [], {"segment_a": [], "segment_b": [], "n_points": [], "rms": []}
    for a, b, pts in _pair_groups(x0, seg):
        if len(pts) < min_points:
            continue
        for _ in range(2):
            c = pts.mean(axis=0)
            _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
            u = vt[0]
            r = pts - c - np.outer((pts - c) @ u, u)
            dist = np.linalg.norm(r, axis=1)
            med = np.median(dist)
            mad = np.median(np.abs(dist - med)) * 1.4826
            inl = dist <= med + 3 * mad + 1e-12
            if inl.all() or inl.sum() < min_points:
                break
            pts = pts[inl]
        t = (pts - c) @ u
        starts.append(c + t.min() * u)
        ends.append(c + t.max() * u)
        attr["segment_a"].append(a)
        attr["segment_b"].append(b)
        attr["n_points"].append(len(pts))
        attr["rms"].append(float(np.sqrt(np.mean(dist[inl] ** 2))) if len(dist) else 0.0)
    attr = _line_attributes(attr)
    if not starts:
        return Polylines([], attr)
    return Polylines.from_segments(np.array(starts), np.array(ends), attr)


def _polyline_rms(v, pts):
    """RMS distance of `pts` to the polyline of vertices `v`."""
    a, b = v[:-1], v[1:]
    ab = b - a
    t = np.clip(np.einsum("pkj,kj->pk", pts[:, None, :] - a[None], ab) /
                np.maximum(np.einsum("kj,kj->k", ab, ab), 1e-300), 0.0, 1.0)
    d = np.linalg.norm(pts[:, None, :] - a[None] - t[:, :, None] * ab[None], axis=2).min(1)
    return float(np.sqrt(np.mean(d ** 2)))


def curved_lines(x0, seg, curved, *, min_points=5, max_gap, bin_angle=2.0, tolerance=None):
    """Polylines through the local intersection points of segment pairs with a curved
    member (`curved`: per segment, 1-based ids at index id - 1), chained by
    :func:`lidarstat.segment._intersect.chain_curve`; pieces split at gaps above `max_gap`.

    Returns
    -------
    Polylines
        Attributes as :func:`fit_lines` (``rms``: RMS distance of the points to their
        polyline), one line per piece.
    """
    from ._intersect import chain_curve

    verts, attr = [], {"segment_a": [], "segment_b": [], "n_points": [], "rms": []}
    for a, b, pts in _pair_groups(x0, seg):
        if len(pts) < min_points or not (curved[a - 1] or curved[b - 1]):
            continue
        for v in chain_curve(pts, bin_angle=bin_angle, max_gap=max_gap, tolerance=tolerance):
            verts.append(v)
            attr["segment_a"].append(a)
            attr["segment_b"].append(b)
            attr["n_points"].append(len(pts))
            attr["rms"].append(_polyline_rms(v, pts))
    attr = _line_attributes(attr)
    return Polylines(verts, attr)


def crease_lines(pts, labels, feats, classes, surface, boundary, cylinders, seg_sigma,
                 csensor, *, min_angle):
    """The intersection lines of a covariance segmentation: straight lines of two planar
    segments (eq. 9-17 and :func:`fit_lines`) and polylines where a cylinder meets a plane
    or another cylinder (:func:`curved_lines`).

    The local planes are those of the neighbourhoods the plane test accepted (a surface
    accepted by the cylinder test is curved: its covariance plane is not the tangent
    plane), else the segment's trimmed plane when the noise model accepts it, and the
    cylinder's tangent plane on cylinder segments.
    """
    nbh = feats.neighborhoods
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1] if nbh.kind == "knn" else \
        np.full(len(nbh), nbh.radius)
    # local planes from neighbourhoods the plane test accepted (a surface accepted by
    # the cylinder test is curved: its covariance plane is not the tangent plane)
    planar = (classes["plane_p"] >= classes.alpha) & (surface | boundary)
    ref = clean_plane_points(labels, planar, nbh)
    # a point with no such plane in its row (its own straddles the crease) takes no part
    use = labels * planar[ref]
    n_loc, c_loc = feats.normals[ref], feats.centroid[ref]
    from ._intersect import (cylinder_tangent_planes, snap_between_cylinders,
                             snap_to_cylinder)
    from ._refine import PlaneModels

    # a point without a tested neighbourhood plane in its row, on a segment whose own
    # trimmed plane the noise model accepts (a fascia, a soffit: narrow faces where no
    # 50-neighbourhood is a plane), takes its segment's plane
    pm = PlaneModels(pts, labels, seg_sigma, csensor)
    pm_planar, pm_normal, pm_centroid = pm.planar, pm.normal, pm.centroid
    del pm  # only the per-segment planes are needed from here
    seg_plane = (use == 0) & (labels > 0)
    seg_plane[seg_plane] = pm_planar[labels[seg_plane] - 1]
    sp = labels[seg_plane] - 1
    n_loc[seg_plane], c_loc[seg_plane] = pm_normal[sp], pm_centroid[sp]
    use[seg_plane] = labels[seg_plane]
    # points of cylinder segments: the tangent plane of their segment's cylinder
    on_cyl, cn, cf = cylinder_tangent_planes(pts, labels, cylinders)
    n_loc[on_cyl], c_loc[on_cyl], use[on_cyl] = cn, cf, labels[on_cyl]
    x0, seg, pr = local_intersections(pts, use, n_loc, c_loc, nbh, min_angle=min_angle,
                                      max_distance=2.0 * float(np.median(rk)),
                                      max_offset=3.0 * float(np.median(seg_sigma)),
                                      return_pairs=True)
    # a cylinder against a plane: the crease is their intersection curve; move the
    # eq. 17 point of the tangent plane onto it
    ci, pj = on_cyl[pr[:, 0]], on_cyl[pr[:, 1]]
    one = ci ^ pj
    ax3 = np.c_[cylinders["axis_x"], cylinders["axis_y"], cylinders["axis_z"]]
    ap3 = np.c_[cylinders["axis_point_x"], cylinders["axis_point_y"],
                cylinders["axis_point_z"]]
    rad = np.asarray(cylinders["radius"])
    tol = 3.0 * float(np.median(seg_sigma))
    keep = np.ones(len(seg), dtype=bool)
    both = ci & pj
    if both.any():  # two cylinders: a crease only where they cross (not two pipes
        sa, sb = labels[pr[both, 0]] - 1, labels[pr[both, 1]] - 1  # side by side)
        x0[both], gap2 = snap_between_cylinders(
            x0[both], (ap3[sa], ax3[sa], rad[sa]), (ap3[sb], ax3[sb], rad[sb]))
        keep[both] = gap2 <= tol
    if one.any():
        cp = np.where(ci, pr[:, 0], pr[:, 1])[one]  # the cylinder side
        pp = np.where(ci, pr[:, 1], pr[:, 0])[one]  # the plane side
        s_ = labels[cp] - 1
        # the plane side: its segment's trimmed plane when the noise model accepts it
        # (a 50-neighbourhood's normal tilts by ~0.01 rad: 3 mm at the crease)
        sp = labels[pp] - 1
        glob = pm_planar[sp]
        pn = np.where(glob[:, None], pm_normal[sp], n_loc[pp])
        pc_ = np.where(glob[:, None], pm_centroid[sp], c_loc[pp])
        x0[one], gap1 = snap_to_cylinder(x0[one], ap3[s_], ax3[s_], rad[s_], pn, pc_)
        keep[one] = gap1 <= tol
    x0, seg = x0[keep], seg[keep]
    curved = np.asarray(cylinders["model"]) == 2
    pair_curved = curved[seg[:, 0] - 1] | curved[seg[:, 1] - 1] if len(seg) else \
        np.zeros(0, bool)
    straight = fit_lines(x0[~pair_curved], seg[~pair_curved])
    bent = curved_lines(x0, seg, curved, max_gap=2.0 * float(np.median(rk)),
                        tolerance=float(np.median(seg_sigma)))
    lines_out = Polylines(straight.vertices + bent.vertices,
                          {k: np.r_[straight.attributes[k], bent.attributes[k]]
                           for k in straight.attributes})
    return lines_out
