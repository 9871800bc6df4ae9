"""Surface units from the tested HK classes (seed 000, "Analytical parametric modelling").

Raw clusters: region growing among points of the same HK surface type whose quadric was
accepted, through neighbours whose normals agree within `max_angle` (the paper compares
``Z0_i - Z_i`` and K, H within a threshold; the chi-square acceptance and the common,
*tested* type play that role here, the normal angle stops growth across a crease between
two units of the same type). Optionally each raw cluster is refined by SAR-FS with the
polynomial order implied by its type (planar: 1; cylinders and other quadrics: 2), and
adjacent fitted surfaces are intersected into break lines. The points without a tested
class (next to a crease every neighbourhood straddles two faces) join the touching unit
whose plane or cylinder, fitted to the whole unit, they fit (:mod:`._model_growth`).
"""

from __future__ import annotations

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared.validation import check_points, check_scalar
from ..features import SurfaceType
from ..neighbors import check_copies, knn_neighbors, radius_neighbors
from . import _unit_merge_kernels as _mk
from ._grow import relabel
from ._model_growth import UnitModels, grow_by_models
from ._result import Segmentation, segment_table

#: Smallest planar unit whose merges are tested (a plane test needs degrees of freedom).
MERGE_MIN_POINTS = 10
#: Smallest curved unit whose merges are tested (a quadric has 9 free parameters).
QUADRIC_MIN_POINTS = 30
#: Rounds of model fit and growth of the units (:mod:`._model_growth`).
GROWTH_ROUNDS = 3
#: Nearest neighbours added to the growth graph (beside the points within its radius).
GROWTH_K = 8


@renamed_parameters(min_size="min_points")
def curvature_units(points, curv, *, grow_radius, max_angle=10.0, min_points=30,
                    merge_alpha=0.001, sensor=None):
    """Raw clusters of one HK type with agreeing normals, merged only where the union
    passes the model test.

    Region growing is a union-find over the accepted edges of the growth graph, the most
    similar normals first. The union of two units is refused when each passes its model
    test and their union fails it, at `merge_alpha`:

    * planar units of at least :data:`MERGE_MIN_POINTS` points each: the
      orthogonal-regression residual sum of squares over its expectation,
      ``lambda_min / (sigma^2 mean_i (d_i . n)^2)``, against chi2(n - 3) (``d_i`` the
      noise direction of the curvature run);
    * curved units (every other HK type; a cylinder is a quadric) of at least
      :data:`QUADRIC_MIN_POINTS` points each: the Taubin quadric fitted from the units'
      moments up to degree 4, ``sum f^2 / (sigma^2 mean_i (d_i . grad f)^2)`` against
      chi2(n - 9) (:mod:`._quadric_merge_kernels`); a merge test costs O(1).

    Two faces meeting at a crease flatter than `max_angle` thus stay two units. The
    growth graph joins the points within `grow_radius` and each point's
    :data:`GROWTH_K` nearest neighbours. The points no tested class reached (the bands
    along the creases, narrow faces) then join the touching unit whose plane or cylinder
    they fit (:mod:`._model_growth`).

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    curv : CurvatureResult
        Output of :func:`lidarstat.features.curvature` for `points`.
    grow_radius : float
        Radius (3-D) of the growth graph.
    max_angle : float
        Largest angle between the normals of two neighbours, degrees.
    min_points : int
        Smallest cluster kept.
    merge_alpha : float
        Level of the plane and quadric tests of a merge.
    sensor : (3,) array_like, optional
        Scanner position, for range noise.

    Returns
    -------
    labels : (N,) ndarray of int32
        Clusters 1..C by decreasing size, 0 none.
    types : (C,) ndarray of uint8
        HK type of each cluster.
    """
    return _units(points, curv, grow_radius=grow_radius, max_angle=max_angle,
                  min_points=min_points, merge_alpha=merge_alpha, sensor=sensor)[:2]


