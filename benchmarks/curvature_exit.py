#!/usr/bin/env python
"""What the end of a ``lidarstat curvature`` process costs, and the whole process against
another version of the package.

On the cloud of ``bench_curvature.py`` (2M points, the radius of about 50 neighbours):

* ``teardown``: the command run in a child through :func:`lidarstat.cli._app.main` (its
  argument list given, so it returns); the child notes the time and its CPU seconds, then
  either returns to the interpreter (``teardown``: Python's exit, which unloads the
  modules and the compiled kernels) or ends at once with ``os._exit`` (``at_once``). The
  parent's ``os.wait4`` gives the wall from the child's note to its end and the CPU
  seconds after the note. Alternating, ``--rounds`` times each.
* ``whole``: ``python -m lidarstat.cli curvature IN OUT -q --radius R`` of this package
  and of the package at ``--against`` (a PYTHONPATH, e.g. main's src), alternating, each
  version with its own Numba cache (compiled by one run first); wall, CPU (user + system)
  and peak RSS per run, and whether the two outputs are byte-identical.

Writes under ``--key`` of ``results_curvature_speed.json``::

    python benchmarks/curvature_exit.py --against OLD/src --key NAME --shared
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RADIUS = 0.901118757864343  # about 50 neighbours on this cloud (bench_curvature)


def child(args):
    """Run the command in-process, note the time, then end as `args.end` says."""
    from lidarstat.cli._app import main

    rc = main(["curvature", args.input, args.output, "-q", "--radius", repr(RADIUS)])
    note = {"rc": rc, "time": time.time(), "cpu": time.process_time()}
    Path(args.note).write_text(json.dumps(note))
    if args.end == "at_once":
        os._exit(rc)
    return rc


def _run(cmd, env):
    t0 = time.time()
    p = subprocess.Popen(cmd, env=env)
    _, status, ru = os.wait4(p.pid, 0)
    t1 = time.time()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"{cmd[:4]} failed ({code})")
    return t0, t1, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def teardown(las, tmp, env, rounds):
    out = {"teardown": [], "at_once": []}
    note = tmp / "note.json"
    for _ in range(rounds):
        for end in out:
            cmd = [sys.executable, __file__, "--child", "--input", str(las), "--output",
                   str(tmp / "t.las"), "--note", str(note), "--end", end]
            _, t1, cpu, _ = _run(cmd, env)
            n = json.loads(note.read_text())
            out[end].append({"wall_after_return": t1 - n["time"],
                             "cpu_after_return": cpu - n["cpu"]})
    return {k: dict(runs=v, wall_median=float(np.median([r["wall_after_return"] for r in v])),
                    cpu_median=float(np.median([r["cpu_after_return"] for r in v])))
            for k, v in out.items()}


def whole(las, tmp, versions, rounds):
    out = {name: [] for name in versions}
    for name, env in versions.items():  # each version's cache compiled before the timing
        _run([sys.executable, "-m", "lidarstat.cli", "curvature", str(las),
              str(tmp / f"{name}.las"), "-q", "--radius", repr(RADIUS)], env)
    for _ in range(rounds):
        for name, env in versions.items():
            t0, t1, cpu, rss = _run([sys.executable, "-m", "lidarstat.cli", "curvature",
                                     str(las), str(tmp / f"{name}.las"), "-q", "--radius",
                                     repr(RADIUS)], env)
            out[name].append({"seconds": t1 - t0, "cpu_seconds": cpu, "peak_rss_mb": rss})
    res = {name: dict(runs=v, seconds_median=float(np.median([r["seconds"] for r in v])),
                      cpu_seconds_median=float(np.median([r["cpu_seconds"] for r in v])))
           for name, v in out.items()}
    names = list(versions)
    if len(names) == 2:
        a, b = (tmp / f"{n}.las" for n in names)
        res["same_output"] = a.read_bytes() == b.read_bytes()
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--against", default=None, metavar="SRC",
                    help="PYTHONPATH of the other version (whole-process comparison)")
    ap.add_argument("--key", default="exit")
    ap.add_argument("--shared", action="store_true", help="record machine_shared: true")
    ap.add_argument("--tmp", default=None, help="work folder (the cloud is kept there)")
    ap.add_argument("--out", default=str(HERE / "results_curvature_speed.json"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    for name in ("--input", "--output", "--note", "--end"):
        ap.add_argument(name, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args)
    tmp = Path(args.tmp or tempfile.mkdtemp(prefix="lidarstat_exit_"))
    tmp.mkdir(parents=True, exist_ok=True)
    las = tmp / "cloud.las"
    if not las.exists():
        sys.path.insert(0, str(HERE))
        from bench_curvature import make_cloud

        from lidarstat.io import PointCloud, write

        write(las, PointCloud(xyz=make_cloud(args.points)[0]))
    src = str(Path(__file__).resolve().parents[1] / "src")
    base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    versions = {"this": dict(base, PYTHONPATH=src, NUMBA_CACHE_DIR=str(tmp / "nc_this"))}
    if args.against:
        versions["against"] = dict(base, PYTHONPATH=args.against,
                                   NUMBA_CACHE_DIR=str(tmp / "nc_against"))
    res = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               machine_shared=bool(args.shared), points=args.points, radius=RADIUS,
               rounds=args.rounds, against=args.against,
               how=("teardown: CPU s and wall s of a curvature process after its command "
                    "returned, through the interpreter's exit or os._exit; whole: the "
                    "console command start to exit, alternating with --against"))
    res["whole"] = whole(las, tmp, versions, args.rounds)
    res["teardown"] = teardown(las, tmp, versions["this"], args.rounds)
    out = Path(args.out)
    data = json.loads(out.read_text()) if out.exists() else {}
    data[args.key] = res
    out.write_text(json.dumps(data, indent=1))
    for k, v in res["teardown"].items():
        print(f"{k}: wall {v['wall_median']:.3f} s, cpu {v['cpu_median']:.3f} s after return")
    for k, v in res["whole"].items():
        if isinstance(v, dict):
            print(f"{k}: {v['seconds_median']:.2f} s, cpu {v['cpu_seconds_median']:.2f} s")
    print("same output:", res["whole"].get("same_output"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
