"""Where the building test misses the producer's building points, by cause, and what the
rules that would take them back cost.

Used by ``buildings.py``. A *missed* point is in the producer's class 6 and not in the
building class of `moments`. The decision of every candidate is rebuilt from the fields
`moments` writes (``building_evidence``, ``building_patch``, ``building_patch_p``,
``building_residual``) and the test's own rules (``classify/_buildings.py``: k = 12
nearest candidates, roof cells of 1 m, 2 m ``min_height``, level 0.01). Each missed point
gets the first cause that applies, in this order (lengths in metres):

* ``ground``: the ground step took it (terrain step, raised patches);
* ``below_object_height``: not ground, under ``min_object_height`` (0.5) above the surface;
* ``wall``: a candidate whose 12 nearest candidates' plane is steep (normal within 17.5
  degrees of horizontal, ``|n_z| < 0.3``): walls and facades;
* ``low_roof_patch``: under 2 m, on a roof patch (tested planes, enough points, share of
  non-last returns not rejected): a low roof or the low end of one, which the 2 m floor
  of the roof cells leaves out;
* ``low_near_roof``: under 2 m, off any roof patch, in a roof cell (a roof point in its
  3 x 3 1 m cells): annexes, terraces, porches, eaves over low parts;
* ``low_away``: under 2 m and no roof point within its 3 x 3 cells;
* ``patch_rejected``: at least 2 m, on a patch the test rejected (too small, or too many
  non-last returns);
* ``no_roof_near``: at least 2 m, no roof point within its 3 x 3 cells (roofs whose planes
  the chi-square test rejects everywhere: rough, curved or sparse roofs);
* ``foliage_test``: in a roof cell, its neighbourhood's share of non-last returns rejected
  (roofs under or beside trees);
* ``above_roof_top``: in a roof cell, above the cell's highest roof point by more than
  the tolerance (1 m, 0.2 m for a non-last return).

Per cause (and per group of ``GROUPS``): the points and the building F1 if they alone
were all recovered with no false point (an upper bound of any rule on that cause). :func:`recovery_rules` measures rules
that take points of the largest causes back, with the true and false points each adds.
"""

from __future__ import annotations

import numpy as np

CAUSES = ("ground", "below_object_height", "wall", "low_roof_patch", "low_near_roof",
          "low_away", "patch_rejected", "no_roof_near", "foliage_test", "above_roof_top")
K, ALPHA, MIN_HEIGHT, MIN_POINTS, SHARE, CELL = 12, 0.01, 2.0, 10, 0.3, 1.0
STEEP = 0.3  # |n_z| of a wall's local plane
#: Causes taken together: the building parts under 2 m, the roofs under or beside trees.
GROUPS = {"all_low": ("low_roof_patch", "low_near_roof", "low_away"),
          "all_trees": ("foliage_test", "above_roof_top")}


def _f1(tp, fp, fn):
    p = tp / max(tp + fp, 1)
    r = tp / max(tp + fn, 1)
    return round(100 * 2 * p * r / (p + r), 2) if p + r > 0 else 0.0


def candidate_state(xyz, fields, height, multi):
    """What the building test saw at each candidate (rows of ``cand``): its local plane's
    normal, the roof patches of any height, the highest roof point of its 3 x 3 cells and
    its neighbourhood's foliage test, rebuilt from the written fields."""
    from scipy.spatial import cKDTree

    from lidarstat.classify._buildings import _roof_top
    from lidarstat.stats import binomial_test

    ev = np.asarray(fields["building_evidence"])
    cand = np.flatnonzero(ev > 0)
    pts = np.ascontiguousarray(xyz[cand] - xyz[cand].mean(axis=0))
    _, nb = cKDTree(pts).query(pts, k=K)
    q = pts[nb] - pts[nb].mean(axis=1, keepdims=True)
    val, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", q, q))
    nz = np.abs(vec[:, 2, 0])
    rss = np.maximum(val[:, 0], 0.0)
    del q, vec, val
    mi = multi[cand]
    foliage = binomial_test(mi[nb].sum(axis=1), np.full(cand.size, K), SHARE,
                            alpha=ALPHA).reject
    patch = np.asarray(fields["building_patch"])[cand].astype(np.int64)
    size = np.bincount(patch)
    patch_p = np.asarray(fields["building_patch_p"])[cand]
    roof_patch = (patch > 0) & (size[patch] >= MIN_POINTS) & (patch_p >= ALPHA)
    roof = ev[cand] == 1
    top = _roof_top(pts, roof, CELL)
    ij = np.floor((pts[:, :2] - pts[:, :2].min(axis=0)) / CELL).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    own = np.full(len(pts), -np.inf)  # highest roof point of the point's own cell
    if roof.any():
        cells, inv = np.unique(key, return_inverse=True)
        zmax = np.full(cells.size, -np.inf)
        np.maximum.at(zmax, inv[roof], pts[roof, 2])
        own = zmax[inv]
    return {"cand": cand, "pts": pts, "nb": nb, "nz": nz, "rss": rss, "multi": mi,
            "foliage": foliage, "patch": patch, "roof_patch": roof_patch, "roof": roof,
            "top": top, "height": height[cand],
            "on_plane": np.asarray(fields["building_residual"])[cand] <= 2.576,
            "building": np.isin(ev[cand], (1, 2)), "own_roof_cell": pts[:, 2] < own}


