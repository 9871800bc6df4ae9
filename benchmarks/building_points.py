"""Per-point rules on the building test's remaining errors, and what bounds them.

Used by ``buildings.py``. After the patch rules (``building_joint.py``,
``building_echoes.py``) three groups of errors are left on St-Barthelemy: candidates at
least 2 m high with no accepted plane in their 3 x 3 roof cells (``no_roof_near`` of
``building_recall.py``), walls, and roof-cell points (``building_evidence`` 2) beside true
roofs that the reference calls vegetation. Every rule below is a per-point test on what
the building test already holds (``building_recall.candidate_state``: the 12 nearest
candidates, their plane, the roof points and the 1 m roof cells), level ``ALPHA``,
lengths in metres; each is scored alone on the class written, as the true and false
points it removes or adds and the F1 after it (:func:`point_rules`):

Roof-cell points removed:

* ``cell_beyond_roof_edge``: the point's planimetric distance to the nearest roof point
  exceeds the nearest-neighbour distance a point at a roof's edge reaches with
  probability ``ALPHA`` (a Poisson half-disc: ``d > sqrt(-ln ALPHA / (lambda pi / 2))``,
  ``lambda`` the roof points within 1 m of that roof point per square metre);
* ``cell_above_roof_plane_beside``: its own 1 m cell holds no roof point and it lies above
  the local plane of its nearest roof point in plan (that point's 12 nearest roof points)
  by more than the normal test's limit ``z_{1-ALPHA/2} sigma sqrt(1 + 1/k)``: foliage
  rising beside a roof;
* ``cell_ground_seen``: returns more than 1 m under it within 0.5 m (plan) significantly
  more frequent (binomial, upper tail) than under the file's roof-patch points: a roof
  hides the ground, a crown does not.

Candidates not building added:

* ``holes_in_roof_outline``: at least 2 m, in a hole of the roof cells' region (closed
  by filling), not above the highest roof point within 4 m plus the roof cells'
  tolerance (1 m, 0.2 m for a non-last return);
* ``plane_k6``, ``plane_k8``: at least 2 m, no roof point in its 3 x 3 cells, the plane
  of its 6 (8) nearest candidates accepted by the chi-square test (``chi2(k - 3)``);
* ``ground_hidden``: at least 2 m, no roof point in its 3 x 3 cells, no return more than
  1 m under it within 0.5 m;
* ``steep_below_roof_top``: a wall: its 12 nearest candidates' plane steep (``|n_z| <
  0.3``), in a roof cell, below the roof top, its neighbourhood not foliage;
* ``steep_under_eave``: the same within the roof-edge distance of
  ``cell_beyond_roof_edge`` of a roof point (under the eave);
* ``vertical_plane_tested``: the same with the planimetric line of its 12 neighbours
  accepted at ``sigma`` (``chi2(k - 2)``): a tested vertical plane.

:func:`no_plane_components` describes the ``no_roof_near`` points joined at 1 m: the
plane of each component's points, over all of them and per flight strip.
:func:`learned_bound` trains a classifier on the reference labels of the other 25 m
blocks of the same file (grouped 5-fold), on the per-point features the rules use: what
any per-point rule on that evidence could reach, chosen with the reference itself.
"""

from __future__ import annotations

import numpy as np
from building_recall import CAUSES, K, _f1
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.stats import chi2, norm

ALPHA = 0.01
DROP, DISC = 1.0, 0.5  # m: a return this far under a point, within this plan radius
BLOCK = 25.0  # m: the blocks of the learned bound's folds


def _roof_edge_distance(pts, roof):
    """Planimetric distance of every candidate to its nearest roof point, that roof
    point's row, and the edge limit of ``cell_beyond_roof_edge``."""
    ri = np.flatnonzero(roof)
    tree = cKDTree(pts[ri, :2])
    dn, j = tree.query(pts[:, :2])
    near = np.unique(j)
    count = np.zeros(ri.size)
    count[near] = [len(x) for x in tree.query_ball_point(pts[ri[near], :2], 1.0)]
    lam = count[j] / np.pi
    return dn, ri[j], np.sqrt(-np.log(ALPHA) / (lam * np.pi / 2))


def _under_counts(xyz, rows):
    """Returns within `DISC` (plan) of each of `rows` and those more than `DROP` under it."""
    tree = cKDTree(xyz[:, :2])
    under = np.zeros(rows.size)
    total = np.zeros(rows.size)
    for s in range(0, rows.size, 20000):
        part = rows[s:s + 20000]
        lists = tree.query_ball_point(xyz[part, :2], DISC)
        n = np.array([len(x) for x in lists])
        flat = np.concatenate([np.asarray(x, np.int64) for x in lists])
        owner = np.repeat(np.arange(part.size), n)
        under[s:s + part.size] = np.bincount(
            owner, weights=xyz[flat, 2] < xyz[part[owner], 2] - DROP, minlength=part.size)
        total[s:s + part.size] = n
    return under, total


