#!/usr/bin/env python
"""Planar Delaunay triangulation: ``lidarstat.neighbors.delaunay_triangles`` against
``scipy.spatial.Delaunay`` (Qhull) in the same run.

Each configuration runs in a fresh process (so that its peak memory is its own): the points
are made, then one triangulation is timed (CPU and wall) and the growth of the process's
peak resident memory during it is recorded. The two libraries alternate within each repeat
(the machine may be shared: ``machine_shared`` and the load average are in the results;
compare ratios of the same run). The point sets:

* ``uniform``: N points uniform in a square of N / 10 m2 (10 points/m2, cm coordinates);
* ``national_grid``: the same moved to Dutch national-grid coordinates (155 km, 463 km);
* ``lattice``: the centres of the filled cells of a 1 m grid, 30 % of the cells empty
  (the vertices of a terrain grid: four co-circular points in most squares).

For ``uniform`` the triangles are compared with Qhull's on coordinates about their
middle: ``triangles_not_in_qhull`` counts lidarstat's triangles Qhull does not have. Points
in general position have one Delaunay triangulation; centimetre coordinates hold some
exactly co-circular quadruples, whose two diagonals are both Delaunay.

Usage::

    python benchmarks/bench_delaunay.py --out benchmarks/results_delaunay.json
    python benchmarks/bench_delaunay.py --points 100000 --repeats 1   # seconds
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _results import store

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"


def make_points(kind: str, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    side = np.sqrt(n / 10.0)
    if kind in ("uniform", "national_grid"):
        xy = rng.uniform(0, side, (n, 2)).round(2)
        return xy + [155000.0, 463000.0] if kind == "national_grid" else xy
    if kind == "lattice":
        m = int(np.ceil(np.sqrt(n / 0.7)))
        g = np.stack(np.meshgrid(np.arange(m) + 0.5, np.arange(m) + 0.5), -1).reshape(-1, 2)
        return g[rng.random(len(g)) < 0.7][:n]
    raise ValueError(kind)


def child(library: str, kind: str, n: int) -> dict:
    """One triangulation in this process: seconds, CPU seconds, peak growth (MiB)."""
    sys.path.insert(0, str(SRC))
    from scipy.spatial import Delaunay

    from lidarstat.neighbors import delaunay_triangles

    delaunay_triangles(make_points("uniform", 1000))  # load the compiled kernel
    xy = make_points(kind, n)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    c0, t0 = time.process_time(), time.perf_counter()
    if library == "lidarstat":
        tri = delaunay_triangles(xy)
    else:
        tri = Delaunay(xy).simplices
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    out = {"seconds": round(wall, 3), "cpu_s": round(cpu, 3),
           "peak_growth_mib": round((after - before) / 1024, 1), "triangles": len(tri)}
    if kind == "uniform" and library == "lidarstat":
        other = Delaunay(xy - xy.mean(axis=0)).simplices
        a = {tuple(t) for t in np.sort(tri, axis=1).tolist()}
        b = {tuple(t) for t in np.sort(other, axis=1).tolist()}
        out["triangles_not_in_qhull"] = len(a - b)
    return out


def run(library, kind, n):
    cmd = [sys.executable, __file__, "--child", library, kind, str(n)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--kinds", nargs="+", default=["uniform", "national_grid", "lattice"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--key", default="delaunay")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child[0], args.child[1], int(args.child[2]))))
        return
    rows = {}
    for n in args.points:
        for kind in args.kinds:
            runs = {"lidarstat": [], "qhull": []}
            for _ in range(args.repeats):
                for lib in runs:
                    runs[lib].append(run(lib, kind, n))
            row = {lib: {k: float(np.median([r[k] for r in rs])) for k in rs[0]}
                   for lib, rs in runs.items()}
            row["cpu_ratio"] = round(row["lidarstat"]["cpu_s"] / row["qhull"]["cpu_s"], 3)
            rows[f"{kind}_{n}"] = row
            print(f"{kind:>14} {n:>9}: lidarstat {row['lidarstat']['cpu_s']:.2f} s "
                  f"{row['lidarstat']['peak_growth_mib']:.0f} MiB, Qhull "
                  f"{row['qhull']['cpu_s']:.2f} s {row['qhull']['peak_growth_mib']:.0f} MiB,"
                  f" ratio {row['cpu_ratio']}", flush=True)
    result = {"what": "CPU and wall seconds and peak memory growth of one planar Delaunay "
                      "triangulation, lidarstat (sweep-hull, Numba) against scipy.spatial."
                      "Delaunay (Qhull), each in a fresh process, alternating; median of "
                      "the repeats",
              "repeats": args.repeats, "cpus": os.cpu_count(),
              "load_average": list(os.getloadavg()), "machine_shared": True,
              "rows": rows}
    if args.out:
        store(args.out, args.key, result)


if __name__ == "__main__":
    main()
