#!/usr/bin/env python
"""CPU seconds of two fixed parts of ``moments`` around the analysis, two versions alternating.

The parts: the canonical order (:func:`lidarstat.classify._moments_kernels.canonical_order`
of the cloud's coordinates and intensity) and the streamed LAS write of the command
(:func:`lidarstat.io.rewrite` of the input's records with the seven fields ``moments``
writes: 30-byte records in, 63-byte records out). Each child process times its part
`--inner` times after one warm call and reports the least user + system CPU seconds
(``os.times``: the machine is shared, wall times are not comparable); the versions run
alternately, `--repeats` times each, and both parts' outputs are checked equal across
the versions (the permutation; the output file byte for byte).

Usage::

    mkdir -p /tmp/old && git archive REV src | tar -x -C /tmp/old
    python benchmarks/moments_fixed_parts.py --against /tmp/old/src --points 10000000 \\
        --out benchmarks/results_moments_fixed_parts.json --label NAME
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"


def child(part, inp, out, inner):
    import numpy as np

    from lidarstat.io import read, rewrite

    if part == "canonical order":
        from lidarstat.classify._moments_kernels import canonical_order

        c = read(inp, fields=("intensity",))
        xyz, w = c.xyz, c["intensity"]

        def run():
            return canonical_order(xyz[:, 0], xyz[:, 1], xyz[:, 2], w)
    else:
        import laspy

        with laspy.open(inp) as reader:
            n = int(reader.header.point_count)
        g = np.random.default_rng(0)
        cand = g.random(n) < 0.1

        def floats(v):
            a = np.full(n, np.nan)
            a[cand] = v
            return a

        fields = {"classification": g.choice(np.array([1, 2, 5, 6], np.uint8), n),
                  "cluster_id": g.integers(0, 5, n).astype(np.int32),
                  "building_plane_p": floats(0.5), "building_residual": floats(1.0),
                  "building_patch": np.where(cand, 3, 0).astype(np.int32),
                  "building_patch_p": floats(0.2),
                  "building_evidence": np.where(cand, 1, 0).astype(np.uint8)}

        def run():
            if os.path.exists(out):  # the replace of an old output is not timed
                os.unlink(out)
            rewrite(inp, out, lambda start, chunk: {
                k: a[start:start + len(chunk)] for k, a in fields.items()}, decode=False)
    res = run()  # compiles or pages in
    best = float("inf")
    for _ in range(inner):
        t0 = os.times()
        res = run()
        t1 = os.times()
        best = min(best, t1.user + t1.system - t0.user - t0.system)
    if part == "canonical order":
        np.save(out, res)
    print(json.dumps({"cpu_s": round(best, 3)}))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", help="src folder of the other version (required)")
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--inner", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None,
                    help="NUMBA_NUM_THREADS of the children (default: all cores)")
    ap.add_argument("--work", default="/tmp/moments_fixed_parts")
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default="current")
    ap.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        part, inp, out, inner = args.child
        return child(part, inp, out, int(inner))
    if not args.against:
        ap.error("--against is required")
    sys.path.insert(0, str(HERE))
    from bench_moments import write_cloud

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    inp, _ = write_cloud(args.points, work)
    versions = {"this": str(SRC), "against": str(Path(args.against).resolve())}
    rows = {}
    for part, suffix in (("canonical order", "npy"), ("rewrite", "las")):
        cpu = {v: [] for v in versions}
        for _ in range(args.repeats):
            for v, src in versions.items():
                env = dict(os.environ, PYTHONPATH=src)
                if args.threads:
                    env["NUMBA_NUM_THREADS"] = str(args.threads)
                res = subprocess.run([sys.executable, __file__, "--child", part, str(inp),
                                      str(work / f"{v}.{suffix}"), str(args.inner)],
                                     env=env, capture_output=True, text=True, check=True)
                cpu[v].append(json.loads(res.stdout.strip().splitlines()[-1])["cpu_s"])
        same = filecmp.cmp(work / f"this.{suffix}", work / f"against.{suffix}",
                           shallow=False)
        rows[part] = {"cpu_s": cpu, "least_cpu_s": {v: min(c) for v, c in cpu.items()},
                      "outputs_identical": same}
        print(part, json.dumps(rows[part]), flush=True)
    result = {"points": args.points, "repeats": args.repeats, "inner": args.inner,
              "threads": args.threads or os.cpu_count(),
              "against": args.against, "machine_shared": True,
              "load_average": [round(v, 2) for v in os.getloadavg()], "parts": rows}
    if args.out:
        path = Path(args.out)
        data = json.loads(path.read_text()) if path.exists() else {
            "what": __doc__.splitlines()[0], "runs": {}}
        data["runs"][args.label] = result
        path.write_text(json.dumps(data, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
