"""Per-patch evidence of the building test's roof patches, false against true.

Used by ``buildings.py``. A roof patch (``building_evidence`` 1) is *false* when most of
its points are not in the producer's building class, *true* otherwise. For every patch
of at least 3 points (lengths in metres, 1 m cells):

* ``points``, ``width_m`` (sqrt(12) times the std along its minor planimetric axis: a
  hedge is a narrow patch) and ``median_height_m`` (above the ground surface);
* ``under_share``: the share of all returns (ground included) in the patch's interior
  cells (cells whose four neighbours hold the patch too) more than 0.5 m below the
  patch's lowest point in that cell. A crown lets pulses through its depth, a roof
  none (except over a lower roof level);
* ``ring_foliage_share``: the share of the cells around the patch (its eight-neighbour
  ring) holding at least two candidates that are on no tested plane and lie less than
  1 m below the patch's lowest point in the cell beside them: foliage around the patch
  at its own height (a crown fragment is surrounded by it, a roof by a drop);
* ``multi_share``: its share of non-last returns; ``intensity_cv``: the coefficient of
  variation of its intensity;
* ``planes``: how many of its points' own local planes the test accepted, as a share.

Returned as points-weighted quartiles per group and the points of false and true
patches each simple rule on one feature would remove, with the roof-cell points whose
nearest roof point lies on a false patch (what rejecting the false patches would also
remove from the roof cells), and the points a relative return-share test would remove
(:func:`relative_share_test`).
"""

from __future__ import annotations

import numpy as np

FEATURES = ("points", "width_m", "median_height_m", "under_share", "ring_foliage_share",
            "multi_share", "intensity_cv", "planes")


def _cells(xy, cell=1.0):
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64) + 2
    width = int(ij[:, 1].max()) + 4
    return ij[:, 0] * width + ij[:, 1], width


def patch_table(xyz, ev, patch, fields, multi, intensity, height, ground, pred, truth,
                z_crit=2.576):
    """One row per roof patch of at least 3 points: (id, false, FEATURES...)."""
    key, width = _cells(xyz[:, :2])
    order = np.argsort(key, kind="stable")
    skey = key[order]
    cand = ev > 0
    planar = fields["building_plane_p"] >= 0.01
    on_plane = fields["building_residual"] <= z_crit
    foliage = cand & ~on_plane & (ev != 1)
    ring_dirs = np.array([width, -width, 1, -1, width + 1, width - 1, -width + 1,
                          -width - 1])
    inten = None if intensity is None else np.asarray(intensity, float)
    on = pred & (ev == 1)
    rows = []
    for p in np.unique(patch[on]):
        m = np.flatnonzero(on & (patch == p))
        if m.size < 3:
            continue
        xy = xyz[m, :2] - xyz[m, :2].mean(axis=0)
        s = np.linalg.svd(xy, compute_uv=False)
        wid = float(np.sqrt(12.0) * s[1] / np.sqrt(m.size))
        cells, inv = np.unique(key[m], return_inverse=True)
        zmin = np.full(cells.size, np.inf)
        np.minimum.at(zmin, inv, xyz[m, 2])
        inside = np.isin(cells[:, None] + ring_dirs[None, :4], cells).all(axis=1)
        under = total = 0
        for c, z0 in zip(cells[inside], zmin[inside]):
            a, b = np.searchsorted(skey, c), np.searchsorted(skey, c, "right")
            total += b - a
            under += int(np.sum(xyz[order[a:b], 2] < z0 - 0.5))
        ring = cells[:, None] + ring_dirs[None, :]
        level = np.repeat(zmin, ring_dirs.size)
        ring = ring.ravel()
        outside = ~np.isin(ring, cells)
        ring, level = ring[outside], level[outside]
        uniq, first = np.unique(ring, return_inverse=True)
        low = np.full(uniq.size, np.inf)
        np.minimum.at(low, first, level)
        occupied = 0
        for c, z0 in zip(uniq, low):
            a, b = np.searchsorted(skey, c), np.searchsorted(skey, c, "right")
            q = order[a:b]
            occupied += int(np.sum(foliage[q] & (xyz[q, 2] > z0 - 1.0)) >= 2)
        cv = (float(np.std(inten[m]) / max(np.mean(inten[m]), 1e-9))
              if inten is not None else np.nan)
        rows.append((int(p), bool(truth[m].mean() < 0.5), m.size, wid,
                     float(np.median(height[m])), under / max(total, 1),
                     occupied / max(uniq.size, 1), float(multi[m].mean()), cv,
                     float(planar[m].mean())))
    return rows


def _wq(v, w, qs=(0.25, 0.5, 0.75)):
    """Quantiles of `v` weighted by `w` (points of each patch)."""
    o = np.argsort(v)
    c = np.cumsum(w[o]) / w.sum()
    return [round(float(v[o][min(np.searchsorted(c, q), v.size - 1)]), 3) for q in qs]


