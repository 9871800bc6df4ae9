"""Whole `moments` classification on a synthetic airborne cloud, with CSF on the same points.

Cloud: sloped sine terrain, box buildings, tree blobs with two returns, intensity with a
dark road band; generated with NumPy in seconds (deterministic seed).

Usage::

    python benchmarks/bench_moments.py --quick            # 200k points, seconds
    python benchmarks/bench_moments.py --out benchmarks/results_moments.json   # 10M points
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
sys.path.insert(0, str(HERE))

from lidarstat.classify import classify_moments, filter_errors  # noqa: E402


def make_cloud(n, seed=20261122):
    g = np.random.default_rng(seed)
    side = np.sqrt(n / 10.0)  # 10 pts/m2
    xy = g.uniform(0, side, (n, 2))
    z = 5 * np.sin(xy[:, 0] / 150) + 3 * np.cos(xy[:, 1] / 110) + 0.02 * xy[:, 0]
    z += g.normal(0, 0.03, n)
    ground = np.ones(n, bool)
    inten = g.normal(150, 12, n)
    road = np.abs((xy[:, 1] % 200) - 100) < 5
    inten[road] = g.normal(60, 8, road.sum())
    cx = (xy[:, 0] // 60) * 60 + 30
    cy = (xy[:, 1] // 60) * 60 + 30
    bld = (np.abs(xy[:, 0] - cx) < 12) & (np.abs(xy[:, 1] - cy) < 9) & ~road
    z[bld] += 8 + (cx[bld] % 7)
    ground[bld] = False
    tree = (np.hypot(xy[:, 0] - cx - 22, xy[:, 1] - cy + 20) < 4) & ~bld & ~road
    first = tree & (g.uniform(size=n) < 0.6)
    z[first] += g.uniform(3, 10, first.sum())
    ground[first] = False
    nret = np.where(tree, 2, 1)
    rnum = np.where(first, 1, nret)
    return np.c_[xy + 5e5, z + 100], inten, nret, rnum, ground


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    n = 200_000 if args.quick else args.points
    t = time.perf_counter()
    xyz, inten, nret, rnum, truth = make_cloud(n)
    gen = time.perf_counter() - t
    classify_moments(xyz[:20000], inten[:20000])  # JIT warm-up
    t = time.perf_counter()
    res = classify_moments(xyz, inten, number_of_returns=nret, return_number=rnum)
    t_mom = time.perf_counter() - t
    e = filter_errors(res.ground, truth)
    from isprs_filtertest import csf_ground

    t = time.perf_counter()
    g = csf_ground(xyz, 1.0)
    t_csf = time.perf_counter() - t
    ec = filter_errors(g, truth)
    out = {"points": n, "generate_s": gen, "moments_s": t_mom, "csf_s": t_csf,
           "ratio_moments_over_csf": t_mom / t_csf, "moments_total_error": e.total,
           "csf_total_error": ec.total}
    print("| points | moments (s) | CSF (s) | moments / CSF | total error moments | CSF |")
    print("|---|---|---|---|---|---|")
    print(f"| {n} | {t_mom:.1f} | {t_csf:.1f} | {t_mom / t_csf:.2f} | "
          f"{100 * e.total:.2f} % | {100 * ec.total:.2f} % |")
    if args.out and not args.quick:
        Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        main()
