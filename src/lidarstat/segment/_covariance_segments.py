"""Region growing on covariance classes, local surface intersections, reintegration (seed 003).

* Region growing (Fig. 4): from every surface point, its neighbours are taken in order of
  distance and join its region until the first non-surface neighbour (the "cut plane"
  of edge and boundary points); a point already in another region merges the two
  (union-find). This is :func:`lidarstat.segment.grow_regions` with ``merge=True`` over
  the CSR edges before the first non-surface neighbour of each row; boundary points join
  a region but do not grow it. Seeds in order of increasing surface variation (option).
* Adaptive scale (kNN neighbourhoods): every point's largest planar neighbourhood prefix
  (:func:`lidarstat.segment._scales.planar_scales`: 8 to k nearest, plane test at
  `alpha`) joins the growing too, so faces narrower than the k-neighbourhood are found
  (``scale_k``, ``scale_plane_p``); boundary points whose neighbourhood passed a surface
  test grow.
* Intersection lines (eq. 9-17): :mod:`lidarstat.segment._covariance_lines`.
* Reintegration: an edge point joins the segment of a neighbour whose local plane (centroid
  and normal of that neighbour's neighbourhood) it lies on within 3 sigma; the closest
  such plane wins.
* Segment-level planes (:mod:`lidarstat.segment._refine`): border points that are
  outliers of their segment's plane move to the touching segment whose plane they fit;
  faces seen on one or two scan rows become strip segments when their plane is
  identified and passes the plane test.
"""

from __future__ import annotations

import enum

import numpy as np

from .._shared import _memory as _mem
from .._shared._deprecate import renamed_parameters
from .._shared._jit import kernel_array
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import PointClass
from ..neighbors import Neighborhoods
from ..neighbors import check_copies
from . import _edge_kernels as _ek
from ._covariance_lines import crease_lines
from ._grow import grow_regions
from ._result import Segmentation


class SeedOrder(str, enum.Enum):
    """Seed order of :func:`segment_covariance`'s region growing (``--seeds``)."""

    #: Increasing surface variation: the flattest points first.
    CURVATURE = "curvature"
    #: File order.
    INDEX = "index"

    def __str__(self):
        return self.value


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
    ref, mom = _seg_moments(kernel_array(points), labels, np.ones(labels.size), s)
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


#: Level of the one-plane test of a merge (:func:`merge_coplanar`): the union's plane
#: against one plane per part. Small, because the parts of one real surface are not
#: exact planes, and a crease between two faces rejects at any level.
MERGE_ALPHA = 0.001


def one_plane_p(n_a, rss_a, n_b, rss_b, rss_u):
    """p-value of "segments a and b lie on one plane" (Chow's test): with the residual
    sums of squares of each part's total-least-squares plane and of the union's,
    ``F = ((RSS_u - RSS_a - RSS_b) / 3) / ((RSS_a + RSS_b) / (n_a + n_b - 6)) ~ F(3,
    n_a + n_b - 6)`` (three parameters of the second plane)."""
    from ..stats import f_pvalue

    df2 = np.maximum(n_a + n_b - 6, 1).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = ((rss_u - rss_a - rss_b) / 3.0) / ((rss_a + rss_b) / df2)
    return f_pvalue(np.maximum(f, 0.0), 3.0, df2)


def merge_coplanar(points, labels, nbh, *, max_angle=5.0, nsigma=3.0, normals=None,
                   centroids=None, tolerance=1.5, merge_alpha=MERGE_ALPHA, width=None):
    """Merge touching segments that are one surface (split by a window, a pipe in front, ...).

    Two segments that share neighbour pairs merge when their plane normals differ by less
    than `max_angle` degrees and each centroid lies within `nsigma` times the other's RMS
    (plus the first's) of the other's plane, or - with per-point `normals` - when the
    median angle between the local normals of their touching points is below `max_angle`
    and the touching points lie on each other's local planes (median distance within the
    plane tolerance): a smooth continuation. Either way the plane fitted to the union
    must have an orthogonal RMS at most `tolerance` times the larger RMS of the two
    (two parallel planes a recess apart are not one surface; pieces of one cylinder are
    merged by :func:`lidarstat.segment._cylinders.merge_cylinders`), and one plane for
    the union must not be rejected against a plane per part at `merge_alpha`
    (:func:`one_plane_p`; None: not tested). Segments touch through the first `width`
    entries of each row of `nbh` (every entry when None). Ids are renumbered by size.
    """
    from ._grow import adjacency_of_pairs, relabel

    # the touching pairs of points once: both directions for the segment adjacency, the
    # ascending ones (0 < labels[si] < labels[di], in CSR order) for the local test below
    src, dst = _ek.label_pairs(nbh, labels, different_only=True, width=width)
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
        if merge_alpha is not None:
            # the model test each part passes must hold for the union: one plane for both
            # (a flange's face and its cylindrical rim meet at a crease, where the union's
            # RMS stays within the tolerance of the rim's own)
            na, nb = t["n_points"][a[cand]], t["n_points"][b[cand]]
            p = one_plane_p(na, na * t["rms"][a[cand]] ** 2, nb, nb * t["rms"][b[cand]] ** 2,
                            (na + nb) * union ** 2)
            ok[cand] &= p >= merge_alpha
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


