#!/usr/bin/env python
"""Where ``lidarstat ridges`` and ``segment --method ridges`` spend their time and memory
on a real airborne crop, step by step.

Runs one command in this process with a timer (process CPU seconds, all threads; wall)
and a resident-memory sampler around each step (the jets, the neighbourhoods, the
crossing and tracing kernels, the creases, the joining of traced pieces into lines, the
segmentation's steps), and writes the key ``<command>`` of
``benchmarks/results_ridges_real.json``. With ``--reference`` every call of
``join_lines`` is repeated with the exhaustive pairwise pass
(``tests/segment/test_ridge_lines.py``), timed apart, and the two answers must be equal
(chains, alive flags, owners): the k-d tree of line ends changes the time, not the lines.
Steps nest (``creases`` holds its own ``trace`` and ``join_lines``); CPU seconds of a
step include its children. The machine is shared: CPU seconds are the figure to read.

    PYTHONPATH=src nice -n 10 python benchmarks/ridges_real.py ridges --reference
    PYTHONPATH=src nice -n 10 python benchmarks/ridges_real.py segment --reference
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import resource
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CROP = HERE.parent.parent / "shared" / "data" / "ahn3_delft_3dfier" / "ahn3_cropped_1.laz"
RESULTS = HERE / "results_ridges_real.json"


def _rss_mib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024.0
    return 0.0


class Steps:
    """CPU, wall and peak resident memory of named steps (summed over calls)."""

    def __init__(self):
        self.rows = {}
        self.active = []
        self.peak = 0.0
        threading.Thread(target=self._sample, daemon=True).start()

    def _sample(self):
        while True:
            r = _rss_mib()
            self.peak = max(self.peak, r)
            for row in list(self.active):
                row["peak_rss_mib"] = max(row["peak_rss_mib"], r)
            time.sleep(0.05)

    def wrap(self, module, name, label=None):
        fn = getattr(module, name)
        label = label or name
        steps = self

        def timed(*a, **kw):
            row = steps.rows.setdefault(label, {"calls": 0, "cpu_s": 0.0, "wall_s": 0.0,
                                                "peak_rss_mib": 0.0})
            row["peak_rss_mib"] = max(row["peak_rss_mib"], _rss_mib())
            steps.active.append(row)
            c0, w0 = time.process_time(), time.perf_counter()
            try:
                return fn(*a, **kw)
            finally:
                row["cpu_s"] += time.process_time() - c0
                row["wall_s"] += time.perf_counter() - w0
                row["calls"] += 1
                steps.active.remove(row)

        setattr(module, name, timed)
        return fn


def _instrument(steps, reference):
    from lidarstat import segment
    from lidarstat.segment import _ridge_creases as rc
    from lidarstat.segment import _ridge_kernels as rk
    from lidarstat.segment import _ridge_lines as rl
    from lidarstat.segment import _ridge_segments as rs
    from lidarstat.segment import _ridges as rr

    steps.wrap(rr, "jets")
    steps.wrap(rr, "knn_neighbors", "knn_cross")
    for name in ("candidates", "crossings", "trace", "jet_consistent_edges",
                 "assign_by_jets", "unit_boundaries"):
        steps.wrap(rk, name)
    steps.wrap(rr, "find_creases", "creases")
    steps.wrap(rc, "variance_factor", "creases.variance_factor")
    steps.wrap(rc, "crease_points", "creases.crease_points")
    steps.wrap(rr, "_build_lines", "build_lines")
    steps.wrap(segment, "ridges")
    steps.wrap(rs, "knn_neighbors", "knn_grow")
    steps.wrap(rs, "components")
    steps.wrap(rs, "_assign_by_jets", "assign_by_jets_step")
    steps.wrap(rs, "_extend_ends", "extend_ends")
    steps.wrap(segment, "ridge_segments")
    box = type("B", (), {"f": staticmethod(rl.join_lines)})
    steps.wrap(box, "f", "join_lines")
    exhaustive = None
    if reference:
        sys.path.insert(0, str(HERE.parent / "tests" / "segment"))
        from test_ridge_lines import _exhaustive

        ref = type("R", (), {"f": staticmethod(_exhaustive)})
        steps.wrap(ref, "f", "join_lines_exhaustive")
        exhaustive = ref.f

    def join(chains, vert, ridge, width):
        got = box.f(chains, vert, ridge, width)
        # chains per call; calls: those found equal to the exhaustive pass
        checks = steps.rows.setdefault("join_lines_checks", {"calls": 0, "chains": []})
        checks["chains"].append(len(chains))
        if exhaustive is not None:
            want = exhaustive(chains, vert, ridge, width)
            same = (got[1] == want[1] and got[2] == want[2] and len(got[0]) == len(want[0])
                    and all(a.shape == b.shape and (a == b).all()
                            for a, b in zip(got[0], want[0])))
            if not same:
                raise SystemExit(f"join_lines differs from the exhaustive pass on "
                                 f"{len(chains)} chains")
            checks["calls"] += 1
        return got

    rr.join_lines = rc.join_lines = join


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", choices=("ridges", "segment"))
    ap.add_argument("--reference", action="store_true",
                    help="repeat join_lines with the exhaustive pass and compare")
    ap.add_argument("--input", default=str(CROP))
    ap.add_argument("--corner", type=float, default=None,
                    help="only the points within this many metres of the crop's lowest x "
                         "and y (a square corner)")
    ap.add_argument("--keep", default=None, help="keep the output here")
    ap.add_argument("--key", default=None, help="results key (default the command)")
    args = ap.parse_args()
    if not Path(args.input).exists():
        print("crop not found:", args.input)
        return
    from lidarstat.cli._app import main as cli

    steps = Steps()
    _instrument(steps, args.reference)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or str(Path(tmp) / "out.laz")
        src = args.input
        n_points = None
        if args.corner is not None:
            from lidarstat.io import read, write

            cloud = read(src)
            lo = cloud.xyz.min(axis=0)
            keep = ((cloud.xyz[:, :2] - lo[:2]) < args.corner).all(axis=1)
            src = str(Path(tmp) / "corner.laz")
            write(src, cloud.subset(keep))
            n_points = int(keep.sum())
            del cloud
        argv = ([args.command, src, out] + (["--method", "ridges"]
                                                  if args.command == "segment" else [])
                + ["--quiet"])
        c0, w0 = time.process_time(), time.perf_counter()
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = cli(argv)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    ru = resource.getrusage(resource.RUSAGE_SELF)
    row = {"input": os.path.relpath(args.input, HERE.parent.parent),
           "corner_m": args.corner, "corner_points": n_points,
           "argv": ["lidarstat"] + argv[:1] + ["IN", "OUT"] + argv[3:],
           "exit": code, "error": err.getvalue().strip()[-400:] or None, "process_cpu_s": round(cpu, 2), "process_wall_s": round(wall, 2),
           "peak_rss_mib": round(ru.ru_maxrss / 1024.0, 1),
           "reference": args.reference,
           "steps": {k: ({kk: (round(vv, 3) if isinstance(vv, float) else vv)
                          for kk, vv in v.items()} if isinstance(v, dict) else v)
                     for k, v in steps.rows.items()},
           "machine_shared": True, "cores": os.cpu_count(),
           "note": "process CPU seconds include numba compilation where the cache is cold; "
                   "with --reference the exhaustive join_lines runs too (its step is "
                   "join_lines_exhaustive; subtract it for the process figures)"}
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    results[args.key or args.command] = row
    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    print(json.dumps(row, indent=1))


if __name__ == "__main__":
    main()
