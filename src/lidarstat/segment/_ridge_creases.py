"""Crease points and crease lines of :func:`lidarstat.segment.ridges`: where the jets'
own test says the surface is not smooth.

A crease (a jump of the tangent plane or of the curvature, such as the feet of a
circular arc standing on flat ground) is no ridge of a smooth surface: the paper's
ridge, an extremum of a principal curvature along its line, is there that of the
curvature the jets smooth into the crease, and it lies one to three spacings away.
What locates a crease is the chi-square test of the jet (eq. 7): a jet whose
neighbourhood holds the crease cannot fit it, so the rejected jets form a band about the
crease. So:

1. jets of degree 4 at the crease radius (:func:`crease_rung`: the smallest rung of
   the ladder, from :data:`MIN_CREASE_RUNG`, over which a kink of the design angle
   rises well above the noise);
2. candidates: jets the chi-square rejects at the Bonferroni level ``alpha / n_eff``
   over the cloud's independent neighbourhoods (so that a smooth cloud has, with
   probability about ``1 - alpha``, none);
3. the centre line of their band (:func:`crease_points`): the misfit itself peaks on
   each side of a sharp fold, not on it, so a point's score is the band's depth on its
   poorer side across the crease (directions from the plane normals, which turn about
   the crease), averaged along it, and a candidate is a crease point where no neighbour
   across scores more than :data:`TOLERANCE` above it;
4. crease points are chained into lines like ridge points (``ridges``), and a line is
   kept when it is at least twice the crease radius long and its misfit grows with the
   radius no faster than a kink's (:func:`misfit_growth`, :data:`MAX_GROWTH`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..features import FitStatus, fit_jets, height_variance, jet_tests, point_spacing
from ..neighbors import KnnIndex
from . import _ridge_kernels as _rk
from ._ridge_lines import group_rows, join_lines, smooth_vertices

#: Code of a crease point in the ``ridge`` field.
CREASE = 3
#: Neighbours examined per point.
CREASE_K = 32
#: Reach of the average along the crease and of the comparison across it, in spacings.
ALONG = 3.5
ACROSS = 3.0
#: Least reach along and across, in jet radii.
REACH = 0.5
#: A crease point's depth is at least (1 - TOLERANCE) times its largest neighbour's
#: across the crease.
TOLERANCE = 0.2
#: |cos| of the angle to the across direction: at least COS_ACROSS across, at most
#: COS_ALONG along.
COS_ACROSS = 0.87
COS_ALONG = 0.5
#: Design angle of the crease radius, degrees: the smallest change of the tangent
#: plane's direction across a crease that the radius is chosen to find (the paper's a
#: priori curvature K_0 of eq. 19-21, for a kink).
DESIGN_ANGLE = 45.0
#: Rise of a kink of :data:`DESIGN_ANGLE` over the crease radius, in noise standard
#: deviations: a symmetric V of that angle leaves ``r tan(angle / 2)`` between its sides
#: and its tangent plane at one radius from the crease, and the jets' misfit grows as
#: its square over sigma^2. The crease points are the centre line of the band of
#: rejected jets, which must be about a radius wide to have one. Measured on the scene
#: family's cylindrical profiles and the machined parts (``benchmarks/ridge_family.py``,
#: docs/methods/jets.md): rungs whose rise is below about 30 sigma leave parts of the
#: family's lines unfound; above about 40 the machined parts' close folds merge their
#: bands and the crease points leave the folds. 35 lies between.
KINK_RISE = 35.0


#: Smallest rung of the crease radius: the third of the ladder (about 190 points, a
#: radius of about 8 spacings), so that the band of rejected jets holds enough points
#: across on each side of its centre line even where the noise is low.
MIN_CREASE_RUNG = 2


def crease_rung(radii, sigma):
    """Index into the ladder `radii` of the crease radius: the smallest rung, from
    :data:`MIN_CREASE_RUNG` on, over which a kink of :data:`DESIGN_ANGLE` rises
    :data:`KINK_RISE` noise standard deviations (``r tan(angle / 2) >= KINK_RISE
    sigma``), at most the last but one (the next rung gives the misfit's growth)."""
    radii = np.asarray(radii, float)
    if radii.size < 2:
        return 0
    need = KINK_RISE * float(sigma) / np.tan(np.radians(DESIGN_ANGLE) / 2.0)
    j = max(int(np.searchsorted(radii, need * (1.0 - 1e-9))), MIN_CREASE_RUNG)
    return min(j, radii.size - 2)


#: Largest median growth of a crease line's excess misfit from one rung to the next
#: (radius times sqrt 2): a kink's. A kink leaves residuals proportional to the radius,
#: so its excess variance factor grows as r^2 (x 2 per rung; 1.7 to 1.8 measured on
#: folds and the feet of cylindrical profiles, where the jets straddle the crease
#: unevenly); the truncation of a smooth surface by a degree-4 jet leaves residuals of
#: order r^5 (x 32 per rung), and a narrow smooth crest seen by jets wider than itself
#: still grows faster than a kink (2.4 to 3.7 measured).
MAX_GROWTH = 2.0


def across_directions(fields):
    """Unit direction of the larger |principal curvature| per point (the one a crease
    bends), and the other one (along the crease)."""
    d1 = np.c_[fields["d1x"], fields["d1y"], fields["d1z"]]
    d2 = np.c_[fields["d2x"], fields["d2y"], fields["d2z"]]
    first = (np.abs(np.asarray(fields["k1"])) >= np.abs(np.asarray(fields["k2"])))[:, None]
    return np.where(first, d1, d2), np.where(first, d2, d1)


def crease_points(points, fields, *, alpha, n_eff, radius=0.0, spacing=None):
    """Boolean mask of the crease points of `points` (local coordinates) from the jet
    `fields` (``status``, ``chi2_p``, ``k1``, ``k2``, ``d1*``, ``d2*``) at `radius`.

    The band of jets rejected at the Bonferroni level is centred on the crease: a jet
    whose neighbourhood holds the crease on either side of its centre cannot fit it.
    Its misfit is not: at a sharp fold it peaks on each side, where the jet straddles
    the fold asymmetrically, and dips on the fold, where an even polynomial fits the
    symmetric V best. So a point's score is the band's depth on its poorer side: the
    number of rejected jets within `radius` across the crease on that side (in a cone of
    30 degrees about the direction of the larger principal curvature), the smaller of the
    two sides' counts, averaged along the crease. It is largest on the band's centre line
    and falls by a row of points per spacing off it; a candidate is a crease point when
    no neighbour across the crease (within :data:`ACROSS` spacings or :data:`REACH`
    radii) scores more than :data:`TOLERANCE` above it, with neighbours on both sides.
    """
    n = points.shape[0]
    mask = np.zeros(n, bool)
    status = np.asarray(fields["status"])
    with np.errstate(invalid="ignore"):
        strong = (status == FitStatus.MODEL_REJECTED) & (
            np.asarray(fields["chi2_p"]) < alpha / max(1.0, n_eff))
    if n < 8 or not strong.any():
        return mask
    if spacing is None:
        spacing = point_spacing(points)
    across_reach = max(ACROSS * spacing, REACH * radius)
    along_reach = max(ALONG * spacing, REACH * radius)
    band_reach = max(across_reach, float(radius))
    reach = max(band_reach, along_reach) / spacing
    k = min(max(CREASE_K, int(np.ceil(1.5 * np.pi * reach * reach))), n)
    index = KnnIndex(points)
    normals = np.full((n, 3), np.nan)
    depth = np.zeros(n)

    def fold_across(at, idx, dist):
        """Across the crease at `at`, in the point's tangent plane: normal to the crease
        line, the least axis of the neighbours' normals within the band's reach (the
        normals turn about the crease line, so they span the plane normal to it)."""
        ok = dist <= band_reach
        todo = np.zeros(n, bool)
        todo[idx[ok]] = True
        todo = np.flatnonzero(todo & np.isnan(normals[:, 0]))
        if todo.size:
            normals[todo] = _pca_normals(index, todo)
        nn = np.where(ok[..., None], normals[idx], 0.0)  # the normals within reach
        m = np.einsum("nki,nkj->nij", nn, nn)
        axis = np.linalg.eigh(m)[1][:, :, 0]
        c = np.cross(axis, normals[at])
        return axis, c / np.maximum(np.linalg.norm(c, axis=1), 1e-12)[:, None]

    def cosines(at, idx, d, axis, across):
        """Per neighbour: the sine of its offset's angle to the crease line, signed by
        the side (the sign of the offset along the across direction): the surface bends
        at the crease, so the offsets to the other side leave the tangent plane."""
        off = points[idx] - points[at][:, None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.einsum("nkj,nj->nk", off, axis) / d
            side = np.where(np.einsum("nkj,nj->nk", off, across) >= 0, 1.0, -1.0)
        return np.where(d > 0, side * np.sqrt(np.clip(1.0 - c * c, 0.0, 1.0)), 0.0)

    def examine(at, lists):
        """One search per point of `at`, block by block: its depth (the band's on its
        poorer side), and with `lists` its neighbours along the crease (for the average)
        and across it (for the comparison) with the sides the latter cover."""
        along, across, both = _Lists(), _Lists(), []
        step = max(1, CREASE_BLOCK // k)
        for s in range(0, at.size, step):
            b = at[s:s + step]
            nb = index.query(k, query=b)
            idx, d = nb.indices.reshape(-1, k), nb.distances.reshape(-1, k)
            cos = cosines(b, idx, d, *fold_across(b, idx, d))
            cone = (np.abs(cos) >= COS_ACROSS) & (d > 0) & (d <= band_reach) & strong[idx]
            depth[b] = np.minimum((cone & (cos > 0)).sum(axis=1),
                                  (cone & (cos < 0)).sum(axis=1))
            if not lists:
                continue
            al = ((np.abs(cos) <= COS_ALONG) & (d <= along_reach)) | (d == 0)
            ac = (np.abs(cos) >= COS_ACROSS) & (d > 0) & (d <= across_reach)
            along.add(b, idx, al)
            across.add(b, idx, ac)
            both.append((ac & (cos > 0)).any(axis=1) & (ac & (cos < 0)).any(axis=1))
        if not lists:
            return None
        return along, across, np.concatenate(both) if both else np.zeros(0, bool)

    # each point examined is searched once: the candidates, the points across the
    # crease they compare with, then the points along the crease their averages take in
    rows = np.flatnonzero(strong)
    along_r, across_r, both_r = examine(rows, True)
    near = np.flatnonzero(across_r.members(n) & ~strong)
    along_n, _, _ = examine(near, True)
    need = np.union1d(near, rows)
    extra = along_r.members(n) | along_n.members(n)
    extra[need] = False
    examine(np.flatnonzero(extra), False)
    # the depth averaged along the crease
    smooth = np.zeros(n)
    for lst in (along_r, along_n):
        lst.average(depth, smooth)
    # a candidate is a crease point where no neighbour across scores well above it
    higher = across_r.exceeds((1.0 - TOLERANCE) * smooth, smooth)
    mask[rows[~higher & both_r & (smooth[rows] > 0)]] = True
    return mask


#: Neighbour pairs a pass of the crease test works on at once (its temporaries hold
#: about 60 bytes a pair).
CREASE_BLOCK = 1 << 22


class _Lists:
    """Per block of rows, the neighbours `idx` kept where `keep` (CSR): what the crease
    test reads again of a point's neighbourhood, a block at a time."""

    def __init__(self):
        self.parts = []

    def add(self, rows, idx, keep):
        indptr = np.zeros(rows.size + 1, np.int64)
        np.cumsum(keep.sum(axis=1), out=indptr[1:])
        self.parts.append((rows, indptr, idx[keep]))

    def members(self, n):
        """Boolean mask of the points in any row."""
        mark = np.zeros(n, bool)
        for _, _, ind in self.parts:
            mark[ind] = True
        return mark

    def average(self, values, out):
        """``out[row]``: the mean of `values` over the row's neighbours (in their order;
        0 for an empty row)."""
        for rows, indptr, ind in self.parts:
            count = np.diff(indptr)
            total = np.add.reduceat(np.r_[values[ind], 0.0], indptr[:-1]) * (count > 0)
            out[rows] = total / np.maximum(count, 1)

    def exceeds(self, values, bound):
        """Per row, in order: whether `values` of any neighbour exceeds ``bound[row]``."""
        out = []
        for rows, indptr, ind in self.parts:
            count = np.diff(indptr)
            row = np.repeat(np.arange(rows.size), count)
            hit = values[ind] > bound[rows][row]
            out.append(np.bincount(row[hit], minlength=rows.size) > 0)
        return np.concatenate(out) if out else np.zeros(0, bool)


#: Neighbours of the plane fits whose normals give the direction across a crease.
NORMAL_K = 10


def _pca_normals(index, at):
    """Unit normals at `at`: the least axis of the covariance of the :data:`NORMAL_K`
    nearest points (`index`: a :class:`lidarstat.neighbors.KnnIndex` of the points)."""
    points = index.points
    k = min(NORMAL_K, points.shape[0])
    nb = index.query(k, query=at)
    x = points[nb.indices.reshape(-1, k)]
    x = x - x.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", x, x))[1][:, :, 0]


def variance_factor(points, query, radius, *, sigma, noise, sensor, weight, alpha):
    """Jets of degree 4 at `radius` for the `query` rows: their fields (``jet_tests``) and
    the variance factor in units of the noise, ``sigma0_sq / var(height)``."""
    # the crease pass reads the test, the principal curvatures and their directions
    fit = fit_jets(points, radius=radius, query=query, degree=4, monge_degree=2,
                   weight=weight, sensor=sensor, standard_errors=False)
    var = height_variance(fit.frame, sigma, noise=noise, points=points[query], sensor=sensor)
    fields = jet_tests(fit, var, alpha)
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.asarray(fields["sigma0_sq"]) / var
    return fields, factor


def misfit_growth(factor_small, factor_large):
    """Growth of the excess variance factor ``F - 1`` from one rung to the next (NaN
    where the smaller rung shows no excess)."""
    e0 = np.asarray(factor_small) - 1.0
    e1 = np.maximum(np.asarray(factor_large) - 1.0, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(e0 > 0, e1 / e0, np.nan)


@dataclass(frozen=True)
class Creases:
    """Crease points and lines of one cloud.

    ``mask`` marks the points of the kept lines; ``line`` is each point's index into
    ``vertices`` plus one (0 none); ``attributes`` per line: ``n_vertices``, ``n_points``,
    ``length``, ``misfit`` (median variance factor, in units of the noise, at the crease
    radius), ``misfit_p`` (median p-value of the jets' chi-square test there),
    ``misfit_growth`` (median growth of the excess variance factor to the next rung);
    ``radii`` the rungs climbed, ``rung`` each crease point's (-1 none).
    """

    mask: np.ndarray
    line: np.ndarray
    vertices: list
    attributes: dict
    radii: np.ndarray
    rung: np.ndarray


def _scatter(fields, factor, rows, n):
    """Fields of the jets fitted at `rows`, on all `n` points (unfitted: status
    TOO_FEW_NEIGHBORS, NaN elsewhere)."""
    out = {}
    for key in ("chi2_p", "sigma0_sq", "k1", "k2", "d1x", "d1y", "d1z", "d2x", "d2y", "d2z"):
        out[key] = np.full(n, np.nan)
        out[key][rows] = fields[key]
    out["status"] = np.full(n, int(FitStatus.TOO_FEW_NEIGHBORS), np.uint8)
    out["status"][rows] = fields["status"]
    full = np.full(n, np.nan)
    full[rows] = factor
    return out, full


def find_creases(local, nb, step, radii, *, sigma, noise, sensor, weight, alpha,
                 min_vertices, smooth, min_length=None):
    """Crease points and lines of `local` (coordinates about their mean), climbing the
    ladder `radii` (``ridges`` passes two: the crease rung and the next). At each rung the
    jets are fitted where those of the rung below are rejected (level `alpha`; every point
    at the first; at the last, only the rung below's crease points, whose misfit's growth
    is all that is read there), crease
    points are the crests of the misfit across a band of jets rejected at the
    Bonferroni level, and they are chained into lines, each line tested on its own rung
    (length, growth of the misfit to the rung above). A line of a larger rung whose
    points mostly lie within two steps of a smaller rung's crease points is the same
    crease and is dropped. `nb` and `step` are the neighbourhoods and step of the ridge
    tracing."""
    n = local.shape[0]
    kw = {"sigma": sigma, "noise": noise, "sensor": sensor, "weight": weight, "alpha": alpha}
    radii = np.asarray(radii, float)
    rows = np.arange(n, dtype=np.int64)
    n_eff = float(n)
    spacing = point_spacing(local) if n >= 16 and radii.size else 0.0
    found = []  # per rung: candidates, variance factor, p-value, along direction
    for j, r in enumerate(radii):
        if not rows.size:
            break
        fields, f_j = variance_factor(local, rows, float(r), **kw)
        full, f_full = _scatter(fields, f_j, rows, n)
        if j == 0:
            fitted = np.isin(fields["status"], (FitStatus.OK, FitStatus.MODEL_REJECTED))
            med = float(np.median(fields["neighbors"][fitted])) if fitted.any() else 1.0
            n_eff = max(1.0, n / max(1.0, med))
        del fields, f_j  # the fits' arrays: the scattered fields are all that is read
        if j:
            cand, factor = found[-1][0], found[-1][1]
            found[-1][4][cand] = misfit_growth(factor[cand], f_full[cand])
        if j == len(radii) - 1:
            break
        cand = crease_points(local, full, alpha=alpha, n_eff=n_eff / 2.0 ** j, radius=r,
                             spacing=spacing)
        found.append((cand, f_full, full["chi2_p"],
                      np.nan_to_num(across_directions(full)[1]), np.full(n, np.nan)))
        # climb where the jets are still rejected; of the last rung only the growth of
        # the candidates' misfit is read, so only they are fitted there
        rows = np.flatnonzero(cand if j == len(radii) - 2
                              else full["status"] == FitStatus.MODEL_REJECTED)
    mask = np.zeros(n, bool)
    line = np.zeros(n, np.int64)
    rung = np.full(n, -1, np.int64)
    attrs = {key: [] for key in ("n_vertices", "n_points", "length", "misfit", "misfit_p",
                                 "misfit_growth", "radius")}
    verts = []
    for j, (cand, factor, p_value, along, growth) in enumerate(found):
        shortest = 2.0 * float(radii[j]) if min_length is None else min_length
        near = np.zeros(n, bool)
        if mask.any():  # within two steps of a smaller rung's crease points
            from scipy.spatial import cKDTree

            near[cand] = cKDTree(local[mask]).query(local[cand])[0] <= 2.0 * step
        for members, v, length in _chain(local, nb, step, cand, factor, along, min_vertices,
                                         smooth):
            g = float(np.nanmedian(growth[members])) if np.isfinite(growth[members]).any() \
                else np.nan
            # correlated patches are about a radius wide: a line must outrun them
            if length < shortest or not g <= MAX_GROWTH or near[members].mean() > 0.8:
                continue
            members = members[~mask[members]]
            verts.append(v)
            mask[members] = True
            line[members] = len(verts)
            rung[members] = j
            attrs["n_vertices"].append(len(v))
            attrs["n_points"].append(members.size)
            attrs["length"].append(length)
            attrs["misfit"].append(float(np.median(factor[members])))
            attrs["misfit_p"].append(float(np.median(p_value[members])))
            attrs["misfit_growth"].append(g)
            attrs["radius"].append(float(radii[j]))
    return Creases(mask=mask, line=line, vertices=verts,
                   attributes={k: np.asarray(v) for k, v in attrs.items()},
                   radii=radii, rung=rung)


def _chain(local, nb, step, cand, factor, along, min_vertices, smooth):
    """Lines of the crease points `cand` traced like ridge points: (member points,
    smoothed vertices, length) per line of at least `min_vertices` vertices."""
    n = local.shape[0]
    if not cand.any():
        return []
    rows = np.flatnonzero(cand)
    lab = cand.astype(np.uint8) * CREASE
    order = rows[np.argsort(-factor[rows], kind="stable")].astype(np.int64)
    line_of = np.zeros(n, np.int64)
    out_pts = np.zeros(n, np.int64)
    out_start = np.zeros(n + 1, np.int64)
    nl = _rk.trace(nb.indptr, nb.indices, lab, local, np.ascontiguousarray(along),
                   step * 1.0001, np.cos(np.radians(50.0)), order, line_of, out_pts,
                   out_start)
    chains = [out_pts[out_start[li]:out_start[li + 1]] for li in range(nl)]
    chains, alive, owner = join_lines(chains, local, lab, 4.0 * step)
    owner = np.asarray([0] + [o + 1 for o in owner], np.int64)  # by traced line id
    members = group_rows(owner[line_of], nl + 1)
    out = []
    for li in range(nl):  # one iteration per line, not per point
        ids = chains[li]
        if not alive[li] or ids.size < min_vertices:
            continue
        v = smooth_vertices(local[ids], smooth)
        length = float(np.linalg.norm(np.diff(v, axis=0), axis=1).sum())
        out.append((members[li + 1], v, length))
    return out
