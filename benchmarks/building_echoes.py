"""Echo, footprint and strip evidence of the building test's roof patches: what a pulse,
the returns under a patch and the overlap of two flight strips say about a roof against a
clipped hedge, measured per patch and searched as rejection rules.

Used by ``buildings.py``. A roof patch (``building_evidence`` 1) is *false* when most of
its points are outside the producer's building class. Per patch of at least 3 points
(lengths in metres):

* ``points``, ``median_height_m`` (above the ground surface);
* ``single_share``, ``first_share``: its share of single returns and of first returns of
  pulses with several;
* ``pulse_below_share``: the share of its points whose pulse's last return lies more than
  0.5 m below them (pulses joined by GPS time and strip): a hedge is penetrable, a roof
  only at its edges;
* ``footprint_split_share``: among the first returns in the patch's 0.5 m footprint cells
  (whichever surface they hit), the share from pulses with several returns;
* ``below_per_point``, ``below_ground_per_point``: the returns within 0.5 m (plan) of the
  patch and more than 0.5 m under its nearest point, per patch point; those of them
  within 0.5 m of the ground surface;
* ``intensity_rel``: the median intensity of its single returns over that of every roof
  patch's single returns in the file; ``intensity_cv``: their coefficient of variation;
* ``strip_offset``: per pair of strips (``point_source_id``) with at least 5 points on the
  patch each, the median signed distance of one strip's points to the other strip's local
  planes (8 nearest points, normal up), less the file's offset of that pair (the
  points-weighted mean over patches of at least 300 points: the strips' adjustment), in
  units of the file's noise sigma; points-weighted over the pairs, absolute;
  ``strip_spread``: the median absolute deviation of those distances from their median
  (sigma units); ``own_strip_residual``: the median absolute distance of a point to the
  local plane of its own strip's 8 nearest points (sigma units; about 0.7 on a plane).

A file without GPS times or strip ids gets NaN for the features that need them
(``missing``). :func:`rule_search` scores every one- and two-feature rule "reject the
patch when a is beyond t_a (and b beyond t_b)" with each patch's own effect on the
building class (its points and the roof cells decided again without it, in a window
around it) summed over the patches rejected, keeps the rules under which no file's F1
falls, and ranks them by St-Barthelemy's gain; the rules are chosen on the files they are
scored on (an upper bound of what such a rule can do). :func:`mixed_patches` describes the
false patches that hold a large share of class 6 by reference class.
"""

from __future__ import annotations

import itertools

import numpy as np

FEATURES = ("points", "median_height_m", "single_share", "first_share",
            "pulse_below_share", "footprint_split_share", "below_per_point",
            "below_ground_per_point", "intensity_rel", "intensity_cv", "strip_offset",
            "strip_spread", "own_strip_residual")
RASTER = 0.5  # m: the footprint cells
DROP = 0.5  # m: a return this far under the patch is below it
K_LOCAL = 8  # points of a strip's local plane


def _last_z(xyz, rnum, gps, psid):
    """Height of the last return of each point's pulse (its own where the pulse is not
    found): pulses are the returns of one strip with the same GPS time."""
    key = np.round(np.asarray(gps, float) * 1e7).astype(np.int64)
    strip = np.unique(psid, return_inverse=True)[1].astype(np.int64)
    order = np.lexsort((rnum, strip, key))
    k2, s2 = key[order], strip[order]
    new = np.r_[True, (k2[1:] != k2[:-1]) | (s2[1:] != s2[:-1])]
    group = np.cumsum(new) - 1
    last = np.flatnonzero(np.r_[new[1:], True])  # the last row of each group
    out = np.empty(len(xyz))
    out[order] = xyz[order[last[group]], 2]
    return out


def _local_offsets(a, b, k=K_LOCAL):
    """Signed distance of points `a` to the up-oriented orthogonal planes of their `k`
    nearest points of `b`."""
    from scipy.spatial import cKDTree

    kk = min(k, len(b))
    _, nb = cKDTree(b).query(a, k=kk)
    nb = nb.reshape(len(a), kk)
    p = b[nb]
    c = p.mean(axis=1)
    q = p - c[:, None]
    _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", q, q))
    normal = vec[:, :, 0] * np.where(vec[:, 2:3, 0] < 0, -1.0, 1.0)
    return np.einsum("ni,ni->n", a - c, normal)


