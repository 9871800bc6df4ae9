"""Region growing on covariance classes, local surface intersections, reintegration (seed 003).

* Region growing (Fig. 4): from every surface point, its neighbours are taken in order of
  distance and join its region until the first non-surface neighbour (the "cut plane"
  of edge and boundary points); a point already in another region merges the two
  (union-find). This is :func:`lidarstat.segment.grow_regions` with ``merge=True`` over
  the CSR edges before the first non-surface neighbour of each row; boundary points join
  a region but do not grow it (with adaptive scales, those whose neighbourhood passed a
  surface test grow). Seeds in order of increasing surface variation (option).
* Local intersections (eq. 9-17): for neighbouring points of two segments whose normals
  differ by more than ``min_angle``, the planes through their neighbourhood centroids
  meet in the line ``l(t) = x0 + t a`` with ``a = n1 x n2``; the point of the line that
  minimises ``|l(t) - p1|^2 + |l(t) - p2|^2`` (eq. 17) is the line's point closest to the
  midpoint of p1 and p2. Points farther than ``max_distance`` from p1 or p2 are rejected
  (parallel surfaces, step edges). Per segment pair the points are fitted by a line
  (principal axis, one round of 3-MAD trimming) with its extent.
* Reintegration: an edge point joins the segment of a neighbour whose local plane (centroid
  and normal of that neighbour's neighbourhood) it lies on within 3 sigma; the closest
  such plane wins.
* Segment-level planes (:mod:`lidarstat.segment._refine`): border points that are
  outliers of their segment's plane move to the touching segment whose plane they fit;
  faces seen on one or two scan rows become strip segments when their plane is
  identified and passes the plane test.
* Curved creases: points of cylinder segments use their cylinder's tangent plane, the
  eq. 17 point is moved onto the cylinder-plane intersection curve and the points of a
  pair are chained into polylines (:mod:`lidarstat.segment._intersect`).
"""

from __future__ import annotations

import numpy as np

from .._shared import _memory as _mem
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import PointClass
from ..neighbors import Neighborhoods
from ..neighbors import check_copies
from . import _edge_kernels as _ek
from ._grow import grow_regions
from ._result import Polylines, Segmentation


def surface_prefix_edges(nbh: Neighborhoods, surface):
    """CSR edges before the first non-surface neighbour of each row (rows sorted by distance).

    The row's own point (distance 0) is skipped when looking for the first non-surface one.
    """
    surface = np.ascontiguousarray(surface, dtype=bool)
    out = np.empty(nbh.nnz, dtype=bool)
    _ek.prefix_ok(nbh.indptr, nbh.indices, nbh.query_indices(), surface, out)
    return out


def truncate_rows(nbh: Neighborhoods, m: int) -> Neighborhoods:
    """The first `m` neighbours of every row of fixed-size (kNN) neighbourhoods."""
    k = nbh.k
    if nbh.kind != "knn" or k is None or m >= k:
        return nbh
    n = len(nbh)
    idx = _mem.empty(n * m, dtype=nbh.indices.dtype)
    d = _mem.empty(n * m)
    _ek.first_columns(nbh.indices, nbh.distances, k, m, idx, d)
    return Neighborhoods(np.arange(n + 1, dtype=np.int64) * m, idx, d, nbh.n_points,
                         kind="knn", k=m, query=nbh.query, row_order=nbh.row_order)


