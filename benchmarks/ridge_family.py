#!/usr/bin/env python
"""Ridges on the independent scene family: the automatic scale against a fixed ``k = 50``.

The scenes are those of ``tests/independent/indep_ridges.py`` (plain NumPy, exact truth,
not ``lidarstat.synth``): Gaussian and cylindrical crest and trench profiles along
straight and circular axes, random azimuths, widths, heights, spacings (0.01 to 0.02 m)
and noise (0.5 to 2 mm along z); planes, spheres and cylinders for "no ridge there".
For every scene and both scales: the recall of each true line (share of its length,
beyond 0.1 m of the scene's ends, with a detected point of its type within one spacing:
crest and ravine lines of the Gaussian profiles, crease lines at the feet of the
cylindrical ones), the precision (share of crest, ravine and crease points within 2.5
spacings of a true line), the crease points on the Gaussian scenes (none is true), the
number of ridge and crease points on the null scenes, the umbilic share and the wall seconds (machine shared:
timings are indicative, ratios in the same run).

Usage::

    PYTHONPATH=src python benchmarks/ridge_family.py            # 2 seeds per configuration,
                                                                # key "family" of
                                                                # benchmarks/results_ridges.json
    PYTHONPATH=src python benchmarks/ridge_family.py --seeds 1 --no-write
    PYTHONPATH=src python benchmarks/ridge_family.py --size-only  # only family.scale_size
    PYTHONPATH=src python benchmarks/ridge_family.py --family-only  # the scale's null and
                                                                   # size kept
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE.parent / "tests" / "independent"))

from indep_ridges import (line_recall, make_null_scene, make_ridge_scene,  # noqa: E402
                          plane_scale_statistic, ridge_precision)

from lidarstat.segment import ridges  # noqa: E402

SCALES = {"auto": {}, "k50": {"k": 50}}


def run_ridge_scene(kind, sign, curved, seed):
    with np.errstate(divide="ignore"):
        scene = make_ridge_scene(1000 * seed + 7, kind=kind, sign=sign, curved=curved)
    row = dict(kind=kind, sign=sign, curved=curved, seed=seed, points=len(scene.xyz),
               **{k: round(v, 4) for k, v in scene.params.items()
                  if k in ("spacing", "sigma", "amp", "width")})
    for name, kw in SCALES.items():
        t0 = time.perf_counter()
        res = ridges(scene.xyz, **kw)
        dt = time.perf_counter() - t0
        rec = line_recall(scene, res["ridge"], scene.xyz, margin=0.1)
        row[name] = dict(seconds=round(dt, 2), recall=[round(r, 3) for _, r in rec],
                         line_types=[int(t) for t, _ in rec],
                         precision=round(ridge_precision(scene, res["ridge"]), 3),
                         crease_points=int((res["ridge"] == 3).sum()),
                         umbilic=round(float(res["umbilic"].mean()), 4),
                         crease_radius=round(float(res.params.get("crease_radius", np.nan)), 4),
                         radius_median=round(float(np.nanmedian(res.jets.fit.bandwidth)), 4))
    return row


def run_null_scene(kind, seed):
    xyz, _ = make_null_scene(500 + seed, kind)
    row = dict(kind=kind, seed=seed, points=len(xyz))
    for name, kw in SCALES.items():
        t0 = time.perf_counter()
        res = ridges(xyz, **kw)
        row[name] = dict(seconds=round(time.perf_counter() - t0, 2),
                         ridge_points=int((res["ridge"] > 0).sum()),
                         crease_points=int((res["ridge"] == 3).sum()), lines=len(res.lines),
                         umbilic=round(float(res["umbilic"].mean()), 4))
        if "radius" in res.fields:  # nothing to detect: the smallest radius should stay
            row[name]["smallest_radius_share"] = round(
                float(np.mean(res["radius"] == res.params["radii"][0])), 4)
    return row


def scale_null(rungs=5, samples=3000):
    """Quantiles of the automatic scale's k'' statistic on simulated planes, per rung (the
    calibration pools the smallest rungs), and the calibrated threshold at alpha 0.01."""
    from lidarstat.features._jet_scale import NULL_RUNGS, SCALE_RUNGS, _null_sample, null_quantile
    from lidarstat.segment._ridges import RIDGE_SCALE

    kw = dict(degree=4, weight="tricube", min_neighbors=16)
    out = {"pooled_rungs": NULL_RUNGS,
           "threshold_alpha_0.01": round(null_quantile(RIDGE_SCALE, 0, 0.01 / SCALE_RUNGS, kw), 3),
           "normal_bonferroni_alpha_0.01": 3.189, "rungs": []}
    for j in range(rungs):
        s = _null_sample(RIDGE_SCALE, j, 4, "tricube", 16, samples=samples, seed=99)
        q = np.quantile(s, [0.5, 0.99, 0.998])
        out["rungs"].append(dict(rung=j, samples=int(s.size), q50=round(float(q[0]), 3),
                                 q99=round(float(q[1]), 3), q998=round(float(q[2]), 3)))
        print(out["rungs"][-1], flush=True)
    return out


def scale_size(seeds=6, rungs=4, tilts=(0.0, 60.0)):
    """Size of the automatic scale's k'' selection test with the simulated null: per tilt
    (noise along z), generator seed and rung, the seeds above the null's upper quantiles
    at alpha / J (alpha 0.01), 0.2 % and 1 %, on 2,000 seeds whose neighbourhoods at the
    largest rung do not overlap (independent counts; the rungs of one seed share them)."""
    from indep_ridges import _plane_field

    from lidarstat.features._jet_scale import SCALE_RUNGS, null_quantile
    from lidarstat.segment._ridges import RIDGE_SCALE

    kw = dict(degree=4, weight="tricube", min_neighbors=16)
    probs = (0.01 / SCALE_RUNGS, 0.002, 0.01)
    rows = []
    for tilt in tilts:
        for seed in range(1, seeds + 1):
            for j in range(rungs):
                s = plane_scale_statistic(tilt, j, seed, rungs - 1)
                rows.append(dict(tilt=tilt, seed=seed, rung=j, seeds=int(s.size), above=[
                    int(np.sum(s > null_quantile(RIDGE_SCALE, j, p, kw))) for p in probs]))
            _plane_field.cache_clear()
            print(rows[-rungs:], flush=True)
    total = {}
    for t in tilts:
        rs = [r for r in rows if r["tilt"] == t]
        n = int(sum(r["seeds"] for r in rs))
        total[f"tilt_{t:g}"] = dict(seeds=n, above=[int(sum(r["above"][i] for r in rs))
                                                     for i in range(len(probs))],
                                    expected=[round(n * p, 1) for p in probs])
    return {"probs": [round(p, 6) for p in probs], "totals": total, "runs": rows}


def machined_parts(sigma=0.0015):
    """Crease and ridge points of the synthetic machined parts (``lidarstat.synth``
    agpart and column, range scans with 90-degree folds, spacing 0.02 dm) with the jets
    at radius 0.2 as in ``tests/segment/test_ridges.py``: the share within 2.5 spacings
    (0.05) of a true edge."""
    from lidarstat.synth import make_agpart, make_column

    out = {}
    for name, make in (("agpart", make_agpart), ("column", make_column)):
        sc = make(sigma=sigma, rng=0)
        for creases in (True, False):
            t0 = time.process_time()
            res = ridges(sc.xyz, radius=0.2, sigma=sigma, alpha=0.01, creases=creases)
            rp = res["ridge"] > 0
            out[f"{name}_{'creases' if creases else 'no_creases'}"] = dict(
                points=len(sc.xyz), ridge_points=int(rp.sum()),
                crease_points=int((res["ridge"] == 3).sum()),
                within_2_5_spacings=round(float(np.mean(sc.edge_distance[rp] < 0.05)), 4),
                crease_radius=res.params.get("crease_radius"),
                cpu_seconds=round(time.process_time() - t0, 1))
            print(name, creases, out[f"{name}_{'creases' if creases else 'no_creases'}"],
                  flush=True)
    return out


def per_spacing(rows, name="auto"):
    """Crease lines of the cylindrical profiles per scene spacing."""
    out = []
    for sp in sorted({r["spacing"] for r in rows if r["kind"] == "cyl"}):
        rs = [r for r in rows if r["kind"] == "cyl" and r["spacing"] == sp]
        rec = np.concatenate([r[name]["recall"] for r in rs])
        out.append(dict(spacing=sp, sigma=sorted({r["sigma"] for r in rs}),
                        crease_radius=sorted({r[name]["crease_radius"] for r in rs}),
                        lines=int(rec.size), lines_found_90=int(np.sum(rec >= 0.9)),
                        recall_median=round(float(np.median(rec)), 3),
                        recall_min=round(float(rec.min()), 3),
                        precision_min=round(float(min(r[name]["precision"] for r in rs)), 3)))
    return out


def summarise(rows, nulls):
    out = {}
    for name in SCALES:
        for kind in ("gauss", "cyl"):
            rs = [r for r in rows if r["kind"] == kind]
            rec = np.concatenate([r[name]["recall"] for r in rs])
            out[f"{name}_{kind}"] = dict(
                lines=int(rec.size), lines_found_90=round(float(np.mean(rec >= 0.9)), 3),
                recall_median=round(float(np.median(rec)), 3),
                recall_min=round(float(rec.min()), 3),
                precision_median=round(float(np.median([r[name]["precision"] for r in rs])), 3),
                precision_min=round(float(min(r[name]["precision"] for r in rs)), 3),
                crease_points=int(sum(r[name]["crease_points"] for r in rs)),
                seconds_total=round(float(sum(r[name]["seconds"] for r in rs)), 1))
        out[f"{name}_null"] = dict(
            scenes=len(nulls), ridge_points=int(sum(r[name]["ridge_points"] for r in nulls)),
            crease_points=int(sum(r[name]["crease_points"] for r in nulls)),
            lines=int(sum(r[name]["lines"] for r in nulls)),
            umbilic_plane=round(float(np.mean([r[name]["umbilic"] for r in nulls
                                               if r["kind"] == "plane"])), 4),
            smallest_radius_share_min=min((r[name]["smallest_radius_share"] for r in nulls
                                           if "smallest_radius_share" in r[name]),
                                          default=None))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--out", default=str(HERE / "results_ridges.json"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--size-only", action="store_true",
                    help="recompute only the scale's test size (key family.scale_size)")
    ap.add_argument("--family-only", action="store_true",
                    help="keep the scale's null and size (family.scale_null, scale_size) "
                         "from the results file: they do not depend on the creases")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    path = Path(args.out)
    if args.size_only:
        size = scale_size()
        print(json.dumps(size["totals"], indent=1))
        if not args.no_write:
            data = json.loads(path.read_text())
            data["family"]["scale_size"] = size
            path.write_text(json.dumps(data, indent=1))
            print(f"written {path}")
        return
    ridges(make_null_scene(0, "plane", half=0.2)[0])  # compile (not timed)
    ridges(make_null_scene(0, "plane", half=0.2)[0], k=50)
    rows, nulls = [], []
    for kind in ("gauss", "cyl"):
        for curved in (False, True):
            for sign in (1.0, -1.0):
                for seed in range(args.seeds):
                    rows.append(run_ridge_scene(kind, sign, curved, seed))
                    r = rows[-1]
                    print(kind, "curved" if curved else "straight", sign, seed, r["points"],
                          {n: (r[n]["recall"], r[n]["precision"], r[n]["seconds"])
                           for n in SCALES}, flush=True)
    for kind in ("plane", "sphere", "cylinder"):
        for seed in range(args.seeds):
            nulls.append(run_null_scene(kind, seed))
            print(nulls[-1], flush=True)
    summary = summarise(rows, nulls)
    summary["auto_cyl_per_spacing"] = per_spacing(rows)
    print(json.dumps(summary, indent=1))
    parts = machined_parts()
    data = json.loads(path.read_text()) if path.exists() else {}
    if isinstance(data, list):
        data = {"scenes": data}
    if args.family_only:
        null, size = data["family"]["scale_null"], data["family"]["scale_size"]
    else:
        null, size = scale_null(), scale_size()
    if not args.no_write:
        data["family"] = {"summary": summary, "scenes": rows, "null_scenes": nulls,
                          "machined_parts": parts, "seeds": args.seeds, "scale_null": null,
                          "scale_size": size, "machine_shared": True}
        path.write_text(json.dumps(data, indent=1))
        print(f"written {path}")


if __name__ == "__main__":
    main()
