#!/usr/bin/env python
"""Where the ground passes of ``moments`` spend their time: the parts of the surface fits,
the TIN evaluations and the cut interpolations, timed on the inputs of one run.

One ``lidarstat moments`` run on the synthetic airborne cloud of ``bench_moments.py``
saves what the ground passes hand to :func:`~lidarstat.classify._surface.ground_surface`
(the ground rows of every pass) and to :func:`~lidarstat.classify._seams.interpolate_cuts`
(every pass's window cuts) into the work folder. Then, in fresh processes alternating
between the source trees named by ``--src`` (e.g. the code without a change and with it),
every part is timed on those inputs, CPU seconds of the process (all threads) and wall:

* ``pick``: the TIN vertices, the median ground point of every cell (``_cell_pick``);
* ``delaunay``: SciPy's (Qhull's) Delaunay triangulation of those vertices alone;
* ``tin_build``: the whole ``TinSurface`` (the triangulation, the triangles' bins and
  barycentric maps);
* ``fit``: the whole surface fit the run makes (``ground_surface``: the pick, the
  triangulation, the triangles' bins and barycentric maps);
* ``evaluation``: that surface at every point (the TIN kernel and, outside the hull, the
  nearest vertices' planes);
* ``cut``: the cut interpolation of every pass;
* ``delaunay_two_threads`` against ``delaunay_one_after_other``: two triangulations of
  the same vertices at once in two threads and in turn (whether Qhull releases the GIL).

Each child prints the sums over the passes; the parent writes the median of the repeats
per source tree (``--out``, runs kept under ``--label``).

Usage::

    python benchmarks/moments_ground_parts.py --points 10000000 --repeats 3 \\
        --src main=/tmp/main/src new=src --out benchmarks/results_moments_ground_parts.json \\
        --label NAME
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
PARTS = ("pick", "delaunay", "tin_build", "fit", "evaluation", "cut", "delaunay_one_after_other",
         "delaunay_two_threads")


def capture(inp, folder):
    """Run ``moments`` on `inp`, saving the ground passes' inputs into `folder` (the
    inputs are the same whatever the code timed, as long as its output is)."""
    import lidarstat.classify._moments_ground as mg
    from lidarstat.cli import main

    folder = Path(folder)
    count = {"fit": 0, "cut": 0}
    fit, cut = mg.ground_surface, mg.interpolate_cuts

    def ground_surface(xy, z, *, cell, rank=None, where=None, frame=None, **kw):
        if count["fit"] == 0:
            for name, a in (("xy", xy), ("z", z), ("rank", rank), ("cell", [cell])):
                np.save(folder / f"{name}.npy", np.asarray(a))
            np.save(folder / "framed.npy", np.array([frame is not None]))
        np.save(folder / f"where{count['fit']}.npy", where)
        count["fit"] += 1
        return fit(xy, z, cell=cell, rank=rank, where=where, frame=frame, **kw)

    def interpolate_cuts(xy, c, cell, frame=False):
        np.save(folder / f"cut{count['cut']}.npy", c)
        np.save(folder / "cut_cell.npy", np.array([cell]))
        count["cut"] += 1
        return cut(xy, c, cell, frame=frame)

    mg.ground_surface, mg.interpolate_cuts = ground_surface, interpolate_cuts
    rc = main(["moments", str(inp), str(folder / "out.las"), "--no-report", "-q"])
    (folder / "out.las").unlink(missing_ok=True)
    if rc or np.load(folder / "framed.npy")[0]:
        raise RuntimeError("capture failed, or the surfaces use a band frame (not timed here)")
    return count


def time_parts(folder):
    """CPU and wall seconds of every part, summed over the passes saved in `folder`."""
    from concurrent.futures import ThreadPoolExecutor

    from scipy.spatial import Delaunay

    from lidarstat.classify import _seams, _surface

    folder = Path(folder)
    def ld(name):
        return np.load(folder / f"{name}.npy")

    xy, z, rank = ld("xy"), ld("z"), ld("rank")
    cell, cut_cell = float(ld("cell")[0]), float(ld("cut_cell")[0])
    passes = sum(1 for _ in folder.glob("where*.npy"))
    cuts = sum(1 for _ in folder.glob("cut[0-9]*.npy"))
    # load (or compile) every kernel once, untimed
    small = np.arange(0, min(len(z), 4000), 2)
    _surface.ground_surface(xy, z, cell=cell, rank=rank, where=small)(xy[:100])
    _seams.interpolate_cuts(xy[:1000], np.zeros(1000), cut_cell, frame=None)
    cpu = dict.fromkeys(PARTS, 0.0)
    wall = dict.fromkeys(PARTS, 0.0)

    def timed(part, f, *a, **k):
        c0, t0 = time.process_time(), time.perf_counter()
        out = f(*a, **k)
        cpu[part] += time.process_time() - c0
        wall[part] += time.perf_counter() - t0
        return out

    def two_threads(P):
        with ThreadPoolExecutor(2) as pool:
            return list(pool.map(Delaunay, [P, P]))

    vertices = []
    for i in range(passes):
        sel = timed("pick", _surface._cell_pick, xy, z, cell, "median", rank, ld(f"where{i}"))
        P = np.ascontiguousarray(xy[sel])
        vertices.append(len(P))
        timed("delaunay", Delaunay, P)
        timed("tin_build", _surface.TinSurface, P, z[sel], cell)
        surf = timed("fit", _surface.ground_surface, xy, z, cell=cell, rank=rank,
                     where=ld(f"where{i}"))
        timed("evaluation", surf, xy)
        timed("delaunay_one_after_other", lambda P: [Delaunay(P), Delaunay(P)], P)
        timed("delaunay_two_threads", two_threads, P)
    for i in range(cuts):
        timed("cut", _seams.interpolate_cuts, xy, ld(f"cut{i}"), cut_cell, frame=None)
    return {"passes": passes, "cuts": cuts, "vertices": vertices,
            "cpu_seconds": {k: round(v, 3) for k, v in cpu.items()},
            "seconds": {k: round(v, 3) for k, v in wall.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--src", nargs="+", default=[f"current={HERE.parent / 'src'}"],
                    help="LABEL=PATH of each source tree timed (alternating)")
    ap.add_argument("--work", default=None, help="folder of the cloud and the inputs")
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default="current")
    ap.add_argument("--child", nargs=2, metavar=("MODE", "ARG"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        mode, arg = args.child
        if mode == "capture":
            print(json.dumps(capture(arg, Path(arg).parent / "inputs")))
        else:
            print(json.dumps(time_parts(arg)))
        return
    sys.path.insert(0, str(HERE))
    from bench_moments import write_cloud

    folder = Path(args.work or tempfile.mkdtemp(prefix="ground_parts_"))
    folder.mkdir(parents=True, exist_ok=True)
    inp, _ = write_cloud(args.points, folder)
    (folder / "inputs").mkdir(exist_ok=True)
    srcs = dict(s.split("=", 1) for s in args.src)
    env = dict(os.environ)

    def child(src, *cmd):
        env["PYTHONPATH"] = str(Path(src).resolve())
        res = subprocess.run([sys.executable, __file__, "--child", *map(str, cmd)], env=env,
                             capture_output=True, text=True, check=True)
        return json.loads(res.stdout.strip().splitlines()[-1])

    if not (folder / "inputs" / "framed.npy").exists():  # the inputs are reused when present
        child(next(iter(srcs.values())), "capture", inp)
    runs = {k: [] for k in srcs}
    for _ in range(args.repeats):
        for name, src in srcs.items():
            runs[name].append(child(src, "time", folder / "inputs"))
            print(name, json.dumps(runs[name][-1]["cpu_seconds"]), flush=True)
    rows = {}
    for name, rs in runs.items():
        rows[name] = {"points": args.points, "passes": rs[0]["passes"], "cuts": rs[0]["cuts"],
                      "vertices": rs[0]["vertices"],
                      **{f"{kind}_median": {p: round(float(np.median([r[kind][p] for r in rs])), 3)
                                            for p in PARTS}
                         for kind in ("cpu_seconds", "seconds")},
                      "cpu_seconds_all": [r["cpu_seconds"] for r in rs]}
        print(name, json.dumps(rows[name]["cpu_seconds_median"]))
    if args.out:
        out = Path(args.out)
        old = json.loads(out.read_text()) if out.exists() else {}
        old.setdefault("runs", {})[args.label] = {
            "repeats": args.repeats, "load_average": os.getloadavg(),
            "sources": list(srcs), "rows": rows}
        old.update(what="CPU seconds (all threads) and wall seconds of the parts of the "
                        "ground passes of one moments run, summed over the passes, on the "
                        "inputs that run handed them; median of alternating repeats",
                   machine_shared=True, cpus=os.cpu_count(), python=platform.python_version())
        out.write_text(json.dumps(old, indent=1) + "\n")


if __name__ == "__main__":
    main()
