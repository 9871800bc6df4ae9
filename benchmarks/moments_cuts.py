#!/usr/bin/env python
"""Cuts of `moments`' work that change its result, scored on the real data before any is kept.

Each variant runs ``lidarstat.classify.moments`` (defaults otherwise) on the seven ISPRS
filter-test samples and the six producer-classified files of ``ground_filters.py``, in
one process, and is scored as there and as in ``buildings.py``: ground total error and
kappa (bare earth and road as ground, the same points left out), building F1 against the
producers' class 6, and the CPU seconds of the classification alone. Variants:

* ``defaults``;
* ``iterations_3``, ``iterations_2``, ``iterations_1``: fewer ground-surface refits (each
  drops a pass of window analyses, a TIN and its evaluation);
* ``terrain_grid``: the terrain step's surface bilinear between the 2 m cells' values
  instead of the TIN of their lowest ground points (no Delaunay triangulation);
* ``patches_on_ground``: the raised-patch graph built on the ground points alone instead
  of every point;
* ``qhull_delaunay``: the ground and terrain TINs triangulated by ``scipy.spatial.Delaunay``
  (Qhull) instead of ``lidarstat.neighbors.delaunay_triangles``: the same triangles but
  for the diagonals of co-circular vertices (``--out
  benchmarks/results_moments_delaunay.json --variants qhull_delaunay``).

A cut is kept only when no figure gets worse by more than 0.05 points. Usage::

    python benchmarks/moments_cuts.py --out benchmarks/results_moments_cuts.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE))

from buildings import LEFT_OUT, scores  # noqa: E402
from ground_filters import ISPRS, PRODUCER, load  # noqa: E402

VARIANTS = ["defaults", "iterations_3", "iterations_2", "iterations_1", "terrain_grid",
            "patches_on_ground", "qhull_delaunay"]


def _patches_on_ground(xy, z, rank, ground, height, surf, *, surface_cell, step):
    """``drop_raised_patches`` with the patch graph on the ground points only."""
    from lidarstat.classify import _moments_ground as mg

    rows = np.flatnonzero(ground)
    r = np.asarray(rank)[rows]
    mark = np.zeros(len(z), bool)
    mark[r] = True
    sub = (np.cumsum(mark) - 1)[r]  # the ranks among the ground points
    raised = np.zeros(len(z), bool)
    raised[rows] = mg.raised_patches(xy[rows], z[rows], step=step, rank=sub)
    if raised.any() and (ground & ~raised).sum() >= 3:
        ground = ground & ~raised
        surf = mg.ground_surface(xy, z, cell=surface_cell, rank=rank,
                                 where=np.flatnonzero(ground))
        height = mg.heights(z, surf(xy), overwrite=True)
    return ground, height, surf


def _qhull_triangles(xy):
    """Qhull's Delaunay triangles of `xy` (none when collinear)."""
    from scipy.spatial import Delaunay, QhullError

    try:
        return np.ascontiguousarray(Delaunay(xy).simplices, dtype=np.int64)
    except QhullError:
        return np.empty((0, 3), np.int64)


def variant(name):
    """Keyword arguments of `moments` and the patches (module, attribute, replacement)."""
    from lidarstat.classify import _moments, _terrain

    if name.startswith("iterations_"):
        return {"iterations": int(name.split("_")[1])}, []
    if name == "terrain_grid":
        return {}, [(_terrain, "_tin", lambda *a: None)]
    if name == "patches_on_ground":
        return {}, [(_moments, "drop_raised_patches", _patches_on_ground)]
    if name == "qhull_delaunay":
        from lidarstat.classify import _surface

        return {}, [(_surface, "delaunay_triangles", _qhull_triangles),
                    (_terrain, "delaunay_triangles", _qhull_triangles)]
    return {}, []


def run(name):
    from lidarstat.classify import filter_errors, moments

    kw0, patches = variant(name)
    saved = [(m, a, getattr(m, a)) for m, a, _ in patches]
    for m, a, f in patches:
        setattr(m, a, f)
    rows = {}
    try:
        for rel in ISPRS + list(PRODUCER):
            c, a, ref, keep, units = load(rel)
            kw = {"units": units, **kw0}
            if "number_of_returns" in a:
                kw.update(number_of_returns=a["number_of_returns"],
                          return_number=a["return_number"])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = time.process_time()
                r = moments(c.xyz, a.get("intensity"), **kw)
                cpu = time.process_time() - t
            e = filter_errors(r.ground[keep], ref[keep])
            row = {"ground_total": round(100 * e.total, 3), "kappa": round(e.kappa, 4),
                   "cpu_s": round(cpu, 2)}
            if rel in PRODUCER:
                cls = np.asarray(a["classification"]).astype(int)
                k2 = ~np.isin(cls, LEFT_OUT) & (cls < 19)
                row["building_f1"] = scores((r.classification == 6)[k2], (cls == 6)[k2])["f1"]
            rows[Path(rel).name.split("_ref")[0]] = row
            print(f"{name:18s} {rel:70s} {row}", flush=True)
    finally:
        for m, a, f in saved:
            setattr(m, a, f)
    isprs = [rows[Path(r).name.split("_ref")[0]] for r in ISPRS]
    return {"files": rows,
            "isprs_mean_total": round(float(np.mean([v["ground_total"] for v in isprs])), 3),
            "isprs_worst_total": max(v["ground_total"] for v in isprs),
            "isprs_mean_kappa": round(float(np.mean([v["kappa"] for v in isprs])), 4),
            "cpu_s": round(sum(v["cpu_s"] for v in rows.values()), 2)}


def verdict(res, tol=0.05):
    """Per variant, every figure worse than the defaults' by more than `tol` points."""
    base = res["defaults"]
    out = {}
    for name, v in res.items():
        worse = []
        for f, row in v["files"].items():
            b = base["files"][f]
            if row["ground_total"] > b["ground_total"] + tol:
                worse.append(f"{f} ground {b['ground_total']} -> {row['ground_total']}")
            if "building_f1" in row and row["building_f1"] < b["building_f1"] - tol:
                worse.append(f"{f} F1 {b['building_f1']} -> {row['building_f1']}")
        if v["isprs_mean_total"] > base["isprs_mean_total"] + tol:
            worse.append(f"ISPRS mean {base['isprs_mean_total']} -> {v['isprs_mean_total']}")
        out[name] = {"kept": not worse, "worse": worse}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=VARIANTS, choices=VARIANTS)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    names = ["defaults"] + [v for v in args.variants if v != "defaults"]
    res = {name: run(name) for name in names}
    ver = verdict(res)
    for name, v in res.items():
        print(f"{name:18s} ISPRS mean {v['isprs_mean_total']:.3f} worst "
              f"{v['isprs_worst_total']:.3f} kappa {v['isprs_mean_kappa']:.4f}  CPU "
              f"{v['cpu_s']:.1f} s  {'kept' if ver[name]['kept'] else 'worse: '}"
              f"{'; '.join(ver[name]['worse'])}")
    if args.out:
        Path(args.out).write_text(json.dumps({
            "what": "moments with cuts that change the result, on the ISPRS samples and the "
                    "producer-classified files: ground total error % and kappa (as "
                    "ground_filters.py), building F1 % (as buildings.py), CPU seconds of "
                    "the classification; a cut is kept when no figure is worse than the "
                    "defaults' by more than 0.05 points",
            "machine_shared": True, "cpus": os.cpu_count(),
            "python": platform.python_version(), "variants": res, "verdict": ver},
            indent=1) + "\n")


if __name__ == "__main__":
    main()
