#!/usr/bin/env python
"""What `lidarstat moments`' time is made of, against the irreducible parts of its work.

On the synthetic airborne cloud of ``bench_moments.py`` (10 points per m^2, a LAS file),
CPU seconds (user + system of all threads) and wall seconds of the parts every
classification of the file pays, each timed alone in one process on a warm Numba cache
(a small call first compiles or loads each kernel), median of ``--repeats``:

* ``start``: a Python process that imports what the command imports (``lidarstat.cli``
  and the classification), against a bare interpreter, one importing numpy and laspy,
  and one importing CSF (what the peer's process pays); and the whole command on 20,000
  points (start-up plus every compiled kernel loaded from the cache on its first call,
  with almost no work); fresh processes timed by GNU ``time``;
* ``read_laspy`` / ``write_laspy``: laspy reading the file into float coordinates and
  writing it back with a classification (what CSF's run pays), against
  ``read_lidarstat`` (``lidarstat.io.read``) and ``write_lidarstat``
  (``lidarstat.io.rewrite`` with the command's fields, the records copied as read);
* ``sort_x``: one ``np.argsort`` of N float keys; ``canonical_order``: the command's
  order by x, y, z and intensity (equal to ``np.lexsort`` of the four keys);
* ``knn8_grid``: the 8 nearest planimetric neighbours of every point with the raised-patch
  graph's grid search (and its smoothness flags); ``knn8_ckdtree``: SciPy's ``cKDTree``
  built and queried for the same graph; ``raised_patches``: the whole step (graph,
  union-find, patch test);
* ``moment_updates``: one pass of the window moments' O(N) part alone: in every 64 m
  root window, one sort of the heights and the one-pass updates of the central sums
  (``stats._moments._sequential_stats``); ``moments`` runs five such passes (and the
  splits, cut searches and dip tests around them);
* ``csf_filter``: CSF's own filtering (cloth 1 m, slope smoothing) of the coordinates;
* the hardware's unit costs at N values: ``one_sort`` (``np.sort`` of N float64 in
  random order), ``one_pass`` (one compiled pass over N float64 values: the sum and the
  sum of squares), ``one_gather`` (``np.take`` of N float64 by a random permutation: one
  reordering of a column).

Writes ``results_moments_floor.json`` (``--label``: the run under ``runs``, the file's
other contents kept; ``--parts`` a subset)::

    python benchmarks/moments_floor.py --points 2000000 --out benchmarks/results_moments_floor.json
    python benchmarks/moments_floor.py --points 10000000 --label hardware_10m \
        --parts one_sort one_pass one_gather sort_x knn8_grid moment_updates \
        --out benchmarks/results_moments_floor.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(SRC))

from bench_moments import write_cloud  # noqa: E402


def timed(fn, repeats):
    """Median CPU and wall seconds of `fn()` over `repeats` calls."""
    cpu, wall = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return {"cpu_s": round(float(np.median(cpu)), 3), "wall_s": round(float(np.median(wall)), 3)}


def process_cpu(code, repeats):
    """Median CPU and wall seconds of ``python -c code`` in fresh processes (GNU time)."""
    env = dict(os.environ, PYTHONPATH=f"{SRC}{os.pathsep}{HERE}")
    cpu, wall = [], []
    for _ in range(repeats):
        res = subprocess.run(["/usr/bin/time", "-f", "TIME %e %U %S", sys.executable, "-c",
                              code], env=env, capture_output=True, text=True, check=True)
        _, sec, user, system = [s for s in res.stderr.splitlines()
                                if s.startswith("TIME ")][-1].split()
        cpu.append(float(user) + float(system))
        wall.append(float(sec))
    return {"cpu_s": round(float(np.median(cpu)), 3), "wall_s": round(float(np.median(wall)), 3)}


def knn8_grid(xy, z, k=8):
    """The raised-patch graph's neighbour search alone: every point's `k` nearest other
    points and their smoothness flags, block by block as ``raised_patches`` runs it."""
    from lidarstat._shared._columns import column_max, column_min
    from lidarstat.classify._continuity import _Grid2D, _knn_smooth

    n = z.size
    lo = column_min(xy)
    span = np.maximum(column_max(xy) - lo, 1e-12)
    cell = float(np.sqrt((k + 1) * span[0] * span[1] / n))
    grid = _Grid2D(xy, cell, lo)
    zs = z[grid.pos]
    for c0, c1 in grid.blocks(1_000_000):
        s0, s1 = grid.cell_start[c0], grid.cell_start[c1]
        nbr = np.empty((s1 - s0, k), np.int32)
        smooth = np.empty((s1 - s0, k), np.bool_)
        _knn_smooth(c0, c1, grid.points, zs, grid.cell_keys, grid.cell_start, grid.dims,
                    cell, k, cell, 0.3, 1.0, nbr, smooth)


def knn8_ckdtree(xy, k=8):
    from scipy.spatial import cKDTree

    cKDTree(xy).query(xy, k=k + 1, workers=1)


def moment_updates(xy, h, window=64.0):
    """One pass of the windows' sort and one-pass moment updates (no cut search, no
    split, no dip test)."""
    from lidarstat.classify._moments_windows import root_windows
    from lidarstat.stats._moments import _sequential_stats

    perm, roots = root_windows(xy - xy.min(axis=0), window)
    hp = h[perm]
    for t in roots:
        xs = np.sort(hp[t.points])
        n = xs.size
        if n < 8:
            continue
        c = float(np.median(xs))
        y = xs - c
        m = n - 3
        mean, std, sk, ku, thr = (np.empty(m) for _ in range(5))
        _sequential_stats(xs, y, c, 1.0, m, mean, std, sk, ku, thr)


def one_pass(x):
    """One compiled pass over `x`: its sum and sum of squares."""
    from numba import njit

    @njit(cache=False)
    def _pass(v):  # pragma: no cover - compiled
        s = 0.0
        q = 0.0
        for i in range(v.size):
            s += v[i]
            q += v[i] * v[i]
        return s, q

    _pass(x[:10])
    return lambda: _pass(x)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--work", default=None, help="folder of the clouds (default: a temp dir)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default=None, help="store the run under runs[LABEL]")
    ap.add_argument("--parts", nargs="+", default=None, help="only these parts")
    args = ap.parse_args(argv)
    import warnings

    warnings.simplefilter("ignore")
    import laspy

    from lidarstat.classify import BUILDING_FIELDS
    from lidarstat.classify._continuity import raised_patches
    from lidarstat.classify._moments_kernels import canonical_order
    from lidarstat.io import read, rewrite
    from isprs_filtertest import csf_ground

    folder = Path(args.work or tempfile.mkdtemp(prefix="moments_floor_"))
    folder.mkdir(parents=True, exist_ok=True)
    inp, _ = write_cloud(args.points, folder)
    small, _ = write_cloud(20_000, folder)
    n, r = args.points, args.repeats
    rows = {}

    def want(*names):
        return args.parts is None or any(p in args.parts for p in names)

    # start-up, fresh processes
    for name, code in (("start_python", "pass"), ("start_numpy_laspy", "import numpy, laspy"),
                       ("start_csf", "import numpy, laspy, CSF"),
                       ("start_lidarstat", "import lidarstat.cli, lidarstat.classify, "
                                           "lidarstat.io, lidarstat.report")):
        if want(name):
            rows[name] = process_cpu(code, r)
    # the whole command on 20,000 points: start-up, loading every compiled kernel from
    # the cache on its first call, and a negligible amount of work
    if want("moments_20k_points"):
        rows["moments_20k_points"] = process_cpu(
            "from lidarstat.cli import main; main(['moments', %r, %r, '--no-report', '-q'])"
            % (str(small), str(folder / "floor_small_out.las")), r)

    # read and write
    def laspy_read():
        las = laspy.read(inp)
        return las, np.c_[las.x, las.y, las.z]

    if want("read_laspy"):
        rows["read_laspy"] = timed(laspy_read, r)
    las, xyz = laspy_read()
    out = folder / "floor_out.las"

    def laspy_write():
        las.classification = np.full(n, 2, np.uint8)
        las.write(out)

    if want("write_laspy"):
        rows["write_laspy"] = timed(laspy_write, r)
    del las
    if want("read_lidarstat"):
        rows["read_lidarstat"] = timed(lambda: read(inp), r)
    if want("write_lidarstat"):
        fields = {"classification": np.full(n, 2, np.uint8),
                  "cluster_id": np.arange(n, dtype=np.int32)}
        for name, (dtype, _) in BUILDING_FIELDS.items():
            fields[name] = np.zeros(n, dtype)
        rows["write_lidarstat"] = timed(lambda: rewrite(inp, out, lambda s, c: {
            k: v[s:s + len(c)] for k, v in fields.items()}, decode=False), r)
        del fields

    # the hardware's unit costs: one sort, one pass, one gather of N values
    x, y, z = (np.ascontiguousarray(xyz[:, j]) for j in range(3))
    shuffled = np.random.default_rng(0).permutation(x)
    if want("one_sort"):
        rows["one_sort"] = timed(lambda: np.sort(shuffled), r)
    if want("one_pass"):
        rows["one_pass"] = timed(one_pass(x), r)
    if want("one_gather"):
        perm = np.random.default_rng(1).permutation(n)
        rows["one_gather"] = timed(lambda: np.take(x, perm), r)
        del perm
    del shuffled

    # one sort, the canonical order
    if want("sort_x"):
        rows["sort_x"] = timed(lambda: np.argsort(x), r)
    if want("canonical_order"):
        inten = read(inp, fields=["intensity"])["intensity"]
        canonical_order(x[:100], y[:100], z[:100], inten[:100])  # load the kernel
        rows["canonical_order"] = timed(lambda: canonical_order(x, y, z, inten), r)

    # the 8-NN graph
    xy = np.ascontiguousarray(xyz[:, :2] - xyz[:, :2].min(axis=0))
    knn8_grid(xy[:5000], z[:5000])
    raised_patches(xy[:5000], z[:5000])
    if want("knn8_grid"):
        rows["knn8_grid"] = timed(lambda: knn8_grid(xy, z), r)
    if want("knn8_ckdtree"):
        rows["knn8_ckdtree"] = timed(lambda: knn8_ckdtree(xy), r)
    if want("raised_patches"):
        rows["raised_patches"] = timed(lambda: raised_patches(xy, z), r)

    # the moments' one-pass updates (heights above a plane of the terrain trend)
    if want("moment_updates"):
        h = z - np.polyval(np.polyfit(x - x.min(), z, 1), x - x.min())
        moment_updates(xy[:5000], h[:5000])
        rows["moment_updates"] = timed(lambda: moment_updates(xy, h), r)

    # the peer's filtering itself
    if want("csf_filter"):
        rows["csf_filter"] = timed(lambda: csf_ground(xyz, 1.0), r)

    for name, v in rows.items():
        print(f"  {name:18s} {v['cpu_s']:8.2f} s CPU  {v['wall_s']:8.2f} s wall", flush=True)
    if args.out:
        run = {"points": n, "repeats": r, "machine_shared": True, "cpus": os.cpu_count(),
               "load_average": os.getloadavg(), "python": platform.python_version(),
               "numpy": np.__version__, "laspy": laspy.__version__, "parts": rows}
        what = ("CPU (user + system, all threads) and wall seconds of the irreducible "
                "parts of classifying the synthetic airborne LAS file of "
                "bench_moments.py, each alone in one process on a warm Numba cache "
                "(start: fresh processes by GNU time); median of the repeats")
        out_path = Path(args.out)
        if args.label:
            doc = json.loads(out_path.read_text()) if out_path.exists() else {"what": what}
            doc.setdefault("runs", {})[args.label] = run
        else:
            old = json.loads(out_path.read_text()) if out_path.exists() else {}
            doc = {"what": what, **run, **({"runs": old["runs"]} if "runs" in old else {})}
        out_path.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
