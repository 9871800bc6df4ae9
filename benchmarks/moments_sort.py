#!/usr/bin/env python
"""The sorts of the window moments: ``np.sort`` against ``lidarstat.stats.sort_values``.

Every analysis of the moments classification sorts its values: a root window's heights
(about 30,000 values at 10 points per m^2 in a 64 m window), the sample of a dip test
(at most 20,000, sorted twice where its ties are spread), a cluster's intensities. On
the heights of the root windows of ``bench_moments.py``'s synthetic cloud (rounded to
1e-6 as the classification rounds them) and on samples of 2,000 and 20,000 of them,
this times both sorts (CPU seconds of the process, median of ``--repeats`` rounds,
each round alternating the two) and checks that they give the same arrays.

Writes ``results_moments_sort.json``::

    python benchmarks/moments_sort.py --points 2000000 --out benchmarks/results_moments_sort.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "src"))


def _cpu():
    return time.process_time()


#: Sorts of every set per round (the process clock ticks too coarsely for one).
_INNER = 10


def _groups(n, seed=0):
    """Heights of every 64 m root window, and samples of 20,000 and 2,000 of them."""
    from bench_moments import make_cloud

    xyz = make_cloud(n, seed=seed)[0]
    key = np.floor(xyz[:, 0] / 64.0) * 1e6 + np.floor(xyz[:, 1] / 64.0)
    order = np.argsort(key, kind="stable")
    cuts = np.flatnonzero(np.diff(key[order])) + 1
    h = np.round(xyz[order, 2] - np.median(xyz[:, 2]), 6)
    windows = [np.ascontiguousarray(w) for w in np.split(h, cuts)]
    g = np.random.default_rng(seed)
    big = [w for w in windows if w.size > 20_000]
    return {"windows": windows,
            "samples_20000": [g.choice(w, 20_000, replace=False) for w in big],
            "samples_2000": [g.choice(w, 2_000, replace=False) for w in windows]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    from lidarstat.stats import sort_values

    out = {"what": "CPU seconds (process) of sorting the values the window moments sort, "
                   "np.sort against lidarstat.stats.sort_values (radix sort of the bits), "
                   "median of the rounds, the two alternating; 'equal': the arrays are equal",
           "points": args.points, "repeats": args.repeats, "machine_shared": True,
           "cpus": os.cpu_count(), "load_average": list(os.getloadavg()),
           "python": platform.python_version(), "numpy": np.__version__, "sets": {}}
    for name, arrays in _groups(args.points).items():
        equal = all(np.array_equal(sort_values(a), np.sort(a)) for a in arrays)
        t = {"np_sort": [], "sort_values": []}
        for _ in range(args.repeats):
            for label, f in (("np_sort", np.sort), ("sort_values", sort_values)):
                c = _cpu()
                for _ in range(_INNER):
                    for a in arrays:
                        f(a)
                t[label].append((_cpu() - c) / _INNER)
        values = int(sum(a.size for a in arrays))
        rec = {"arrays": len(arrays), "values": values, "equal": bool(equal)}
        for label, ts in t.items():
            rec[f"{label}_cpu_s"] = round(float(np.median(ts)), 5)
            rec[f"{label}_ns_per_value"] = round(float(np.median(ts)) / values * 1e9, 1)
        rec["ratio"] = round(rec["sort_values_cpu_s"] / rec["np_sort_cpu_s"], 3)
        out["sets"][name] = rec
        print(name, rec, flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
