"""Direct segmentation along ridges: surface units are the regions that creases and ridge
lines separate (:func:`ridge_segments`, on the output of :func:`lidarstat.segment.ridges`)."""

from __future__ import annotations

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import FitStatus
from ..io import register_field_descriptions
from ..neighbors import check_copies, knn_neighbors
from ..stats import z_critical
from . import _ridge_kernels as _rk
from ._grow import components
from ._result import Polylines, Segmentation, segment_table
from ._ridge_creases import CREASE
from ._ridges import RidgeResult

#: Per-point fields of :func:`ridge_segments` beside ``segment_id``.
SEGMENT_FIELDS = {
    "ridge": ("uint8", "0 none, 1 crest, 2 ravine, 3 crease (points of ridges())"),
    "crease": ("uint8", "0 none, 1 convex, 2 concave: on the boundary between two units"),
    "barrier": ("uint8", "1 ridge band or jet rejected by the chi-square test"),
}
register_field_descriptions(SEGMENT_FIELDS)


@renamed_parameters(min_size="min_points", k="grow_k")
def ridge_segments(points, ridge_result: RidgeResult, *, grow_k=8, width=None, min_points=50,
                   extend=None):
    """Direct segmentation: surface units are the regions that creases and ridges separate.

    1. **Barrier.** Crest, ravine and crease points, the points within `width` of a crest
       or ravine line (sampled every width/4) or of its straight extensions beyond both ends (along the end tangent, up
       to `extend`, as long as the cloud has a point within `width`: the detector fails
       within about a jet radius of a border or of another crease, where lines stop short
       of face corners), and every point whose degree-4 jet the
       chi-square test of the variance factor rejects (points with too few neighbours for
       a jet are no evidence either way and are not barriers): a crease (a C0
       discontinuity) inside a neighbourhood is exactly what a smooth jet cannot fit, so
       the rejections form a band about one jet radius wide on each side of every crease,
       and they close the gaps where the ridge lines stop (weak k'', thinly sampled faces,
       line ends at silhouettes).
    2. **Units.** Connected components of the other points over the `grow_k`-nearest-neighbour
       graph (:func:`lidarstat.segment.components`), smaller than `min_points` dropped. An
       edge is used only when each end lies on the other's fitted jet
       within the noise (``|residual| <= sqrt(2) z_{alpha/2} sigma``, sigma the jets'
       noise): growth stays within a curvature-consistent band, and a crease that the
       chi-square test missed (a face corner where the neighbourhood is one-sided, a
       weak fold) still cuts the graph.
    3. **Assignment**: each barrier point joins the unit whose jet explains it
       best: among the (up to 24) nearest unit points within the jet radius, each unit
       scores the median, over its five nearest, of the height of the point above their
       fitted degree-4 Monge surfaces, and the smallest score wins (the point lies on the
       surface that continues smoothly through it, not on the one across a crease).
       Points of the ridge band (crest and ravine points and those within `width` of
       their lines, where the surface may be smooth and both sides' jets fit) join the
       unit of their nearest unit point instead; crease points, where it is not smooth,
       are assigned by the jets.
    4. **Creases.** Points with one of their `grow_k` neighbours in another unit within 1.5
       `width` lie on the boundary between two units: ``crease`` 1 where the crease is convex, 2 concave (the
       unit normals open away from, or toward, each other across it).

    Parameters
    ----------
    points : (N, 3) array_like
    ridge_result : RidgeResult
        From :func:`ridges` on the same points.
    grow_k : int
        Neighbours of the growing graph.
    width : float, optional
        Half-width of the band around ridge lines and largest crease-pair distance; default
        the median distance to the `grow_k`-th neighbour (so that no edge jumps over the band).
    min_points : int
        Smaller units get 0 (their points are then assigned like barrier points).
    extend : float, optional
        Longest extension of the ridge lines at their ends; default the jet radius (0: none).

    Returns
    -------
    lidarstat.segment.Segmentation
        ``segment_id`` plus the per-point ``ridge``, ``crease`` and ``barrier`` fields
        (:data:`SEGMENT_FIELDS`); lines = the ridge lines.
    """
    from scipy.spatial import cKDTree

    func = "ridge_segments"
    pts = check_points(points)
    check_copies(pts, what=func)  # neighbors/_duplicates.py
    grow_k = check_scalar(grow_k, "grow_k", func=func, low=2, closed="left", integer=True)
    min_points = check_scalar(min_points, "min_points", func=func, low=1, closed="left",
                              integer=True)
    n = pts.shape[0]
    if len(ridge_result.fields["ridge"]) != n:
        raise InvalidParameterError(f"{func}: `ridge_result` has "
                                    f"{len(ridge_result.fields['ridge'])} points, `points` {n}")
    origin = pts.mean(axis=0)
    local = pts - origin
    nb = knn_neighbors(local, min(grow_k, n))
    if width is None:
        width = float(np.median(nb.distances[nb.indptr[1:] - 1]))
    width = check_scalar(width, "width", func=func, low=0.0)
    lines = ridge_result.lines
    ridge = ridge_result.fields["ridge"]
    ridge_band = (ridge == 1) | (ridge == 2)
    crease_points = ridge == CREASE  # a barrier, assigned by the jets like rejected ones
    if extend is None:
        extend = ridge_result.params.get("radius")
        if extend is None:
            extend = float(np.nanmedian(ridge_result.jets.fit.bandwidth))
    extend = check_scalar(extend, "extend", func=func, low=0.0, closed="left")
    smooth_lines = lines.attributes["ridge"] != CREASE if len(lines) else np.zeros(0, bool)
    if smooth_lines.any():
        sampled = Polylines([v for v, s in zip(lines.vertices, smooth_lines) if s]).sample(
            width / 4.0)[0]
        tree = cKDTree(local)
        ext = [_extend_ends(v - origin, tree, width, extend)
               for v, s in zip(lines.vertices, smooth_lines) if s]
        sampled = np.vstack([sampled - origin] + [e for e in ext if len(e)])
        dist, _ = cKDTree(sampled).query(local, k=1)
        ridge_band |= dist < width
    # rejected jets are barriers; unfitted points (too few neighbours) are no evidence
    band = ridge_band | crease_points | (ridge_result.fields["status"] ==
                                         FitStatus.MODEL_REJECTED)
    fit = ridge_result.jets.fit
    monge = np.ascontiguousarray(fit.monge)
    frames = np.ascontiguousarray(fit.frame)
    offset = np.nan_to_num(fit.offset)
    # growth only along edges where each end lies on the other's jet (within the noise,
    # two-sided z at alpha): creases the chi-square test missed cut the graph
    tol = z_critical(ridge_result.params["alpha"]) * ridge_result.jets.sigma
    edge_ok = np.empty(nb.indices.size, np.bool_)
    _rk.jet_consistent_edges(local, nb.indptr, nb.indices, monge, frames, offset,
                             np.sqrt(2.0) * tol, edge_ok)
    labels = components(nb, edge_ok=edge_ok, mask=~band, min_points=min_points)
    labels = _assign_by_jets(local, labels, ~ridge_band, fit, ridge_result)
    # the ridge band (a line, smooth or not) is split by the nearest unit point
    todo = np.flatnonzero(labels == 0)
    done = np.flatnonzero(labels > 0)
    if todo.size and done.size:
        d, j = cKDTree(local[done]).query(local[todo], k=1, distance_upper_bound=4 * width)
        hit = np.isfinite(d)
        labels[todo[hit]] = labels[done[j[hit]]]
    crease = np.zeros(n, np.uint8)
    normals = np.ascontiguousarray(fit.frame[:, 2, :])
    _rk.unit_boundaries(local, nb.indptr, nb.indices, nb.distances, labels, normals,
                        1.5 * float(width), crease)
    return Segmentation(labels=labels, table=segment_table(labels, pts), lines=lines,
                        fields={"ridge": ridge, "crease": crease,
                                "barrier": band.astype(np.uint8)},
                        method="ridges",
                        params={**ridge_result.params, "grow_k": grow_k, "width": width,
                                "min_points": min_points, "extend": extend})


