#!/usr/bin/env python
"""Two source trees of lidarstat, one command, alternating runs: CPU seconds and peak memory.

The runs are those of ``benchmarks/scaling.py`` (fresh process, whole process, the
command with its defaults on the synthetic town, peak resident memory from ``os.wait4``),
with ``PYTHONPATH`` set to each tree's ``src`` in turn: ``before, after, before, after,
...`` on the same input file, so the CPU-time ratio is measured in one run on the shared
machine. Each tree has its own Numba cache, filled by an untimed run on a small file.

Usage::

    python benchmarks/scaling_compare.py --before /path/to/main --after . \\
        --commands covariance --sizes 200000 2000000 --repeat 2 \\
        --out benchmarks/results_scaling_blocks.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import scaling  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="source tree (its src/ is used)")
    ap.add_argument("--after", required=True, help="source tree (its src/ is used)")
    ap.add_argument("--commands", nargs="+", default=["covariance"],
                    choices=list(scaling.COMMANDS))
    ap.add_argument("--sizes", type=int, nargs="+", default=[200_000, 2_000_000])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=1500.0)
    ap.add_argument("--max-mib", type=float, default=None)
    ap.add_argument("--only", choices=["before", "after"], default=None,
                    help="run one tree only (its peak memory and CPU seconds)")
    ap.add_argument("--cache", default=None,
                    help="folder of the trees' Numba caches, kept between runs "
                         "(default: a temporary one)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--tmp", default=None)
    args = ap.parse_args(argv)
    trees = {"before": Path(args.before).resolve(), "after": Path(args.after).resolve()}
    if args.only:
        trees = {args.only: trees[args.only]}
    rows = []
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        tmp = Path(tmp)
        cache = Path(args.cache) if args.cache else tmp
        envs = {name: dict(os.environ, PYTHONPATH=str(tree / "src"),
                           NUMBA_CACHE_DIR=str(cache / f"numba_{name}"))
                for name, tree in trees.items()}
        warm = tmp / "warm.laz"
        scaling.write_cloud(warm, 20_000)
        for name in args.commands:
            for tree, env in envs.items():
                out = scaling.run([a.format(i=warm, o=tmp / "w.laz")
                                   for a in scaling.COMMANDS[name]], env, timeout=1800)
                print(f"warm-up {name} {tree}: {out['status']}", flush=True)
        for n in args.sizes:
            src = tmp / f"town_{n}.laz"
            scaling.write_cloud(src, n)
            for name in args.commands:
                for rep in range(args.repeat):
                    for tree, env in envs.items():
                        dst = tmp / "out.laz"
                        res = scaling.run([a.format(i=src, o=dst)
                                           for a in scaling.COMMANDS[name]], env,
                                          args.timeout, args.max_mib)
                        dst.unlink(missing_ok=True)
                        res.update(command=name, points=n, tree=tree, repeat=rep)
                        rows.append(res)
                        print(f"{name:20s} {n:>10,d} {tree:6s} {res.get('cpu_seconds')} s CPU"
                              f"  {res['seconds']} s  {res['peak_mib']} MiB  {res['status']}",
                              flush=True)
            src.unlink()
    summary = []
    for name in args.commands:
        for n in args.sizes:
            got = {t: [r for r in rows if r["command"] == name and r["points"] == n
                       and r["tree"] == t and r["status"] == "ok"] for t in trees}
            entry = {"command": name, "points": n}
            for t, rs in got.items():
                if rs:
                    entry[t] = {"cpu_seconds": statistics.median(r["cpu_seconds"] for r in rs),
                                "peak_mib": max(r["peak_mib"] for r in rs),
                                "bytes_per_point": round(max(r["peak_mib"] for r in rs)
                                                         * 2**20 / n)}
            if got.get("before") and got.get("after"):
                entry["cpu_ratio_after_before"] = round(
                    entry["after"]["cpu_seconds"] / entry["before"]["cpu_seconds"], 3)
            summary.append(entry)
            print(json.dumps(entry), flush=True)
    result = {"machine": {"platform": platform.platform(), "cores": os.cpu_count(),
                          "python": platform.python_version(), "machine_shared": True,
                          "note": "two cores shared with other jobs: CPU-second ratios "
                                  "from alternating runs; peak memory is not affected"},
              "trees": {k: str(v) for k, v in trees.items()}, "runs": rows,
              "summary": summary}
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
