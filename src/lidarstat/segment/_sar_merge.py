"""Best-fit assignment, merge test and final refit of the SAR-FS units (seed 002, section 5.4).

The Forward Search of neighbouring raw clusters accepts overlapping point sets: every
point claimed by several units goes to the one it fits best (smallest standardised
residual); units of the same order whose raw clusters do not differ by Chow's F test are
merged (a plane split by a dormer or a chimney becomes one unit again); every final
segment is refitted on its final points (:func:`refit_unit`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidParameterError
from ..stats import chi2_test, chow_test
from ._sar_refine import refit_unit
from ._search_area import search_areas


def two_hop_contacts(graph, labels):
    """(point, other segment) pairs: labelled points with another segment within 2 hops."""
    indptr, idx, _ = graph
    n = labels.size
    G = sp.csr_matrix((np.ones(idx.size), idx, indptr), shape=(n, n))
    G = G + sp.identity(n, format="csr")
    lab = labels > 0
    L = sp.csr_matrix((np.ones(lab.sum()), (np.flatnonzero(lab), labels[lab] - 1)),
                      shape=(n, int(labels.max()) if labels.size else 0))
    reach = (G @ (G @ L)).tocoo()
    p, s = reach.row, reach.col + 1
    keep = lab[p] & (labels[p] != s)
    return p[keep], s[keep]


def area_contacts(points, graph, labels, search):
    """(point, other segment) pairs: labelled points touching another segment's search area.

    The search area of a segment (its points plus the unlabelled points reachable within
    a Delaunay path of `search`, :func:`search_areas`) is widened by one triangulation
    edge; labelled points of other segments inside it are contacts. Two parts of one roof
    plane separated by a dormer or a chimney (unlabelled points a few metres wide) are
    thereby candidates for the merge, which two-hop adjacency misses.
    """
    n = labels.size
    indptr, idx, _ = graph
    lab = labels > 0
    s_max = int(labels.max()) if n else 0
    areas = search_areas(points, labels, search, graph=graph)
    owner = np.repeat(np.arange(s_max), np.diff(areas.indptr))
    rows = np.r_[np.flatnonzero(lab), areas.indices]
    cols = np.r_[labels[lab] - 1, owner]
    M = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, s_max))
    G = sp.csr_matrix((np.ones(idx.size), idx, indptr), shape=(n, n))
    reach = (G @ M + M).tocoo()
    p, c = reach.row, reach.col + 1
    keep = lab[p] & (labels[p] != c)
    return p[keep], c[keep]


def assign(units, n):
    """Final labels: every accepted point to the unit it fits best."""
    pts, who, score = [], [], []
    for u, unit in enumerate(units):
        pts.append(unit.accepted)
        who.append(np.full(unit.accepted.size, u))
        sd = max(unit.sigma, 1e-12)
        sc = np.abs(unit.residuals) / sd
        sc[:unit.n_s] = -1.0  # raw clusters keep their points (listed first)
        score.append(sc)
    labels = np.zeros(n, dtype=np.int64)
    if not pts:
        return labels
    pts, who, score = (np.concatenate(a) for a in (pts, who, score))
    o = np.lexsort((who, score))
    pts, who = pts[o], who[o]
    first = np.unique(pts, return_index=True)[1]
    labels[pts[first]] = who[first] + 1
    return labels


def _design(points, idx, degree, origin, scale):
    """Monomials up to `degree` in coordinates relative to `origin`, divided by `scale`."""
    u = (points[idx, :2] - origin) / scale
    cols = [u[:, 0] ** (i - j) * u[:, 1] ** j for i in range(degree + 1) for j in range(i + 1)]
    return np.column_stack(cols)


def _moments(points, idx, degree, origin, scale, z0):
    """Normal-equation moments (A'A, A'z, z'z, n) of one point set (heights minus z0)."""
    A = _design(points, idx, degree, origin, scale)
    z = points[idx, 2] - z0
    return A.T @ A, A.T @ z, float(z @ z), idx.size


def _rss(mom):
    ata, atz, zz, n = mom
    try:
        coef = np.linalg.solve(ata, atz)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(ata, atz, rcond=None)[0]
    return max(zz - coef @ atz, 0.0), ata.shape[0], n


def _chow(ma, mb, alpha):
    """Chow's F test (:func:`lidarstat.stats.chow_test`) that two point sets lie on one
    polynomial surface, from the normal-equation moments of each set (the union's moments
    are their sums)."""
    ra, r, na = _rss(ma)
    rb, _, nb = _rss(mb)
    rab, _, _ = _rss(tuple(x + y for x, y in zip(ma, mb)))
    return chow_test(rab, ra, rb, r, na, nb, alpha=alpha)


def find_root(parent, u):
    """Root of `u` in the union-find forest `parent` (path halving, in place)."""
    while parent[u] != u:
        parent[u] = parent[parent[u]]
        u = parent[u]
    return u


def contact_pairs(a, b, n_labels, min_contacts):
    """The label pairs linked at least `min_contacts` times by the links ``a[i] - b[i]``.

    Links with a label 0 or within one label are ignored. Returns the pairs as keys
    ``lo * (n_labels + 1) + hi`` (``lo < hi``, ascending) and their numbers of links.
    """
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    keep = (a > 0) & (b > 0) & (a != b)
    lo, hi = np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])
    keys, counts = np.unique(lo * (n_labels + 1) + hi, return_counts=True)
    cand = counts >= min_contacts
    return keys[cand], counts[cand]


