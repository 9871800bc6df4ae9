#!/usr/bin/env python
"""Two source trees of lidarstat, one method, a seed sweep: are the result fields identical?

A change made for memory or speed must not change results. Each tree runs in its own
process (``PYTHONPATH`` set to its ``src``) on the synthetic town of
``bench_moments.make_cloud`` (terrain, buildings, trees, roads), one cloud per seed, and
saves every result field; the fields are then compared one by one. Both trees run the same
arithmetic, so the comparison is exact (NaN equal to NaN); a field that differs is
reported with its largest difference and the number of points where it differs.

Usage::

    python benchmarks/tree_fields_compare.py --before /path/to/main --after . \\
        --method curvature --points 20000 --seeds 0 1 2 3 \\
        --out benchmarks/results_curvature_ladder_compare.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: method -> (library call on ``xyz``, description); every call returns a result with
#: ``to_fields()`` or ``.fields`` (dict of per-point arrays)
METHODS = {
    "curvature": ("features.curvature(xyz)", "automatic scale (the default)"),
    "curvature-radii": ("features.curvature(xyz, radius=[0.9, 1.3, 1.8])",
                        "three radii: the smallest accepted per point"),
    "covariance": ("features.covariance_features(xyz)", "automatic scale (the default)"),
    "segment-covariance": ("segment.segment_covariance(xyz, features.covariance_features(xyz))",
                           "defaults"),
}

CHILD = r"""
import sys, numpy as np
sys.path.insert(0, {here!r})
from bench_moments import make_cloud
from lidarstat import features, segment
xyz = make_cloud({n}, seed={seed})[0]
res = {call}
fields = res.to_fields() if hasattr(res, "to_fields") else res.fields
np.savez({out!r}, **{{k: np.asarray(v) for k, v in fields.items()}})
"""


def run_tree(tree: Path, method: str, n: int, seed: int, out: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(tree / "src"))
    code = CHILD.format(here=str(HERE), n=n, seed=seed, call=METHODS[method][0], out=str(out))
    subprocess.run([sys.executable, "-c", code], env=env, check=True)


def compare(a: Path, b: Path) -> dict:
    fa, fb = np.load(a), np.load(b)
    out = {"fields": sorted(fa.files), "differ": {}}
    if sorted(fa.files) != sorted(fb.files):
        out["differ"]["field names"] = {"before": sorted(fa.files), "after": sorted(fb.files)}
        return out
    for k in fa.files:
        x, y = fa[k], fb[k]
        same = (x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == "f" else x == y
        if x.shape != y.shape or not np.all(same):
            bad = ~same if x.shape == y.shape else np.ones(1, bool)
            diff = (float(np.nanmax(np.abs(x.astype(float) - y.astype(float))))
                    if x.shape == y.shape else None)
            out["differ"][k] = {"points": int(bad.sum()), "max_abs_difference": diff}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="source tree (its src/ is used)")
    ap.add_argument("--after", required=True, help="source tree (its src/ is used)")
    ap.add_argument("--method", nargs="+", default=["curvature"], choices=list(METHODS))
    ap.add_argument("--points", type=int, default=20_000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for method in args.method:
            for seed in args.seeds:
                paths = {}
                for name in ("before", "after"):
                    paths[name] = tmp / f"{name}_{method}_{seed}.npz"
                    run_tree(Path(getattr(args, name)).resolve(), method, args.points, seed,
                             paths[name])
                cmp = compare(paths["before"], paths["after"])
                row = {"method": method, "call": METHODS[method][0], "seed": seed,
                       "points": args.points, "identical": not cmp["differ"], **cmp}
                rows.append(row)
                print(f"{method:20s} seed {seed}: "
                      f"{'identical' if row['identical'] else 'DIFFER ' + str(cmp['differ'])}"
                      f" ({len(cmp['fields'])} fields)", flush=True)
    result = {"comparison": "exact, field by field (NaN equal to NaN)",
              "data": "bench_moments.make_cloud synthetic town, one cloud per seed",
              "rows": rows, "all_identical": all(r["identical"] for r in rows)}
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print("all identical" if result["all_identical"] else "SOME FIELDS DIFFER")
    return 0 if result["all_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
