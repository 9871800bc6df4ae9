"""Ridges of point clouds from fourth-order jets: crest and ravine points, ridge lines."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..features import (
    JET_FIELDS,
    MONGE_NAMES,
    FitStatus,
    JetScaleCriterion,
    Weight,
    jets,
    radius_ladder,
)
from ..io import register_field_descriptions
from ..neighbors import find_duplicates, knn_neighbors, map_rows, run_on_unique
from ..stats import z_critical
from . import _ridge_kernels as _rk
from ._result import Polylines
from ._ridge_creases import CREASE, crease_rung, find_creases
from ._ridge_lines import join_lines, smooth_vertices

#: Per-point fields added by :func:`ridges` to those of :func:`lidarstat.features.jets`.
RIDGE_FIELDS = {
    "ridge": ("uint8", ("0 none, 1 crest (convex), 2 ravine (concave), 3 crease (the centre "
                        "line of a band of rejected jets)")),
    "ridge_line": ("int32", "id of the ridge or crease line (0 none)"),
    "umbilic": ("uint8", "1 where k1 = k2 is accepted and the curvature is significant"),
    "extremality": ("float64", "derivative of the dominant k along its line"),
}
register_field_descriptions(RIDGE_FIELDS)
#: Attributes of each ridge line.
LINE_ATTRIBUTES = ("line_id", "ridge", "n_vertices", "n_points", "length", "strength",
                   "sharpness", "mean_k", "position_sd", "k_z")
#: Attributes of the crease lines' test (NaN on ridge lines).
CREASE_ATTRIBUTES = ("misfit", "misfit_p", "misfit_growth")


@dataclass(frozen=True)
class RidgeResult:
    """Per-point Monge coefficients and ridge labels, and the traced ridge lines.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        The fields of :func:`lidarstat.features.jets` plus ``ridge`` (0 none, 1 crest, 2
        ravine, 3 crease), ``ridge_line``, ``umbilic``, ``extremality`` (input order).
    lines : lidarstat.segment.Polylines
        Ridge lines, then crease lines. A ridge line's vertices are interpolated zero
        crossings of the extremality, a crease line's the moving average of its crease
        points; attributes ``line_id``, ``ridge`` (1 crest, 2 ravine, 3 crease),
        ``n_vertices``, ``n_points``
        (points absorbed), ``length``, ``strength`` (integral of |k| ds), ``sharpness``
        (integral of |k''| ds, k'' the second derivative of k along its line),
        ``mean_k`` and ``position_sd`` (median over vertices of sd(e)/|k''|: the standard
        deviation of a crossing's position across the line), ``k_z`` (median over the
        vertices of |k| / sd(k)); these are NaN on crease lines, whose test is in
        ``misfit`` (median variance factor of the jets at the crease radius, in units of
        the noise), ``misfit_p`` (median p-value of their chi-square test) and
        ``misfit_growth`` (median growth of the excess variance factor from the crease
        radius to the next rung), NaN on ridge lines.
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

    def _scale_text(self):
        p = self.params
        if p.get("scale") == "auto":
            r = self.fields["radius"]
            r = r[np.isfinite(r)]
            if not r.size:
                return "automatic"
            per = ", ".join(f"{a:.4g}: {c}" for a, c in zip(p["radii"], p["points_per_radius"])
                            if c)
            return (f"automatic, radius median {np.median(r):.4g} (points per radius: "
                    f"{per})")
        return f"radius {p['radius']:g}" if p.get("radius") is not None else f"k {p.get('k')}"

    def summary(self) -> str:
        r = self.fields["ridge"]
        n = r.size
        lines = [f"{n} points, jets of degree {self.params.get('degree')}, sigma "
                 f"{self.jets.sigma:.6g}" + (" (estimated)" if self.jets.sigma_estimated else ""),
                 "  scale: " + self._scale_text(),
                 f"  crest points  {int((r == 1).sum()):>9d}",
                 f"  ravine points {int((r == 2).sum()):>9d}",
                 f"  crease points {int((r == CREASE).sum()):>9d}"
                 + (f" (crease radius {self.params['crease_radius']:.4g})"
                    if "crease_radius" in self.params else ""),
                 f"  umbilic       {int(self.fields['umbilic'].sum()):>9d}",
                 f"  ridge lines   {len(self.lines):>9d}"]
        if len(self.lines):
            a = self.lines.attributes
            lines.append(f"    crests {int((a['ridge'] == 1).sum())}, ravines "
                         f"{int((a['ridge'] == 2).sum())}, creases "
                         f"{int((a['ridge'] == CREASE).sum())}, total length "
                         f"{float(a['length'].sum()):.6g}")
        return "\n".join(lines)