def _plane_accepted(pts, rows, k, sigma):
    """Rows (a mask) whose ``k`` nearest candidates' plane the chi-square test accepts."""
    out = np.zeros(len(pts), bool)
    if not rows.any():
        return out
    _, nb = cKDTree(pts).query(pts[rows], k=k)
    q = pts[nb] - pts[nb].mean(axis=1, keepdims=True)
    rss = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", q, q))[:, 0]
    out[rows] = rss / sigma**2 <= chi2.ppf(1 - ALPHA, k - 3)
    return out


def point_evidence(state, xyz, sigma):
    """The per-candidate arrays the rules and the learned bound read."""
    s = state
    pts, cand, roof = s["pts"], s["cand"], s["roof"]
    dn, nearest, edge = _roof_edge_distance(pts, roof)
    _, nbr = cKDTree(pts[roof]).query(pts[nearest], k=K)
    q = pts[roof][nbr]
    c = q.mean(axis=1)
    q = q - c[:, None]
    normal = np.linalg.eigh(np.einsum("nki,nkj->nij", q, q))[1][:, :, 0]
    normal *= np.where(normal[:, 2:3] < 0, -1.0, 1.0)
    above = np.einsum("ni,ni->n", pts - c, normal) / (sigma * np.sqrt(1 + 1 / K))
    under, total = _under_counts(xyz, cand)
    q = pts[s["nb"]][:, :, :2]
    q = q - q.mean(axis=1, keepdims=True)
    line = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", q, q))[:, 0] / sigma**2
    return {"dn": dn, "edge": edge, "above": above, "under": under, "total": total,
            "line_ok": line <= chi2.ppf(1 - ALPHA, K - 2)}


def point_rules(state, ev_all, pred, truth, keep, sigma, extra):
    """True and false points each rule removes or adds (module docstring), the F1 after
    it, alone on the building class written."""
    from lidarstat.stats import binomial_test

    s, e = state, extra
    cand, pts = s["cand"], s["pts"]
    ev = ev_all[cand]
    high = s["height"] >= 2.0
    in_cells = np.isfinite(s["top"])
    built = pred[cand]
    p0 = float(np.sum(e["under"][s["roof"]]) / max(np.sum(e["total"][s["roof"]]), 1))
    seen = binomial_test(e["under"].astype(np.int64), e["total"].astype(np.int64), p0,
                         alpha=ALPHA).reject
    own_cell = np.isfinite(_own_top(pts, s["roof"]))
    tol = np.where(s["multi"], 0.2, 1.0)
    # the roof cells' region on a 1 m grid, its holes and the highest roof point 4 m round
    ij = np.floor((pts[:, :2] - pts[:, :2].min(axis=0)) / 1.0).astype(np.int64) + 5
    grid = np.zeros(ij.max(axis=0) + 6, bool)
    grid[ij[s["roof"], 0], ij[s["roof"], 1]] = True
    top = np.full(grid.shape, -np.inf)
    np.maximum.at(top, (ij[s["roof"], 0], ij[s["roof"], 1]), pts[s["roof"], 2])
    region = ndimage.binary_dilation(grid, np.ones((3, 3), bool))
    holes = (ndimage.binary_fill_holes(region) & ~region)[ij[:, 0], ij[:, 1]]
    top9 = ndimage.maximum_filter(top, size=9)[ij[:, 0], ij[:, 1]]
    steep = (s["nz"] < 0.3) & in_cells & (pts[:, 2] <= s["top"]) & ~s["foliage"] & ~built
    z_lim = norm.ppf(1 - ALPHA / 2)
    remove = {"cell_beyond_roof_edge": (ev == 2) & (e["dn"] > e["edge"]),
              "cell_above_roof_plane_beside": (ev == 2) & ~own_cell & (e["above"] > z_lim),
              "cell_ground_seen": (ev == 2) & seen}
    far = high & ~in_cells & ~built
    add = {"holes_in_roof_outline": high & holes & ~built & (pts[:, 2] <= top9 + tol),
           "plane_k6": _plane_accepted(pts, far, 6, sigma),
           "plane_k8": _plane_accepted(pts, far, 8, sigma),
           "ground_hidden": far & (e["under"] == 0),
           "steep_below_roof_top": steep,
           "steep_under_eave": steep & (e["dn"] <= e["edge"]),
           "vertical_plane_tested": steep & e["line_ok"]}
    tp = int(np.sum(pred & truth & keep))
    fp = int(np.sum(pred & ~truth & keep))
    fn = int(np.sum(~pred & truth & keep))
    out = {"f1": _f1(tp, fp, fn), "alpha": ALPHA, "roof_under_share": round(p0, 4)}
    for name, rule in remove.items():
        r = np.zeros(len(pred), bool)
        r[cand[rule]] = True
        r &= pred & keep
        dt, df = int(np.sum(r & truth)), int(np.sum(r & ~truth))
        out[name] = {"true_removed": dt, "false_removed": df,
                     "f1_after": _f1(tp - dt, fp - df, fn + dt)}
    for name, rule in add.items():
        a = np.zeros(len(pred), bool)
        a[cand[rule]] = True
        a &= ~pred & keep
        dt, df = int(np.sum(a & truth)), int(np.sum(a & ~truth))
        out[name] = {"true_added": dt, "false_added": df,
                     "f1_after": _f1(tp + dt, fp + df, fn - dt)}
    return out