def missed_causes(state, pred, truth, keep, ground, height, sigma, min_object_height=0.5):
    """Missed building points by cause (module docstring), with the F1 each cause's
    perfect recovery would give, and the quartiles of ``sqrt(RSS / (k - 3)) / sigma`` of
    the local planes (about 1 on a plane within the noise `sigma`) of each cause's
    candidates, of the roof-patch points found and of the candidates that are neither
    found nor in the producer's class 6."""
    n = len(pred)
    cause = np.full(n, -1)
    missed = truth & ~pred & keep
    c = {name: i for i, name in enumerate(CAUSES)}
    cause[missed & ground] = c["ground"]
    cause[missed & ~ground & (height < min_object_height)] = c["below_object_height"]
    s = state
    cand = s["cand"]
    low = s["height"] < MIN_HEIGHT
    in_cells = np.isfinite(s["top"])
    tol = np.where(s["multi"], 0.2, 1.0)
    rows = np.full(cand.size, -1)
    rows[s["nz"] < STEEP] = c["wall"]
    for name, sel in (("low_roof_patch", low & s["roof_patch"]),
                      ("low_near_roof", low & in_cells), ("low_away", low),
                      ("patch_rejected", (s["patch"] > 0) & ~s["roof_patch"] & s["on_plane"]),
                      ("no_roof_near", ~in_cells), ("foliage_test", s["foliage"]),
                      ("above_roof_top", s["pts"][:, 2] > s["top"] + tol)):
        rows[(rows < 0) & sel] = c[name]
    m = missed[cand]
    cause[cand[m]] = rows[m]
    tp = int(np.sum(pred & truth & keep))
    fp = int(np.sum(pred & ~truth & keep))
    fn = int(missed.sum())
    out = {"missed": fn, "unexplained": int(np.sum(missed & (cause < 0))),
           "f1": _f1(tp, fp, fn)}
    ratio = np.sqrt(s["rss"] / (K - 3)) / sigma

    def quartiles(sel):
        return [round(float(v), 2) for v in np.quantile(ratio[sel], [0.25, 0.5, 0.75])]

    for name, i in c.items():
        k = int(np.sum(cause == i))
        out[name] = {"points": k, "f1_if_all_recovered": _f1(tp + k, fp, fn - k)}
        if np.any(cause[cand] == i):
            out[name]["plane_sd_over_sigma"] = quartiles(cause[cand] == i)
    kc = keep[cand]
    out["plane_sd_over_sigma"] = {
        "roof_patch_found": quartiles(s["roof"] & kc),
        "other_candidates": quartiles(~s["building"] & ~truth[cand] & kc)}
    for name, group in GROUPS.items():
        k = int(np.isin(cause, [c[g] for g in group]).sum())
        out[name] = {"points": k, "f1_if_all_recovered": _f1(tp + k, fp, fn - k)}
    return out, cause


