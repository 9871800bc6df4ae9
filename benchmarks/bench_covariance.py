#!/usr/bin/env python
"""Benchmark of lidarstat's covariance features and segmentation against peers (seed 003).

Whole process from coordinates in memory to per-point features, neighbour search
included, k = 50 (radius peers: the radius whose median neighbour count is 50), on the
synthetic airborne-like cloud of ``bench_curvature.py``. Each measurement runs in a fresh
subprocess (``--child``); Numba kernels load from a benchmark-private cache warmed by one
untimed run. Peers, in the same run: jakteristics ``compute_features`` (radius), pgeof
(``knn_search`` + ``compute_features``), Open3D ``estimate_normals`` (kNN 50).

Usage::

    python benchmarks/bench_covariance.py                 # 2M points, 3 repeats, JSON + table
    python benchmarks/bench_covariance.py --quick         # 100k points, 1 repeat, no JSON

See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_curvature import _cpu_name, _git_rev, _vmhwm_mb, calibrate_radius, make_cloud  # noqa: E402

K = 50


def child_lidarstat(args, pts):
    from lidarstat.features import covariance_features

    t0 = time.perf_counter()
    res = covariance_features(pts, k=args.k)
    return dict(seconds=time.perf_counter() - t0,
                median_neighbors=float(np.median(res["neighbors"])))


def child_classify(args, pts):
    from lidarstat.classify import covariance

    t0 = time.perf_counter()
    res = covariance(pts, k=args.k)
    return dict(seconds=time.perf_counter() - t0, counts=res.classes.counts())


def child_segment(args, pts):
    from lidarstat.segment import segment_covariance

    t0 = time.perf_counter()
    seg = segment_covariance(pts, k=args.k)
    return dict(seconds=time.perf_counter() - t0, n_segments=seg.n_segments,
                n_lines=len(seg.lines))


def child_jakteristics(args, pts):
    import jakteristics

    xyz = np.ascontiguousarray(pts - pts.min(0))
    t0 = time.perf_counter()
    f = jakteristics.compute_features(xyz, search_radius=args.radius, num_threads=-1,
                                      feature_names=["linearity", "planarity", "sphericity",
                                                     "verticality", "surface_variation",
                                                     "nx", "ny", "nz"])
    return dict(seconds=time.perf_counter() - t0, note=f"radius {args.radius:.4g}, {f.shape}")


def child_pgeof(args, pts):
    import pgeof

    xyz = np.ascontiguousarray(pts - pts.min(0), dtype=np.float32)
    t0 = time.perf_counter()
    knn, _ = pgeof.knn_search(xyz, xyz, args.k)
    n = xyz.shape[0]
    nn = np.ascontiguousarray(knn.ravel().astype(np.uint32))
    f = pgeof.compute_features(xyz, nn, (np.arange(n + 1) * args.k).astype(np.uint32))
    return dict(seconds=time.perf_counter() - t0, note=f"knn_search + compute_features {f.shape}")


def child_open3d(args, pts):
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts - pts.min(0)))
    t0 = time.perf_counter()
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=args.k))
    return dict(seconds=time.perf_counter() - t0, note="estimate_normals, KNN 50")


CHILDREN = dict(lidarstat=child_lidarstat, classify=child_classify, segment=child_segment,
                jakteristics=child_jakteristics, pgeof=child_pgeof, open3d=child_open3d)


def run_child(mode, data, env, **kw):
    """This script in `mode` in a fresh process: its JSON result plus its peak RSS."""
    with tempfile.NamedTemporaryFile("w+", suffix=".json", delete=False) as out:
        pass
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", mode, "--data", data,
           "--child-out", out.name] + [f"--{k}={v}" for k, v in kw.items()]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True)
    res = json.loads(Path(out.name).read_text())
    os.unlink(out.name)
    res["process_wall"] = time.perf_counter() - t0
    return res


def run_repeats(mode, repeats, data, env, **kw):
    runs = [run_child(mode, data, env, **kw) for _ in range(repeats)]
    secs = [r["seconds"] for r in runs]
    best = dict(runs[int(np.argsort(secs)[len(secs) // 2])])
    best.update(seconds=float(np.median(secs)), all_seconds=secs,
                peak_rss_mb=max(r["vmhwm_mb"] for r in runs))
    return best


def print_table(results):
    rows = results["measurements"]
    ref = min(v["seconds"] for k, v in rows.items() if k in ("jakteristics", "pgeof", "open3d")) \
        if any(k in rows for k in ("jakteristics", "pgeof", "open3d")) else None
    print(f"\n{results['points']} points, k = {K}, {results['cpu']} ({results['cores']} cores)\n")
    print("| run | seconds | peak RSS MB | vs fastest peer |")
    print("|---|---:|---:|---:|")
    for name, v in rows.items():
        ratio = f"{v['seconds'] / ref:.2f}" if ref else "-"
        print(f"| {name} | {v['seconds']:.2f} | {v['peak_rss_mb']:.0f} | {ratio} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="100k points, 1 repeat, no JSON")
    ap.add_argument("--out", default=str(HERE / "results_covariance.json"))
    ap.add_argument("--skip-peers", action="store_true")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--data", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--k", type=int, default=K, help=argparse.SUPPRESS)
    ap.add_argument("--radius", type=float, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        pts = np.load(args.data)
        res = CHILDREN[args.child](args, pts)
        res["vmhwm_mb"] = _vmhwm_mb()
        Path(args.child_out).write_text(json.dumps(res))
        return
    if args.quick:
        args.points, args.repeats = 100_000, 1
    tmp = Path(tempfile.mkdtemp(prefix="bench_cov_"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba"))
    src = HERE.parent / "src"
    env["PYTHONPATH"] = str(src) + os.pathsep + env.get("PYTHONPATH", "")
    xyz, _ = make_cloud(args.points)
    data = str(tmp / "cloud.npy")
    np.save(data, xyz)
    radius, med = calibrate_radius(xyz, K)
    results = {"date": datetime.datetime.now().isoformat(timespec="seconds"),
               "git": _git_rev(), "cpu": _cpu_name(), "cores": os.cpu_count(),
               "points": int(xyz.shape[0]), "k": K, "radius_for_k": radius,
               "radius_median_neighbors": med, "measurements": {}}
    m = results["measurements"]
    for mode in ("lidarstat", "classify", "segment"):
        run_child(mode, data, env)  # warm the Numba cache (compiles once)
        m[mode] = run_repeats(mode, args.repeats, data, env)
        print(f"{mode}: {m[mode]['seconds']:.2f} s", flush=True)
    if not args.skip_peers:
        for mode in ("jakteristics", "pgeof", "open3d"):
            try:
                m[mode] = run_repeats(mode, args.repeats, data, env, radius=radius)
                print(f"{mode}: {m[mode]['seconds']:.2f} s", flush=True)
            except (subprocess.CalledProcessError, ImportError) as exc:
                print(f"{mode}: skipped ({exc})", flush=True)
    print_table(results)
    if not args.quick:
        Path(args.out).write_text(json.dumps(results, indent=1))
        print(f"\nwritten {args.out}")


if __name__ == "__main__":
    main()