def _sd_matrix(fields, n):
    sd = np.full((n, 11), np.nan)
    for j, name in enumerate(MONGE_NAMES):
        if f"{name}_sd" in fields:
            sd[:, j] = fields[f"{name}_sd"]
    return sd


def _ridge_statistic(fit, fields):
    """``max(k2''/sd(c4), -k1''/sd(c0))`` per point (0 where the jet is not fitted)."""
    m = fit.monge
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        k1, k2 = m[:, 0], m[:, 1]
        gap = np.maximum(k1 - k2, 0.0)
        k2pp = m[:, 10] - 3.0 * k2 ** 3 - 3.0 * m[:, 4] ** 2 / gap
        k1pp = m[:, 6] - 3.0 * k1 ** 3 + 3.0 * m[:, 3] ** 2 / gap
        zc = np.nan_to_num(k2pp / fields["c4_sd"], nan=0.0, posinf=0.0, neginf=0.0)
        zr = np.nan_to_num(-k1pp / fields["c0_sd"], nan=0.0, posinf=0.0, neginf=0.0)
    return np.where(fit.status == FitStatus.OK, np.fmax(zc, zr), 0.0)


#: The automatic scale of :func:`ridges`: a ridge's k'' is significant. Per point the
#: one-sided z of the second derivative of each principal curvature along its line,
#: ``k2''/sd(c4)`` for a crest (|k2| maximal across the line: k2'' > 0) and
#: ``-k1''/sd(c0)`` for a ravine, and their maximum. Its null distribution is simulated
#: (``calibrate``), not taken as normal: the principal directions are those of the
#: fitted quadratic part, whose estimate is correlated with the quartic one (the columns
#: u^2 and u^4 are), so on a plane c4 along the direction of least curvature is pushed
#: up (median z about 0.7, upper 0.1 % quantile of the maximum about 3.6).
RIDGE_SCALE = JetScaleCriterion("k'' of a ridge", _ridge_statistic, 2, calibrate=True)