def segment_planes(points, labels):
    """Per segment: size, centroid, total-least-squares plane (normal, d) and RMS.

    Returns
    -------
    dict of str -> (S,) ndarray
        ``segment_id, n_points, centroid_x/y/z, normal_x/y/z, d`` (plane ``n . x + d = 0``),
        ``rms`` (orthogonal residuals), ``surface_variation`` (lambda0 / sum).
    """
    from ._refine import _planes, _seg_moments

    labels = np.ascontiguousarray(labels, dtype=np.int64)
    s = int(labels.max()) if labels.size else 0
    # one Numba pass of moments about each segment's first point (no O(N) temporaries)
    ref, mom = _seg_moments(np.ascontiguousarray(points, dtype=np.float64), labels,
                            np.ones(labels.size), s)
    cnt = mom[:, 0]
    cen_file, normal, w = _planes(ref, mom)
    normal = normal * np.where(normal[:, 2] < 0, -1.0, 1.0)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        sv = w[:, 0] / w.sum(axis=1)
    return {
        "segment_id": np.arange(1, s + 1, dtype=np.int32), "n_points": cnt.astype(np.int64),
        "centroid_x": cen_file[:, 0], "centroid_y": cen_file[:, 1], "centroid_z": cen_file[:, 2],
        "normal_x": normal[:, 0], "normal_y": normal[:, 1], "normal_z": normal[:, 2],
        "d": -np.einsum("ij,ij->i", normal, cen_file),
        "rms": np.sqrt(np.maximum(w[:, 0], 0.0)), "surface_variation": sv,
    }


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
                     np.ascontiguousarray(clean, dtype=bool), np.ascontiguousarray(labels), ref)
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


def reintegrate(points, labels, candidates, normals, centroids, nbh, sigma, *, nsigma=3.0):
    """Give each candidate point the segment of the neighbour whose local plane it fits best.

    Returns
    -------
    (N,) ndarray of int32
        Labels with the reintegrated points set; unchanged elsewhere.
    """
    out = labels.copy()
    s, t = _ek.reintegration_pairs(nbh, candidates, labels)  # unlabelled -> labelled
    sig = np.broadcast_to(np.asarray(sigma, dtype=np.float64), labels.shape)[t]
    dist = np.abs(np.einsum("ij,ij->i", points[s] - centroids[t], normals[t])) / sig
    fit = dist <= nsigma
    s, t, dist = s[fit], t[fit], dist[fit]
    if not s.size:
        return out
    order = np.lexsort((dist, s))
    s, t = s[order], t[order]
    first = np.r_[True, s[1:] != s[:-1]]
    out[s[first]] = labels[t[first]]
    return out


def _union_plane_rms(points, labels, a, b):
    """Orthogonal RMS of the plane fitted to the union of segments a and b (1-based ids)."""
    from ._cylinders import group_outer

    s = int(labels.max())
    origin = points.mean(axis=0)
    x = points - origin
    ins = labels > 0
    lab = labels[ins] - 1
    cnt = np.bincount(lab, minlength=s).astype(np.float64)
    cen = np.stack([np.bincount(lab, weights=x[ins, j], minlength=s) for j in range(3)], 1)
    cen /= np.maximum(cnt, 1)[:, None]
    S = group_outer(x[ins] - cen[lab], lab, s)
    a0, b0 = a - 1, b - 1
    na, nb = cnt[a0], cnt[b0]
    dc = cen[a0] - cen[b0]
    U = S[a0] + S[b0] + (na * nb / (na + nb))[:, None, None] * np.einsum("ij,ik->ijk", dc, dc)
    w = np.linalg.eigvalsh(U)[:, 0]
    return np.sqrt(np.maximum(w, 0.0) / (na + nb))


