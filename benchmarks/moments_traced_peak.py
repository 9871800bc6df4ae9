#!/usr/bin/env python
"""Peak of the memory ``lidarstat moments`` allocates through Python and NumPy, per code tree.

The peak resident set (GNU ``time``, the profile's sampler) moves by 100 MiB or more from
run to run with the allocator's reuse and the timing of the steps run beside the others;
the peak of the allocations ``tracemalloc`` sees (every NumPy array and Python object, in
every thread; not Numba's own arrays) depends only on what the code keeps alive when
the steps run in turn (``--workers 1``; beside each other, on where the side steps'
arrays fall among the others': 30 MiB apart from run to run at 10M points). Each code
tree runs ``lidarstat moments IN OUT --no-report -q [ARGS]`` in a fresh process.

Usage::

    mkdir -p /tmp/old && git archive REV src | tar -x -C /tmp/old
    python benchmarks/moments_traced_peak.py IN.las --trees /tmp/old/src src \\
        --labels main branch --args=--workers=1 --out benchmarks/results_moments_traced_peak.json \
        --key NAME
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import sys, tracemalloc, warnings
warnings.simplefilter("ignore")
import lidarstat.classify, lidarstat.io
from lidarstat.cli import main
tracemalloc.start()
rc = main(["moments", sys.argv[1], sys.argv[2], "--no-report", "-q", *sys.argv[3:]])
print("PEAK", rc, tracemalloc.get_traced_memory()[1])
"""


def traced_peak(tree, inp, out, args=()):
    """(return code, traced peak in MiB) of the command run with the package in `tree`."""
    env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
    res = subprocess.run([sys.executable, "-c", CHILD, str(inp), str(out), *args], env=env,
                         capture_output=True, text=True, check=True)
    _, rc, peak = next(s for s in res.stdout.splitlines() if s.startswith("PEAK")).split()
    return int(rc), round(int(peak) / 2**20, 1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input")
    ap.add_argument("--trees", nargs="+", required=True, help="folders holding `lidarstat`")
    ap.add_argument("--labels", nargs="+", required=True)
    ap.add_argument("--args", default="", help="more options of the command, e.g. "
                    "--args=--workers=1 (split at spaces)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--key", default="current", help="name of this run in --out")
    args = ap.parse_args(argv)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for tree, label in zip(args.trees, args.labels, strict=True):
            rc, peak = traced_peak(tree, args.input, Path(tmp) / "out.las", args.args.split())
            rows[label] = {"rc": rc, "traced_peak_mib": peak}
            print(label, rows[label], flush=True)
    if args.out:
        out = Path(args.out)
        old = json.loads(out.read_text()) if out.exists() else {}
        runs = old.get("runs", {})
        runs[args.key] = {"input": Path(args.input).name, "args": args.args, "rows": rows}
        out.write_text(json.dumps({
            "what": "peak of the allocations tracemalloc sees (NumPy arrays and Python "
                    "objects, all threads; not Numba's own arrays) during `lidarstat "
                    "moments IN OUT --no-report -q ARGS`, one fresh process per code tree",
            "machine_shared": True, "runs": runs}, indent=1) + "\n")


if __name__ == "__main__":
    main()
