#!/usr/bin/env python
"""CPU seconds of the five window passes of ``moments``, two code trees run alternately.

The step "ground: window moments" of ``bench_moments.py --profile`` also carries the CPU
of the raised patches' graph, which runs beside it in a thread; this script times the
passes alone. One ``lidarstat moments`` run on the synthetic cloud of ``bench_moments.py``
(the code of this checkout) saves the inputs of every window pass (coordinates, heights
of each pass, intensity, root windows, options) to a work folder. Then child processes,
alternating between the tree of ``--before`` and this checkout for ``--rounds`` rounds,
run :func:`lidarstat.classify._moments_windows.window_pass` on those inputs (threads, as
the command runs it) ``--repeats`` times and report each pass's CPU seconds (process time,
all threads) and wall seconds. A tree's row is the per-pass minimum over its repeats and
rounds (the machine is shared: the minimum is the run least disturbed by the others).
``--parts`` adds one run of each tree with the analysis functions wrapped: each part's
CPU seconds of its own thread, less the parts it calls (sorts, the ``diptest`` package,
the rest of the dip test, sequential moments, cycle choice, the MAD bound, what a window
costs around them), the number of windows and the CPU of the largest window (a pass of
two threads waits at its end for its last window).

Usage::

    git -C .. worktree add /tmp/main_tree main   # or: git archive main src | tar -x -C DIR
    python benchmarks/moments_window_passes.py --points 10000000 --before /tmp/main_tree/src \\
        --out benchmarks/results_moments_window_passes.json --label LABEL
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PASSES = 5


def capture(n, folder):
    """Inputs of every window pass of one ``moments`` run on the cloud of `n` points."""
    sys.path.insert(0, str(HERE))
    from bench_moments import write_cloud

    import lidarstat.classify._moments_ground as mg
    from lidarstat.cli import main

    inp, _ = write_cloud(n, folder)
    orig, k = mg.window_pass, [0]

    def saving(xy, h, roots, p, inten, scheduler, workers, *, final):
        if k[0] == 0:
            np.save(folder / "xy.npy", xy)
            np.save(folder / "inten.npy", np.empty(0) if inten is None else inten)
            with open(folder / "meta.pkl", "wb") as fh:
                pickle.dump((roots, p, scheduler, workers), fh)
        np.save(folder / f"h{k[0]}.npy", h)
        k[0] += 1
        return orig(xy, h, roots, p, inten, scheduler, workers, final=final)

    mg.window_pass = saving
    out = folder / "out.las"
    if main(["moments", str(inp), str(out), "--no-report", "-q"]) != 0 or k[0] != PASSES:
        raise SystemExit(f"capture failed ({k[0]} passes)")
    out.unlink()


def child(folder, repeats):
    """Per-pass minimum CPU and wall seconds of `repeats` runs of the five passes."""
    from lidarstat.classify._moments_windows import window_pass

    xy = np.load(folder / "xy.npy")
    inten = np.load(folder / "inten.npy")
    inten = inten if inten.size else None
    with open(folder / "meta.pkl", "rb") as fh:
        roots, p, scheduler, workers = pickle.load(fh)
    heights = [np.load(folder / f"h{k}.npy") for k in range(PASSES)]
    window_pass(xy, heights[0], roots[:8], p, inten, scheduler, workers, final=False)  # load
    window_pass(xy, heights[-1], roots[:8], p, inten, scheduler, workers, final=True)
    cpu, wall = [np.inf] * PASSES, [np.inf] * PASSES
    for _ in range(repeats):
        for k, h in enumerate(heights):
            c0, w0 = time.process_time(), time.perf_counter()
            window_pass(xy, h, roots, p, inten, scheduler, workers, final=k == PASSES - 1)
            cpu[k] = min(cpu[k], time.process_time() - c0)
            wall[k] = min(wall[k], time.perf_counter() - w0)
    return {"cpu_s": cpu, "wall_s": wall}


#: (module, function, part) wrapped by ``--parts``.
PARTS = (
    ("lidarstat.classify._moments_analysis", "sort_values", "sort (window, cluster)"),
    ("lidarstat.stats._moments", "sort_values", "sort (dip-test sample)"),
    ("lidarstat.classify._moments_analysis", "dip_test", "dip test: subsample, ties, rest"),
    ("diptest", "diptest", "dip test: diptest package"),
    ("lidarstat.classify._moments_analysis", "sequential_moments", "sequential moments"),
    ("lidarstat.classify._moments_analysis", "choose_cycle", "cycle choice (curves)"),
    ("lidarstat.classify._moments_analysis", "symmetry_cycle", "cycle choice (prefix sums)"),
    ("lidarstat.classify._moments_analysis", "density_estimate", "density estimate"),
    ("lidarstat.classify._moments_analysis", "_cluster_bound", "ground bound (MAD)"),
    ("lidarstat.classify._moments_analysis", "paper_clusters", "clusters: the rest"),
    ("lidarstat.classify._moments_windows", "_classify_window", "window: the rest"),
)


def wrap_parts():
    """Wrap :data:`PARTS` (those the tree has); returns (CPU by part, calls, windows)."""
    import importlib
    import threading

    cpu, calls, windows, lock, local = {}, {}, [], threading.Lock(), threading.local()
    for mod, name, part in PARTS:
        owner = importlib.import_module(mod)
        f = getattr(owner, name, None)
        if f is None:
            continue

        def timed(*a, _f=f, _part=part, **kw):
            stack = getattr(local, "stack", None) or []
            local.stack = stack
            t0 = time.thread_time()
            stack.append(0.0)
            try:
                return _f(*a, **kw)
            finally:
                dt = time.thread_time() - t0
                inner = stack.pop()
                if stack:
                    stack[-1] += dt
                with lock:
                    cpu[_part] = cpu.get(_part, 0.0) + dt - inner
                    calls[_part] = calls.get(_part, 0) + 1
                    if _part == "window: the rest":
                        windows.append(dt)

        setattr(owner, name, timed)
    return cpu, calls, windows


def child_parts(folder):
    """One run of the five passes with :data:`PARTS` timed: rows per pass."""
    from lidarstat.classify._moments_windows import window_pass

    cpu, calls, windows = wrap_parts()
    xy = np.load(folder / "xy.npy")
    inten = np.load(folder / "inten.npy")
    inten = inten if inten.size else None
    with open(folder / "meta.pkl", "rb") as fh:
        roots, p, scheduler, workers = pickle.load(fh)
    window_pass(xy, np.load(folder / "h0.npy"), roots[:8], p, inten, scheduler, workers,
                final=False)
    window_pass(xy, np.load(folder / f"h{PASSES - 1}.npy"), roots[:8], p, inten, scheduler,
                workers, final=True)
    rows = []
    for k in range(PASSES):
        h = np.load(folder / f"h{k}.npy")
        cpu.clear(), calls.clear(), windows.clear()
        c0 = time.process_time()
        window_pass(xy, h, roots, p, inten, scheduler, workers, final=k == PASSES - 1)
        total = time.process_time() - c0
        rows.append({"cpu_s": round(total, 3),
                     "parts_cpu_s": {a: round(v, 3) for a, v in
                                     sorted(cpu.items(), key=lambda t: -t[1])},
                     "calls": dict(calls), "windows": len(windows),
                     "windows_cpu_s": round(sum(windows), 3),
                     "largest_window_cpu_s": round(max(windows), 3)})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--before", required=False, help="src folder of the code compared")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--work", default=None, help="folder of the cloud and the pass inputs")
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default="current")
    ap.add_argument("--note", default=None, help="what code each tree holds (stored)")
    ap.add_argument("--parts", action="store_true", help="also one run of each tree "
                    "with the parts timed")
    ap.add_argument("--child", nargs=2, metavar=("WORK", "REPEATS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        folder, reps = Path(args.child[0]), args.child[1]
        print(json.dumps(child_parts(folder) if reps == "parts" else child(folder, int(reps))))
        return
    folder = Path(args.work or f"/tmp/moments_window_passes_{args.points}")
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / f"h{PASSES - 1}.npy").exists():
        capture(args.points, folder)
    trees = {"after": str(HERE.parent / "src")}
    if args.before:
        trees = {"before": str(Path(args.before).resolve()), **trees}
    rows = {name: {"cpu_s": [np.inf] * PASSES, "wall_s": [np.inf] * PASSES, "runs": []}
            for name in trees}
    for r in range(args.rounds):
        for name, src in trees.items():
            env = {**os.environ, "PYTHONPATH": src}
            res = subprocess.run([sys.executable, __file__, "--child", str(folder),
                                  str(args.repeats)], env=env, capture_output=True,
                                 text=True, check=True)
            got = json.loads(res.stdout.strip().splitlines()[-1])
            row = rows[name]
            row["runs"].append([round(c, 3) for c in got["cpu_s"]])
            for key in ("cpu_s", "wall_s"):
                row[key] = [min(a, b) for a, b in zip(row[key], got[key])]
            print(name, r, json.dumps(got), flush=True)
    for name, src in trees.items() if args.parts else ():
        res = subprocess.run([sys.executable, __file__, "--child", str(folder), "parts"],
                             env={**os.environ, "PYTHONPATH": src}, capture_output=True,
                             text=True, check=True)
        rows[name]["parts"] = json.loads(res.stdout.strip().splitlines()[-1])
        print(name, "parts", json.dumps(rows[name]["parts"]), flush=True)
    for row in rows.values():
        row["cpu_s"] = [round(c, 3) for c in row["cpu_s"]]
        row["wall_s"] = [round(c, 3) for c in row["wall_s"]]
        row["cpu_s_five_passes"] = round(sum(row["cpu_s"]), 3)
        row["wall_s_five_passes"] = round(sum(row["wall_s"]), 3)
        print(json.dumps(row))
    if args.out:
        out = Path(args.out)
        old = json.loads(out.read_text()) if out.exists() else {}
        runs = old.get("runs", {})
        runs[args.label] = {"points": args.points, "rounds": args.rounds,
                            "repeats": args.repeats, "load_average": os.getloadavg(),
                            "machine_shared": True, "trees": rows,
                            **({"code": args.note} if args.note else {})}
        out.write_text(json.dumps({
            "what": "CPU seconds (process time, all threads) and wall seconds of each of "
                    "the five window passes of moments on the synthetic cloud of "
                    "bench_moments.py, replayed on the inputs one run saved; per pass the "
                    "minimum over the repeats and rounds of each code tree, the trees run "
                    "alternately in fresh processes",
            "machine_shared": True, "cpus": os.cpu_count(), "runs": runs}, indent=1) + "\n")


if __name__ == "__main__":
    import warnings

    warnings.simplefilter("ignore")
    main()
