#!/usr/bin/env python
"""Degree-4 jets: lidarstat against CGAL ``Monge_via_jet_fitting`` in the same run.

Both get the same kNN neighbourhoods (k = 50, the point itself included, from SciPy's
cKDTree, not timed) of the airborne-like cloud of ``bench_curvature.py`` and fit a degree-4
jet with a degree-4 Monge form at every point, on all cores. Timed:

* ``cgal``: CGAL 5/6 ``Monge_via_jet_fitting`` (unweighted, SVD), OpenMP over points, the
  C++ driver ``cgal_monge.cpp`` compiled with -O3 (its own timer around the fit loop);
* ``lidarstat_cgal_equivalent``: ``fit_jets(weight='none', standard_errors=False)``, the
  same estimator (tested equal to CGAL to 1e-8);
* ``lidarstat_full``: ``fit_jets(weight='tricube', standard_errors=True)``: tricube
  weights, Satterthwaite traces and the propagated standard errors of all 11 coefficients;
* ``lidarstat_radius_full``: the fused radius driver ``jets(radius=r)`` with r calibrated to
  a median of 50 neighbours, whole call including the neighbour search and the tests;
* ``lidarstat_auto_full``: ``jets()`` at the automatic scale (no radius, no k: the rung
  selection on the seeds and the final fit at every point's radius), whole call;
* ``lidarstat_ridges_radius``, ``lidarstat_ridges_auto``: ``ridges`` (jets, tests,
  crossings, lines) at the fixed radius and at its automatic scale (the k'' criterion,
  its simulated null included), whole call.

The lidarstat configurations alternate within each repeat (the machine may be shared:
``machine_shared`` in the results; compare ratios of the same run).

Each lidarstat timing runs in a fresh subprocess after a cold run has filled a
benchmark-private Numba cache (compilation is not timed). Ratios are CGAL time / lidarstat
time. The agreement of the unweighted fit with CGAL is checked on the first 20,000 points.

Usage::

    python benchmarks/bench_jets.py --quick                 # seconds: 20,000 points
    python benchmarks/bench_jets.py                         # 2,000,000 points, writes
                                                            # benchmarks/results_jets.json
    python benchmarks/bench_jets.py --points 200000         # the same at 200,000 points
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
K = 50


def _env(tmp):
    env = dict(os.environ)
    env["NUMBA_CACHE_DIR"] = str(Path(tmp) / "numba_cache")
    src = str(HERE.parent / "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    return env


def child(args):
    """Time one lidarstat configuration on the cloud in args.tmp; print JSON."""
    from lidarstat.features import fit_jets, jets
    from lidarstat.neighbors import Neighborhoods
    from lidarstat.segment import ridges

    tmp = Path(args.tmp)
    xyz = np.load(tmp / "xyz.npy")
    if args.child == "auto_full":
        t = time.perf_counter()
        res = jets(xyz, sigma=0.02, degree=4)
        dt = time.perf_counter() - t
        print(json.dumps({"seconds": dt, "median_neighbors": float(np.median(res["neighbors"])),
                          "radius_median": float(np.median(res["radius"])),
                          "radii": res.meta["radii"],
                          "points_per_radius": res.meta["points_per_radius"]}))
        return
    if args.child in ("ridges_radius", "ridges_auto"):
        kw = {"radius": args.radius} if args.child == "ridges_radius" else {}
        t = time.perf_counter()
        res = ridges(xyz, sigma=0.02, creases=False, **kw)  # the ridge steps CGAL has
        dt = time.perf_counter() - t
        # the radius of every point: the given one, or the automatic scale's per-point
        # field (the fit's bandwidth is NaN where no jet was fitted)
        r = float(np.median(res["radius"])) if args.child == "ridges_auto" else args.radius
        print(json.dumps({"seconds": dt, "ridge_points": int((res["ridge"] > 0).sum()),
                          "radius_median": r}))
        return
    if args.child == "radius_full":
        t = time.perf_counter()
        res = jets(xyz, radius=args.radius, sigma=0.02, degree=4)
        dt = time.perf_counter() - t
        print(json.dumps({"seconds": dt, "median_neighbors": float(np.median(res["neighbors"]))}))
        return
    knn = np.load(tmp / "knn.npy")
    n, k = knn.shape
    d = np.load(tmp / "dist.npy")
    nb = Neighborhoods(indptr=np.arange(n + 1, dtype=np.int64) * k, indices=knn.ravel(),
                       distances=d.ravel(), n_points=n, kind="knn", k=k)
    weighted = args.child == "full"
    t = time.perf_counter()
    fit = fit_jets(xyz, nb, degree=4, weight="tricube" if weighted else "none",
                   standard_errors=weighted)
    dt = time.perf_counter() - t
    if not weighted:
        np.save(tmp / "ours.npy", np.c_[fit.monge, fit.frame.reshape(n, 9)][:20000])
    print(json.dumps({"seconds": dt, "failed": int((fit.status != 0).sum())}))


def _run_child(mode, tmp, radius=0.0):
    cmd = [sys.executable, __file__, "--child", mode, "--tmp", str(tmp), "--radius", str(radius)]
    r = subprocess.run(cmd, capture_output=True, text=True, env=_env(tmp), check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _build_cgal(tmp):
    exe = Path(tmp) / "cgal_monge"
    if shutil.which("g++") is None or not Path("/usr/include/CGAL/Monge_via_jet_fitting.h").exists():
        return None
    subprocess.run(["g++", "-O3", "-DNDEBUG", "-fopenmp", "-std=c++17", "-I/usr/include/eigen3",
                    str(HERE / "cgal_monge.cpp"), "-o", str(exe)], check=True)
    return exe


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--quick", action="store_true", help="20,000 points, no JSON")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", default=str(HERE / "results_jets.json"))
    ap.add_argument("--tmp", default=None)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--radius", type=float, default=0.0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args)
    if args.quick:
        args.points = 20_000
    sys.path.insert(0, str(HERE))
    from bench_curvature import calibrate_radius, make_cloud
    from scipy.spatial import cKDTree

    tmp = Path(args.tmp or tempfile.mkdtemp(prefix="bench_jets_"))
    tmp.mkdir(parents=True, exist_ok=True)
    xyz, _ = make_cloud(args.points)
    xyz = xyz - xyz.min(axis=0)  # local coordinates for both programs
    np.save(tmp / "xyz.npy", xyz)
    t = time.perf_counter()
    dist, knn = cKDTree(xyz).query(xyz, k=K, workers=-1)
    t_knn = time.perf_counter() - t
    np.save(tmp / "knn.npy", knn.astype(np.int64))
    np.save(tmp / "dist.npy", dist)
    xyz.tofile(tmp / "xyz.bin")
    knn.astype(np.int32).tofile(tmp / "knn.bin")
    radius, _ = calibrate_radius(xyz, K)
    res = {"points": args.points, "k": K, "knn_seconds": t_knn, "radius_50": radius,
           "date": datetime.datetime.now().isoformat(timespec="seconds"),
           "machine": platform.platform(), "cpus": os.cpu_count()}
    # cold runs fill the Numba cache (not timed)
    modes = ("cgal_equivalent", "full", "radius_full", "auto_full", "ridges_radius",
             "ridges_auto")
    for mode in modes:
        _run_child(mode, tmp, radius)
    all_runs = {mode: [] for mode in modes}
    for _ in range(args.repeats):  # alternate the configurations
        for mode in modes:
            all_runs[mode].append(_run_child(mode, tmp, radius))
    res["machine_shared"] = True
    for mode in modes:
        runs = all_runs[mode]
        res[f"lidarstat_{mode}"] = float(np.median([r["seconds"] for r in runs]))
        if mode.startswith("ridges"):
            res[mode] = runs[0]
        if mode == "radius_full":
            res["radius_median_neighbors"] = runs[0]["median_neighbors"]
        if mode == "auto_full":
            res["auto"] = {k: runs[0][k] for k in ("median_neighbors", "radius_median", "radii",
                                                   "points_per_radius")}
    exe = _build_cgal(tmp)
    if exe is not None:
        times = []
        for _ in range(args.repeats):
            r = subprocess.run([str(exe), str(tmp / "xyz.bin"), str(tmp / "knn.bin"),
                                str(tmp / "cgal.bin"), "4", "4"], capture_output=True,
                               text=True, check=True)
            times.append(json.loads(r.stdout)["fit_seconds"])
        res["cgal"] = float(np.median(times))
        n = args.points
        cg = np.fromfile(tmp / "cgal.bin").reshape(n, 21)[:20000]
        ours = np.load(tmp / "ours.npy")
        sys.path.insert(0, str(HERE.parent / "src"))  # this checkout's lidarstat first
        sys.path.insert(0, str(HERE.parent / "tests" / "features"))
        from test_jets import align_cgal

        coef, _ = align_cgal(cg[:, :11], cg[:, 11:20].reshape(-1, 3, 3),
                             ours[:, 11:].reshape(-1, 3, 3))
        ok = np.isfinite(coef).all(axis=1) & np.isfinite(ours[:, :11]).all(axis=1)
        scale = np.abs(coef[ok]).max(axis=0)
        rel = (np.abs(coef[ok] - ours[ok, :11]) / scale).max(axis=1)
        res["max_rel_diff_vs_cgal"] = float(rel.max())
        # the differences are rounding errors of two solvers of one least-squares
        # problem (CGAL: SVD, ~ eps kappa; fit_jets: normal equations, ~ eps kappa^2):
        # they follow the condition number kappa of the neighbourhood's design matrix
        cond = np.fromfile(tmp / "cgal.bin").reshape(n, 21)[:20000, 20][ok]
        big = cond > 1e4
        res["diff_vs_cgal"] = {
            "quantiles_50_99_999": [float(q) for q in np.quantile(rel, [0.5, 0.99, 0.999])],
            "cond_at_max": float(cond[np.argmax(rel)]),
            "share_cond_above_1e4": float(big.mean()),
            "max_rel_diff_cond_below_1e4": float(rel[~big].max()) if (~big).any() else None}
        for mode in modes:
            res[f"ratio_{mode}"] = res["cgal"] / res[f"lidarstat_{mode}"]
    rows = [("CGAL Monge_via_jet_fitting d=4 (kNN given)", res.get("cgal")),
            ("lidarstat fit_jets, unweighted, no SEs (kNN given)", res["lidarstat_cgal_equivalent"]),
            ("lidarstat fit_jets, tricube + SEs (kNN given)", res["lidarstat_full"]),
            ("lidarstat jets(radius), search + fit + tests", res["lidarstat_radius_full"]),
            ("lidarstat jets(), automatic scale, search + fit + tests",
             res["lidarstat_auto_full"]),
            ("lidarstat ridges(radius)", res["lidarstat_ridges_radius"]),
            ("lidarstat ridges(), automatic scale", res["lidarstat_ridges_auto"])]
    print(f"\n{args.points} points, k = {K}, {os.cpu_count()} cpus\n")
    print("| run | seconds | CGAL / run |")
    print("|---|---|---|")
    for name, sec in rows:
        ratio = f"{res['cgal'] / sec:.2f}" if sec and res.get("cgal") else "-"
        print(f"| {name} | {sec:.2f} | {ratio} |" if sec else f"| {name} | - | - |")
    if "max_rel_diff_vs_cgal" in res:
        print(f"\nmax relative difference to CGAL (20,000 points): {res['max_rel_diff_vs_cgal']:.2e}")
    if not args.quick:
        Path(args.out).write_text(json.dumps(res, indent=2))
        print(f"written {args.out}")
    if args.tmp is None:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