def _own_top(pts, roof):
    ij = np.floor((pts[:, :2] - pts[:, :2].min(axis=0)) / 1.0).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    cells, inv = np.unique(key, return_inverse=True)
    zmax = np.full(cells.size, -np.inf)
    np.maximum.at(zmax, inv[roof], pts[roof, 2])
    return zmax[inv]


def no_plane_components(xyz, cause, ref, multi, psid, min_points=50):
    """The missed ``no_roof_near`` points joined at 1 m (plan): per component of at least
    `min_points`, its points, its share of non-last returns, the sd (m) of the points
    about their own plane and the same per flight strip (at least 10 points)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = np.flatnonzero(cause == CAUSES.index("no_roof_near"))
    if m.size == 0:
        return {"points": 0, "components": []}
    pairs = cKDTree(xyz[m, :2]).query_pairs(1.0, output_type="ndarray")
    _, lab = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                             shape=(m.size, m.size)), directed=False)

    def sd(rows):
        q = xyz[rows] - xyz[rows].mean(axis=0)
        return round(float(np.sqrt(np.linalg.eigvalsh(q.T @ q)[0] / rows.size)), 3)

    comps = []
    for c in np.argsort(-np.bincount(lab)):
        rows = m[lab == c]
        if rows.size < min_points:
            break
        strips = {int(p): sd(rows[psid[rows] == p]) for p in np.unique(psid[rows])
                  if np.sum(psid[rows] == p) >= 10}
        comps.append({"points": int(rows.size), "multi_share": round(float(multi[rows].mean()), 3),
                      "plane_sd_m": sd(rows), "plane_sd_m_per_strip": strips,
                      "reference_6_share": round(float(np.mean(ref[rows] == 6)), 3)})
    return {"points": int(m.size), "components_of_50_or_more": comps}


FEATURES = ("height", "above_roof_top", "non_last", "neighbour_non_last_share",
            "plane_sd_over_sigma", "abs_normal_z", "roof_distance", "above_roof_plane",
            "building_residual", "building_plane_p", "building_evidence", "intensity",
            "on_roof_patch", "under_own_cell_roof", "under_share")


def learned_bound(state, extra, fields, intensity, pred, truth, keep, sigma, seed=0):
    """F1 with every candidate decided by gradient-boosted trees on `FEATURES`, trained on
    the reference labels of the other `BLOCK`-metre blocks (grouped 5-fold), and trained
    on every block (the fit to the file itself); the other points as written."""
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.model_selection import GroupKFold

    s, e = state, extra
    cand = s["cand"]
    inten = np.zeros(cand.size) if intensity is None else np.asarray(intensity, float)[cand]
    x = np.c_[s["height"], np.where(np.isfinite(s["top"]), s["pts"][:, 2] - s["top"], 99.0),
              s["multi"], s["multi"][s["nb"]].mean(axis=1),
              np.sqrt(s["rss"] / (K - 3)) / sigma, s["nz"], e["dn"], e["above"],
              np.nan_to_num(np.asarray(fields["building_residual"])[cand], posinf=99.0),
              np.asarray(fields["building_plane_p"])[cand],
              np.asarray(fields["building_evidence"])[cand], inten, s["roof_patch"],
              s["own_roof_cell"], e["under"] / np.maximum(e["total"], 1)]
    y, k = truth[cand], keep[cand]
    blk = np.floor(s["pts"][:, :2] / BLOCK).astype(np.int64)
    groups = blk[:, 0] * 10_000 + blk[:, 1]
    cv = np.zeros(cand.size, bool)
    for tr, te in GroupKFold(5).split(x, y, groups):
        model = HistGradientBoostingClassifier(max_iter=100, random_state=seed)
        cv[te] = model.fit(x[tr][k[tr]], y[tr][k[tr]]).predict(x[te])
    fit = HistGradientBoostingClassifier(max_iter=100, random_state=seed).fit(x[k], y[k])
    out = {"features": list(FEATURES), "block_m": BLOCK, "folds": 5}
    for name, decided in (("cross_validated", cv), ("fitted_to_the_file", fit.predict(x))):
        b = pred.copy()
        b[cand] = decided
        tp = int(np.sum(b & truth & keep))
        fp = int(np.sum(b & ~truth & keep))
        fn = int(np.sum(~b & truth & keep))
        out[name] = {"f1": _f1(tp, fp, fn), "precision": round(100 * tp / max(tp + fp, 1), 2),
                     "recall": round(100 * tp / max(tp + fn, 1), 2)}
    return out