def _grow_cylinders(pts, labels, nbh, cylinders, normals, sigma, nsensor):
    """Unlabelled points, and outliers of a planar segment's plane, join the touching
    segment whose fitted plane or cylinder they fit (:mod:`._model_growth`): a narrow
    cylindrical strip between two creases (a flange's rim seen steeply) is mostly edge
    points, and its segment grows over them by its cylinder. `normals` are the features'
    own (at each point's scale): on a strip a few rows wide the larger rows straddle its
    creases and tilt the cylinder's axis."""
    from ._model_growth import UnitModels, free_pairs, grow_by_models
    from ._refine import PlaneModels

    dirs = None
    if nsensor is not None:
        dirs = pts - nsensor
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    models = UnitModels(pts, labels, np.asarray(cylinders["model"]) == 2, normals, sigma,
                        dirs=dirs, sensor=nsensor)
    # the pairs from the points each growth may give a unit (both directions): the
    # whole graph's would be 32 bytes a neighbour entry
    labels, _ = grow_by_models(pts, labels, *free_pairs(nbh, labels == 0), models)
    out = PlaneModels(pts, labels, sigma, nsensor).outliers()
    start = np.where(out, 0, labels)
    lab, joined = grow_by_models(pts, start, *free_pairs(nbh, start == 0), models)
    return np.where(out & ~joined, labels, lab).astype(np.int32)