def summarise(rows, xyz, ev, patch, pred, truth):
    """Quartiles per group, the points one-feature rules remove, and the roof-cell points
    beside false patches."""
    if not rows:
        return {}
    a = np.array([r[2:] for r in rows], float)
    false = np.array([r[1] for r in rows], bool)
    pts = a[:, 0]
    out = {}
    for name, g in (("false_patches", false), ("true_patches", ~false)):
        if g.any():
            out[name] = {"patches": int(g.sum()), "points": int(pts[g].sum()),
                         **{f: _wq(a[g, j], pts[g]) for j, f in enumerate(FEATURES)}}
    # what a rule "reject the patch when feature beyond t" would remove, at the false
    # patches' points-weighted median: points of false and of true patches
    rules = {}
    for j, f in enumerate(FEATURES[1:], start=1):
        if not false.any() or not np.isfinite(a[false, j]).any():
            continue
        t = _wq(a[false, j], pts[false], (0.5,))[0]
        below = a[:, j] <= t if f in ("width_m", "median_height_m", "planes") else \
            a[:, j] >= t
        rules[f] = {"threshold": t, "removes_false_points": int(pts[false & below].sum()),
                    "removes_true_points": int(pts[~false & below].sum())}
    out["one_feature_rules_at_false_median"] = rules
    from scipy.spatial import cKDTree

    roof = np.flatnonzero(pred & (ev == 1))
    cells = pred & (ev == 2)
    if roof.size and cells.any():
        _, j = cKDTree(xyz[roof, :2]).query(xyz[cells, :2])
        false_ids = np.array([r[0] for r in rows if r[1]], np.int64)
        beside = np.isin(patch[roof[j]], false_ids)
        tr = truth[cells]
        out["roof_cell_points_beside_false_patches"] = {
            "false": int(np.sum(beside & ~tr)), "of_false": int(np.sum(~tr)),
            "true": int(np.sum(beside & tr)), "of_true": int(np.sum(tr))}
    return out


def relative_share_test(xyz, ev, patch, multi, pred, truth, k=12, alpha=0.01,
                        factors=(1.0, 2.0, 3.0)):
    """The roof patches' non-last returns against the file's own roofs: a patch point is
    interior when its `k` nearest candidates lie on its patch, an edge point otherwise;
    the file's roof patches give the shares ``p_i`` and ``p_e`` of non-last returns of
    interior and edge points, and a patch is rejected when its count is significantly
    above ``c (n_i p_i + n_e p_e)`` (binomial upper tail at the mean share, level
    `alpha`: conservative against the two binomials' sum). Returns, per factor ``c``,
    the points of false and true roof patches it rejects."""
    from scipy.spatial import cKDTree

    from lidarstat.stats import binomial_test

    cand = np.flatnonzero(ev > 0)
    on = pred & (ev == 1)
    if cand.size <= k or not on.any():
        return {}
    _, nb = cKDTree(xyz[cand]).query(xyz[cand], k=k)
    pc = patch[cand]
    interior = np.zeros(len(ev), bool)
    interior[cand] = (pc[nb] == pc[:, None]).all(axis=1) & (pc > 0)
    size = int(patch.max()) + 1
    count = lambda m, w=None: np.bincount(patch[m], weights=w, minlength=size)
    n, n_i = count(on), count(on & interior)
    x = count(on, multi[on].astype(float))
    p_i = float(multi[on & interior].mean()) if (on & interior).any() else 0.0
    p_e = float(multi[on & ~interior].mean()) if (on & ~interior).any() else 0.0
    ids = np.flatnonzero(n > 0)
    ids = ids[ids > 0]
    tp = count(on, truth[on].astype(float))
    false = tp[ids] / n[ids] < 0.5
    out = {"interior_share": round(p_i, 4), "edge_share": round(p_e, 4)}
    for c in factors:
        rej = np.zeros(ids.size, bool)
        for j, q in enumerate(ids):  # the null share differs per patch
            p0 = min(1.0, c * (n_i[q] * p_i + (n[q] - n_i[q]) * p_e) / n[q])
            rej[j] = bool(binomial_test(x[q], n[q], p0, alpha=alpha).reject)
        out[f"factor_{c:g}"] = {"removes_false_points": int(n[ids][rej & false].sum()),
                                "removes_true_points": int(n[ids][rej & ~false].sum())}
    return out


def figure(tables, out):
    """Histograms of the features of false and true patches (points-weighted), one row
    per file of `tables` (name -> rows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    feats = ("width_m", "median_height_m", "under_share", "ring_foliage_share",
             "multi_share")
    fig, axes = plt.subplots(len(tables), len(feats), figsize=(13, 2.3 * len(tables)),
                             squeeze=False)
    for r, (name, rows) in enumerate(tables.items()):
        a = np.array([x[2:] for x in rows], float)
        false = np.array([x[1] for x in rows], bool)
        for c, f in enumerate(feats):
            j = FEATURES.index(f)
            ax = axes[r, c]
            v = a[:, j]
            hi = float(np.nanquantile(v, 0.98)) if f in ("width_m", "median_height_m") \
                else 1.0
            bins = np.linspace(0.0, max(hi, 1e-6), 25)
            for g, col, lab in ((~false, (0.15, 0.6, 0.2), "true"),
                                (false, (0.1, 0.2, 0.85), "false")):
                if g.any():
                    ax.hist(np.clip(v[g], 0, hi), bins=bins, weights=a[g, 0] / a[g, 0].sum(),
                            histtype="step", color=col, label=lab)
            if r == 0:
                ax.set_title(f, fontsize=9)
            if c == 0:
                ax.set_ylabel(name, fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("roof patches false (blue) and true (green) against the producer's "
                 "class 6, share of points", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