def patch_features(xyz, ev, patch, attributes, height, sigma, truth):
    """Rows ``(patch, points, true_share, FEATURES[1:]...)`` for every roof patch of at
    least 3 points, and the names of the attributes the file lacks."""
    from scipy.spatial import cKDTree

    nret = np.asarray(attributes["number_of_returns"]).astype(np.int64)
    rnum = np.asarray(attributes["return_number"]).astype(np.int64)
    have = {f: f in attributes for f in ("gps_time", "point_source_id", "intensity")}
    missing = [f for f, ok in have.items() if not ok]
    psid = np.asarray(attributes["point_source_id"]) if have["point_source_id"] else None
    last_z = (_last_z(xyz, rnum, attributes["gps_time"],
                      psid if psid is not None else np.zeros(len(xyz), np.int64))
              if have["gps_time"] else None)
    inten = np.asarray(attributes["intensity"], float) if have["intensity"] else None
    single = nret == 1
    first = (rnum == 1) & (nret > 1)
    roof = ev == 1
    ids, counts = np.unique(patch[roof], return_counts=True)
    keep_ids = ids[(ids > 0) & (counts >= 3)]
    if keep_ids.size == 0:
        return np.zeros((0, 2 + len(FEATURES))), missing
    roof_int = (np.median(inten[roof & single]) if inten is not None
                and (roof & single).any() else np.nan)
    lo = xyz[:, :2].min(axis=0)
    ij = np.floor((xyz[:, :2] - lo) / RASTER).astype(np.int64) + 1
    width = int(ij[:, 1].max()) + 2
    key = ij[:, 0] * width + ij[:, 1]
    order = np.argsort(key, kind="stable")
    skey = key[order]
    plan = cKDTree(xyz[:, :2])
    members = {p: np.flatnonzero(roof & (patch == p)) for p in keep_ids}
    # the strips' adjustment: per pair, the offset on the file's large patches
    pairs = {}
    if psid is not None:
        for p, m in members.items():
            pairs[p] = _strip_pairs(xyz, m, psid)
    system = {}
    for p, pp in pairs.items():
        if members[p].size >= 300:
            for k, (med, n, _, _) in pp.items():
                system.setdefault(k, []).append((med, n))
    system = {k: np.average([a for a, _ in v], weights=[n for _, n in v])
              for k, v in system.items()}
    rows = []
    for p, m in members.items():
        f = {"points": m.size, "median_height_m": float(np.median(height[m])),
             "single_share": float(single[m].mean()), "first_share": float(first[m].mean())}
        f["pulse_below_share"] = (float(np.mean(xyz[m, 2] - last_z[m] > DROP))
                                  if last_z is not None else np.nan)
        cells = np.unique(key[m])
        a, b = np.searchsorted(skey, cells), np.searchsorted(skey, cells, "right")
        inside = order[np.concatenate([np.arange(s, e) for s, e in zip(a, b)])]
        firsts = inside[rnum[inside] == 1]
        f["footprint_split_share"] = (float(np.mean(nret[firsts] > 1)) if firsts.size
                                      else np.nan)
        near = np.unique(np.concatenate(plan.query_ball_point(xyz[m, :2], RASTER)))
        near = near[~np.isin(near, m)]
        if near.size:
            _, j = cKDTree(xyz[m, :2]).query(xyz[near, :2])
            below = xyz[near, 2] < xyz[m[j], 2] - DROP
        else:
            below = np.zeros(0, bool)
        f["below_per_point"] = float(below.sum()) / m.size
        f["below_ground_per_point"] = float(np.sum(below & (height[near] < DROP))) / m.size
        s = m[single[m]]
        if inten is not None and s.size > 2:
            f["intensity_rel"] = float(np.median(inten[s]) / roof_int)
            f["intensity_cv"] = float(np.std(inten[s]) / max(np.mean(inten[s]), 1e-9))
        else:
            f["intensity_rel"] = f["intensity_cv"] = np.nan
        pp = pairs.get(p, {})
        if pp:
            w = np.array([n for _, n, _, _ in pp.values()], float)
            dev = [abs(med - system.get(k, 0.0)) for k, (med, _, _, _) in pp.items()]
            f["strip_offset"] = float(np.average(dev, weights=w)) / sigma
            f["strip_spread"] = float(np.average([v[2] for v in pp.values()],
                                                 weights=w)) / sigma
            f["own_strip_residual"] = float(np.average([v[3] for v in pp.values()],
                                                       weights=w)) / sigma
        else:
            f["strip_offset"] = f["strip_spread"] = f["own_strip_residual"] = np.nan
        rows.append((p, float(truth[m].mean()), *(f[n] for n in FEATURES)))
    return np.array(rows, float), missing