def _units(points, curv, *, grow_radius, max_angle, min_points, merge_alpha, sensor):
    """Labels, types and the numbers of refused merges (planar, curved) of
    :func:`curvature_units`."""
    from ..features import noise_directions
    from ..stats import chi2_critical

    pts = np.asarray(points, dtype=np.float64)
    f = curv.fields
    st = np.asarray(f["surface_type"])
    ok = (st > 0) & (np.asarray(f["chi2_pass"]) > 0)
    nrm = np.c_[f["NormalX"], f["NormalY"], f["NormalZ"]]
    src, dst = _growth_edges(pts, grow_radius)
    e_src, e_dst = _similar_edges(src, dst, ok, st, nrm, np.cos(np.radians(max_angle)))
    local = pts - pts.mean(axis=0)
    noise = str(getattr(curv, "noise", "z"))
    if noise == "range" and sensor is None:
        noise = "normal"
    dirs = noise_directions(noise, pts.shape[0], points=pts, sensor=sensor)
    noise_normal = dirs is None
    if noise_normal:
        dirs = np.zeros((pts.shape[0], 3))
    n_max = max(int(ok.sum()), 4)
    crit = np.asarray(chi2_critical(merge_alpha, np.arange(1, n_max + 1)), dtype=np.float64)
    crit = np.r_[np.inf, crit]  # index = degrees of freedom
    parent = np.arange(pts.shape[0], dtype=np.int64)
    refused = _mk.grow_tested(e_src, e_dst, local,
                              np.ascontiguousarray(dirs), noise_normal,
                              st == SurfaceType.PLANAR, ok & (st > SurfaceType.PLANAR),
                              float(curv.sigma) ** 2, crit, MERGE_MIN_POINTS,
                              QUADRIC_MIN_POINTS, parent)
    del e_src, e_dst
    labels = np.where(ok, parent + 1, 0)
    labels = relabel(labels, max(int(min_points), 1))
    c = int(labels.max()) if labels.size else 0
    types = np.zeros(c, dtype=np.uint8)
    if c:
        lab = labels[labels > 0]
        # the common type of each cluster (all members share it by construction)
        types[lab - 1] = st[labels > 0]
        # the points no tested class reached (the bands along the creases, the narrow
        # faces) join the touching unit whose plane or cylinder they fit
        for _ in range(GROWTH_ROUNDS):  # refit on the grown units, grow again
            models = UnitModels(pts, labels, types > SurfaceType.PLANAR, nrm,
                                float(curv.sigma), dirs=None if noise_normal else dirs,
                                sensor=sensor if noise == "range" else None)
            labels, joined = grow_by_models(pts, labels, src, dst, models)
            if not joined.any():
                break
    return labels, types, (int(refused[0]), int(refused[1]))

#: Edges per block of the normal-agreement test (bounds its temporaries: the two
#: endpoints' normals, 48 bytes an edge).
EDGE_BLOCK = 1 << 18


def _growth_edges(pts, grow_radius):
    """The growth graph as int32 edge ends (int64 past 2**31 points): the pairs within `grow_radius` (3-D), then
    each point's :data:`GROWTH_K` nearest neighbours in both directions.

    The k nearest neighbours join because a steep face of a range image, or a flat one
    seen at a grazing angle, is sampled more sparsely across the slope than the growth
    radius, and the radius graph alone leaves it in pieces. Each search's table is
    dropped once its edges are copied into the two preallocated arrays.
    """
    itype = np.int32 if pts.shape[0] < 2**31 else np.int64
    knn = knn_neighbors(pts, GROWTH_K + 1)
    k_src = np.repeat(knn.query_indices().astype(itype), knn.counts)
    k_dst = knn.indices.astype(itype)
    del knn
    nbh = radius_neighbors(pts, grow_radius, dim=3)
    m_r, m_k = nbh.indices.size, k_src.size
    src = np.empty(m_r + 2 * m_k, dtype=itype)
    dst = np.empty(m_r + 2 * m_k, dtype=itype)
    src[:m_r] = np.repeat(nbh.query_indices().astype(itype), nbh.counts)
    dst[:m_r] = nbh.indices
    del nbh
    src[m_r:m_r + m_k] = k_src
    dst[m_r + m_k:] = k_src
    del k_src
    dst[m_r:m_r + m_k] = k_dst
    src[m_r + m_k:] = k_dst
    del k_dst
    return src, dst