@renamed_parameters(min_size="min_points")
def segment_covariance(points, result, *, min_points=50, grow_k=20, seeds="curvature",
                       min_angle=20.0, reintegration=True, lines=True) -> Segmentation:
    """Region growing (Fig. 4) and intersection lines (eq. 9-17) of a covariance classification.

    Parameters
    ----------
    points : (N, 3) array_like
    result : CovarianceClassification
        The classification of `points` by :func:`lidarstat.classify.covariance`, computed
        with ``keep_neighbors=True`` (its noise, levels, sensor and neighbourhoods are the
        segmentation's).
    min_points : int
        Smallest segment kept (points).
    grow_k : int
        Region growing looks at the `grow_k` nearest neighbours of a point (kNN), in order
        of distance, up to the first non-surface one.
    seeds : SeedOrder or {'curvature', 'index'}
        Seed order: increasing surface variation (the flattest points first) or file order.
        The final partition does not depend on it (label merging); segment ids do not
        either (they are numbered by size).
    min_angle : float
        Smallest angle (degrees) between normals for a local intersection (eq. 9).
    reintegration : bool
        Give edge points the segment whose local plane they fit (within 3 sigma).
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
    min_points = check_scalar(min_points, "min_points", func=func, low=1, closed="left",
                              integer=True)
    grow_k = check_scalar(grow_k, "grow_k", func=func, low=2, closed="left", integer=True)
    min_angle = check_scalar(min_angle, "min_angle", func=func, low=0.0, high=90.0)
    seeds = SeedOrder(check_option(seeds, "seeds", [o.value for o in SeedOrder], func=func))
    feats, classes = result.features, result.classes
    # the segment-level models (whole-segment planes and cylinders, their borders and
    # lines) use the classification's segment scale when it has one: with the estimated
    # range noise, the plane-median line (noise plus the typical model error of a
    # real scan's surfaces, never below the noise; docs/methods/covariance.md)
    seg_sigma = classes.meta.get("segment_sigma", classes.sigma)
    # the point the noise runs from (the sensor for 'range', far up for 'z', None for
    # 'normal'): every model below weights its points by their noise across it
    nsensor = classes.meta.get("noise_sensor")
    nbh = feats.neighborhoods
    if nbh is None:
        raise InvalidParameterError(f"{func}: `result` must be computed with keep_neighbors=True")
    pc = classes.point_class
    surface = pc == PointClass.SURFACE
    # a boundary point is a border of a surface only when its neighbourhood passed a
    # surface test; the grid boundary test also labels edge candidates beside an
    # occlusion or a crease "boundary", and those must cut the rows like edges
    boundary = (pc == PointClass.BOUNDARY) & surface_tested(feats, classes)
    edge_like = (pc == PointClass.EDGE) | ((pc == PointClass.BOUNDARY) & ~boundary)
    sv = feats["SurfaceVariation"]
    order = np.argsort(np.where(np.isfinite(sv), sv, np.inf), kind="stable") \
        if seeds is SeedOrder.CURVATURE else None
    extra = {}
    if nbh.kind == "knn":
        from ._scales import planar_scales

        kstar, kp, pn = planar_scales(pts, nbh, seg_sigma, alpha=classes.alpha,
                                      sensor=nsensor)
        extra = {"scale_k": kstar.astype(np.uint8), "scale_plane_p": kp}
        # Fig. 4 on the first grow_k neighbours of surface points, plus every point's
        # largest planar prefix; members of either may be joined, only tested points grow
        # (surface points, and boundary points whose neighbourhood passed a surface test:
        # on a thin pipe crossed by shadows most points are near a border).
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
                              min_points=min_points)
        del kstar, pn
    else:
        # boundary points end a surface, they do not separate two: they may be joined (and
        # do not grow), only edge and undetermined points cut the rows (Fig. 4)
        grow_nbh = truncate_rows(nbh, grow_k)  # radius rows: `nbh` itself
        edge_ok = surface_prefix_edges(grow_nbh, surface | boundary)
        labels = grow_regions(grow_nbh, edge_ok, order=order, can_grow=surface,
                              mask=surface | boundary, merge=True, min_points=min_points)
    del edge_ok, order  # per-edge and per-point: not kept beside the steps below
    # at the automatic scale the segment-level steps take the planes of the kept rows of
    # k_max neighbours (the classes keep their own scale): a prefix that stopped at a
    # crease straddles it with a few points, and its plane is no face's (only their
    # normals, centroids and normal-spread directions: the whole feature set of those rows
    # would sit beside the classification's at the segmentation's peak)
    if feats.k is None and feats.radius is None and nbh.kind == "knn":
        from ..features import covariance_frames

        normals, centroids, pdir_all = covariance_frames(pts, nbh, sensor=feats.sensor)
    else:
        normals, centroids = feats.normals, feats.centroid
        pdir_all = None
    # `normals`: one (N, 3) stack for every step below (read only); per-point axes
    # (minimum-curvature directions) of the curved surface points only
    # (computed for those points: no (N, 3) temporaries at the segmentation's peak); at
    # the automatic scale from the kept rows of k_max neighbours: the axes of the smaller
    # neighbourhoods scatter, and the pieces of one pipe then fail to merge
    curved_pts = surface & ~(classes["plane_p"] >= classes.alpha)
    pt_axes = np.full((pts.shape[0], 3), np.nan)
    ci_ = np.flatnonzero(curved_pts)
    if pdir_all is None:
        pdir = np.stack([feats["PrincipalDirX"][ci_], feats["PrincipalDirY"][ci_],
                         feats["PrincipalDirZ"][ci_]], axis=1)
    else:
        pdir = pdir_all[ci_]
    pt_axes[ci_] = np.cross(normals[ci_], pdir)
    del pdir, pdir_all, ci_, curved_pts
    across = seg_sigma
    if nsensor is not None:
        ray = pts - nsensor
        cos = np.abs(np.einsum("ij,ij->i", ray, normals)) / np.linalg.norm(ray, axis=1)
        across = np.maximum(seg_sigma * cos, 1e-12)
        del ray, cos
    reint = np.zeros(pts.shape[0], dtype=np.uint8)
    if reintegration:
        cand = edge_like | (pc == PointClass.UNDETERMINED)
        new = reintegrate(pts, labels, cand & (labels == 0), normals, centroids, nbh, across)
        reint[(new > 0) & (labels == 0)] = 1
        labels = new
    # segment-level plane models (:mod:`._refine`): a point of a planar segment that is
    # an outlier of its plane (beyond 3 noise units) and an inlier of a touching planar
    # segment's plane moves there; points no segment explains (unlabelled, or plane
    # outliers) are searched for planes of narrow faces (RANSAC on connected strips, kept
    # when the plane is identified and passes the plane test)
    from ._refine import refine_borders, strip_segments

    rsensor = nsensor
    labels, moved, models = refine_borders(pts, labels, nbh, seg_sigma,
                                           sensor=rsensor)
    reint[moved] = 2
    if nbh.kind == "knn":
        before = labels
        free = ((labels == 0) & (pc != PointClass.UNDETERMINED)) | models.outliers()
        labels = strip_segments(pts, labels, nbh, seg_sigma, sensor=rsensor,
                                candidates=free, alpha=classes.alpha, min_points=min_points)
        new = labels > before.max()
        reint[new] = 3
        if new.any():  # the new planes take their border points too
            labels, moved, _ = refine_borders(pts, labels, nbh, seg_sigma,
                                              sensor=rsensor, models=models.fit(labels))
            reint[moved & ~new] = 2
    del models, moved  # per-point arrays: not kept beside the neighbourhoods
    if nbh.kind == "knn":
        del free, before, new
    # the merges take the pairs of the first grow_k neighbours of each kNN row straight
    # from the kept rows (no copy of those rows: 12 grow_k bytes a point)
    width = grow_k if nbh.kind == "knn" and nbh.k is not None and grow_k < nbh.k else None
    labels = merge_coplanar(pts, labels, nbh, max_angle=min_angle / 4, normals=normals,
                            centroids=centroids, width=width)
    from ._cylinders import merge_cylinders

    labels, cylinders = merge_cylinders(
        pts, labels, normals, seg_sigma, max_angle=min_angle / 4,
        sensor=nsensor, point_axes=pt_axes)
    from ._cylinders import absorb_into_cylinders, refine_cylinder_table, segment_cylinders

    csensor = nsensor
    cylinders = refine_cylinder_table(pts, labels, cylinders, seg_sigma, sensor=csensor)
    labels, absorbed = absorb_into_cylinders(pts, labels, nbh, cylinders, seg_sigma,
                                             sensor=csensor, width=width)
    if absorbed:
        cylinders = refine_cylinder_table(
            pts, labels, segment_cylinders(pts, labels, normals, seg_sigma,
                                           sensor=csensor, point_axes=pt_axes),
            seg_sigma, sensor=csensor)
    if (np.asarray(cylinders["model"]) == 2).any():
        labels = _grow_cylinders(pts, labels, nbh, cylinders, feats.normals, seg_sigma,
                                 nsensor)
        cylinders = refine_cylinder_table(
            pts, labels, segment_cylinders(pts, labels, normals, seg_sigma,
                                           sensor=csensor, point_axes=pt_axes),
            seg_sigma, sensor=csensor)
    del normals, centroids, pt_axes  # the lines take the features' own planes
    lines_out = None
    if lines:
        lines_out = crease_lines(pts, labels, feats, classes, surface, boundary, cylinders,
                                 seg_sigma, csensor, min_angle=min_angle)
    table = segment_planes(pts, labels)
    for key in ("model", "radius", "axis_x", "axis_y", "axis_z", "axis_point_x",
                "axis_point_y", "axis_point_z", "cylinder_p"):
        table[key] = cylinders[key]
    fields = {"point_class": pc.astype(np.uint8), "reintegrated": reint,
              "NormalX": feats["NormalX"], "NormalY": feats["NormalY"],
              "NormalZ": feats["NormalZ"], "SurfaceVariation": sv, **extra}
    params = {"k": feats.k, "radius": feats.radius, "grow_k": grow_k, "min_points": min_points,
              "seeds": seeds.value, "min_angle": min_angle, "alpha": classes.alpha,
              "boundary_alpha": classes.boundary_alpha, "noise": classes.meta.get("noise"),
              "sigma_estimated": classes.sigma_estimated}
    return Segmentation(labels=labels, table=table, lines=lines_out, fields=fields,
                        method="covariance", params=params)
