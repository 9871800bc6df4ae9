#!/usr/bin/env python
"""Where the terrain step of ``moments`` spends its time: each part, wall and CPU seconds.

``capture`` runs :func:`lidarstat.classify.moments` on the synthetic cloud of
``bench_moments.py`` (millimetre coordinates, intensity and returns) and saves the
arguments its terrain step receives (``xy``, ``z``, the moments' ground, units) to an
``.npz`` outside the repository. ``time`` loads them and runs
:func:`lidarstat.classify._terrain.terrain_step` ``--repeats`` times (after one untimed
run that loads the kernels), each part timed exclusively (a part called inside another
is taken out of it) in wall seconds and CPU seconds of the process (all threads):

* ``frame``: the grid without its empty bands (:class:`BandFrame`) and ``xy`` moved in;
* ``cell lowest``, ``bumps``, ``opening``, ``growth``, ``walls``, ``plateaus``,
  ``platforms``, ``fill``: the grid steps;
* ``TIN: first points``, ``TIN: near cells``, ``TIN: build`` (Qhull's Delaunay, the
  triangles binned);
* ``test: TIN evaluation``, ``test: slope``, ``test: heights`` (the compiled test),
  ``test: other`` (the rest of the point test);
* ``fence: cells``, ``fence: blocks``, ``fence: gather``, ``fence: test``, ``fence: other``;
* ``other``: the rest of the step.

The total is the step's wall and CPU; ``--identity`` also checks the outputs of the
repeats against an ``.npz`` of another version's (``--save`` writes one). ``tin``
measures the step's Delaunay alone (:func:`tin_findings`): Qhull's CPU seconds, whether
it lets Python run beside it, and how many triangles a build in two overlapping halves
changes (Qhull chooses the diagonal of four co-circular vertices by its own insertion
order, so halves do not give the same TIN).

Usage::

    PYTHONPATH=src python benchmarks/terrain_parts.py capture --points 2000000 /tmp/t2m.npz
    PYTHONPATH=src python benchmarks/terrain_parts.py time /tmp/t2m.npz --repeats 3 \\
        --out benchmarks/results_terrain_parts.json --label LABEL
    PYTHONPATH=src python benchmarks/terrain_parts.py tin /tmp/t2m.npz \\
        --out benchmarks/results_terrain_parts.json --label tin_2M
"""

from __future__ import annotations

import argparse
import functools
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def capture(n, out):
    """The terrain step's arguments in ``moments`` on the cloud of `n` points, to `out`."""
    sys.path.insert(0, str(HERE))
    from bench_moments import make_cloud

    import lidarstat.classify._moments as mom
    from lidarstat.classify import moments

    class Captured(Exception):
        pass

    def save(xy, z, ground, *, ux=1.0, uz=1.0):
        np.savez(out, xy=xy, z=z, ground=ground, ux=ux, uz=uz)
        raise Captured

    xyz, inten, nret, rnum, _ = make_cloud(n)
    xyz = np.round(xyz, 3)
    inten = np.clip(np.round(inten), 0, 65535).astype(np.uint16)
    mom.terrain_step = save
    try:
        moments(xyz, inten, number_of_returns=nret, return_number=rnum, overwrite_xyz=True)
    except Captured:
        return
    raise RuntimeError("the terrain step was not reached")


#: (part, module, attribute): the functions timed, as the step looks them up.
PARTS = (
    ("frame", "lidarstat.classify._terrain", "BandFrame.of"),
    ("frame", "lidarstat.classify._terrain", "BandFrame.__call__"),
    ("cell lowest", "lidarstat.classify._terrain", "cell_lowest"),
    ("bumps", "lidarstat.classify._terrain", "drop_bumps"),
    ("opening", "lidarstat.classify._terrain", "drop_opened"),
    ("growth", "lidarstat.classify._terrain", "grow_ground"),
    ("walls", "lidarstat.classify._terrain", "reject_walled"),
    ("plateaus", "lidarstat.classify._terrain", "reject_plateaus"),
    ("platforms", "lidarstat.classify._terrain", "grow_platforms"),
    ("fill", "lidarstat.classify._terrain", "_fill"),
    ("TIN: other", "lidarstat.classify._terrain", "_tin"),
    ("TIN: first points", "lidarstat.classify._terrain", "first_on_surface"),
    ("TIN: near cells", "lidarstat.classify._terrain", "near_points"),
    ("TIN: build", "lidarstat.classify._surface", "TinSurface.__init__"),
    ("test: other", "lidarstat.classify._terrain", "_test_points"),
    ("test: TIN evaluation", "lidarstat.classify._surface", "TinSurface.__call__"),
    ("test: slope", "lidarstat.classify._terrain", "grid_bilinear"),
    ("test: heights", "lidarstat.classify._terrain", "height_test"),
    ("fence: other", "lidarstat.classify._terrain", "noise_fence"),
    ("fence: other", "lidarstat.classify._terrain", "_fence_cells"),
    ("fence: cells", "lidarstat.classify._terrain", "cell_values"),
    ("fence: blocks", "lidarstat.classify._terrain", "block_spread"),
    ("fence: gather", "lidarstat.classify._terrain", "gather_cells"),
    ("fence: test", "lidarstat.classify._terrain", "fence_test"),
)