def _similar_edges(src, dst, ok, st, nrm, cos_min):
    """The edges between two tested points of one HK type whose normals agree within the
    angle of `cos_min`, the most similar normals first (a stable sort: equal cosines keep
    the edge order), as int64 ends (the union-find kernel's index type).

    The test runs block by block (:data:`EDGE_BLOCK` edges), so its temporaries are one
    block's; only the accepted edges' cosines are kept, in float64: the union order
    follows them, and float32 would turn distinct cosines into ties and change the order.
    """
    ks, kd, cos = [], [], []
    for a in range(0, src.size, EDGE_BLOCK):
        s, d = src[a:a + EDGE_BLOCK], dst[a:a + EDGE_BLOCK]
        c = np.abs(np.einsum("ij,ij->i", nrm[s], nrm[d]))
        good = ok[s] & ok[d] & (st[s] == st[d]) & (c >= cos_min)
        ks.append(s[good])
        kd.append(d[good])
        cos.append(c[good])
    ks, kd = (np.concatenate(x) if x else np.zeros(0, dtype=src.dtype) for x in (ks, kd))
    cos = np.concatenate(cos) if cos else np.zeros(0)
    order = np.argsort(np.negative(cos, out=cos), kind="stable")
    del cos
    ks[:] = ks[order]  # sorted in place: one int32 temporary at a time
    kd[:] = kd[order]
    del order
    e_src = ks.astype(np.int64)
    del ks
    e_dst = kd.astype(np.int64)
    return e_src, e_dst