def _extend_ends(v, tree, width, extend):
    """Points every width/4 along the straight extensions of polyline `v` beyond both ends
    (end tangent over the last ~2 widths), up to `extend`, while the cloud (`tree`) has a
    point within `width`."""
    if extend <= 0 or len(v) < 2:
        return np.empty((0, 3))
    out = []
    steps = np.arange(1, int(extend / (width / 4.0)) + 1) * (width / 4.0)
    for end, inner in ((v[-1], v[:-1][::-1]), (v[0], v[1:])):
        d = np.linalg.norm(inner - end, axis=1)
        back = inner[min(int(np.searchsorted(d, 2.0 * width)), len(inner) - 1)]
        t = end - back
        nt = np.linalg.norm(t)
        if not nt > 0:
            continue
        cand = end + steps[:, None] * (t / nt)
        near, _ = tree.query(cand, k=1, distance_upper_bound=width)
        stop = np.flatnonzero(~np.isfinite(near))
        out.append(cand[: stop[0] if stop.size else len(cand)])
    return np.vstack(out) if out else np.empty((0, 3))


def _assign_by_jets(local, labels, allowed, fit, ridge_result, n_candidates=24, per_unit=5):
    """Unlabelled `allowed` points join the unit whose nearby jets fit them best."""
    from scipy.spatial import cKDTree

    done = np.flatnonzero(labels > 0)
    todo = np.flatnonzero((labels == 0) & allowed)
    if done.size == 0 or todo.size == 0:
        return labels
    ok = np.isin(ridge_result.jets["status"], (FitStatus.OK, FitStatus.MODEL_REJECTED))
    radius = ridge_result.params.get("radius")
    if radius is None:
        radius = float(np.nanmax(fit.bandwidth[ok])) if ok.any() else 0.0
    src = done[ok[done]]  # unit points with a jet
    if src.size == 0:
        return labels
    kk = min(n_candidates, src.size)
    dist, j = cKDTree(local[src]).query(local[todo], k=kk, distance_upper_bound=radius)
    dist = dist.reshape(todo.size, kk)
    j = j.reshape(todo.size, kk)
    cand = np.where(np.isfinite(dist), src[np.minimum(j, src.size - 1)], -1).astype(np.int64)
    out = np.zeros(todo.size, np.int32)
    _rk.assign_by_jets(local, todo.astype(np.int64), cand, labels,
                       np.ascontiguousarray(fit.monge), np.ascontiguousarray(fit.frame),
                       np.nan_to_num(fit.offset), per_unit, out)
    labels = labels.copy()
    labels[todo] = out
    return labels