class _Parts:
    """Exclusive wall and process CPU seconds of wrapped functions (main thread only)."""

    def __init__(self):
        self.wall, self.cpu, self.stack, self.saved = {}, {}, [], []

    def wrap(self, name, owner, attr):
        orig = owner.__dict__[attr] if isinstance(owner, type) else getattr(owner, attr)
        self.saved.append((owner, attr, orig))
        func = orig.__func__ if isinstance(orig, classmethod) else orig
        timed = self._timed(name, func)
        setattr(owner, attr, classmethod(timed) if isinstance(orig, classmethod) else timed)

    def restore(self):
        for owner, attr, orig in reversed(self.saved):
            setattr(owner, attr, orig)

    def _timed(self, name, func):
        @functools.wraps(func)
        def timed(*a, **k):
            self.stack.append([time.perf_counter(), time.process_time(), 0.0, 0.0])
            try:
                return func(*a, **k)
            finally:
                t0, c0, inner, cinner = self.stack.pop()
                dt, dc = time.perf_counter() - t0, time.process_time() - c0
                self.wall[name] = self.wall.get(name, 0.0) + dt - inner
                self.cpu[name] = self.cpu.get(name, 0.0) + dc - cinner
                if self.stack:
                    self.stack[-1][2] += dt
                    self.stack[-1][3] += dc

        return timed


def time_parts(path, repeats, save=None, identity=None):
    """Per-part wall and CPU seconds of the terrain step on the captured `path` (the
    medians of `repeats` runs) and the outputs' equality with `identity`."""
    import importlib

    from lidarstat.classify import _terrain

    d = np.load(path)
    args = (d["xy"], d["z"], d["ground"])
    units = {"ux": float(d["ux"]), "uz": float(d["uz"])}
    out = _terrain.terrain_step(*args, **units)  # loads (or compiles) the kernels
    runs = []
    for _ in range(repeats):
        parts = _Parts()
        for name, mod, attr in PARTS:
            owner = importlib.import_module(mod)
            if not hasattr(owner, attr.split(".")[0]):
                continue  # a part the version timed does not have
            *path_, attr_ = attr.split(".")
            for p in path_:
                owner = getattr(owner, p)
            parts.wrap(name, owner, attr_)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            out = _terrain.terrain_step(*args, **units)
        finally:
            parts.restore()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        parts.wall["other"] = wall - sum(parts.wall.values())
        parts.cpu["other"] = cpu - sum(parts.cpu.values())
        runs.append({"wall": wall, "cpu": cpu, "parts_wall": parts.wall,
                     "parts_cpu": parts.cpu})
    ground, height, surface, tolerance = out
    arrays = {"ground": ground, "height": height, "tolerance": tolerance,
              "grid": surface.grid, "slope": surface.slope}
    if save:
        np.savez(save, **arrays)
    same = None
    if identity:
        ref = np.load(identity)
        same = {k: int(np.sum(~((v == ref[k]) | (np.isnan(v) & np.isnan(ref[k])))))
                if v.shape == ref[k].shape else "shape" for k, v in arrays.items()}
    names = list(dict.fromkeys([p[0] for p in PARTS] + ["other"]))

    def med(key, name=None):
        vals = [r[key] if name is None else r[key].get(name, 0.0) for r in runs]
        return round(float(np.median(vals)), 3)

    return {"points": len(args[1]), "repeats": repeats,
            "wall_s": med("wall"), "cpu_s": med("cpu"),
            "runs_wall_s": [round(r["wall"], 3) for r in runs],
            "runs_cpu_s": [round(r["cpu"], 3) for r in runs],
            "parts_wall_s": {n: med("parts_wall", n) for n in names},
            "parts_cpu_s": {n: med("parts_cpu", n) for n in names},
            "differing_values": same}