def _strip_pairs(xyz, m, psid):
    """Per pair of strips with >= 5 points on the patch `m`: (median signed offset of the
    first strip's surface above the second's, points, MAD of the offsets, median
    absolute residual to the own strip's local planes)."""
    strips, counts = np.unique(psid[m], return_counts=True)
    strips = strips[counts >= 5]
    out = {}
    for sa, sb in itertools.combinations(strips, 2):
        a, b = xyz[m[psid[m] == sa]], xyz[m[psid[m] == sb]]
        o = np.concatenate([_local_offsets(a, b), -_local_offsets(b, a)])
        med = float(np.median(o))
        own = np.concatenate([_own_residual(a), _own_residual(b)])
        out[(int(sa), int(sb))] = (med, o.size, float(np.median(np.abs(o - med))),
                                   float(np.median(np.abs(own))))
    return out


def _own_residual(a, k=K_LOCAL):
    """Distance of each point to the plane of its `k` nearest other points of its strip."""
    from scipy.spatial import cKDTree

    kk = min(k, len(a) - 1)
    _, nb = cKDTree(a).query(a, k=kk + 1)
    p = a[nb[:, 1:]]
    c = p.mean(axis=1)
    q = p - c[:, None]
    _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", q, q))
    return np.einsum("ni,ni->n", a - c, vec[:, :, 0])


def _wq(v, w, qs=(0.1, 0.25, 0.5, 0.75, 0.9)):
    ok = np.isfinite(v)
    v, w = v[ok], w[ok]
    if v.size == 0:
        return None
    o = np.argsort(v)
    c = np.cumsum(w[o]) / w.sum()
    return [round(float(v[o][min(np.searchsorted(c, q), v.size - 1)]), 3) for q in qs]


def summarise(a, missing):
    """Points-weighted 10/25/50/75/90 % quantiles of every feature, false against true
    patches."""
    out = {"missing_fields": missing}
    if a.size == 0:
        return out
    false = a[:, 1] < 0.5
    for name, g in (("false_patches", false), ("true_patches", ~false)):
        if g.any():
            out[name] = {"patches": int(g.sum()), "points": int(a[g, 2].sum()),
                         **{f: _wq(a[g, 2 + j], a[g, 2]) for j, f in enumerate(FEATURES)
                            if f != "points"}}
    return out


def marginal_effects(xyz, ev, patch, multi, truth, keep, ids, margin=6.0):
    """(building points, true ones) each patch of `ids` removes from the building class
    when it alone is rejected, the roof cells decided again in a window `margin` metres
    around it (``building_joint.redecide``)."""
    from building_joint import redecide

    out = np.zeros((len(ids), 2), np.int64)
    for r, p in enumerate(ids):
        m = (ev == 1) & (patch == p)
        lo, hi = xyz[m, :2].min(axis=0) - margin, xyz[m, :2].max(axis=0) + margin
        box = np.flatnonzero((xyz[:, 0] > lo[0]) & (xyz[:, 1] > lo[1])
                             & (xyz[:, 0] < hi[0]) & (xyz[:, 1] < hi[1]))
        args = (xyz[box], ev[box], patch[box], multi[box])
        before = redecide(*args, np.zeros(0, np.int64)) & keep[box]
        after = redecide(*args, np.array([p], np.int64)) & keep[box]
        gone = before & ~after
        out[r] = int(gone.sum()), int(np.sum(gone & truth[box]))
    return out


def _f1(tp, fp, fn):
    p = tp / max(tp + fp, 1)
    r = tp / max(tp + fn, 1)
    return 100 * 2 * p * r / (p + r) if p + r > 0 else 0.0


