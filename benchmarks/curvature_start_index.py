#!/usr/bin/env python
"""Pieces of ``lidarstat curvature`` around its fused kernel, each against another form of
it, alternating, on a machine that may be shared (medians; CPU seconds where a whole
process is timed).

* ``start``: a whole ``lidarstat curvature`` process on a small cloud (20,000 points, so
  that the start dominates), this version against the package at ``--before SRC``;
* ``help``: ``lidarstat curvature --help``, the same two versions;
* ``index_scatter``: the counting sort's scatter of the 2-million-point cloud of
  ``bench_curvature.py`` (``CellIndex``) on one range of cells (serial) and on one per
  thread, in one process.

Usage::

    mkdir -p /tmp/old && git archive main src | tar -x -C /tmp/old
    PYTHONPATH=src python benchmarks/curvature_start_index.py --before /tmp/old/src \\
        --out benchmarks/results_curvature_speed.json --key pieces_start_index
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _process(cmd, env):
    """Wall and CPU seconds (user + system) of one process."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status):
        raise RuntimeError(f"{cmd} failed: {p.stderr.read().decode()[-400:]}")
    return wall, ru.ru_utime + ru.ru_stime


def _summary(runs):
    wall, cpu = np.array(runs).T
    return dict(wall_median=float(np.median(wall)), cpu_median=float(np.median(cpu)),
                wall=[round(float(v), 4) for v in wall], cpu=[round(float(v), 4) for v in cpu])


def whole(args, tmp):
    """``start`` and ``help``: this version and ``--before``, alternating."""
    from bench_curvature import calibrate_radius, make_cloud

    from lidarstat.io import PointCloud, write

    xyz, _ = make_cloud(20000, seed=3)
    small = tmp / "small.las"
    write(small, PointCloud(xyz=xyz))
    radius = calibrate_radius(xyz, 50)[0]
    envs = {}
    for name, src in (("this", os.environ.get("PYTHONPATH", "")), ("before", args.before)):
        envs[name] = dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=str(tmp / f"nc_{name}"))
        envs[name].pop("PYTHONDONTWRITEBYTECODE", None)
    run = [sys.executable, "-m", "lidarstat", "curvature", str(small), str(tmp / "o.las"),
           "--radius", repr(radius), "-q"]
    helpcmd = [sys.executable, "-m", "lidarstat", "curvature", "--help"]
    for env in envs.values():  # compile into each version's cache
        _process(run, env)
    res = {"start": {k: [] for k in envs}, "help": {k: [] for k in envs}}
    for _ in range(args.repeats):
        for name, env in envs.items():
            res["start"][name].append(_process(run, env))
            res["help"][name].append(_process(helpcmd, env))
    return {piece: {k: _summary(v) for k, v in by.items()} for piece, by in res.items()}


def in_process(args):
    """``index_scatter``: both forms in this process, alternating."""
    import numba
    from bench_curvature import make_cloud

    from lidarstat.neighbors import _kernels

    xyz, _ = make_cloud(args.points)
    radius = 0.901118757864343  # about 50 neighbours on this cloud (bench_curvature)
    origin = xyz.min(axis=0)
    dims = np.floor((xyz.max(axis=0) - origin) / radius).astype(np.int64) + 1
    keys = np.empty(len(xyz), dtype=np.int64)
    _kernels.grid_keys(xyz, origin, radius, dims, False, keys)
    counts = np.bincount(keys, minlength=int(np.prod(dims)))
    order, sorted_points = np.empty(len(xyz), dtype=np.int64), np.empty((len(xyz), 3))
    threads = numba.get_num_threads()

    def scatter(parts):
        start = np.cumsum(counts) - counts
        t0 = time.perf_counter()
        _kernels.counting_scatter(xyz, origin, keys, start, parts, order, sorted_points)
        return time.perf_counter() - t0

    scatter(threads)
    runs = {"serial": [], "threads": []}
    for _ in range(args.repeats):
        runs["serial"].append(scatter(1))
        runs["threads"].append(scatter(threads))
    out = {k: dict(wall_median=float(np.median(v)), wall=[round(float(x), 4) for x in v])
           for k, v in runs.items()}
    out["threads_used"] = threads
    return {"index_scatter": out}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", required=True, metavar="SRC",
                    help="PYTHONPATH of the version to compare with (e.g. main's src)")
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--shared", action="store_true",
                    help="record that other work ran on the machine meanwhile")
    ap.add_argument("--out", default=str(HERE / "results_curvature_speed.json"))
    ap.add_argument("--key", default="pieces_start_index")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(HERE))
    tmp = Path(tempfile.mkdtemp(prefix="lidarstat_pieces_"))
    res = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               machine_shared=bool(args.shared), cores=os.cpu_count(), repeats=args.repeats,
               before=args.before, how=__doc__.split("\n\n")[1].strip())
    res.update(whole(args, tmp))
    res.update(in_process(args))
    shutil.rmtree(tmp, ignore_errors=True)
    path = Path(args.out)
    stored = json.loads(path.read_text()) if path.exists() else {}
    stored[args.key] = res
    path.write_text(json.dumps(stored, indent=1) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k not in ("how",)}, indent=1)[:3000])
    print(f"wrote {path} (key {args.key})")


if __name__ == "__main__":
    main()
