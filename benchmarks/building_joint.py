"""Joint evidence of the building test's roof patches: what a building has around and
inside its roof that a clipped hedge or a crown fragment has not, measured per patch and
searched two features at a time.

Used by ``buildings.py``. A roof patch (``building_evidence`` 1) is *false* when most of
its points are outside the producer's building class. Per patch of at least 3 points
(lengths in metres, 0.5 m raster of the patch's footprint, closed and hole-filled):

The raster's cell is 0.5 m or, on sparser data, two mean point spacings of the file's
roof patches; its footprint is closed over two cells.

* ``length_m``: its extent along its major planimetric axis;
* ``inradius_m``: the largest distance from a footprint cell to the footprint's edge
  (a hedge or a hedge enclosure is thin everywhere, a roof is not);
* ``band_ground_share``: the share of the returns in the 1 m band around the footprint
  within 0.5 m of the ground surface (a wall drops to the ground: a building's band is
  ground where no eave hides it);
* ``band_mid_share``: the share of the band's cells whose highest return lies between
  0.5 m above the ground and 0.5 m under the patch (the sides of a hedge or of a crown);
* ``intensity_rel``: the patch's median intensity over the median intensity of every
  roof-patch point of the file (calibrated on the file's own roofs);
* ``multi_rel``: its share of non-last returns over the share of the file's wide roof
  patches (inradius at least 2 m: the file's confident roofs);
* ``roughness``: the median of its points' local-plane statistic ``RSS / sigma^2``
  (chi-square with ``k - 3`` degrees of freedom on a plane).

:func:`pair_search` tries every rule "reject a patch when feature a is beyond t_a and
feature b beyond t_b" (thresholds at the pooled 5-95 % quantiles) and keeps the rules that
cost no file more than 0.3 points of F1, ranked by St-Barthelemy's gain. The rules are
chosen on the same files they are scored on (an upper bound of what such a rule can do),
and count the roof-patch points only (a rejected patch's roof cells are not re-decided).
"""

from __future__ import annotations

import itertools

import numpy as np

FEATURES = ("length_m", "inradius_m", "band_ground_share", "band_mid_share",
            "intensity_rel", "multi_rel", "roughness")
RASTER = 0.5  # m: the finest footprint cell


