"""The moment analysis of one window: the elevation cut and the paper's clustering steps.

Crosilla et al. (2011), per window:

1. density estimates and dip tests of elevation and intensity; the category with the more
   clearly multimodal distribution (smaller dip-test p-value) is analysed first;
2. the sequential skewness/kurtosis analysis of that category gives a separating cycle:
   the values left form the first cluster, the removed ones stay unclassified;
3. the cluster is analysed by the complementary category and split again when that is
   multimodal;
4. steps 2-3 are repeated on the unclassified values until nothing separates.

The ground cut of a window is step 2 on heights above the ground model; the progressive
method of the paper's section 4 splits a window into four while its ground cluster stays
multimodal by the dip test.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..stats import density_estimate, dip_test, sequential_moments, sort_values
from ._cycle import ElevationRule, choose_cycle, skewness_balance_cycle, symmetry_cycle
from ._moments_kernels import sorted_mad
from ._moments_options import MomentsMethod, MomentsOptions
from ._moments_result import MomentsStep, curve_step, thin_curves
from ._surface import cell_keys

__all__ = ["analyse", "dip_tests", "paper_clusters", "progressive_cut"]

#: Values a dip test takes as they are (``dip_test``'s ``max_points``): a larger sample is
#: subsampled, and the sample sorted by the test.
_DIP_MAX_POINTS = 20000


def analyse(values, category, p: MomentsOptions, *, window, step, population, dips,
            record=True, sorted_values=None):
    """Sequential moments of one population and the cycle choice; (choice, MomentsStep).
    `sorted_values`: ``np.sort(values)`` when the caller has it."""
    ch, rec, _ = _analysis(values, category, p, window=window, step=step,
                           population=population, dips=dips, record=record,
                           sorted_values=sorted_values)
    return ch, rec


def _analysis(values, category, p: MomentsOptions, *, window, step, population, dips,
              record=True, sorted_values=None):
    """:func:`analyse`, and the values sorted: ``(choice, MomentsStep, sorted values)``.
    An elevation cut by the symmetry rule forms the moments of the cycles up to the cut
    and of the curves a record keeps, not of every cycle (:func:`~._cycle.symmetry_cycle`:
    the same choice and curves)."""
    if (category == "elevation" and p.method is MomentsMethod.MOMENTS
            and p.elevation_rule == ElevationRule.SYMMETRY
            and (step != 1 or p.cycle is None) and values.size >= 2):
        xs = sort_values(values) if sorted_values is None else sorted_values
        if np.isfinite(xs[0]) and np.isfinite(xs[-1]):
            m = xs.size - max(2, min(4, xs.size)) + 1
            ch, curves = symmetry_cycle(xs, min_points=p.min_points, smoothing=p.smoothing,
                                        curve_step=curve_step(m) if record else 0)
            return ch, _record(values, xs, category, p, ch, curves, window=window, step=step,
                               population=population, dips=dips, record=record), xs
    sm = sequential_moments(values, min_points=max(2, min(4, values.size)),
                            sorted_values=sorted_values)
    if p.method is MomentsMethod.SKEWNESS_BALANCING:
        ch = skewness_balance_cycle(sm)
    else:
        ch = choose_cycle(sm, category, min_points=p.min_points, smoothing=p.smoothing,
                          cycle=p.cycle if step == 1 else None,
                          elevation_rule=p.elevation_rule)
    rec = _record(values, sm.sorted_values, category, p, ch,
                  thin_curves(sm) if record else None, window=window, step=step,
                  population=population, dips=dips, record=record)
    return ch, rec, sm.sorted_values


def _record(values, xs, category, p, ch, curves, *, window, step, population, dips, record):
    """The analysis's MomentsStep (None unless `record`); `xs`: the values sorted."""
    if not record:
        return None
    de = (density_estimate(values, bandwidth=p.bandwidth, gridsize=256, sorted_values=xs)
          if p.evidence else None)
    return MomentsStep(window=window, step=step, population=population, category=category,
                       n=int(values.size), dip=dips, choice=ch, curves=curves, density=de)