def tin_findings(path, margin=10.0):
    """What the terrain TIN's Delaunay costs and whether it can be split: its vertices
    (captured from :func:`terrain_step` on `path`), Qhull's CPU seconds on them, whether
    Qhull lets Python run beside it (a Python loop's count of turns during the build
    against the same time asleep), and the triangles two overlapping halves (split at
    the median x, `margin` cells of overlap, each triangle taken from the half holding
    its centroid) give that the whole build does not."""
    import threading

    from scipy.spatial import Delaunay

    from lidarstat.classify import _surface, _terrain

    d = np.load(path)
    got = {}
    orig = _surface.TinSurface.__init__

    def keep(self, P, V, cell, **kw):
        got["P"] = np.array(P)
        return orig(self, P, V, cell, **kw)

    _surface.TinSurface.__init__ = keep
    try:
        _terrain.terrain_step(d["xy"], d["z"], d["ground"], ux=float(d["ux"]),
                              uz=float(d["uz"]))
    finally:
        _surface.TinSurface.__init__ = orig
    P = got["P"]
    cpu = []
    for _ in range(2):
        c0 = time.process_time()
        whole = Delaunay(P).simplices
        cpu.append(time.process_time() - c0)

    def turns(during):
        count, stop = [0], threading.Event()

        def spin():
            while not stop.is_set():
                count[0] += 1

        th = threading.Thread(target=spin)
        t0 = time.perf_counter()
        th.start()
        during()
        stop.set()
        th.join()
        return count[0] / (time.perf_counter() - t0)

    beside = turns(lambda: Delaunay(P))
    idle = turns(lambda: time.sleep(0.5))
    cx = float(np.median(P[:, 0]))
    parts = []
    for low in (True, False):
        rows = np.flatnonzero(P[:, 0] < cx + margin if low else P[:, 0] >= cx - margin)
        tri = rows[Delaunay(P[rows]).simplices]
        c = P[tri].mean(axis=1)[:, 0]
        parts.append(tri[c < cx] if low else tri[c >= cx])

    def canon(t):
        return set(map(tuple, np.sort(t, axis=1).tolist()))

    a, b = canon(whole), canon(np.concatenate(parts))
    return {"vertices": len(P), "triangles": len(a),
            "qhull_cpu_s": [round(c, 3) for c in cpu],
            "python_turns_per_s_during_qhull": round(beside),
            "python_turns_per_s_asleep": round(idle),
            "halves_triangles": len(b), "triangles_only_in_whole": len(a - b),
            "triangles_only_in_halves": len(b - a)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture")
    c.add_argument("out")
    c.add_argument("--points", type=int, default=2_000_000)
    t = sub.add_parser("time")
    t.add_argument("inputs")
    t.add_argument("--repeats", type=int, default=3)
    t.add_argument("--save", default=None, help="write the outputs to this .npz")
    t.add_argument("--identity", default=None, help="count differences from this .npz")
    t.add_argument("--out", default=None, help="results JSON to add the run to")
    t.add_argument("--label", default=None)
    q = sub.add_parser("tin")
    q.add_argument("inputs")
    q.add_argument("--out", default=None, help="results JSON to add the findings to")
    q.add_argument("--label", default=None)
    args = ap.parse_args(argv)
    if args.cmd == "capture":
        capture(args.points, args.out)
        return
    if args.cmd == "tin":
        row = tin_findings(args.inputs)
    else:
        row = time_parts(args.inputs, args.repeats, save=args.save, identity=args.identity)
    print(json.dumps(row, indent=1))
    if args.out:
        p = Path(args.out)
        res = json.loads(p.read_text()) if p.exists() else {
            "what": "the terrain step of moments on the arguments it gets on the synthetic "
                    "cloud of bench_moments.py: wall and CPU seconds (all threads) of the "
                    "step and of each part, medians of the repeats, and the outputs' "
                    "differences from the code without the change (runs base_*: that "
                    "code, run alternately with new_*); tin_*: the step's Delaunay alone",
            "script": "benchmarks/terrain_parts.py", "machine_shared": True,
            "machine": f"{platform.machine()}, {__import__('os').cpu_count()} cores",
            "runs": {}}
        res["runs"][args.label or "run"] = row
        p.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