def patch_features(xyz, ev, patch, plane_p, multi, intensity, height, truth, k=12):
    """Rows ``(patch, points, true_share, FEATURES...)`` for every roof patch of >= 3
    points."""
    from scipy import ndimage
    from scipy.stats import chi2

    roof = ev == 1
    ids = np.unique(patch[roof])
    if ids.size == 0:
        return np.zeros((0, 3 + len(FEATURES)))
    lo = xyz[:, :2].min(axis=0)
    # two mean point spacings of the roofs (their points per occupied 1 m cell)
    _, per_cell = np.unique(np.floor(xyz[roof, :2] - lo).astype(np.int64), axis=0,
                            return_counts=True)
    raster = max(RASTER, 2.0 / np.sqrt(np.median(per_cell)))
    ij = np.floor((xyz[:, :2] - lo) / raster).astype(np.int64)
    inten = None if intensity is None else np.asarray(intensity, float)
    roof_int = np.median(inten[roof]) if inten is not None else np.nan
    rows = []
    for p in ids:
        m = np.flatnonzero(roof & (patch == p))
        if m.size < 3:
            continue
        a0, a1 = ij[m].min(axis=0) - 4, ij[m].max(axis=0) + 5
        near = np.flatnonzero((ij[:, 0] >= a0[0]) & (ij[:, 0] < a1[0])
                              & (ij[:, 1] >= a0[1]) & (ij[:, 1] < a1[1]))
        shape = tuple(a1 - a0)
        fp = np.zeros(shape, bool)
        fp[ij[m, 0] - a0[0], ij[m, 1] - a0[1]] = True
        fp = ndimage.binary_fill_holes(ndimage.binary_closing(fp, iterations=2) | fp)
        inradius = float(ndimage.distance_transform_edt(fp).max() * raster)
        band = ndimage.binary_dilation(fp, iterations=max(1, round(1.0 / raster))) & ~fp
        loc = ij[near] - a0
        in_band = band[loc[:, 0], loc[:, 1]]
        hb = height[near][in_band]
        top = float(np.median(height[m]))
        cell = loc[in_band, 0] * shape[1] + loc[in_band, 1]
        hmax = np.full(shape[0] * shape[1], -np.inf)
        np.maximum.at(hmax, cell, hb)
        hmax = hmax[np.unique(cell)]
        xy = xyz[m, :2] - xyz[m, :2].mean(axis=0)
        major = np.linalg.svd(xy, full_matrices=False)[2][0]
        rows.append((p, m.size, float(truth[m].mean()), float(np.ptp(xy @ major)), inradius,
                     float(np.mean(hb < 0.5)) if hb.size else np.nan,
                     float(np.mean((hmax >= 0.5) & (hmax < top - 0.5))) if hmax.size
                     else np.nan,
                     float(np.median(inten[m]) / roof_int) if inten is not None else np.nan,
                     float(multi[m].mean()),
                     float(np.median(chi2.isf(np.clip(plane_p[m], 1e-300, 1.0), k - 3)))))
    a = np.array(rows, float)
    wide = a[:, 4] >= 2.0
    n = a[:, 1]
    p0 = (float(np.sum(a[wide, 8] * n[wide]) / n[wide].sum()) if wide.any()
          else float(np.sum(a[:, 8] * n) / n.sum()))
    a[:, 8] = a[:, 8] / max(p0, 1e-3)
    return a


def summarise(a):
    """Points-weighted quartiles of every feature over the false and the true patches."""
    out = {}
    if a.size == 0:
        return out
    false = a[:, 2] < 0.5
    for name, g in (("false_patches", false), ("true_patches", ~false)):
        if not g.any():
            continue
        w = a[g, 1]
        q = {"patches": int(g.sum()), "points": int(w.sum())}
        for j, f in enumerate(FEATURES, start=3):
            v = a[g, j]
            ok = np.isfinite(v)
            if not ok.any():
                continue
            o = np.argsort(v[ok])
            c = np.cumsum(w[ok][o]) / w[ok].sum()
            q[f] = [round(float(v[ok][o][min(np.searchsorted(c, t), ok.sum() - 1)]), 3)
                    for t in (0.25, 0.5, 0.75)]
        out[name] = q
    return out


def _f1(tp, fp, fn):
    return 200.0 * tp / max(2.0 * tp + fp + fn, 1.0)


def pair_search(tables, counts, target, keep=10, max_loss=0.3):
    """Two-feature rejection rules scored on every file (`tables`: name -> patch array,
    `counts`: name -> (TP, FP, FN) of the building class): the `keep` rules of largest
    gain on `target` among those that lower no file's F1 by more than `max_loss`."""
    names = list(tables)
    pooled = np.vstack([tables[n] for n in names if tables[n].size])
    grid = {f: np.unique(np.nanquantile(pooled[:, j], np.linspace(0.05, 0.95, 19)))
            for j, f in enumerate(FEATURES, start=3)}
    base = {n: _f1(*counts[n]) for n in names}
    found = []
    for (ja, fa), (jb, fb) in itertools.combinations(enumerate(FEATURES, start=3), 2):
        for sa, sb in itertools.product((1, -1), repeat=2):
            for ta in grid[fa]:
                for tb in grid[fb]:
                    gain = {}
                    for n in names:
                        a = tables[n]
                        if a.size == 0:
                            gain[n] = 0.0
                            continue
                        with np.errstate(invalid="ignore"):
                            rej = (sa * a[:, ja] > sa * ta) & (sb * a[:, jb] > sb * tb)
                        rt = float(np.sum(a[rej, 1] * a[rej, 2]))
                        rf = float(np.sum(a[rej, 1])) - rt
                        tp, fp, fn = counts[n]
                        gain[n] = _f1(tp - rt, fp - rf, fn + rt) - base[n]
                    if min(gain.values()) >= -max_loss:
                        found.append((gain[target], fa, sa, float(ta), fb, sb, float(tb),
                                      gain))
    found.sort(key=lambda r: -r[0])
    return [{"rule": f"{fa} {'>' if sa > 0 else '<'} {ta:.3g} and "
                     f"{fb} {'>' if sb > 0 else '<'} {tb:.3g}",
             "terms": [[fa, sa, ta], [fb, sb, tb]],
             "f1_change_patch_points": {n: round(g, 2) for n, g in gains.items()}}
            for _, fa, sa, ta, fb, sb, tb, gains in found[:keep]]


