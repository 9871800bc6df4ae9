#!/usr/bin/env python
"""What ``curvature``'s fields kernel costs a point, on one thread, against another version.

On the cloud of ``bench_curvature.py`` (2M points, the radius of about 50 neighbours) each
version runs in a process of its own (``NUMBA_NUM_THREADS=1``, its own Numba cache),
alternating, ``--rounds`` times; per process, CPU ns a point of
``_curvature_kernels.curvature_fields`` (through ``_curvature._block_fields``):

* ``hot``: one block of the middle of the cloud (about 131k fits, computed once), its
  fields computed again and again into the block's own rows (minimum of 5);
* ``blocks_fresh``: every block fitted and its fields written into the cloud's rows in
  sorted order, as the command does, the rows newly allocated (their pages are first
  written by the kernel);
* ``blocks_touched``: the same into rows already written once.

The fields of the hot block are compared byte by byte between the versions. Writes the
figures under ``--key`` of ``results_curvature_speed.json``::

    NUMBA_NUM_THREADS=1 python benchmarks/curvature_fields.py --against OLD/src --key NAME
"""

from __future__ import annotations

import argparse
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
    """One version's timings (JSON on stdout); the hot block's fields to ``args.dump``."""
    sys.path.insert(0, str(HERE))
    from bench_curvature import make_cloud

    from lidarstat.features import _curvature as C
    from lidarstat.features import _curvature_kernels as _ck
    from lidarstat.features._quadric import _allocate, _run_cells
    from lidarstat.neighbors import CellIndex

    xyz, _ = make_cloud(args.points)
    idx = CellIndex(xyz, RADIUS)
    blocks = idx.cell_blocks(131072)
    params = C._params(0.02, RADIUS, 0.05, False, idx.origin[2])
    buf = _allocate(max(int(idx.cell_start[b] - idx.cell_start[a]) for a, b in blocks))

    def fits(c0, c1):
        return _run_cells(idx, c0, c1, bandwidth=RADIUS, frame="pca", sensor=None,
                          min_neighbors=7, covariance="sandwich", buffers=buf)

    def fields(out, s0, s1, dest, rows):
        C._block_fields(out, _ck.NOISE_Z, C._NO_VALUES, C._NO_VALUES,
                        idx.sorted_points[s0:s1], None, params, "calibrated", dest, *rows)

    c0, c1 = blocks[len(blocks) // 2]
    s0, s1 = int(idx.cell_start[c0]), int(idx.cell_start[c1])
    out = {k: v.copy() for k, v in fits(c0, c1).items()}
    rows = C._field_arrays(s1 - s0, False)
    dest = np.arange(s1 - s0, dtype=np.int64)
    fields(out, s0, s1, dest, rows)
    hot = []
    for _ in range(5):
        t = time.process_time()
        fields(out, s0, s1, dest, rows)
        hot.append((time.process_time() - t) / (s1 - s0) * 1e9)
    np.savez(args.dump, floats=rows[0], flags=rows[1], neighbors=rows[2])

    def all_blocks(rows):
        spent = 0.0
        positions = np.arange(idx.n_points, dtype=np.int64)
        for a, b in blocks:
            s, e = int(idx.cell_start[a]), int(idx.cell_start[b])
            block = fits(a, b)
            t = time.process_time()
            fields(block, s, e, positions[s:e], rows)
            spent += time.process_time() - t
        return spent / idx.n_points * 1e9

    rows = C._field_arrays(idx.n_points, False)
    fresh = all_blocks(rows)
    touched = all_blocks(rows)
    print(json.dumps({"hot": min(hot), "blocks_fresh": fresh, "blocks_touched": touched,
                      "block_points": s1 - s0}))


def run_child(src, cache, dump, points):
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache),
               NUMBA_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1")
    out = subprocess.run([sys.executable, __file__, "--child", "--dump", str(dump),
                          "--points", str(points)], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--against", default=None, metavar="SRC",
                    help="the other version's source folder (its src)")
    ap.add_argument("--key", default="fields_kernel")
    ap.add_argument("--shared", action="store_true", help="record machine_shared: true")
    ap.add_argument("--out", default=str(HERE / "results_curvature_speed.json"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--dump", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args)
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="lidarstat_fields_"))
    versions = {"this": HERE.parent / "src"}
    if args.against:
        versions["against"] = Path(args.against)
    runs = {name: [] for name in versions}
    for r in range(args.rounds + 1):  # the first round fills the Numba caches
        for name, src in versions.items():
            got = run_child(src, tmp / f"cache_{name}", tmp / f"{name}.npz", args.points)
            if r:
                runs[name].append(got)
    res = {"how": ("NUMBA_NUM_THREADS=1 python benchmarks/curvature_fields.py --against "
                   "SRC: CPU ns a point of curvature_fields on one thread, each version in "
                   "processes of its own, alternating; medians over the rounds"),
           "points": args.points, "radius": RADIUS, "rounds": args.rounds,
           "machine_shared": bool(args.shared)}
    for name, got in runs.items():
        res[name] = {k: round(float(np.median([g[k] for g in got])), 1)
                     for k in ("hot", "blocks_fresh", "blocks_touched")}
        res[name]["all_hot"] = [round(g["hot"], 1) for g in got]
    if args.against:
        a, b = np.load(tmp / "this.npz"), np.load(tmp / "against.npz")
        res["against"]["version"] = str(args.against)
        res["same_fields"] = all(a[k].tobytes() == b[k].tobytes() for k in a.files)
    path = Path(args.out)
    whole = json.loads(path.read_text()) if path.exists() else {}
    whole[args.key] = res
    path.write_text(json.dumps(whole, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