def ridges(points, *, radius=None, k=None, sigma=None, alpha=0.01, weight="tricube",
           sensor=None, noise=None, ratio=2.0, cross_k=16, min_length=None, min_vertices=3,
           smooth=5, scale_criterion=None, scales=None, jet_result=None, creases=True,
           progress=None) -> RidgeResult:
    """Crest, ravine and crease points and lines from the fourth-order Monge form of every
    point.

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
    Crease points (``_ridge_creases``): jets at the crease radius (the smallest rung of
    the ladder, from the third, over which a kink of 45 degrees rises 35 noise standard
    deviations) that
    the chi-square test rejects at that Bonferroni level, the centre line of their band
    (where the band is as deep on both sides), chained into lines like the ridge points
    and kept when at least twice that radius long and when the misfit grows with the
    radius no faster than a kink's (at most twice to the next rung; a smooth surface's
    truncation grows up to 32 times). A crest or ravine point whose jet holds a crease point is dropped:
    its k'' is the crease's, smoothed.

    Parameters
    ----------
    points : (N, 3) array_like
    radius, k : float, int
        Jet neighbourhood (at most one), as :func:`lidarstat.features.jets`. With neither,
        the automatic scale: per point the smallest radius of a ladder at which the k''
        of a ridge is significant (:data:`RIDGE_SCALE`; the radius is the
        ``radius`` field).
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
        radius (for `k`, twice the median distance to the k-th neighbour; at the
        automatic scale, twice the median radius of the line's points): neighbouring
        jets share most of their points, so noise makes correlated patches about one
        radius wide where a test passes by chance; a line must outrun them.
    min_vertices : int
        Lines with fewer vertices are dropped too.
    smooth : int
        Line vertices are the moving average over this many consecutive crossings (the
        crossings scatter across the line by ``position_sd``; 1 keeps them raw).
    scale_criterion : lidarstat.features.JetScaleCriterion, optional
        What the automatic scale must detect (without `radius` and `k`); default
        :data:`RIDGE_SCALE` (the k'' of a ridge). The direct segmentation uses
        :data:`lidarstat.features.CURVATURE_SCALE`: creases want the smallest radius
        whose jets detect a curvature, not the larger one a smooth ridge's k'' needs.
    scales : sequence of float, optional
        The automatic scale's ladder of radii (default
        :func:`lidarstat.features.radius_ladder` of `points`); see
        :func:`lidarstat.features.jets`.
    jet_result : JetResult, optional
        Reuse jets already computed on `points`.
    creases : bool
        Label crease points (code 3) and trace crease lines (docs/methods/jets.md,
        "Creases"); False leaves them out (and skips their jets).
    progress : callable, optional

    Returns
    -------
    RidgeResult
    """
    func = "ridges"
    pts = check_points(points)
    ratio = check_scalar(ratio, "ratio", func=func, low=1.0, closed="left")
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    weight = Weight.parse(weight, "weight", func=func)
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
            min_vertices=min_vertices, smooth=smooth, scale_criterion=scale_criterion,
            scales=scales, jet_result=jet_result, creases=creases,
            progress=progress), what=func)
        return replace(res, fields=map_rows(res.fields, dup.n_unique, dup.inverse),
                       jets=map_rows(res.jets, dup.n_unique, dup.inverse))
    if jet_result is None:
        crit = None
        if radius is None and k is None:
            crit = RIDGE_SCALE if scale_criterion is None else scale_criterion
        jet_result = jets(pts, radius=radius, k=k, sigma=sigma, alpha=alpha, degree=4,
                          weight=weight, sensor=sensor, noise=noise, scale_criterion=crit,
                          scales=scales, progress=progress)
    elif len(jet_result) != pts.shape[0] or jet_result.fit.monge_degree != 4:
        raise InvalidParameterError(f"{func}: `jet_result` has {len(jet_result)} points, "
                                    f"`points` {pts.shape[0]}, or is not of Monge degree 4")
    fit = jet_result.fit
    n = pts.shape[0]
    fitted = np.isin(jet_result["status"], (FitStatus.OK, FitStatus.MODEL_REJECTED))
    z1 = z_critical(alpha, sides=1)  # k'' of the right sign
    zk = z_critical(alpha / 2, sides=1)  # k1 and k2 both looked at: Bonferroni
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
    # creases at the crease radius (crease_rung); a ridge point whose jet holds a
    # crease point is the crease's smoothed image, not a ridge of a smooth surface
    radii = jet_result.meta.get("radii")
    if radii is None:
        radii = scales if scales is not None or not creases else radius_ladder(pts)
    radii = np.asarray(radii if creases else [], float)
    radii = radii[crease_rung(radii, jet_result.sigma):][:2]
    if 0 < radii.size < 2:
        radii = np.r_[radii, radii * np.sqrt(2.0)]
    found = find_creases(local, nb, step, radii,
                         sigma=jet_result.sigma, noise=jet_result.meta.get("noise"),
                         sensor=sensor, weight=weight, alpha=alpha,
                         min_vertices=min_vertices, smooth=smooth)
    if found.mask.any() and (ridge > 0).any():
        from scipy.spatial import cKDTree

        on = np.flatnonzero(ridge > 0)
        d, _ = cKDTree(local[found.mask]).query(local[on])
        ridge[on[d <= fit.bandwidth[on]]] = 0
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
    auto = jet_result.meta.get("scale") == "auto"
    if min_length is None and auto:
        line_min = 2.0 * fit.bandwidth  # per line: twice the median radius of its points
    else:
        if min_length is None:
            scale = radius if radius is not None else float(np.median(fit.bandwidth[fitted]))
            min_length = 2.0 * float(scale)
        min_length = check_scalar(min_length, "min_length", func=func, low=0.0,
                                  closed="left")
        line_min = np.full(n, min_length)
    # line test: the curvature along the line significant at family-wise level alpha over
    # the cloud's ~N / median(neighbours) independent neighbourhoods (Bonferroni)
    n_eff = max(1.0, n / max(1.0, float(np.median(fit.neighbors[fitted])) if fitted.any()
                             else 1.0))
    z_line = z_critical(alpha / n_eff)
    lines, new_id = _build_lines(nl, out_pts, out_start, line_of, vert + origin, ridge, cval,
                                 min_vertices, smooth, line_min, 4.0 * step, z_line)
    line_of = new_id[line_of]
    ridge[line_of == 0] = 0
    ridge[found.mask] = CREASE
    line_of[found.mask] = found.line[found.mask] + len(lines)
    ridge_line = line_of.astype(np.int32)
    lines = _with_creases(lines, found, origin)
    with np.errstate(invalid="ignore"):
        # umbilic: k1 = k2 accepted (two-sided z of k1 - k2) and the curvature significant
        # (two-sided z of k1 + k2): a plane (k1 = k2 = 0) is not umbilic
        z2 = z_critical(alpha)
        gap_sd = np.sqrt(sd[:, 0] ** 2 + sd[:, 1] ** 2)
        k1, k2 = jet_result["k1"], jet_result["k2"]
        umbilic = fitted & ((k1 - k2) <= z2 * gap_sd) & (np.abs(k1 + k2) > z2 * gap_sd)
    fields = dict(jet_result.fields)
    fields.update(ridge=ridge, ridge_line=ridge_line, umbilic=umbilic.astype(np.uint8),
                  extremality=cval[:, 1])
    scale = {key: jet_result.meta[key] for key in ("scale", "scale_criterion", "radii",
                                                  "points_per_radius") if key in jet_result.meta}
    if auto:
        r_used = fit.bandwidth[fitted]
        scale["radius_median"] = float(np.median(r_used)) if r_used.size else float("nan")
    if found.radii.size:
        scale.update(crease_radius=float(radii[0]), crease_growth_radius=float(radii[1]))
    params = dict(radius=radius, k=k, **scale, sigma=jet_result.sigma,
                  sigma_estimated=jet_result.sigma_estimated, alpha=alpha, degree=4,
                  z_line=z_line, weight=weight, noise=jet_result.meta.get("noise"),
                  ratio=ratio, cross_k=cross_k,
                  min_vertices=min_vertices, smooth=smooth, step=step,
                  min_length=None if auto and min_length is None else min_length)
    return RidgeResult(fields=fields, lines=lines, jets=jet_result, params=params)