def rule_search(tables, effects, counts, target, keep_best=5):
    """Every one- and two-feature rule (thresholds at the pooled 2-98 % quantiles)
    under which no file's F1 falls (each patch's effect from :func:`marginal_effects`,
    summed), ranked by the gain on `target`."""
    names = [n for n in tables if tables[n].size]
    feats = list(FEATURES)
    pooled = np.vstack([tables[n] for n in names])
    grid = {}
    for j, f in enumerate(feats):
        v = pooled[:, 2 + j]
        v = v[np.isfinite(v)]
        grid[f] = np.unique(np.quantile(v, np.linspace(0.02, 0.98, 33))) if v.size else []
    base = {n: _f1(*counts[n]) for n in names}

    def gains(rej):
        g = {}
        for n in names:
            tp, fp, fn = counts[n]
            gone, gone_true = effects[n][rej[n]].sum(axis=0)
            g[n] = _f1(tp - gone_true, fp - (gone - gone_true), fn + gone_true) - base[n]
        return g

    def cond(f, s, t):
        j = 2 + feats.index(f)
        with np.errstate(invalid="ignore"):
            return {n: s * tables[n][:, j] > s * t for n in names}

    found = []
    terms = [(f, s, float(t)) for f in feats for s in (1, -1) for t in grid[f]]
    masks = {tm: cond(*tm) for tm in terms}
    for tm in terms:
        g = gains(masks[tm])
        if min(g.values()) >= -0.005:
            found.append((g[target], [tm], g))
    for (fa, fb) in itertools.combinations(feats, 2):
        ta = [tm for tm in terms if tm[0] == fa]
        tb = [tm for tm in terms if tm[0] == fb]
        for a, b in itertools.product(ta, tb):
            g = gains({n: masks[a][n] & masks[b][n] for n in names})
            if min(g.values()) >= -0.005 and g[target] > 0:
                found.append((g[target], [a, b], g))
    found.sort(key=lambda r: -r[0])
    return [{"rule": " and ".join(f"{f} {'>' if s > 0 else '<'} {t:.3g}" for f, s, t in tm),
             "terms": [[f, s, t] for f, s, t in tm],
             "f1_change_estimated": {n: round(v, 2) for n, v in g.items()}}
            for _, tm, g in found[:keep_best]]


def rejected(a, terms):
    """Patch labels a rule's `terms` (``[feature, sign, threshold]`` each) rejects."""
    from building_joint import rejected as joint_rejected

    return joint_rejected(a, terms, features=FEATURES, first=2)


def mixed_patches(xyz, ev, patch, ref, attributes, a, min_true=0.25, min_points=300):
    """The false roof patches of at least `min_points` that hold at least `min_true` of
    class 6: per reference class, points, median height (file units), share of single
    returns and median intensity."""
    nret = np.asarray(attributes["number_of_returns"])
    inten = attributes.get("intensity")
    out = {}
    for row in a:
        if not (row[1] < 0.5 and row[1] >= min_true and row[2] >= min_points):
            continue
        m = (ev == 1) & (patch == int(row[0]))
        out[str(int(row[0]))] = {
            str(int(c)): {"points": int(np.sum(m & (ref == c))),
                          "median_z": round(float(np.median(xyz[m & (ref == c), 2])), 2),
                          "single_share": round(float(np.mean(nret[m & (ref == c)] == 1)), 3),
                          "median_intensity": (float(np.median(np.asarray(inten)[m & (ref == c)]))
                                               if inten is not None else None)}
            for c in np.unique(ref[m])}
    return out


def section_figure(xyz, ev, patch, ref, ids, out, title, half=1.0, margin=4.0):
    """Sections of the patches `ids` along and across their major axis (points within
    `half` metres of the section line), coloured by the reference class, the patch's
    points ringed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {6: (0.85, 0.1, 0.1), 5: (0.1, 0.6, 0.2), 2: (0.6, 0.4, 0.2)}
    fig, axes = plt.subplots(len(ids), 2, figsize=(11, 3.0 * len(ids)), squeeze=False)
    for r, p in enumerate(ids):
        m = (ev == 1) & (patch == p)
        c = xyz[m, :2].mean(axis=0)
        lo, hi = xyz[m, :2].min(axis=0) - margin, xyz[m, :2].max(axis=0) + margin
        box = np.flatnonzero((xyz[:, 0] > lo[0]) & (xyz[:, 1] > lo[1])
                             & (xyz[:, 0] < hi[0]) & (xyz[:, 1] < hi[1]))
        _, _, vt = np.linalg.svd(xyz[m, :2] - c, full_matrices=False)
        q = xyz[box, :2] - c
        along, across = q @ vt[0], q @ vt[1]
        col = np.array([colours.get(int(k), (0.6, 0.6, 0.6)) for k in ref[box]])
        for ax, t, w, name in ((axes[r, 0], along, across, "along"),
                               (axes[r, 1], across, along, "across")):
            sel = np.abs(w) < half
            ax.scatter(t[sel], xyz[box[sel], 2], c=col[sel], s=4, linewidths=0)
            ring = sel & m[box]
            ax.scatter(t[ring], xyz[box[ring], 2], facecolors="none", edgecolors="k",
                       s=9, linewidths=0.3)
            ax.set_title(f"patch {p}, section {name} its major axis", fontsize=9)
            ax.set_xlabel("m")
            ax.set_ylabel("z (m)")
            ax.set_aspect("equal")
    fig.suptitle(f"{title}: reference class 6 red, 5 green, 2 brown, other grey; "
                 "the patch's points ringed", fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
