#!/usr/bin/env python
"""Benchmark of lidarstat's covariance features and segmentation against peers (seed 003).

Whole process from coordinates in memory to per-point features, neighbour search
included, k = 50 (radius peers: the radius whose median neighbour count is 50), on the
synthetic airborne-like cloud of ``bench_curvature.py``. Each measurement runs in a fresh
subprocess (``--child``); Numba kernels load from a benchmark-private cache warmed by one
untimed run. Peers, in the same run: jakteristics ``compute_features`` (radius), pgeof
(``knn_search`` + ``compute_features``), Open3D ``estimate_normals`` (kNN 50), and
CloudCompare (command line, headless through ``xvfb-run``): ``-FEATURE SURFACE_VARIATION``
and ``-OCTREE_NORMALS`` (least-squares plane) at the radius whose median neighbour count is
50. CloudCompare runs as a whole external process from a binary PLY file; its ``seconds``
are that process minus the median process that only loads the file (both kept in the
JSON), i.e. the octree plus the feature step, as the other rows time neighbour search plus
features from coordinates in memory.

Usage::

    python benchmarks/bench_covariance.py                 # 2M points, 3 repeats, JSON + table
    python benchmarks/bench_covariance.py --quick         # 100k points, 1 repeat, no JSON
    mkdir -p /tmp/s5 && git archive REV src | tar -x -C /tmp/s5   # another version
    python benchmarks/bench_covariance.py --skip-peers --baseline /tmp/s5/src
                                                          # both versions in one run, alternating

With ``--baseline SRC`` the lidarstat runs (features, classification, segmentation) are
repeated with the package found in SRC (its own Numba cache), alternating with the
current code repeat by repeat, so machine drift hits both alike: the rows ``<mode>@base``
and the ratios current / baseline say what the code changed.

See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_curvature import (_cpu_name, _git_rev, _vmhwm_mb, calibrate_radius,  # noqa: E402
                             make_cloud, run_external, write_ply)

K = 50


def child_lidarstat(args, pts):
    from lidarstat.features import covariance_features

    t0 = time.perf_counter()
    res = covariance_features(pts, k=args.k)
    return dict(seconds=time.perf_counter() - t0,
                median_neighbors=float(np.median(res["neighbors"])))


def child_pieces(args, pts):
    """covariance_features(k) piece by piece (wall seconds, kernels already loaded): the
    cell size (thinned KD-tree), the grid index (counting sort), the fused kNN +
    covariance + eigen kernel, the second pass over the kNN table (eq. 5 variance, normal
    spread), the output arrays in input order."""
    from lidarstat._shared import _memory as _mem
    from lidarstat.features import _covariance as C
    from lidarstat.features import _covariance_kernels as ck
    from lidarstat.neighbors import CellIndex, knn_cell_size

    k, n = args.k, pts.shape[0]
    C.covariance_features(pts[:5000], k=k)  # load every kernel from the cache (untimed)
    out = {}
    t0 = time.perf_counter()
    cell, tau0 = knn_cell_size(pts, k)
    out["cell_size"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    index = CellIndex(pts, cell)
    out["grid_index"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    table = _mem.empty((n, k), dtype=np.int32)  # as _knn_table allocates them
    raw = _mem.empty((n, ck.NCOL))
    for c0, c1 in index.cell_blocks(262144):
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        ck.knn_cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start,
                     index.dims, float(index.cell), k, tau0, False, table[s0:s1],
                     # the library's argument types (an int64 empty array here would
                     # compile a second specialisation inside the timing)
                     index.order, np.empty(0, np.int32), np.empty(0), np.zeros(3), False,
                     raw[s0:s1])
    out["knn_covariance_eigen"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mean_sv, var_sv, spread = np.empty(n), np.empty(n), np.empty((n, 4))
    ck.table_second_pass(raw, table, np.empty(n), np.empty((n, 3)), mean_sv, var_sv, spread)
    out["second_pass"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    C._assemble(raw, mean_sv, var_sv, spread, index.origin, index.order, k=k, radius=None,
                eigen_mode="raw", neighborhoods=None)
    out["output_arrays"] = time.perf_counter() - t0
    return dict(seconds=sum(out.values()), pieces=out)


def child_classify(args, pts):
    from lidarstat.classify import covariance

    t0 = time.perf_counter()
    res = covariance(pts, k=args.k)
    return dict(seconds=time.perf_counter() - t0, counts=res.classes.counts())


def child_segment(args, pts):
    from lidarstat.segment import segment_covariance

    t0 = time.perf_counter()
    from lidarstat.classify import covariance

    seg = segment_covariance(pts, covariance(pts, k=args.k, keep_neighbors=True))
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


CHILDREN = dict(lidarstat=child_lidarstat, pieces=child_pieces, classify=child_classify, segment=child_segment,
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
    return _summary([run_child(mode, data, env, **kw) for _ in range(repeats)])


def _summary(runs):
    """Median run of `runs` (its fields), the median seconds, every run's, the peak RSS."""
    secs = [r["seconds"] for r in runs]
    best = dict(runs[int(np.argsort(secs)[len(secs) // 2])])
    best.update(seconds=float(np.median(secs)), all_seconds=secs,
                peak_rss_mb=max(r["vmhwm_mb"] for r in runs))
    return best


def cloudcompare(tmp, xyz, radius, repeats):
    """CloudCompare's covariance features and normals (whole process minus loading)."""
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    xvfb = shutil.which("xvfb-run")
    if exe is None or xvfb is None:
        print("cloudcompare: skipped (apt-get install -y cloudcompare xvfb)", flush=True)
        return {}
    ply = Path(tmp) / "cloud.ply"
    write_ply(ply, xyz - np.floor(xyz.min(0)))
    base = [xvfb, "-a", exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP", "-O",
            "-GLOBAL_SHIFT", "AUTO", str(ply)]
    steps = {"cloudcompare_load_only": [],
             "cloudcompare_feature": ["-FEATURE", "SURFACE_VARIATION", f"{radius:.6f}"],
             "cloudcompare_normals": ["-OCTREE_NORMALS", f"{radius:.6f}", "-MODEL", "LS"]}
    out = {}
    for name, extra in steps.items():
        runs = []
        for _ in range(repeats):
            t, rc, log, mb = run_external(base + extra)
            if rc != 0:
                print(f"{name}: skipped (rc {rc}: {log.strip()[-300:]})", flush=True)
                return out
            runs.append((t, mb))
        wall = float(np.median([t for t, _ in runs]))
        out[name] = dict(process_wall=wall, all_process_wall=[t for t, _ in runs],
                         peak_rss_mb=max(mb for _, mb in runs), note=" ".join(extra) or "load")
    load = out["cloudcompare_load_only"]["process_wall"]
    for name in ("cloudcompare_feature", "cloudcompare_normals"):
        if name in out:
            out[name]["seconds"] = out[name]["process_wall"] - load
            print(f"{name}: {out[name]['seconds']:.2f} s (process {out[name]['process_wall']:.2f}"
                  f" s, load {load:.2f} s)", flush=True)
    out["cloudcompare_load_only"]["seconds"] = load
    return out


PEERS = ("jakteristics", "pgeof", "open3d", "cloudcompare_feature", "cloudcompare_normals")


def print_table(results):
    rows = results["measurements"]
    peers = [v["seconds"] for k, v in rows.items() if k in PEERS]
    ref = min(peers) if peers else None
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
    ap.add_argument("--baseline", default=None,
                    help="a source tree (the src/ of another version) to time alternately")
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
    base_env = None
    if args.baseline:
        base_env = dict(env, NUMBA_CACHE_DIR=str(tmp / "numba_base"),
                        PYTHONPATH=str(Path(args.baseline).resolve()) + os.pathsep
                        + os.environ.get("PYTHONPATH", ""))
        results["baseline"] = str(args.baseline)
    for mode in ("lidarstat", "classify", "segment"):
        run_child(mode, data, env)  # warm the Numba cache (compiles once)
        if base_env is None:
            m[mode] = run_repeats(mode, args.repeats, data, env)
            print(f"{mode}: {m[mode]['seconds']:.2f} s", flush=True)
            continue
        run_child(mode, data, base_env)
        cur, old = [], []
        for _ in range(args.repeats):  # alternate: drift of the machine hits both
            cur.append(run_child(mode, data, env))
            old.append(run_child(mode, data, base_env))
        m[mode], m[mode + "@base"] = _summary(cur), _summary(old)
        ratio = m[mode]["seconds"] / m[mode + "@base"]["seconds"]
        results.setdefault("ratio_to_baseline", {})[mode] = ratio
        print(f"{mode}: {m[mode]['seconds']:.2f} s, baseline {m[mode + '@base']['seconds']:.2f}"
              f" s (ratio {ratio:.3f}; peak {m[mode]['peak_rss_mb']:.0f} / "
              f"{m[mode + '@base']['peak_rss_mb']:.0f} MB)", flush=True)
    pieces = run_child("pieces", data, env)
    results["lidarstat_pieces"] = pieces["pieces"]
    print("lidarstat pieces: " + ", ".join(f"{k} {v:.2f} s" for k, v in pieces["pieces"].items()),
          flush=True)
    if not args.skip_peers:
        for mode in ("jakteristics", "pgeof", "open3d"):
            try:
                m[mode] = run_repeats(mode, args.repeats, data, env, radius=radius)
                print(f"{mode}: {m[mode]['seconds']:.2f} s", flush=True)
            except (subprocess.CalledProcessError, ImportError) as exc:
                print(f"{mode}: skipped ({exc})", flush=True)
        m.update(cloudcompare(tmp, xyz, radius, args.repeats))
    print_table(results)
    if not args.quick:
        Path(args.out).write_text(json.dumps(results, indent=1))
        print(f"\nwritten {args.out}")


if __name__ == "__main__":
    main()