def recovery_rules(state, pred, truth, keep):
    """True and false points that rules on the largest causes would add, and the F1
    after each (every rule alone on the building class written):

    * ``low_roof_patch_joined``: the points under 2 m of a roof patch that holds roof
      points at least 2 m high;
    * ``low_roof_cells``: candidates under 2 m in a roof cell, not foliage and under the
      cell's roof top plus its tolerance (the roof-cell rule without its 2 m floor);
    * ``low_under_roof``: candidates under 2 m, not foliage, in a 1 m cell that holds a
      roof point and under that roof (below a tested roof plane: walls, porches, eaves);
    * ``walls_under_roof``: candidates on a tested plane (within the normal test's limit
      of a neighbour's accepted plane) that is steep (``|n_z| < 0.3``), in a roof cell and
      below its roof top.
    """
    s = state
    cand = s["cand"]
    low = s["height"] < MIN_HEIGHT
    tol = np.where(s["multi"], 0.2, 1.0)
    joined = np.zeros(s["patch"].max() + 1, bool)
    joined[s["patch"][s["roof"]]] = True
    joined[0] = False
    rules = {"low_roof_patch_joined": low & s["roof_patch"] & joined[s["patch"]],
             "low_roof_cells": low & ~s["foliage"] & (s["pts"][:, 2] <= s["top"] + tol),
             "low_under_roof": low & ~s["foliage"] & s["own_roof_cell"],
             "walls_under_roof": (s["on_plane"] & (s["nz"] < STEEP)
                                  & (s["pts"][:, 2] <= s["top"]))}
    tp = int(np.sum(pred & truth & keep))
    fp = int(np.sum(pred & ~truth & keep))
    fn = int(np.sum(~pred & truth & keep))
    out = {"f1": _f1(tp, fp, fn)}
    for name, rule in rules.items():
        add = np.zeros(len(pred), bool)
        add[cand[rule]] = True
        add &= ~pred & keep
        dt, df = int(np.sum(add & truth)), int(np.sum(add & ~truth))
        out[name] = {"true_added": dt, "false_added": df,
                     "f1_after": _f1(tp + dt, fp + df, fn - dt)}
    return out


def without_patches(fields, reject, building):
    """The fields with the roof patches `reject` no longer roofs: their points' evidence
    is 2 (roof cell) where `building` (the class decided again without them) holds them,
    3 elsewhere, so that :func:`candidate_state` sees the roofs left."""
    ev = np.asarray(fields["building_evidence"]).copy()
    out = np.isin(np.asarray(fields["building_patch"]), reject) & (ev == 1)
    ev[out] = np.where(building[out], 2, 3)
    ev[(ev == 2) & ~building] = 3
    return {**fields, "building_evidence": ev}


def figure(xyz, cause, pred, truth, keep, out, title):
    """Plan view: found building points, false ones, and the missed ones by cause."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"ground": (0.55, 0.35, 0.15), "below_object_height": (0.4, 0.4, 0.4),
               "wall": (0.0, 0.0, 0.0), "low_roof_patch": (1.0, 0.55, 0.0),
               "low_near_roof": (0.95, 0.8, 0.0), "low_away": (0.6, 0.5, 0.0),
               "patch_rejected": (0.6, 0.0, 0.6), "no_roof_near": (0.85, 0.0, 0.0),
               "foliage_test": (0.0, 0.6, 0.6), "above_roof_top": (1.0, 0.4, 0.7)}
    xy = xyz[:, :2] - xyz[:, :2].min(axis=0)
    fig, ax = plt.subplots(figsize=(9.5, 8.6))
    bg = keep & (cause < 0)
    col = np.full((len(xy), 3), 0.9)
    col[pred & truth] = (0.7, 0.88, 0.7)
    col[pred & ~truth] = (0.45, 0.55, 1.0)
    ax.scatter(xy[bg, 0], xy[bg, 1], c=col[bg], s=0.8, linewidths=0)
    for i, name in enumerate(CAUSES):
        m = cause == i
        if m.any():
            ax.scatter(xy[m, 0], xy[m, 1], color=colours[name], s=2.5, linewidths=0,
                       label=f"{name.replace('_', ' ')} ({int(m.sum())})")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, markerscale=4, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              title="missed, by cause", title_fontsize=8)
    ax.set_title(f"{title}: building found (green), false (blue), missed by cause",
                 fontsize=9)
    fig.savefig(out, dpi=80, bbox_inches="tight")
    plt.close(fig)
