"""Ridges of point clouds from fourth-order jets, ridge lines, and the direct segmentation."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats as _st

from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import JET_FIELDS, MONGE_NAMES, FitStatus, jets
from ..io import register_field_descriptions
from ..neighbors import (
    check_copies,
    find_duplicates,
    knn_neighbors,
    map_rows,
    run_on_unique,
)
from . import _ridge_kernels as _rk
from ._grow import components
from ._result import Polylines, Segmentation, segment_table

#: Per-point fields added by :func:`ridges` to those of :func:`lidarstat.features.jets`.
RIDGE_FIELDS = {
    "ridge": ("uint8", "0 none, 1 crest (convex), 2 ravine (concave)"),
    "ridge_line": ("int32", "id of the ridge line (0 none)"),
    "umbilic": ("uint8", "1 where k1 - k2 is not significant"),
    "extremality": ("float64", "derivative of the dominant k along its line"),
}
register_field_descriptions(RIDGE_FIELDS)
#: Attributes of each ridge line.
LINE_ATTRIBUTES = ("line_id", "ridge", "n_vertices", "n_points", "length", "strength",
                   "sharpness", "mean_k", "position_sd", "k_z")


@dataclass(frozen=True)
class RidgeResult:
    """Per-point Monge coefficients and ridge labels, and the traced ridge lines.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        The fields of :func:`lidarstat.features.jets` plus ``ridge``, ``ridge_line``,
        ``umbilic``, ``extremality`` (input order).
    lines : lidarstat.segment.Polylines
        Ridge lines; vertices are interpolated zero crossings of the extremality;
        attributes ``line_id``, ``ridge`` (1 crest, 2 ravine), ``n_vertices``, ``n_points``
        (points absorbed), ``length``, ``strength`` (integral of |k| ds), ``sharpness``
        (integral of |k''| ds, k'' the second derivative of k along its line),
        ``mean_k`` and ``position_sd`` (median over vertices of sd(e)/|k''|: the standard
        deviation of a crossing's position across the line), ``k_z`` (median over the
        vertices of |k| / sd(k)).
    jets : lidarstat.features.JetResult
    params : dict
    """

    fields: dict
    lines: Polylines
    jets: object
    params: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    def to_fields(self):
        """Per-point arrays with their file dtypes."""
        spec = {**JET_FIELDS, **RIDGE_FIELDS}
        return {k: np.asarray(v, dtype=spec[k][0]) for k, v in self.fields.items()}

    def summary(self) -> str:
        r = self.fields["ridge"]
        n = r.size
        lines = [f"{n} points, jets of degree {self.params.get('degree')}, sigma "
                 f"{self.jets.sigma:.6g}" + (" (estimated)" if self.jets.sigma_estimated else ""),
                 f"  crest points  {int((r == 1).sum()):>9d}",
                 f"  ravine points {int((r == 2).sum()):>9d}",
                 f"  umbilic       {int(self.fields['umbilic'].sum()):>9d}",
                 f"  ridge lines   {len(self.lines):>9d}"]
        if len(self.lines):
            a = self.lines.attributes
            lines.append(f"    crests {int((a['ridge'] == 1).sum())}, ravines "
                         f"{int((a['ridge'] == 2).sum())}, total length "
                         f"{float(a['length'].sum()):.6g}")
        return "\n".join(lines)


def _sd_matrix(fields, n):
    sd = np.full((n, 11), np.nan)
    for j, name in enumerate(MONGE_NAMES):
        if f"{name}_sd" in fields:
            sd[:, j] = fields[f"{name}_sd"]
    return sd


def ridges(points, *, radius=None, k=None, sigma=None, alpha=0.01, weight="tricube",
           sensor=None, noise=None, ratio=2.0, cross_k=16, min_length=None, min_vertices=3,
           smooth=5, jet_result=None, progress=None) -> RidgeResult:
    """Crest and ravine points and lines from the fourth-order Monge form of every point.

    Steps (docs/methods/jets.md): jets of degree 4 (:func:`lidarstat.features.jets`);
    candidates where one principal curvature is significant (z test at `alpha`) and
    dominates the other (|k| > `ratio` |k_other|): convex k2 < 0 for crests, concave
    k1 > 0 for ravines; zero crossings of the extremality (b3 along d2, b0 along d1)
    between neighbours lying along the direction, with the directions oriented
    consistently, and a significant second derivative k'' of the right sign from the
    fourth-order terms (a maximum of |k|); points nearer the crossing are ridge points;
    tracing chains them into lines, joins pieces across small aligned gaps, and keeps
    lines at least `min_length` long whose median |k|/sd(k) passes a Bonferroni test at
    level `alpha` over the cloud's independent neighbourhoods (N / median neighbours).

    Parameters
    ----------
    points : (N, 3) array_like
    radius, k : float, int
        Jet neighbourhood (exactly one), as :func:`lidarstat.features.jets`.
    sigma : float, optional
        Measurement noise std (estimated when omitted).
    alpha : float
        Level of the curvature and k'' tests (one-sided).
    weight, sensor, noise
        As :func:`lidarstat.features.jets`.
    ratio : float
        Dominance of the ridge's curvature over the other (>= 1).
    cross_k : int
        Neighbours examined for crossings and tracing.
    min_length : float, optional
        Lines shorter than this are dropped with their points. Default: twice the jet
        radius (for `k`, twice the median distance to the k-th neighbour): neighbouring
        jets share most of their points, so noise makes correlated patches about one
        radius wide where a test passes by chance; a line must outrun them.
    min_vertices : int
        Lines with fewer vertices are dropped too.
    smooth : int
        Line vertices are the moving average over this many consecutive crossings (the
        crossings scatter across the line by ``position_sd``; 1 keeps them raw).
    jet_result : JetResult, optional
        Reuse jets already computed on `points`.
    progress : callable, optional

    Returns
    -------
    RidgeResult
    """
    func = "ridges"
    pts = check_points(points)
    ratio = check_scalar(ratio, "ratio", func=func, low=1.0, closed="left")
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    cross_k = check_scalar(cross_k, "cross_k", func=func, low=3, closed="left", integer=True)
    min_vertices = check_scalar(min_vertices, "min_vertices", func=func, low=1, closed="left",
                                integer=True)
    smooth = check_scalar(smooth, "smooth", func=func, low=1, closed="left", integer=True)
    dup = find_duplicates(pts)
    if dup.any:  # every location once, its result to every point at it (_duplicates)
        if jet_result is not None and len(jet_result) == pts.shape[0]:
            jet_result = map_rows(jet_result, pts.shape[0], dup.first)
        res = run_on_unique(dup, lambda: ridges(
            pts[dup.first], radius=radius, k=k, sigma=sigma, alpha=alpha, weight=weight,
            sensor=sensor, noise=noise, ratio=ratio, cross_k=cross_k, min_length=min_length,
            min_vertices=min_vertices, smooth=smooth, jet_result=jet_result,
            progress=progress), what=func)
        return replace(res, fields=map_rows(res.fields, dup.n_unique, dup.inverse),
                       jets=map_rows(res.jets, dup.n_unique, dup.inverse))
    if jet_result is None:
        jet_result = jets(pts, radius=radius, k=k, sigma=sigma, alpha=alpha, degree=4,
                          weight=weight, sensor=sensor, noise=noise, progress=progress)
    elif len(jet_result) != pts.shape[0] or jet_result.fit.monge_degree != 4:
        raise InvalidParameterError(f"{func}: `jet_result` has {len(jet_result)} points, "
                                    f"`points` {pts.shape[0]}, or is not of Monge degree 4")
    fit = jet_result.fit
    n = pts.shape[0]
    fitted = np.isin(jet_result["status"], (FitStatus.OK, FitStatus.MODEL_REJECTED))
    z1 = float(_st.norm.isf(alpha))
    zk = float(_st.norm.isf(alpha / 2))  # k1 and k2 both looked at: Bonferroni
    sd = _sd_matrix(jet_result.fields, n)
    monge = np.ascontiguousarray(fit.monge)
    ctype = np.zeros(n, np.uint8)
    cval = np.empty((n, 12))
    _rk.candidates(monge, np.nan_to_num(sd, nan=np.inf), np.ascontiguousarray(fit.frame),
                   fitted, ratio, zk, ctype, cval)
    origin = pts.mean(axis=0)
    local = pts - origin
    nb = knn_neighbors(local, min(cross_k, n))
    ridge = np.zeros(n, np.uint8)
    where = np.zeros((n, 3))
    count = np.zeros(n, np.int64)
    cos_max = np.cos(np.radians(45.0))
    _rk.crossings(local, nb.indptr, nb.indices, ctype, cval, z1, cos_max, ridge, where, count)
    # tracing over the same neighbourhoods; step: median distance to the farthest of them
    step = float(np.median(nb.distances[nb.indptr[1:] - 1])) if n else 0.0
    kabs = np.abs(cval[:, 0])
    order = np.argsort(-np.where(ridge > 0, kabs, -1.0), kind="stable").astype(np.int64)
    order = order[: int((ridge > 0).sum())]
    line_of = np.zeros(n, np.int64)
    out_pts = np.zeros(n, np.int64)
    out_start = np.zeros(n + 1, np.int64)
    tangent = np.ascontiguousarray(np.nan_to_num(cval[:, 7:10]))
    vert = np.where(count[:, None] > 0, where, local)
    nl = _rk.trace(nb.indptr, nb.indices, ridge, vert, tangent, step * 1.0001,
                   np.cos(np.radians(50.0)), order, line_of, out_pts, out_start)
    if min_length is None:
        scale = radius if radius is not None else float(np.median(fit.bandwidth[fitted]))
        min_length = 2.0 * float(scale)
    min_length = check_scalar(min_length, "min_length", func=func, low=0.0, closed="left")
    # line test: the curvature along the line significant at family-wise level alpha over
    # the cloud's ~N / median(neighbours) independent neighbourhoods (Bonferroni)
    n_eff = max(1.0, n / max(1.0, float(np.median(fit.neighbors[fitted])) if fitted.any()
                             else 1.0))
    z_line = float(_st.norm.isf(alpha / (2.0 * n_eff)))
    lines, new_id = _build_lines(nl, out_pts, out_start, line_of, vert + origin, ridge, cval,
                                 min_vertices, smooth, min_length, 4.0 * step, z_line)
    line_of = new_id[line_of]
    ridge[line_of == 0] = 0
    ridge_line = line_of.astype(np.int32)
    with np.errstate(invalid="ignore"):
        z2 = float(_st.norm.isf(alpha / 2))
        gap_sd = np.sqrt(sd[:, 0] ** 2 + sd[:, 1] ** 2)
        umbilic = fitted & ((jet_result["k1"] - jet_result["k2"]) <= z2 * gap_sd)
    fields = dict(jet_result.fields)
    fields.update(ridge=ridge, ridge_line=ridge_line, umbilic=umbilic.astype(np.uint8),
                  extremality=cval[:, 1])
    params = dict(radius=radius, k=k, alpha=alpha, degree=4, z_line=z_line, weight=weight, ratio=ratio,
                  cross_k=cross_k, min_length=min_length, min_vertices=min_vertices,
                  smooth=smooth, step=step)
    return RidgeResult(fields=fields, lines=lines, jets=jet_result, params=params)


def _smooth(v, w):
    """Moving average of polyline vertices over `w` vertices (shrinking at the ends)."""
    if w <= 1 or len(v) < 3:
        return v
    h = w // 2
    c = np.vstack([np.zeros((1, 3)), np.cumsum(v, axis=0)])
    i = np.arange(len(v))
    lo = np.maximum(i - np.minimum(h, np.minimum(i, len(v) - 1 - i)), 0)
    hi = np.minimum(i + (i - lo), len(v) - 1) + 1
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def _join_lines(chains, vert, ridge, join):
    """Greedily join chains of the same type whose ends are within `join` and aligned.

    Tracing stops at gaps of a few points where a test failed by chance; two pieces are
    joined when the gap vector continues both end directions (cosines above 0.7). Runs
    once per pair of lines, not per point. Returns the joined chains and, per input chain,
    the index of the chain it ended in.
    """
    chains = [c for c in chains]
    owner = list(range(len(chains)))
    alive = [len(c) >= 2 for c in chains]

    def end(c, first):
        a, b = (c[0], c[1]) if first else (c[-1], c[-2])
        t = vert[a] - vert[b]
        n = np.linalg.norm(t)
        return vert[a], (t / n if n > 0 else t)

    merged = True
    while merged:
        merged = False
        for i in range(len(chains)):
            if not alive[i]:
                continue
            for j in range(i + 1, len(chains)):
                if not alive[j] or ridge[chains[i][0]] != ridge[chains[j][0]]:
                    continue
                for fi in (False, True):
                    for fj in (True, False):
                        pi, ti = end(chains[i], fi)
                        pj, tj = end(chains[j], fj)
                        gap = pj - pi
                        d = np.linalg.norm(gap)
                        if not 0 < d <= join:
                            continue
                        g = gap / d
                        if g @ ti > 0.7 and -(g @ tj) > 0.7:
                            ci = chains[i][::-1] if fi else chains[i]
                            cj = chains[j] if fj else chains[j][::-1]
                            chains[i] = np.concatenate([ci, cj])
                            alive[j] = False
                            owner = [i if o == j else o for o in owner]
                            merged = True
                            break
                    if not alive[j]:
                        break
    return chains, alive, owner


def _build_lines(nl, out_pts, out_start, line_of, vert, ridge, cval, min_vertices, smooth,
                 min_length, join, z_line):
    members = np.bincount(line_of, minlength=nl + 1)[1:]
    chains = [out_pts[out_start[li]:out_start[li + 1]] for li in range(nl)]
    chains, alive, owner = _join_lines(chains, vert, ridge, join)
    verts, attrs = [], {name: [] for name in LINE_ATTRIBUTES}
    new_id = np.zeros(nl + 1, np.int64)
    final = {}
    for li in range(nl):  # one iteration per line, not per point
        if not alive[li]:
            continue
        ids = chains[li]
        if ids.size < min_vertices:
            continue
        v = _smooth(vert[ids], smooth)
        seg = np.linalg.norm(np.diff(v, axis=0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            kz = float(np.median(np.abs(cval[ids, 0]) / cval[ids, 11]))
        if seg.sum() < min_length or not kz > z_line:
            continue
        final[li] = len(verts) + 1
        kk = np.abs(cval[ids, 0])
        kpp = np.abs(cval[ids, 2])
        mid = lambda a: 0.5 * (a[1:] + a[:-1])  # noqa: E731
        verts.append(v)
        attrs["line_id"].append(final[li])
        attrs["ridge"].append(int(ridge[ids[0]]))
        attrs["n_vertices"].append(ids.size)
        attrs["n_points"].append(int(sum(members[k] for k in range(nl) if owner[k] == li)))
        attrs["length"].append(float(seg.sum()))
        attrs["strength"].append(float((mid(kk) * seg).sum()))
        attrs["sharpness"].append(float((mid(np.nan_to_num(kpp)) * seg).sum()))
        attrs["mean_k"].append(float(np.mean(cval[ids, 0])))
        with np.errstate(divide="ignore", invalid="ignore"):
            attrs["position_sd"].append(float(np.median(cval[ids, 10] / np.abs(cval[ids, 2]))))
        attrs["k_z"].append(kz)
    for k in range(nl):
        new_id[k + 1] = final.get(owner[k], 0)
    dtypes = dict(line_id=np.int32, ridge=np.uint8, n_vertices=np.int32, n_points=np.int32)
    attributes = {k: np.asarray(v, dtype=dtypes.get(k, np.float64)) for k, v in attrs.items()}
    return Polylines(verts, attributes), new_id


#: Per-point fields of :func:`ridge_segments` beside ``segment_id``.
SEGMENT_FIELDS = {
    "ridge": ("uint8", "0 none, 1 crest, 2 ravine (ridge points of ridges())"),
    "crease": ("uint8", "0 none, 1 convex, 2 concave: on the boundary between two units"),
    "barrier": ("uint8", "1 ridge band or jet rejected by the chi-square test"),
}
register_field_descriptions(SEGMENT_FIELDS)


def ridge_segments(points, ridge_result: RidgeResult, *, k=8, width=None, min_size=50,
                   extend=None, chi2_barrier=True, consistent=True, assign=True):
    """Direct segmentation: surface units are the regions that creases and ridges separate.

    1. **Barrier.** Ridge points, the points within `width` of a ridge line (sampled every
       width/4) or of its straight extensions beyond both ends (along the end tangent, up
       to `extend`, as long as the cloud has a point within `width`: the detector fails
       within about a jet radius of a border or of another crease, where lines stop short
       of face corners), and, with `chi2_barrier`, every point whose degree-4 jet the
       chi-square test of the variance factor rejects (points with too few neighbours for
       a jet are no evidence either way and are not barriers): a crease (a C0
       discontinuity) inside a neighbourhood is exactly what a smooth jet cannot fit, so
       the rejections form a band about one jet radius wide on each side of every crease,
       and they close the gaps where the ridge lines stop (weak k'', thinly sampled faces,
       line ends at silhouettes).
    2. **Units.** Connected components of the other points over the k-nearest-neighbour
       graph (:func:`lidarstat.segment.components`), smaller than `min_size` dropped. With
       `consistent`, an edge is used only when each end lies on the other's fitted jet
       within the noise (``|residual| <= sqrt(2) z_{alpha/2} sigma``, sigma the jets'
       noise): growth stays within a curvature-consistent band, and a crease that the
       chi-square test missed (a face corner where the neighbourhood is one-sided, a
       weak fold) still cuts the graph.
    3. **Assignment** (`assign`): each barrier point joins the unit whose jet explains it
       best: among the (up to 24) nearest unit points within the jet radius, each unit
       scores the median, over its five nearest, of the height of the point above their
       fitted degree-4 Monge surfaces, and the smallest score wins (the point lies on the
       surface that continues smoothly through it, not on the one across a crease).
       Points of the ridge band (within `width` of a ridge line, where the surface may be
       smooth and both sides' jets fit) join the unit of their nearest unit point
       instead. Without `assign`, barrier points keep 0.
    4. **Creases.** Points with one of their `k` neighbours in another unit within 1.5
       `width` lie on the boundary between two units: ``crease`` 1 where the crease is convex, 2 concave (the
       unit normals open away from, or toward, each other across it).

    Parameters
    ----------
    points : (N, 3) array_like
    ridge_result : RidgeResult
        From :func:`ridges` on the same points.
    k : int
        Neighbours of the growing graph.
    width : float, optional
        Half-width of the band around ridge lines and largest crease-pair distance; default
        the median distance to the k-th neighbour (so that no edge jumps over the band).
    min_size : int
        Smaller units get 0 (their points are then assigned like barrier points).
    extend : float, optional
        Longest extension of the ridge lines at their ends; default the jet radius (0: none).
    chi2_barrier : bool
        Jets rejected by the chi-square test are barriers (default; False, with
        ``consistent=False`` and ``assign=False``, reproduces the ridge-only barrier).
    consistent : bool
        Grow only along jet-consistent edges (default).
    assign : bool
        Assign barrier points to units by their jets (default); False leaves them 0.

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
    k = check_scalar(k, "k", func=func, low=2, closed="left", integer=True)
    min_size = check_scalar(min_size, "min_size", func=func, low=1, closed="left", integer=True)
    n = pts.shape[0]
    if len(ridge_result.fields["ridge"]) != n:
        raise InvalidParameterError(f"{func}: `ridge_result` has "
                                    f"{len(ridge_result.fields['ridge'])} points, `points` {n}")
    origin = pts.mean(axis=0)
    local = pts - origin
    nb = knn_neighbors(local, min(k, n))
    if width is None:
        width = float(np.median(nb.distances[nb.indptr[1:] - 1]))
    width = check_scalar(width, "width", func=func, low=0.0)
    lines = ridge_result.lines
    ridge = ridge_result.fields["ridge"]
    ridge_band = ridge > 0
    if extend is None:
        extend = ridge_result.params.get("radius")
        if extend is None:
            extend = float(np.median(ridge_result.jets.fit.bandwidth))
    extend = check_scalar(extend, "extend", func=func, low=0.0, closed="left")
    if len(lines):
        sampled, _ = lines.sample(width / 4.0)
        tree = cKDTree(local)
        ext = [_extend_ends(v - origin, tree, width, extend) for v in lines.vertices]
        sampled = np.vstack([sampled - origin] + [e for e in ext if len(e)])
        dist, _ = cKDTree(sampled).query(local, k=1)
        ridge_band |= dist < width
    band = ridge_band.copy()
    if chi2_barrier:  # rejected jets; unfitted points (too few neighbours) are no evidence
        band |= ridge_result.fields["status"] == FitStatus.MODEL_REJECTED
    fit = ridge_result.jets.fit
    monge = np.ascontiguousarray(fit.monge)
    frames = np.ascontiguousarray(fit.frame)
    offset = np.nan_to_num(fit.offset)
    edge_ok = None
    if consistent:
        # growth only along edges where each end lies on the other's jet (within the
        # noise, two-sided z at alpha): creases the chi-square test missed cut the graph
        tol = float(_st.norm.isf(ridge_result.params["alpha"] / 2)) * ridge_result.jets.sigma
        edge_ok = np.empty(nb.indices.size, np.bool_)
        _rk.jet_consistent_edges(local, nb.indptr, nb.indices, monge, frames, offset,
                                 np.sqrt(2.0) * tol, edge_ok)
    labels = components(nb, edge_ok=edge_ok, mask=~band, min_size=min_size)
    if assign:
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
                        params={**ridge_result.params, "grow_k": k, "width": width,
                                "min_size": min_size, "chi2_barrier": bool(chi2_barrier),
                                "consistent": bool(consistent), "extend": extend,
                                "assign": bool(assign)})


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