def merge_coplanar(points, labels, nbh, *, max_angle=5.0, nsigma=3.0, normals=None,
                   centroids=None, tolerance=1.5):
    """Merge touching segments that are one surface (split by a window, a pipe in front, ...).

    Two segments that share neighbour pairs merge when their plane normals differ by less
    than `max_angle` degrees and each centroid lies within `nsigma` times the other's RMS
    (plus the first's) of the other's plane, or - with per-point `normals` - when the
    median angle between the local normals of their touching points is below `max_angle`
    and the touching points lie on each other's local planes (median distance within the
    plane tolerance): a smooth continuation. Either way the plane fitted to the union
    must have an orthogonal RMS at most `tolerance` times the larger RMS of the two
    (two parallel planes a recess apart are not one surface; pieces of one cylinder are
    merged by :func:`lidarstat.segment._cylinders.merge_cylinders`). Ids are renumbered
    by size.
    """
    from ._grow import adjacency_of_pairs, relabel

    # the touching pairs of points once: both directions for the segment adjacency, the
    # ascending ones (0 < labels[si] < labels[di], in CSR order) for the local test below
    src, dst = _ek.label_pairs(nbh, labels, different_only=True)
    pairs, _ = adjacency_of_pairs(labels, src, dst)
    if not len(pairs):
        return labels
    t = segment_planes(points, labels)
    n = np.c_[t["normal_x"], t["normal_y"], t["normal_z"]]
    c = np.c_[t["centroid_x"], t["centroid_y"], t["centroid_z"]]
    a, b = pairs[:, 0] - 1, pairs[:, 1] - 1
    cos = np.abs(np.einsum("ij,ij->i", n[a], n[b]))
    tol = nsigma * (t["rms"][a] + t["rms"][b])
    da = np.abs(np.einsum("ij,ij->i", c[b] - c[a], n[a]))
    db = np.abs(np.einsum("ij,ij->i", c[a] - c[b], n[b]))
    ok = (cos >= np.cos(np.radians(max_angle))) & (da <= tol) & (db <= tol)
    if normals is not None:
        asc = labels[src] < labels[dst]
        si, di = src[asc], dst[asc]  # = _ek.label_pairs(nbh, labels)
        del asc, src, dst
        key = labels[si].astype(np.int64) * (int(labels.max()) + 1) + labels[di]
        c_local = np.abs(np.einsum("ij,ij->i", normals[si], normals[di]))
        off = np.abs(np.einsum("ij,ij->i", points[di] - centroids[si], normals[si]))
        order = np.argsort(key, kind="stable")
        key, c_local, off = key[order], c_local[order], off[order]
        uk, start = np.unique(key, return_index=True)
        med = np.array([np.median(v) for v in np.split(c_local, start[1:])]) if uk.size else \
            np.empty(0)
        moff = np.array([np.median(v) for v in np.split(off, start[1:])]) if uk.size else \
            np.empty(0)
        pk = pairs[:, 0].astype(np.int64) * (int(labels.max()) + 1) + pairs[:, 1]
        pos = np.searchsorted(uk, pk)
        found = (pos < uk.size) & (uk[np.minimum(pos, uk.size - 1)] == pk)
        smooth = np.zeros(len(pairs), dtype=bool)
        smooth[found] = (med[pos[found]] >= np.cos(np.radians(max_angle))) & \
            (moff[pos[found]] <= tol[found])
        ok |= smooth
    if ok.any():
        # one plane must fit the union about as well as each part: two parallel planes
        # a recess apart (a window's back and its wall) are not one surface
        pooled = np.sqrt((t["rms"][a] ** 2 * t["n_points"][a] + t["rms"][b] ** 2 *
                          t["n_points"][b]) / (t["n_points"][a] + t["n_points"][b]))
        cand = np.flatnonzero(ok)
        union = _union_plane_rms(points, labels, pairs[cand, 0], pairs[cand, 1])
        ok[cand] = union <= tolerance * np.maximum(pooled[cand], np.maximum(
            t["rms"][a[cand]], t["rms"][b[cand]]))
    if not ok.any():
        return labels
    parent = np.arange(len(t["segment_id"]) + 1)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for u, v in pairs[ok]:  # a few pairs per segment: a Python loop over segments is fine
        ru, rv = find(u), find(v)
        if ru != rv:
            parent[max(ru, rv)] = min(ru, rv)
    root = np.array([find(x) for x in range(parent.size)])
    return relabel(root[labels] * (labels > 0))


