#!/usr/bin/env python
"""The buildings and roads phase of ``moments``: time, CPU and memory of two source trees.

``capture`` runs :func:`lidarstat.classify.moments` once on the synthetic cloud of
``bench_moments.py`` (millimetre coordinates, as ``moments_identity.py`` makes it) and
saves the arguments of its building step and roads step (outside the repository: they
are as large as the cloud). ``run`` then replays that phase in fresh processes, the two
trees alternating: the roads in a thread beside the building step (as ``moments`` runs
them), the building step alone and the roads alone, each with its wall and CPU seconds
and the largest resident memory over the process's memory before it (sampled every
5 ms). Each process also hashes the building fields and the road mask, so the rows show
whether the trees agree.

Usage::

    python benchmarks/moments_buildings_phase.py capture /tmp/phase10m --points 10000000
    python benchmarks/moments_buildings_phase.py run /tmp/phase10m --before ../main/src \\
        --rounds 2 --out benchmarks/results_moments_buildings.json --key buildings_shared
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

CHILD = r"""
import hashlib, json, os, pickle, resource, sys, threading, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from concurrent.futures import ThreadPoolExecutor
from lidarstat._shared._memory import release_freed
from lidarstat.classify import _moments_objects as mo
from lidarstat.classify._roads import road_points

folder, mode = sys.argv[1], sys.argv[2]
a = np.load(os.path.join(folder, "inputs.npz"))
with open(os.path.join(folder, "options.pkl"), "rb") as fh:
    units, bkw, rkw, opts = pickle.load(fh)
xy, z, height, ground, multi, inten = (a[k] for k in ("xy", "z", "height", "ground",
                                                      "multi", "intensity"))
page = os.sysconf("SC_PAGE_SIZE")

def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page / 2**20

def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime

def buildings(s=slice(None)):
    return mo.building_step(xy[s], z[s], height[s], ground[s], multi[s], units, options=opts,
                            **bkw)

def roads(s=slice(None)):
    return road_points(xy[s], inten[s], ground[s], opts, **rkw)

warm = slice(0, 60_000)  # kernels loaded (or compiled) before the timed run
buildings(warm), roads(warm)
release_freed()
base = rss()
peak = [base]
stop = threading.Event()

def sample():
    while not stop.wait(0.005):
        peak[0] = max(peak[0], rss())

threading.Thread(target=sample, daemon=True).start()
w, c = time.perf_counter(), cpu()
blds = road = None
if mode == "beside":
    pool = ThreadPoolExecutor(1)
    fut = pool.submit(roads)
    pool.shutdown(wait=False)
    blds = buildings()
    w_b = time.perf_counter() - w
    road = fut.result()
elif mode == "buildings":
    blds = buildings()
    w_b = time.perf_counter() - w
else:
    road = roads()
    w_b = 0.0
wall, secs = time.perf_counter() - w, cpu() - c
stop.set()
h = hashlib.sha256()
if blds is not None:
    t, rows = blds
    h.update(rows.tobytes())
    h.update(t.building.tobytes())
    for name in sorted(t.fields):
        h.update(t.fields[name].tobytes())
if road is not None:
    h.update(road[0].tobytes())
print(json.dumps({"wall_s": round(wall, 3), "buildings_wall_s": round(w_b, 3),
                  "cpu_s": round(secs, 3), "peak_over_base_mib": round(peak[0] - base),
                  "base_mib": round(base), "sha256": h.hexdigest()[:16]}))
"""


def capture(folder: Path, n: int):
    """Save the building and roads steps' arguments of one ``moments`` run in `folder`."""
    sys.path.insert(0, str(HERE))
    from bench_moments import make_cloud

    from lidarstat.classify import _moments, moments

    folder.mkdir(parents=True, exist_ok=True)
    got = {}
    step, roads = _moments.building_step, _moments.road_points

    def building_step(xy, z, height, ground, multi, units, *, options, **kw):
        got.update(xy=xy, z=z, height=height, ground=ground, multi=multi)
        got["b"] = (units, kw, options)
        return step(xy, z, height, ground, multi, units, options=options, **kw)

    def road_points(xy, inten, ground, opts, **kw):
        got["intensity"] = inten
        got["r"] = kw
        return roads(xy, inten, ground, opts, **kw)

    _moments.building_step, _moments.road_points = building_step, road_points
    try:
        xyz, inten, nret, rnum, _ = make_cloud(n)
        xyz = np.round(xyz, 3)  # millimetre coordinates, as read from a LAS file
        inten = np.clip(np.round(inten), 0, 65535).astype(np.uint16)
        moments(xyz, inten, number_of_returns=nret, return_number=rnum)
    finally:
        _moments.building_step, _moments.road_points = step, roads
    units, bkw, opts = got.pop("b")
    with open(folder / "options.pkl", "wb") as fh:
        pickle.dump((units, bkw, got.pop("r"), opts), fh)
    np.savez(folder / "inputs.npz", **got)
    print(f"saved the phase's inputs of {n:,} points to {folder}")


def _one(src: Path, folder: Path, mode: str) -> dict:
    env = {"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(["nice", "-n", "10", sys.executable, "-c", CHILD, str(folder), mode],
                         capture_output=True, text=True, env=env, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def run(folder: Path, before: Path, rounds: int, out: Path | None, key: str, note=None):
    trees = {"before": before.resolve(), "after": (HERE.parent / "src").resolve()}
    rows = []
    for r in range(rounds):
        for mode in ("beside", "buildings", "roads"):
            for name, src in trees.items():
                row = {"round": r, "mode": mode, "tree": name, **_one(src, folder, mode)}
                print(json.dumps(row), flush=True)
                rows.append(row)
    summary = {}
    for mode in ("beside", "buildings", "roads"):
        for name in trees:
            sel = [x for x in rows if x["mode"] == mode and x["tree"] == name]
            summary[f"{mode}/{name}"] = {
                k: [min(x[k] for x in sel), max(x[k] for x in sel)]
                for k in ("wall_s", "buildings_wall_s", "cpu_s", "peak_over_base_mib")}
        hashes = {x["sha256"] for x in rows if x["mode"] == mode}
        summary[f"{mode}/same_output"] = len(hashes) == 1
    result = {"what": "the buildings and roads phase of moments replayed on the captured "
                      "inputs of one run (roads beside the building step, each alone): "
                      "wall and CPU seconds, resident memory over the process's before it; "
                      "ranges over the rounds",
              "inputs": str(folder), "rounds": rounds, "machine_shared": True,
              "trees": {k: str(v) for k, v in trees.items()}, "summary": summary,
              "rows": rows, **({"note": note} if note else {})}
    if out:
        data = json.loads(out.read_text()) if out.exists() else {}
        data[key] = result
        out.write_text(json.dumps(data, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture")
    c.add_argument("folder", type=Path)
    c.add_argument("--points", type=int, default=2_000_000)
    r = sub.add_parser("run")
    r.add_argument("folder", type=Path)
    r.add_argument("--before", type=Path, required=True, help="the other tree's src")
    r.add_argument("--rounds", type=int, default=2)
    r.add_argument("--out", type=Path, default=None)
    r.add_argument("--key", default="current")
    r.add_argument("--note", default=None)
    args = ap.parse_args(argv)
    if args.cmd == "capture":
        capture(args.folder, args.points)
    else:
        run(args.folder, args.before, args.rounds, args.out, args.key, args.note)


if __name__ == "__main__":
    main()