def crease_refuses_fits(part_a, part_b, union, alpha):
    """The crease test of a merge from three fits ``(rss, df, sigma2)``: True when both
    parts pass the test of their residual sum of squares against the noise
    (``rss / sigma2 ~ chi2(df)``, upper tail at `alpha`) and the union rejects it. A
    fit without degrees of freedom does not refuse."""
    rejects = []
    for rss, df, sigma2 in (part_a, part_b, union):
        if df <= 0:
            return False
        rejects.append(bool(chi2_test(rss / sigma2, df, alpha=alpha).reject))
    return (not rejects[0]) and (not rejects[1]) and rejects[2]


def crease_refuses(mom_a, mom_b, sigma2, alpha):
    """The crease test of a merge: True when the union of two point sets fails the test
    against the noise that each set passes.

    Each set's residual sum of squares about its own least-squares surface (from the
    normal-equation moments) is referred to ``sigma2 chi2(n - r)``, upper tail at
    `alpha` (:func:`crease_refuses_fits`); the merge is refused when both parts pass and
    the union (moments summed) rejects: two faces meeting at a crease each fit a plane,
    their union does not. When a part already fails, the test cannot tell a crease from
    roughness and does not refuse.
    """
    fits = []
    for mom in (mom_a, mom_b, tuple(x + y for x, y in zip(mom_a, mom_b))):
        rss, r, n = _rss(mom)
        fits.append((rss, n - r, sigma2))
    return crease_refuses_fits(*fits, alpha)


def merge_groups(points, unit_labels, units, graph, alpha, search, *, sigma2=None,
                 crease_alpha=None):
    """Union of nearby units whose surfaces do not differ (Chow test at `alpha`).

    Candidates are pairs with at least 4 contacts (:func:`area_contacts` within
    `search`). With `sigma2` and `crease_alpha`, a merge Chow's test allows is still
    refused when the union of the two groups (every unit already merged into either)
    fails the test against the noise each group passes (:func:`crease_refuses`), so a
    chain of pairwise merges cannot join two faces across a crease."""
    n_units = len(units)
    parent = np.arange(n_units + 1)
    if n_units < 2:
        return parent
    pts_c, seg_c = area_contacts(points, graph, unit_labels, search)
    base = n_units + 1
    keys, _ = contact_pairs(unit_labels[pts_c], seg_c, n_units, 4)
    origin = points[:, :2].min(axis=0)
    scale = max(float(np.ptp(points[:, :2], axis=0).max()), 1.0)
    z0 = float(points[:, 2].min())
    moments = {}

    def mom(u):
        # the raw cluster, not the unit's final points: the best-fit assignment splits the
        # points of one plane between two units by the sign of their residuals, and on
        # such a residual-selected split the Chow test rejects one common plane (p down to
        # 1e-5 on the synthetic town); the raw clusters are selected by the local tests.
        if u not in moments:
            moments[u] = _moments(points, units[u - 1].raw, units[u - 1].degree, origin,
                                  scale, z0)
        return moments[u]

    group = {}  # root -> summed moments of its members' raw clusters

    def gmom(r):
        return group.get(r) or mom(r)

    for key in keys:
        ua, ub = int(key // base), int(key % base)
        if units[ua - 1].degree != units[ub - 1].degree or units[ua - 1].frame is not None \
                or units[ub - 1].frame is not None:
            continue
        if not _chow(mom(ua), mom(ub), alpha).reject:
            ra, rb = find_root(parent, ua), find_root(parent, ub)
            if ra == rb:
                continue
            ma, mb = gmom(ra), gmom(rb)
            if sigma2 is not None and crease_alpha is not None and \
                    crease_refuses(ma, mb, sigma2, crease_alpha):
                continue
            lo_r, hi_r = min(ra, rb), max(ra, rb)
            parent[hi_r] = lo_r
            group[lo_r] = tuple(x + y for x, y in zip(ma, mb))
            group.pop(hi_r, None)
    return np.array([find_root(parent, u) for u in range(n_units + 1)])


def refit_group(points, idx, group, w_radius):
    """A unit refitted on its final points `idx` (rho by ML, theta, sigma^2 and the
    surface from the group's raw clusters, residuals of every point), keeping the Table 6
    sizes (summed over a merged group) and the Forward Search record."""
    big = max(group, key=lambda u: u.m)
    raw = np.concatenate([u.raw for u in group])
    raw = raw[np.isin(raw, idx)]
    extra = idx[~np.isin(idx, raw)]
    unit = refit_unit(points, raw, extra, w_radius=w_radius, degree=group[0].degree,
                      rho_hint=big.fit.rho, fs=big.fs)
    return dataclasses.replace(unit, n_s=sum(u.n_s for u in group),
                               n_sa=sum(u.n_sa for u in group), m=sum(u.m for u in group))


def final_units(points, labels, units, w_radius):
    """Every segment refitted on its final points (after the best-fit assignment, the
    merge and the size filter): the accepted sets of the Forward Search overlap, and the
    points given to a neighbouring unit no longer pull this unit's plane. A segment whose
    refit fails keeps its Forward Search fit."""
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(len(units) + 2))
    out = []
    for s, unit in enumerate(units, start=1):
        idx = order[starts[s]:starts[s + 1]]
        try:
            out.append(refit_group(points, idx, [unit], w_radius))
        except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
            out.append(unit)
    return out
