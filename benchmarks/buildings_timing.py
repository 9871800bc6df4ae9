#!/usr/bin/env python
"""Time `moments` on the synthetic cloud of bench_moments.py with two source trees,
alternating (before / after a change), each run in a fresh process.

Usage::

    python benchmarks/buildings_timing.py --before ../main --points 2000000 --rounds 2 \\
        --out benchmarks/results_buildings_timing.json

`--before` is the root of the other checkout (its ``src`` and ``benchmarks`` are used);
this checkout is "after". On a shared machine the times of separate runs are noisy; the
share of the building step in the same run (``building_share``) is the steadier figure.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
sys.path.insert(0, sys.argv[1])
import bench_moments as b
from lidarstat.classify import _moments, moments
spent = [0.0]
if hasattr(_moments, "building_step"):  # time the building step inside the same run
    step = _moments.building_step
    def timed_step(*a, **k):
        t = time.perf_counter()
        try:
            return step(*a, **k)
        finally:
            spent[0] += time.perf_counter() - t
    _moments.building_step = timed_step
xyz, inten, nret, rnum, _ = b.make_cloud(20000)
moments(xyz, inten, number_of_returns=nret, return_number=rnum)
xyz, inten, nret, rnum, _ = b.make_cloud(int(sys.argv[2]))
t = time.perf_counter()
moments(xyz, inten, number_of_returns=nret, return_number=rnum)
print(json.dumps([round(time.perf_counter() - t, 2), round(spent[0], 2)]))
"""


def timed(root: Path, points: int) -> list:
    """[seconds of moments, seconds of its building step] in a fresh process."""
    out = subprocess.run([sys.executable, "-c", CHILD, str(root / "benchmarks"), str(points)],
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="root of the other checkout")
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for _ in range(args.rounds):
        before, _ = timed(Path(args.before).resolve(), args.points)
        after, step = timed(HERE.parent, args.points)
        rows.append({"before_s": before, "after_s": after, "ratio": round(after / before, 3),
                     "building_step_s": step, "building_share": round(step / after, 3)})
        print(json.dumps(rows[-1]), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps({"points": args.points, "runs": rows,
                                              "machine": "shared, 2 cores"}, indent=1))


if __name__ == "__main__":
    main()