def _build_lines(nl, out_pts, out_start, line_of, vert, ridge, cval, min_vertices, smooth,
                 line_min, join, z_line):
    members = np.bincount(line_of, minlength=nl + 1)[1:]
    chains = [out_pts[out_start[li]:out_start[li + 1]] for li in range(nl)]
    chains, alive, owner = join_lines(chains, vert, ridge, join)
    # points absorbed per joined line: the traced lines' counts summed by owner
    absorbed = np.bincount(np.asarray(owner, np.int64), weights=members, minlength=nl)
    verts, attrs = [], {name: [] for name in LINE_ATTRIBUTES}
    new_id = np.zeros(nl + 1, np.int64)
    final = {}
    for li in range(nl):  # one iteration per line, not per point
        if not alive[li]:
            continue
        ids = chains[li]
        if ids.size < min_vertices:
            continue
        v = smooth_vertices(vert[ids], smooth)
        seg = np.linalg.norm(np.diff(v, axis=0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            kz = float(np.median(np.abs(cval[ids, 0]) / cval[ids, 11]))
        if seg.sum() < float(np.median(line_min[ids])) or not kz > z_line:
            continue
        final[li] = len(verts) + 1
        kk = np.abs(cval[ids, 0])
        kpp = np.abs(cval[ids, 2])
        mid = lambda a: 0.5 * (a[1:] + a[:-1])  # noqa: E731
        verts.append(v)
        attrs["line_id"].append(final[li])
        attrs["ridge"].append(int(ridge[ids[0]]))
        attrs["n_vertices"].append(ids.size)
        attrs["n_points"].append(int(absorbed[li]))
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


def _with_creases(lines, creases, origin):
    """Ridge lines followed by the crease lines (``ridge`` 3), every attribute on both:
    the curvature ones NaN on crease lines, the misfit ones NaN on ridge lines."""
    nr, nc = len(lines), len(creases.vertices)
    a, c = lines.attributes, creases.attributes
    attrs = {}
    for name in LINE_ATTRIBUTES:
        if name == "line_id":
            extra = np.arange(nr + 1, nr + nc + 1)
        elif name == "ridge":
            extra = np.full(nc, CREASE)
        elif name in c:
            extra = c[name]
        else:
            extra = np.full(nc, np.nan)
        attrs[name] = np.concatenate([a[name], np.asarray(extra, a[name].dtype)])
    for name in CREASE_ATTRIBUTES:
        attrs[name] = np.concatenate([np.full(nr, np.nan), np.asarray(c[name], float)])
    return Polylines(list(lines.vertices) + [v + origin for v in creases.vertices], attrs)
