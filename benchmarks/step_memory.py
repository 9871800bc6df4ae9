#!/usr/bin/env python
"""Where the memory of one command goes: resident memory sampled per source line of its steps.

The command runs once in a fresh process (``lidarstat COMMAND IN OUT -q`` on the synthetic
town of ``benchmarks/scaling.py``); a thread samples the process's resident memory every
5 ms together with the main thread's stack. Each sample is given to the innermost frame of
one of the named step functions (``--functions``; by default those of ``segment --method
covariance``: the classification's automatic scale and tests, then the segmentation), so
each line of those functions gets the largest resident memory seen while it ran, in MiB
and in bytes a point. ``tracemalloc`` does not see the arrays that Numba kernels allocate;
the resident memory does, and it also holds what the allocator keeps after a free, so a
line's figure is an upper bound of what is live there.

With ``--tree`` the source tree's ``src`` is imported (two trees, one input: the lines
that moved the peak). Rows go to ``--out`` under ``--key`` (other keys are kept).

Usage::

    python benchmarks/step_memory.py --points 500000 --tree /path/to/other/tree \\
        --out benchmarks/results_scaling_segment_covariance.json --key steps_before
    python benchmarks/step_memory.py --points 500000 --tree . \\
        --out benchmarks/results_scaling_segment_covariance.json --key steps_after
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: The step functions of ``segment --method covariance``.
FUNCTIONS = ("_tested_features", "classify_covariance", "segment_covariance")

_CHILD = r"""
import json, linecache, os, sys, threading, time
functions = set(json.loads(sys.argv[1]))
argv = json.loads(sys.argv[2])
page = os.sysconf("SC_PAGE_SIZE")
main_id = threading.get_ident()
peaks, order, stop = {}, [], []

def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page

def sample():
    while not stop:
        r = rss()
        frame = sys._current_frames().get(main_id)
        key = "other"
        while frame is not None:
            code = frame.f_code
            if code.co_name in functions and "lidarstat" in code.co_filename:
                path = code.co_filename.split("lidarstat" + os.sep)[-1]
                key = f"{path}:{frame.f_lineno} {code.co_name}"
                if key not in peaks:
                    order.append(key)
                    peaks[key] = [0, linecache.getline(code.co_filename, frame.f_lineno).strip()]
                break
            frame = frame.f_back
        if key == "other" and key not in peaks:
            order.append(key)
            peaks[key] = [0, ""]
        peaks[key][0] = max(peaks[key][0], r)
        time.sleep(0.005)

from lidarstat.cli import main
t = threading.Thread(target=sample, daemon=True)
t.start()
code = main(argv)
stop.append(1)
t.join()
print(json.dumps({"rc": code, "steps": [[k, peaks[k][0], peaks[k][1]] for k in order]}))
"""


def profile(tree: Path | None, points: int, argv_tail: list[str], functions, tmp: Path):
    """The per-line peaks of one run (MiB and bytes a point, in the order the lines ran)."""
    from scaling import write_cloud

    src = tmp / f"town_{points}.laz"
    if not src.exists():
        write_cloud(src, points)
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve() / "src")
    argv = [a.format(i=src, o=tmp / "out.laz") for a in argv_tail] + ["-q"]
    res = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(list(functions)),
                          json.dumps(argv)], env=env, capture_output=True, text=True,
                         check=False)
    if res.returncode != 0:
        raise SystemExit(f"the run failed: {res.stderr[-2000:]}")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    steps = [{"line": k, "peak_mib": round(b / 2**20), "bytes_per_point": round(b / points),
              "source": s} for k, b, s in out["steps"]]
    top = max(steps, key=lambda s: s["peak_mib"])
    return {"points": points, "command": argv_tail[0:1] + argv_tail[3:], "tree": str(tree),
            "peak_mib": top["peak_mib"], "peak_line": top["line"],
            "bytes_per_point": top["bytes_per_point"], "steps": steps}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=500_000)
    ap.add_argument("--tree", default=None, help="source tree whose src/ is imported")
    ap.add_argument("--command", nargs="+", default=["segment", "{i}", "{o}", "--method",
                                                    "covariance"],
                    help="argv after 'lidarstat' ({i} input, {o} output)")
    ap.add_argument("--functions", nargs="+", default=list(FUNCTIONS))
    ap.add_argument("--out", default=None)
    ap.add_argument("--key", default="steps")
    ap.add_argument("--tmp", default=None)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        row = profile(Path(args.tree) if args.tree else None, args.points, args.command,
                      args.functions, Path(tmp))
    for s in row["steps"]:
        print(f"{s['peak_mib']:7d} MiB {s['bytes_per_point']:6d} B/pt  {s['line']:45s} "
              f"{s['source'][:60]}")
    print(f"peak {row['peak_mib']} MiB at {row['peak_line']}")
    if args.out:
        path = Path(args.out)
        data = json.loads(path.read_text()) if path.exists() else {}
        data.setdefault("machine", {"cores": os.cpu_count(), "machine_shared": True})
        data[args.key] = row
        path.write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