@renamed_parameters(min_size="min_points", threshold="search")
def segment_curvature(points, *, radius=None, sigma=None, alpha=0.05, max_angle=10.0,
                      grow_radius=None, min_points=30, refine=False, search=None,
                      w_radius=None, fs_alpha=0.001, curv=None,
                      frame="pca", noise=None, sensor=None, merge_alpha=0.001):
    """Segment by tested curvature classes, optionally refined by SAR-FS (seed 000).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates; heights are z (the SAR refinement models z as a function of E, N).
    radius : float, optional
        Curvature bandwidth (3-D sphere); default the automatic scale of
        :func:`lidarstat.features.curvature` (per point).
    sigma : float, optional
        Noise; estimated when omitted.
    alpha : float
        Level of the curvature tests.
    max_angle : float
        Normal agreement for region growing, degrees.
    grow_radius : float, optional
        Growth graph radius (default radius / 2; at the automatic scale half the smallest
        radius of the ladder, 1.5 point spacings).
    min_points : int
        Smallest unit.
    refine : bool
        Refine the raw clusters by SAR-FS (polynomial order 1 for planar units, 2 for
        the others) and intersect adjacent surfaces.
    search, w_radius, fs_alpha
        Refinement settings (:func:`refine_raw_clusters`); defaults radius and radius / 2
        (at the automatic scale, the median chosen radius).
    curv : CurvatureResult, optional
        Precomputed curvature of `points`.
    frame : {'pca', 'auto', 'z'}
        Local frame of the curvature quadrics (:func:`lidarstat.features.curvature`); with
        'pca' or 'auto' walls get tested classes too. In the refinement, units more than
        70 degrees from horizontal are modelled in their own plane's frame (table column
        ``frame`` 1; see :func:`refine_cluster`).
    noise, sensor
        Direction of the noise and scanner position (:func:`lidarstat.features.curvature`).
    merge_alpha : float
        Level of the plane test (planar units) and of the quadric test (curved units)
        that refuse a merge (:func:`curvature_units`).

    Returns
    -------
    Segmentation
        Table columns ``surface_type`` and (refined) the SAR columns of
        :func:`segment_sar`; per point ``surface_type``.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.segment import segment_curvature
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 10, (3000, 2))
    >>> z = np.where(xy[:, 0] < 5, 0.0, 0.02 * (xy[:, 0] - 5) ** 2 * 10)
    >>> seg = segment_curvature(np.c_[xy, z + rng.normal(0, 0.005, 3000)], radius=1.0,
    ...                         sigma=0.005)
    >>> sorted(seg.table["surface_type"].tolist())
    [1, 3]
    """
    from ..features import curvature

    func = "segment_curvature"
    points = check_points(points, min_points=10)
    check_copies(points, what=func)  # neighbors/_duplicates.py
    if radius is not None:
        radius = check_scalar(radius, "radius", func=func, low=0.0)
    merge_alpha = check_scalar(merge_alpha, "merge_alpha", func=func, low=0.0, high=1.0)
    if curv is None:
        curv = curvature(points, radius=radius, sigma=sigma, alpha=alpha, frame=frame,
                         noise=noise, sensor=sensor)
    if radius is None:  # the scale the curvature run chose
        scales = curv.radius if isinstance(curv.radius, tuple) else (curv.radius,)
        if "radius" in curv.fields:
            radius = float(np.median(curv.fields["radius"]))
            small = float(min(scales))
        else:
            radius = small = float(max(scales) if isinstance(curv.radius, tuple) else curv.radius)
    else:
        small = radius
    max_angle = check_scalar(max_angle, "max_angle", func=func, low=0.0, high=180.0,
                             closed="right")
    min_points = check_scalar(min_points, "min_points", func=func, low=1, closed="left",
                              integer=True)
    grow_radius = (small / 2.0 if grow_radius is None else
                   check_scalar(grow_radius, "grow_radius", func=func, low=0.0))
    if search is not None:
        search = check_scalar(search, "search", func=func, low=0.0)
    if w_radius is not None:
        w_radius = check_scalar(w_radius, "w_radius", func=func, low=0.0)
    labels, types, refused = _units(points, curv, grow_radius=grow_radius,
                                    max_angle=max_angle, min_points=min_points,
                                    merge_alpha=merge_alpha, sensor=sensor)
    st = np.asarray(curv.fields["surface_type"]).astype(np.uint8)
    if not refine:
        table = segment_table(labels, points)
        table["surface_type"] = types
        return Segmentation(labels, table, None, {"surface_type": st}, "curvature",
                            {"radius": radius, "max_angle": max_angle,
                             "grow_radius": grow_radius, "alpha": alpha,
                             "min_points": min_points, "merge_alpha": merge_alpha,
                             "merges_refused": sum(refused),
                             "merges_refused_curved": refused[1], **_curvature_params(curv)})
    from ._sar_units import refine_raw_clusters

    degrees = np.where(types == 1, 1, 2)
    seg = refine_raw_clusters(points, labels,
                              search=radius if search is None else search,
                              w_radius=radius / 2.0 if w_radius is None else w_radius,
                              degrees=degrees, fs_alpha=fs_alpha,
                              min_points=min_points)
    # type of each refined unit = type of its raw cluster
    raw_of = np.array([int(np.bincount(labels[u.raw]).argmax()) for u in seg.units], dtype=int)
    seg.table["surface_type"] = types[raw_of - 1] if raw_of.size else np.zeros(0, np.uint8)
    seg.fields["surface_type"] = st
    seg.method = "curvature+sar"
    seg.params.update({"radius": radius, "max_angle": max_angle, "grow_radius": grow_radius,
                       "merge_alpha": merge_alpha, "merges_refused": sum(refused),
                             "merges_refused_curved": refused[1],
                       **_curvature_params(curv)})
    return seg


def _curvature_params(curv) -> dict:
    """What the curvature step used (its estimate of sigma included)."""
    p = getattr(curv, "params", {})
    out = {k: p[k] for k in ("sigma", "sigma_estimated", "noise", "frame", "test", "scales",
                             "radius_median") if k in p}
    if p.get("radius") == "auto":
        out["curvature_radius"] = "auto"
    return out
