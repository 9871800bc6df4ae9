#!/usr/bin/env python
"""The end of a ``lidarstat`` process: the interpreter's teardown against ending at once.

Whole processes, alternating, on synthetic airborne clouds (the town of ``bench_moments``):

* ``teardown``: ``python -c "...; sys.exit(main(argv))"``, :func:`lidarstat.cli.main`
  followed by the interpreter's ordinary exit (module teardown, the compiled kernels'
  machine code unloaded);
* ``at_once``: ``python -m lidarstat``, the console script's path
  (:func:`lidarstat.cli.run`: exit handlers, streams flushed, then ``os._exit``).

The same command and input in both; wall and CPU seconds (``os.wait4``), median of
``--repeats``. The outputs of both are compared (the same bytes).

Writes the key ``--key`` of ``results_exit.json``::

    nice -n 10 python benchmarks/bench_exit.py --key shared --shared
"""

from __future__ import annotations

import argparse
import datetime
import filecmp
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
SRC = HERE.parent / "src"

#: name: (subcommand arguments before IN OUT, arguments after, points)
CASES = {
    "moments_0.2M": (["moments"], ["--no-report"], 200_000),
    "moments_2M": (["moments"], ["--no-report"], 2_000_000),
    "curvature_0.2M": (["curvature"], [], 200_000),
    "covariance_0.2M": (["covariance"], [], 200_000),
}

TEARDOWN = "import sys; from lidarstat.cli import main; sys.exit(main(sys.argv[1:]))"


def _timed(cmd, env):
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))}: failed: {err.strip()[-300:]}")
    return wall, usage.ru_utime + usage.ru_stime


def measure(cases, repeats, tmp: Path) -> dict:
    from scaling import write_cloud

    env = dict(os.environ, PYTHONPATH=str(SRC))
    out = {}
    for name in cases:
        head, tail, n = CASES[name]
        src = tmp / f"{n}.las"
        if not src.exists():
            write_cloud(src, n)
        ways = {"teardown": [sys.executable, "-c", TEARDOWN],
                "at_once": [sys.executable, "-m", "lidarstat"]}
        _timed([*ways["at_once"], *head, str(src), str(tmp / "warm.las"), *tail, "-q"], env)
        runs = {w: [] for w in ways}
        for r in range(repeats):
            for way, prefix in ways.items():
                dst = tmp / f"{name}_{way}_{r}.las"
                runs[way].append(_timed([*prefix, *head, str(src), str(dst), *tail, "-q"], env))
        same = all(filecmp.cmp(tmp / f"{name}_teardown_{r}.las", tmp / f"{name}_at_once_{r}.las",
                               shallow=False) for r in range(repeats))
        row = {"points": n, "outputs_equal": same}
        for way, vals in runs.items():
            row[way] = {"seconds": round(float(np.median([v[0] for v in vals])), 3),
                        "cpu_seconds": round(float(np.median([v[1] for v in vals])), 3),
                        "all_seconds": [round(v[0], 3) for v in vals]}
        row["saved_seconds"] = round(row["teardown"]["seconds"] - row["at_once"]["seconds"], 3)
        row["saved_cpu_seconds"] = round(row["teardown"]["cpu_seconds"]
                                         - row["at_once"]["cpu_seconds"], 3)
        print(f"{name:18s} teardown {row['teardown']['seconds']:7.2f} s  at once "
              f"{row['at_once']['seconds']:7.2f} s  saved {row['saved_seconds']:.2f} s "
              f"({row['saved_cpu_seconds']:.2f} CPU s), outputs equal: {same}", flush=True)
        out[name] = row
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--key", default="run")
    ap.add_argument("--shared", action="store_true", help="the machine is shared")
    ap.add_argument("--out", default=str(HERE / "results_exit.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        rows = measure(args.cases, args.repeats, Path(tmp))
    path = Path(args.out)
    store = json.loads(path.read_text()) if path.exists() else {
        "what": __doc__.split("\n\n")[0].strip()}
    store[args.key] = {"date": datetime.date.today().isoformat(), "machine_shared": args.shared,
                       "cpus": os.cpu_count(), "load_average": list(os.getloadavg()),
                       "repeats": args.repeats, "cases": rows}
    path.write_text(json.dumps(store, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