def rejected(a, terms, features=FEATURES, first=3):
    """Patch labels a rule's `terms` (``[feature, sign, threshold]`` each) rejects; the
    columns of `a` from `first` on hold `features`, column 0 the patch label."""
    rej = np.ones(len(a), bool)
    with np.errstate(invalid="ignore"):
        for f, sign, t in terms:
            rej &= sign * a[:, first + features.index(f)] > sign * t
    return a[rej, 0].astype(np.int64)


def redecide(xyz, ev, patch, multi, reject, cell=1.0):
    """The building class once the roof patches `reject` are not roofs: the roof cells
    are decided again against the roofs left (the highest roof point of the 3 x 3 cells,
    1 m above it for a single or last return, 0.2 m for a non-last one); a rejected
    patch's points join a roof cell as any other candidate does. The foliage test is not
    repeated (a roof patch's points passed its share test)."""
    from lidarstat.classify._buildings import _TOL_MULTI, _TOL_SINGLE, _roof_top

    cand = np.flatnonzero(ev > 0)
    e, pc, z = ev[cand], patch[cand], xyz[cand, 2]
    out_ = np.isin(pc, reject) & (e == 1)
    roof = (e == 1) & ~out_
    top = _roof_top(np.ascontiguousarray(xyz[cand], float), roof, cell)
    tol = np.where(multi[cand], _TOL_MULTI, _TOL_SINGLE)
    building = np.zeros(len(ev), bool)
    building[cand] = roof | (((e == 2) | out_) & (z <= top + tol))
    return building


def figure(tables, out, pairs=(("inradius_m", "band_ground_share"),
                               ("intensity_rel", "multi_rel"),
                               ("band_mid_share", "roughness"))):
    """False (blue) and true (green) roof patches on pairs of features, one row per file
    of `tables` (name -> patch array); marker area grows with the patch's points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(tables), len(pairs), figsize=(12, 3.0 * len(tables)),
                             squeeze=False)
    for r, (name, a) in enumerate(tables.items()):
        false = a[:, 2] < 0.5
        for c, (fa, fb) in enumerate(pairs):
            ax = axes[r, c]
            x, y = a[:, 3 + FEATURES.index(fa)], a[:, 3 + FEATURES.index(fb)]
            for g, col in ((~false, (0.15, 0.6, 0.2)), (false, (0.1, 0.2, 0.85))):
                ax.scatter(x[g], y[g], s=4 + 60 * np.sqrt(a[g, 1] / a[:, 1].max()),
                           color=col, alpha=0.6, linewidths=0)
            if fa in ("roughness", "multi_rel", "intensity_rel"):
                ax.set_xscale("symlog", linthresh=0.1)
            if fb in ("roughness", "multi_rel", "intensity_rel"):
                ax.set_yscale("symlog", linthresh=0.1)
            ax.set_xlabel(fa, fontsize=8)
            ax.set_ylabel(f"{name}\n{fb}" if c == 0 else fb, fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle("roof patches false (blue) and true (green) against the producer's "
                 "class 6, joint features", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