def dip_tests(cats: dict, p: MomentsOptions, sorted_cats=None) -> dict:
    """Dip test of every category: statistic, p-value and decision at level ``alpha``.
    `sorted_cats`: the categories' values sorted, where the caller has them."""
    out = {}
    for name, v in cats.items():
        t = dip_test(v, alpha=p.alpha, rng=p.seed,
                     sorted_values=None if sorted_cats is None else sorted_cats.get(name))
        out[name] = {"dip": float(t.statistic), "pvalue": float(t.pvalue),
                     "multimodal": bool(t.reject)}
    return out


def _quadrants(xy, size, origin):
    """Indices of the points in each ``size`` square from `origin` (occupied ones only)."""
    key = cell_keys(xy, size, origin=origin)
    o = np.argsort(key, kind="stable")
    ks = key[o]
    b = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True])
    return [o[a:e] for a, e in zip(b[:-1], b[1:])]


def _cluster_bound(kept, z):
    """``median + z x 1.4826 MAD`` of the kept heights, sorted ascending (-inf for fewer
    than 8 values).

    The sequential cut stops where what is left is symmetric; on ground that the surface
    follows only roughly (sparse or steep terrain) that stop lies inside the ground's own
    upper tail. The cut is never placed closer to the ground cluster's centre than `z`
    robust standard deviations of that cluster. The median and the median absolute
    deviation are read from the sorted values (:func:`~._moments_kernels.sorted_mad`)
    as ``np.median`` takes them.
    """
    n = kept.size
    if n < 8:
        return -np.inf
    med = np.mean(kept[(n - 1) // 2: n // 2 + 1])
    return float(med + z * 1.4826 * sorted_mad(kept, float(med)))


def progressive_cut(xy, h, idx, size, parent_thr, p: MomentsOptions, window_id, steps,
                    windows, record, first=None):
    """Cut of one window on heights; split into four while its ground stays multimodal.

    Returns ``[(indices, threshold), ...]``. A window whose heights do not separate keeps
    its parent's threshold (a window lying on one large roof is unimodal too, so "nothing
    separates" must not mean "everything is ground"). Appends the window's description
    to `windows` and its analysis to `steps`. `first`: a dict that receives this
    window's own analysis (``dips``, ``choice``, ``record``), which the paper's first
    clustering step of the same heights repeats (:func:`paper_clusters`).
    """
    whole = idx.size == h.size  # the root window: idx is every position, in order
    v = h if whole else h[idx]
    wxy = xy if whole else xy[idx]
    thr = parent_thr
    rec = None
    vs = None  # v sorted: for the analysis and the dip tests
    if idx.size >= 2 * p.min_points + 4:
        vs = sort_values(v)
        dips = (dip_tests({"elevation": v}, p, {"elevation": vs}) if record and p.evidence
                else {})
        ch, rec, vs = _analysis(v, "elevation", p, window=window_id, step=1,
                                population="heights above the ground model", dips=dips,
                                record=record, sorted_values=vs)
        if first is not None:
            first.update(dips=dips, choice=ch, record=rec)
        if ch.cycle is not None:
            thr = min(ch.threshold, parent_thr)
            if p.ground_spread > 0 and p.method is MomentsMethod.MOMENTS:
                # the heights <= thr: a prefix of the sorted heights
                kept = vs[:int(np.searchsorted(vs, thr, side="right"))]
                thr = max(thr, _cluster_bound(kept, p.ground_spread))
    info = {"window": window_id, "size": size, "n": int(idx.size),
            "x0": float(wxy[:, 0].min()) if idx.size else None,
            "y0": float(wxy[:, 1].min()) if idx.size else None,
            "threshold": float(thr) if np.isfinite(thr) else None, "split": False}
    kept = v <= thr
    if (size / 2 >= p.min_window and idx.size >= 4 * p.min_window_points
            and kept.sum() >= 8):
        # the heights <= thr sorted: a prefix of the sorted heights
        d = dip_test(v[kept], alpha=p.alpha, rng=p.seed,
                     sorted_values=None if vs is None else vs[:int(kept.sum())])
        info["ground_dip_pvalue"] = float(d.pvalue)
        if d.reject:
            info["split"] = True
            windows.append(info)
            if rec is not None:
                steps.append(rec)
            out = []
            origin = (wxy[:, 0].min(), wxy[:, 1].min())
            # a copy of a whole window's rows: the read-only view would be a second
            # variant of the compiled cell keys
            for j, child in enumerate(_quadrants(xy[idx] if whole else wxy, size / 2, origin)):
                out.extend(progressive_cut(xy, h, idx[child], size / 2, thr, p,
                                           f"{window_id}.{j}", steps, windows, record))
            return out
    windows.append(info)
    if rec is not None:
        steps.append(rec)
    return [(idx, thr)]


def paper_clusters(cats: dict, p: MomentsOptions, window, steps: list, first_cluster: int,
                   first=None):
    """The paper's steps 1-4 on one window's values; (cluster label per point, next id).

    `first`: the window's own elevation analysis from :func:`progressive_cut` (its
    ``first`` dict) on the same values ``cats["elevation"]``: step 1 takes its dip test
    and, when it analyses elevation, its moments and cycle, instead of repeating them
    (the same values in the same order: the same numbers)."""
    n = next(iter(cats.values())).size
    labels = np.zeros(n, np.int32)
    todo = np.arange(n)
    next_id = first_cluster
    step = 1
    known = first if first and first.get("record") is not None else None
    while todo.size >= 2 * p.min_points and step <= p.max_steps:
        sub = {k: v[todo] for k, v in cats.items()}
        done = {}  # step 1: the elevation's dip test the window's cut made
        if step == 1 and known is not None and "elevation" in known["dips"]:
            done["elevation"] = known["dips"]["elevation"]
        # sorted once for the dip tests and the analysis (a dip test of more values
        # draws a sample and sorts that: the analysis sorts its own then)
        ssub = {k: sort_values(v) for k, v in sub.items()
                if v.size <= _DIP_MAX_POINTS and k not in done}
        tested = dip_tests({k: v for k, v in sub.items() if k not in done}, p, ssub)
        dips = {k: done[k] if k in done else tested[k] for k in sub}
        multi = {k: d for k, d in dips.items() if d["multimodal"]}
        if not multi and step > 1:
            break
        pool = multi or dips
        cat = min(pool, key=lambda k: (pool[k]["pvalue"], -pool[k]["dip"]))
        if step == 1 and cat == "elevation" and known is not None:
            ch = known["choice"]
            rec = replace(known["record"], window=window, population="window", dip=dips)
        else:
            ch, rec = analyse(sub[cat], cat, p, window=window, step=step,
                              population="window" if step == 1 else "unclassified",
                              dips=dips, sorted_values=ssub.get(cat))
        del ssub
        steps.append(rec)
        if ch.cycle is None:
            break
        low = sub[cat] <= ch.threshold
        cluster = todo[low]
        rest = todo[~low]
        # step 3: the cluster by the complementary category
        comp = [k for k in cats if k != cat]
        split = False
        if comp and cluster.size >= 2 * p.min_points:
            c2 = comp[0]
            v2 = cats[c2][cluster]
            vs2 = sort_values(v2) if v2.size <= _DIP_MAX_POINTS else None
            d2 = dip_tests({c2: v2}, p, {c2: vs2})
            if d2[c2]["multimodal"]:
                ch2, rec2 = analyse(v2, c2, p, window=window, step=step,
                                    population=f"cluster {next_id}", dips=d2,
                                    sorted_values=vs2)
                steps.append(rec2)
                if ch2.cycle is not None:
                    lo2 = v2 <= ch2.threshold
                    labels[cluster[lo2]] = next_id
                    labels[cluster[~lo2]] = next_id + 1
                    next_id += 2
                    split = True
        if not split:
            labels[cluster] = next_id
            next_id += 1
        todo = rest
        step += 1
    if todo.size:
        labels[todo] = next_id
        next_id += 1
    return labels, next_id
