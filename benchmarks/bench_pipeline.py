#!/usr/bin/env python
"""Memory and time of streamed, tiled processing against the whole-cloud run.

`lidarstat curvature` runs on synthetic airborne-like LAZ files of two sizes, once whole
(the cloud in memory) and once with ``--tile`` (streamed chunks, tile buckets on disk,
results bucketed by output chunk). Each run is a fresh subprocess; its peak RSS comes from ``os.wait4``.
If streaming works, the tiled peak stays flat while the whole-cloud peak grows with the
file.

Usage::

    python benchmarks/bench_pipeline.py --points 4000000 --out benchmarks/results_pipeline.json
    python benchmarks/bench_pipeline.py --quick
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_curvature import make_cloud  # noqa: E402  (same terrain + buildings cloud)

RADIUS = 0.9  # m: about 50 neighbours at 20 pts/m^2
SIGMA = 0.02


def run(cmd, env):
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if status != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{err}")
    return wall, usage.ru_maxrss / 1024.0  # MiB


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=4_000_000, help="size of the larger file")
    ap.add_argument("--tile", type=float, default=100.0, help="tile side (m)")
    ap.add_argument("--quick", action="store_true", help="200k points, a smoke test")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    n_big = 200_000 if args.quick else args.points
    sizes = [n_big // 2, n_big]
    from lidarstat.io import PointCloud, write

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / "numba")}
        for n in sizes:
            xyz, _ = make_cloud(n)
            src = tmp / f"cloud_{n}.laz"
            write(src, PointCloud(xyz=xyz, attributes={}))
            del xyz
            base = [sys.executable, "-m", "lidarstat", "curvature", str(src), None,
                    "--radius", str(RADIUS), "--sigma", str(SIGMA), "-q"]
            variants = {"whole": [],
                        "tiled, 1 thread": ["--tile", str(args.tile), "--scheduler", "sync",
                                            "--chunk-points", "500000"],
                        "tiled, 2 threads": ["--tile", str(args.tile), "--workers", "2",
                                             "--chunk-points", "500000"]}
            for name, extra in variants.items():
                out = tmp / "out.laz"
                cmd = base[:5] + [str(out)] + base[6:] + extra
                if not rows:  # compile into the private cache once, untimed
                    run(cmd, env)
                wall, rss = run(cmd, env)
                rows.append({"points": n, "variant": name, "seconds": round(wall, 2),
                             "peak_rss_mib": round(rss, 1)})
                print(f"{n:>10d}  {name:<18s} {wall:8.2f} s  {rss:8.1f} MiB", flush=True)
                out.unlink()
            src.unlink()
    print("\n| points | run | wall (s, incl. LAZ read/write) | peak RSS (MiB) |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r['points']:,} | {r['variant']} | {r['seconds']} | {r['peak_rss_mib']} |")
    if args.out:
        Path(args.out).write_text(json.dumps({"radius": RADIUS, "tile": args.tile,
                                              "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