def surface_tested(feats, classes):
    """Points whose neighbourhood passed a surface test (plane or consistent curvature),
    whatever their final class: the tests of
    :func:`lidarstat.classify.classify_covariance`, with the user's thresholds when it had
    them."""
    sv = feats["SurfaceVariation"]
    with np.errstate(invalid="ignore"):
        if classes.curvature_threshold is not None:
            low = sv <= classes.curvature_threshold
        else:
            low = classes["plane_p"] >= classes.alpha
        if classes.variance_threshold is not None:
            consistent = feats["CurvatureVariance"] <= classes.variance_threshold
        else:
            alpha = classes.meta.get("curved_alpha", classes.alpha)
            consistent = classes["variation_p"] >= alpha
    return (classes.point_class != 0) & (low | consistent)


def segment_covariance(points, result, *, adaptive_scale=True, min_size=50, grow_k=20,
                       seeds="curvature", min_angle=20.0, reintegration=True, lines=True,
                       refine=True) -> Segmentation:
    """Region growing (Fig. 4) and intersection lines (eq. 9-17) of a covariance classification.

    Parameters
    ----------
    points : (N, 3) array_like
    result : CovarianceClassification
        The classification of `points` by :func:`lidarstat.classify.covariance`, computed
        with ``keep_neighbors=True`` (its noise, levels, sensor and neighbourhoods are the
        segmentation's).
    adaptive_scale : bool
        Also grow through each point's largest planar neighbourhood prefix
        (:func:`lidarstat.segment._scales.planar_scales`: 8 to k nearest, plane test at
        `alpha`), so faces narrower than the k-neighbourhood are found; writes
        ``scale_k`` and ``scale_plane_p``.
    min_size : int
        Smallest segment kept (points).
    grow_k : int
        Region growing looks at the `grow_k` nearest neighbours of a point (kNN), in order
        of distance, up to the first non-surface one.
    seeds : {'curvature', 'index'}
        Seed order: increasing surface variation (the flattest points first) or file order.
        The final partition does not depend on it (label merging); segment ids do not
        either (they are numbered by size).
    min_angle : float
        Smallest angle (degrees) between normals for a local intersection (eq. 9).
    reintegration : bool
        Give edge points the segment whose local plane they fit (within 3 sigma).
    refine : bool
        Segment-level plane models (:mod:`lidarstat.segment._refine`): a point of a planar
        segment that is an outlier of its plane (beyond 3 noise units) and an inlier of a
        touching planar segment's plane moves there; points no segment explains
        (unlabelled, or plane outliers) are searched for planes of narrow faces (RANSAC
        on connected strips, kept when the plane is identified and passes the plane test).
    lines : bool
        Compute the intersection lines.

    Returns
    -------
    Segmentation
        ``labels``; ``table`` from :func:`segment_planes` plus the cylinder model of
        :func:`lidarstat.segment._cylinders.segment_cylinders` (``model`` 1 plane, 2
        cylinder, ``radius``, ``axis_x/y/z``, ``axis_point_x/y/z``, ``cylinder_p``);
        ``lines`` (Polylines);
        ``fields``: ``point_class``, ``reintegrated`` (1 edge point given to the segment
        whose local plane it fits, 2 moved by the border refinement, 3 in a strip
        segment), ``NormalX/Y/Z``,
        ``SurfaceVariation``.
    """
    func = "segment_covariance"
    pts = check_points(points)
    check_copies(pts, what=func)  # neighbors/_duplicates.py
    min_size = check_scalar(min_size, "min_size", func=func, low=1, closed="left", integer=True)
    grow_k = check_scalar(grow_k, "grow_k", func=func, low=2, closed="left", integer=True)
    min_angle = check_scalar(min_angle, "min_angle", func=func, low=0.0, high=90.0)
    if seeds not in ("curvature", "index"):
        raise InvalidParameterError(
            f"The 'seeds' parameter of {func} must be one of 'curvature', 'index'. "
            f"Got {seeds!r} instead.")
    feats, classes = result.features, result.classes
    # the segment-level models (whole-segment planes and cylinders, their borders and
    # lines) use the classification's segment scale when it has one: with the estimated
    # range noise, the plane-median line (noise plus the typical model error of a
    # real scan's surfaces, never below the noise; docs/methods/covariance.md)
    seg_sigma = classes.meta.get("segment_sigma", classes.sigma)
    nbh = feats.neighborhoods
    if nbh is None:
        raise InvalidParameterError(f"{func}: `result` must be computed with keep_neighbors=True")
    pc = classes.point_class
    surface = pc == PointClass.SURFACE
    # a boundary point is a border of a surface only when its neighbourhood passed a
    # surface test; the scan boundary test also labels edge candidates beside an
    # occlusion or a crease "boundary", and those must cut the rows like edges
    boundary = (pc == PointClass.BOUNDARY) & surface_tested(feats, classes)
    edge_like = (pc == PointClass.EDGE) | ((pc == PointClass.BOUNDARY) & ~boundary)
    grow_nbh = truncate_rows(nbh, grow_k)
    sv = feats["SurfaceVariation"]
    order = np.argsort(np.where(np.isfinite(sv), sv, np.inf), kind="stable") \
        if seeds == "curvature" else None
    extra = {}
    if adaptive_scale and nbh.kind == "knn":
        from ._scales import planar_scales

        kstar, kp, pn = planar_scales(pts, nbh, seg_sigma, alpha=classes.alpha,
                                      sensor=feats.sensor if classes.meta.get("noise") ==
                                      "range" else None)
        extra = {"scale_k": kstar.astype(np.uint8), "scale_plane_p": kp}
        # Fig. 4 on the first grow_k neighbours of surface points, plus every point's
        # largest planar prefix; members of either may be joined, only tested points grow
        # (surface points, and boundary points whose neighbourhood passed a surface test:
        # on a thin pipe crossed by shadows most points are near a border, and with the
        # 'visible' boundary test pipe_b of tls_plant at step 0.004 fell apart otherwise).
        # Two growing points of a prefix must also agree in their prefix normals: on a
        # scan whose rows run along a crease, two rows (one per face) are two parallel
        # lines, always coplanar, so a small prefix can pass the test across the crease.
        # (one Numba pass over the rows: no per-edge arrays besides the mask)
        edge_ok = _mem.empty(nbh.nnz, dtype=bool)
        _ek.adaptive_edges(nbh.visit_order(), nbh.indptr, nbh.indices, nbh.query_indices(),
                           surface | boundary, surface | boundary, np.ascontiguousarray(kstar),
                           np.ascontiguousarray(pn),
                           int(grow_k), float(np.cos(np.radians(min_angle / 2))), edge_ok)
        labels = grow_regions(nbh, edge_ok, order=order, can_grow=surface | boundary | (kstar > 0),
                              mask=pc != PointClass.UNDETERMINED, merge=True,
                              min_size=min_size)
    else:
        # boundary points end a surface, they do not separate two: they may be joined (and
        # do not grow), only edge and undetermined points cut the rows (Fig. 4)
        edge_ok = surface_prefix_edges(grow_nbh, surface | boundary)
        labels = grow_regions(grow_nbh, edge_ok, order=order, can_grow=surface,
                              mask=surface | boundary, merge=True, min_size=min_size)
    normals = feats.normals  # one (N, 3) stack for every step below (read only)
    centroids = feats.centroid
    across = seg_sigma
    if classes.meta.get("noise") == "range":
        across = np.maximum(seg_sigma * feats.ray_cos, 1e-12)
    reint = np.zeros(pts.shape[0], dtype=np.uint8)
    if reintegration:
        cand = edge_like | (pc == PointClass.UNDETERMINED)
        new = reintegrate(pts, labels, cand & (labels == 0), normals, centroids, nbh, across)
        reint[(new > 0) & (labels == 0)] = 1
        labels = new
    if refine:
        from ._refine import refine_borders, strip_segments

        rsensor = feats.sensor if classes.meta.get("noise") == "range" else None
        labels, moved, models = refine_borders(pts, labels, nbh, seg_sigma,
                                               sensor=rsensor)
        reint[moved] = 2
        if nbh.kind == "knn":
            before = labels
            free = ((labels == 0) & (pc != PointClass.UNDETERMINED)) | models.outliers()
            labels = strip_segments(pts, labels, nbh, seg_sigma, sensor=rsensor,
                                    candidates=free, alpha=classes.alpha, min_size=min_size)
            new = labels > before.max()
            reint[new] = 3
            if new.any():  # the new planes take their border points too
                labels, moved, _ = refine_borders(pts, labels, nbh, seg_sigma,
                                                  sensor=rsensor, models=models.fit(labels))
                reint[moved & ~new] = 2
        del models, moved  # per-point arrays: not kept beside the neighbourhoods
        if nbh.kind == "knn":
            del free, before, new
    labels = merge_coplanar(pts, labels, grow_nbh, max_angle=min_angle / 4,
                            normals=normals, centroids=feats.centroid)
    from ._cylinders import merge_cylinders

    # per-point axes (minimum-curvature directions) of the curved surface points only
    # (computed for those points: no (N, 3) temporaries at the segmentation's peak)
    curved_pts = surface & ~(classes["plane_p"] >= classes.alpha)
    pt_axes = np.full((pts.shape[0], 3), np.nan)
    ci_ = np.flatnonzero(curved_pts)
    pdir = np.stack([feats["PrincipalDirX"][ci_], feats["PrincipalDirY"][ci_],
                     feats["PrincipalDirZ"][ci_]], axis=1)
    pt_axes[ci_] = np.cross(normals[ci_], pdir)
    del pdir, ci_
    labels, cylinders = merge_cylinders(
        pts, labels, normals, seg_sigma, max_angle=min_angle / 4,
        sensor=feats.sensor if classes.meta.get("noise") == "range" else None,
        point_axes=pt_axes)
    from ._cylinders import absorb_into_cylinders, refine_cylinder_table, segment_cylinders

    csensor = feats.sensor if classes.meta.get("noise") == "range" else None
    cylinders = refine_cylinder_table(pts, labels, cylinders, seg_sigma, sensor=csensor)
    labels, absorbed = absorb_into_cylinders(pts, labels, grow_nbh, cylinders, seg_sigma,
                                             sensor=csensor)
    if absorbed:
        cylinders = refine_cylinder_table(
            pts, labels, segment_cylinders(pts, labels, normals, seg_sigma,
                                           sensor=csensor, point_axes=pt_axes),
            seg_sigma, sensor=csensor)
    lines_out = None
    if lines:
        rk = nbh.distances.reshape(len(nbh), -1)[:, -1] if nbh.kind == "knn" else \
            np.full(len(nbh), nbh.radius)
        # local planes from neighbourhoods the plane test accepted (a surface accepted by
        # the cylinder test is curved: its covariance plane is not the tangent plane)
        planar = (classes["plane_p"] >= classes.alpha) & (surface | boundary)
        ref = clean_plane_points(labels, planar, nbh)
        # a point with no such plane in its row (its own straddles the crease) takes no part
        use = labels * planar[ref]
        n_loc, c_loc = normals[ref], centroids[ref]
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
    table = segment_planes(pts, labels)
    for key in ("model", "radius", "axis_x", "axis_y", "axis_z", "axis_point_x",
                "axis_point_y", "axis_point_z", "cylinder_p"):
        table[key] = cylinders[key]
    fields = {"point_class": pc.astype(np.uint8), "reintegrated": reint,
              "NormalX": feats["NormalX"], "NormalY": feats["NormalY"],
              "NormalZ": feats["NormalZ"], "SurfaceVariation": sv, **extra}
    params = {"k": feats.k, "radius": feats.radius, "grow_k": grow_k, "min_size": min_size,
              "seeds": seeds, "min_angle": min_angle, "alpha": classes.alpha,
              "adaptive_scale": bool(extra),
              "boundary_alpha": classes.boundary_alpha, "noise": classes.meta.get("noise"),
              "sigma_estimated": classes.sigma_estimated}
    return Segmentation(labels=labels, table=table, lines=lines_out, fields=fields,
                        method="covariance", params=params)
