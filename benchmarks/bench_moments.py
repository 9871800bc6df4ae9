"""Whole `moments` classification on a synthetic airborne cloud, with CSF on the same points.

Cloud: sloped sine terrain, box buildings, tree blobs with two returns, intensity with a
dark road band, 10 points/m2; generated with NumPy in seconds (deterministic seed). Each
size runs `moments` (default parameters, tiles in threads) and then CSF (cloth
1 m, slope smoothing) on the same points in the same process; the table gives both times,
their ratio, the CPU time of each (all threads), the ground/object errors against the generator's truth, the time of each
phase of `moments` and the peak memory of the process.

Usage::

    python benchmarks/bench_moments.py --quick            # 200k points, seconds
    python benchmarks/bench_moments.py --out benchmarks/results_moments.json   # 1M and 10M
    python benchmarks/bench_moments.py --points 3000000   # one size, no JSON
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE))

from lidarstat.classify import (_moments, _moments_ground, _moments_objects,  # noqa: E402
                                _moments_windows, _roads, _surface, filter_errors, moments)

FULL_SIZES = (1_000_000, 10_000_000)


def make_cloud(n, seed=20261122, origin=(0.0, 0.0)):
    """`n` points over a square at 10 points/m2 with its lower corner at `origin` (the
    terrain, buildings, trees and roads are functions of the position, so squares with
    other origins are tiles of one town)."""
    g = np.random.default_rng(seed)
    side = np.sqrt(n / 10.0)  # 10 pts/m2
    xy = g.uniform(0, side, (n, 2)) + np.asarray(origin, float)
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


class _Phases:
    """Wall time of the phases of `moments`, by wrapping its module functions."""

    NAMES = {"opening": (_moments_ground, "opening_surface"),
             "windows": (_moments_windows, "tile_grid"),
             "window passes": (_moments_ground, "window_pass"),
             "surface fit": (_moments_ground, "ground_surface"),
             "surface eval": (_surface.TinSurface, "__call__"),
             "low noise": (_moments, "low_outliers"),
             "continuity": (_moments_ground, "raised_patches"),
             "cut interpolation": (_moments_ground, "interpolate_cuts"),
             "roads": (_roads, "cell_median"),
             "vegetation": (_moments_objects, "vegetation_like")}

    def __init__(self):
        self.seconds = defaultdict(float)
        self._saved = []

    def __enter__(self):
        for name, (owner, attr) in self.NAMES.items():
            orig = getattr(owner, attr)
            self._saved.append((owner, attr, orig))
            setattr(owner, attr, self._wrap(name, orig))
        return self

    def _wrap(self, name, orig):
        def timed(*a, **k):
            t = time.perf_counter()
            try:
                return orig(*a, **k)
            finally:
                self.seconds[name] += time.perf_counter() - t
        return timed

    def __exit__(self, *exc):
        for owner, attr, orig in reversed(self._saved):
            setattr(owner, attr, orig)


def run(n, scheduler, workers):
    from isprs_filtertest import csf_ground

    t = time.perf_counter()
    xyz, inten, nret, rnum, truth = make_cloud(n)
    gen = time.perf_counter() - t
    with _Phases() as ph:
        t, c = time.perf_counter(), time.process_time()
        res = moments(xyz, inten, number_of_returns=nret, return_number=rnum,
                      scheduler=scheduler, workers=workers)
        t_mom, c_mom = time.perf_counter() - t, time.process_time() - c
    phases = {k: round(v, 3) for k, v in ph.seconds.items()}
    phases["other"] = round(t_mom - sum(ph.seconds.values()), 3)
    e = filter_errors(res.ground, truth)
    del res
    t, c = time.perf_counter(), time.process_time()
    g = csf_ground(xyz, 1.0)
    t_csf, c_csf = time.perf_counter() - t, time.process_time() - c
    ec = filter_errors(g, truth)
    return {"points": n, "generate_s": round(gen, 3), "moments_s": round(t_mom, 3),
            "csf_s": round(t_csf, 3), "ratio_moments_over_csf": round(t_mom / t_csf, 3),
            "moments_cpu_s": round(c_mom, 3), "csf_cpu_s": round(c_csf, 3),
            "moments_total_error": e.total, "csf_total_error": ec.total,
            "moments_phases_s": phases,
            "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="200,000 points only (seconds)")
    ap.add_argument("--points", type=int, nargs="+", default=list(FULL_SIZES),
                    help="cloud sizes (default: the full mode, 1M and 10M)")
    ap.add_argument("--scheduler", default="threads", choices=("threads", "sync", "dask"))
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default=None, help="JSON of the results (full mode only)")
    args = ap.parse_args(argv)
    sizes = [200_000] if args.quick else args.points
    xyz, inten, *_ = make_cloud(20_000)
    moments(xyz, inten)  # JIT warm-up (or cache load)
    rows = []
    for n in sizes:
        rows.append(run(n, args.scheduler, args.workers))
        print(json.dumps(rows[-1]), flush=True)
    print("\n| points | moments (s) | CSF (s) | moments / CSF | total error moments | CSF "
          "| peak RSS (MiB) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['points']:,} | {r['moments_s']:.1f} | {r['csf_s']:.1f} | "
              f"{r['ratio_moments_over_csf']:.2f} | {100 * r['moments_total_error']:.2f} % | "
              f"{100 * r['csf_total_error']:.2f} % | {r['peak_rss_mib']} |")
    print("\nmoments phases (s): " + "; ".join(
        f"{r['points']:,}: " + ", ".join(f"{k} {v:.1f}" for k, v in r["moments_phases_s"].items())
        for r in rows))
    if args.out and not args.quick:
        Path(args.out).write_text(json.dumps({"runs": rows, "scheduler": args.scheduler,
                                              "workers": args.workers}, indent=1))


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        main()
