"""`lidarstat moments` against CSF on a synthetic airborne cloud, whole process, and where the time goes.

Cloud: sloped sine terrain, box buildings, tree blobs with two returns, intensity with a
dark road band, 10 points/m2, written once to a LAS file (point format 6) in a work
folder. Each repeat runs, alternating, in fresh processes timed by GNU ``time`` (wall
seconds and peak RSS of the process):

* ``lidarstat moments IN OUT --no-report -q`` (start, read the LAS, classify, write the LAS);
* CSF (the authors' ``cloth_simulation_filter``, cloth 1 m, slope smoothing) in a Python
  process that reads the LAS with laspy, filters and writes the classification with laspy.

The row of each size is the median of the repeats. The profile (``--profile``) runs the
same command once more in a process that times every named step of ``moments`` (start
and imports, read, low noise, windows, each part of the ground, terrain, roads,
buildings, classes, fields, write) and samples its resident memory every 10 ms, giving
each step's wall time and the peak RSS reached during it (the steps run in a thread
beside the others are also timed in their thread, and the main thread's wait for them
is a row of its own); ``--profile --profile`` adds a
second profile in which the freed memory is not handed back to the system between the
steps (``release_freed``), to show what that saves.

Usage::

    python benchmarks/bench_moments.py --quick                      # 200k points, one repeat
    python benchmarks/bench_moments.py --points 10000000 --repeats 3 --profile \\
        --out benchmarks/results_moments.json
    python benchmarks/bench_moments.py --points 2000000 --repeats 1 --profile --skip-peers
    python benchmarks/bench_moments.py --points 10000000 --repeats 3 --io-floor \\
        --variant 'core=--no-terrain --no-continuity' --out benchmarks/results_moments.json

``--io-floor`` adds a process that only reads the file and writes it back with laspy (what
CSF's process does besides filtering); each ``--variant`` times ``moments`` with other
options, all alternating with the two commands above.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"


def make_cloud(n, seed=20261122, origin=(0.0, 0.0)):
    """`n` points over a square at 10 points/m2 with its lower corner at `origin` (the
    terrain, buildings, trees and roads are functions of the position, so squares with
    other origins are tiles of one town)."""
    g = np.random.default_rng(seed)
    side = np.sqrt(n / 10.0)  # 10 pts/m2
    xy = g.uniform(0, side, (n, 2)) + np.asarray(origin, float)
    z = 5 * np.sin(xy[:, 0] / 150) + 3 * np.cos(xy[:, 1] / 110) + 0.02 * xy[:, 0]
    z += g.normal(0, 0.03, n)
    ground = np.ones(n, bool)
    inten = g.normal(150, 12, n)
    road = np.abs((xy[:, 1] % 200) - 100) < 5
    inten[road] = g.normal(60, 8, road.sum())
    cx = (xy[:, 0] // 60) * 60 + 30
    cy = (xy[:, 1] // 60) * 60 + 30
    bld = (np.abs(xy[:, 0] - cx) < 12) & (np.abs(xy[:, 1] - cy) < 9) & ~road
    z[bld] += 8 + (cx[bld] % 7)
    ground[bld] = False
    tree = (np.hypot(xy[:, 0] - cx - 22, xy[:, 1] - cy + 20) < 4) & ~bld & ~road
    first = tree & (g.uniform(size=n) < 0.6)
    z[first] += g.uniform(3, 10, first.sum())
    ground[first] = False
    nret = np.where(tree, 2, 1)
    rnum = np.where(first, 1, nret)
    return np.c_[xy + 5e5, z + 100], inten, nret, rnum, ground


def write_cloud(n, folder: Path):
    """The cloud of `n` points as ``cloud_<n>.las`` and its truth (ground mask) as
    ``truth_<n>.npy`` in `folder` (reused when present)."""
    import laspy

    las_path, truth_path = folder / f"cloud_{n}.las", folder / f"truth_{n}.npy"
    if las_path.exists() and truth_path.exists():
        return las_path, truth_path
    xyz, inten, nret, rnum, truth = make_cloud(n)
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales = np.full(3, 0.001)
    header.offsets = np.floor(xyz.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = np.clip(np.round(inten), 0, 65535).astype(np.uint16)
    las.number_of_returns = nret.astype(np.uint8)
    las.return_number = rnum.astype(np.uint8)
    las.write(las_path)
    np.save(truth_path, truth)
    return las_path, truth_path


# ------------------------------------------------------------------------- children
def child_csf(inp, out):
    """CSF as a user runs it: read with laspy, filter (cloth 1 m), write with laspy."""
    import laspy

    sys.path.insert(0, str(HERE))
    from isprs_filtertest import csf_ground

    las = laspy.read(inp)
    xyz = np.c_[las.x, las.y, las.z]
    g = csf_ground(xyz, 1.0)
    del xyz
    las.classification = np.where(g, 2, 1).astype(np.uint8)
    las.write(out)


def child_io(inp, out):
    """What every filter of this file does besides filtering: start Python, read the LAS
    with laspy, write it back with a classification (all ground: the truth's error)."""
    import laspy

    las = laspy.read(inp)
    xyz = np.c_[las.x, las.y, las.z]  # the coordinates a filter reads
    del xyz
    las.classification = np.full(len(las.points), 2, np.uint8)
    las.write(out)


class _Steps:
    """Exclusive wall time and peak resident memory of named steps.

    Module functions are wrapped; a step called inside another is timed on its own and
    taken out of the outer one. A thread samples the resident set every 10 ms and
    charges it to the innermost running step. The rows add up to the main thread's
    time: a step run in a thread beside the others (the raised patches' graph, the roads)
    is charged, wall and CPU, to the main thread's steps it runs beside, and the main
    thread's wait for its result is a row of its own (:meth:`wrap_beside`). Such a step
    is also timed in its own thread (wall and that thread's CPU), in `beside`, outside
    the sum.
    """

    def __init__(self):
        self.seconds, self.cpu, self.peak_mib, self.stack, self.saved = {}, {}, {}, [], []
        self.beside = {}
        self._stop = threading.Event()
        self._page = os.sysconf("SC_PAGE_SIZE")

    def rss_mib(self):
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * self._page / 2**20

    def _sample(self):
        while not self._stop.wait(0.01):
            name = self.stack[-1][0] if self.stack else "other"
            self.peak_mib[name] = max(self.peak_mib.get(name, 0.0), self.rss_mib())

    def start(self):
        threading.Thread(target=self._sample, daemon=True).start()

    def stop(self):
        self._stop.set()
        for owner, attr, orig in reversed(self.saved):
            setattr(owner, attr, orig)

    def wrap(self, name, owner, attr):
        orig = getattr(owner, attr)
        self.saved.append((owner, attr, orig))
        setattr(owner, attr, self._timed(name, orig))

    def _timed(self, name, orig):
        @functools.wraps(orig)
        def timed(*a, **k):
            if threading.current_thread() is not threading.main_thread():
                return orig(*a, **k)  # a step run beside the others: its CPU is the process's
            self.stack.append([name, time.perf_counter(), 0.0, time.process_time(), 0.0])
            try:
                return orig(*a, **k)
            finally:
                _, t0, inner, c0, cinner = self.stack.pop()
                dt = time.perf_counter() - t0
                dc = time.process_time() - c0
                self.seconds[name] = self.seconds.get(name, 0.0) + dt - inner
                self.cpu[name] = self.cpu.get(name, 0.0) + dc - cinner
                self.peak_mib[name] = max(self.peak_mib.get(name, 0.0), self.rss_mib())
                if self.stack:
                    self.stack[-1][2] += dt
                    self.stack[-1][4] += dc

        return timed

    def wrap_beside(self, name, owner, attr="_beside"):
        """Time ``owner._beside(run, func, ...)`` (a step started in a thread of its own,
        a Future): the step in its thread (``beside[func name]``, wall and thread CPU)
        and the main thread's wait in ``future.result()`` as the step `name`."""
        orig = getattr(owner, attr)
        self.saved.append((owner, attr, orig))
        steps = self

        def in_thread(func):
            def run(*a, **k):
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    return func(*a, **k)
                finally:
                    steps.beside[func.__name__] = {
                        "seconds": round(time.perf_counter() - t0, 3),
                        "thread_cpu_seconds": round(time.thread_time() - c0, 3)}
            return run

        class Waited:
            def __init__(self, future):
                self._future = future

            def cancel(self):
                return self._future.cancel()

        def beside(run, func, *a, **k):
            future = orig(run, in_thread(func), *a, **k)
            if future is None:
                return None
            waited = Waited(future)
            waited.result = self._timed(name, future.result)
            return waited

        setattr(owner, attr, beside)


#: The named steps of ``lidarstat moments``: (label, module, attribute). A module
#: function is wrapped where its caller looks it up.
STEPS = (
    ("read", "lidarstat.io", "read"),
    ("driver (checks, copies, reorderings)", "lidarstat.classify", "moments"),
    ("driver: checks", "lidarstat.classify._moments", "check_points"),
    ("driver: checks", "lidarstat.classify._moments", "_usable_intensity"),
    ("canonical order", "lidarstat.classify._moments", "canonical_order"),
    ("driver: copies, reorderings", "lidarstat.classify._moments", "_permute_columns"),
    ("driver: copies, reorderings", "lidarstat.classify._moments", "_without_low_noise"),
    ("driver: copies, reorderings", "lidarstat.classify._moments", "_window_frame"),
    ("driver: freed memory handed back", "lidarstat.classify._moments", "release_freed"),
    ("ground: frames, pass inputs, masks", "lidarstat.classify._moments", "ground_cut"),
    ("TIN evaluation", "lidarstat.classify._surface", "_tin_eval"),
    ("TIN evaluation", "lidarstat.classify._surface", "_extrapolate"),  # outside the hull
    ("low noise", "lidarstat.classify._moments", "low_outliers"),
    ("windows", "lidarstat.classify._moments", "root_windows"),
    ("ground: opening", "lidarstat.classify._moments_ground", "opening_surface"),
    ("ground: window moments", "lidarstat.classify._moments_ground", "window_pass"),
    ("ground: cut interpolation", "lidarstat.classify._moments_ground", "interpolate_cuts"),
    ("ground: surface fit", "lidarstat.classify._moments_ground", "ground_surface"),
    ("ground: heights above the surface", "lidarstat.classify._moments_ground", "heights"),
    ("ground: raised patches", "lidarstat.classify._moments", "drop_raised_patches"),
    ("terrain", "lidarstat.classify._moments", "terrain_step"),
    ("roads", "lidarstat.classify._moments", "road_points"),
    ("buildings", "lidarstat.classify._moments", "building_step"),
    ("buildings: noise from the ground", "lidarstat.classify._buildings", "ground_sigma"),
    ("buildings: kNN search", "lidarstat.classify._buildings", "knn_indices"),
    ("buildings: kNN search", "lidarstat.neighbors._query", "KnnIndex.query_indices"),
    ("buildings: kNN tree (ties)", "lidarstat.neighbors._query", "KnnIndex.__init__"),
    ("buildings: local planes", "lidarstat.classify._buildings", "_planes"),
    ("buildings: plane and share tests", "lidarstat.classify._buildings", "chi2_test"),
    ("buildings: plane and share tests", "lidarstat.classify._buildings", "binomial_test"),
    ("buildings: residuals to the planes",
     "lidarstat.classify._buildings_kernels", "nearest_plane_residual"),
    ("buildings: patches", "lidarstat.classify._buildings_kernels", "planar_patches"),
    ("buildings: roof cells", "lidarstat.classify._buildings", "_roof_top"),
    ("classes", "lidarstat.classify._moments", "asprs_classes"),
    ("fields (input order)", "lidarstat.classify._moments", "_expand"),
    ("write", "lidarstat.io", "write"),
    ("write", "lidarstat.io", "rewrite"),  # LAS/LAZ out: the input's records copied
    ("write: records copied, fields packed", "lidarstat.io._las", "_copied_record"),
    ("write: laspy header statistics, file write", "laspy.laswriter", "LasWriter.write_points"),
)

#: The main thread's wait for the steps run beside the others (``_beside``'s Futures).
WAIT_STEP = ("waiting for side steps", "lidarstat.classify._moments")


def _since_process_start():
    """Seconds since this process started (interpreter start-up included)."""
    with open("/proc/self/stat") as fh:
        start = int(fh.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
    with open("/proc/uptime") as fh:
        return float(fh.read().split()[0]) - start


def child_profile(inp, out, trim=True):
    """``lidarstat moments IN OUT --no-report -q`` with every named step timed.

    `trim` False: the freed memory is not handed back between the steps
    (``lidarstat._shared._memory.release_freed`` does nothing), to show what that saves."""
    import importlib

    if not trim:
        import lidarstat._shared._memory as mem

        mem._TRIM = None
    steps = _Steps()
    steps.start()
    import lidarstat.classify
    import lidarstat.io
    from lidarstat.cli import main

    del lidarstat  # imported as the command imports them on its first call
    started = _since_process_start()
    for label, mod, attr in STEPS:
        owner = importlib.import_module(mod)
        *path, attr = attr.split(".")  # a class's method: wrapped on the class
        for name in path:
            owner = getattr(owner, name)
        steps.wrap(label, owner, attr)
    steps.wrap_beside(WAIT_STEP[0], importlib.import_module(WAIT_STEP[1]))
    t1, c1 = time.perf_counter(), time.process_time()
    rc = main(["moments", str(inp), str(out), "--no-report", "-q"])
    total, ctotal = time.perf_counter() - t1, time.process_time() - c1
    steps.stop()
    secs = {"start + imports": started}
    secs.update(steps.seconds)
    secs["other"] = total - sum(steps.seconds.values())
    cpu = {"start + imports": c1}
    cpu.update(steps.cpu)
    cpu["other"] = ctotal - sum(steps.cpu.values())
    with open("/proc/self/status") as fh:
        hwm = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM"))
    return {"rc": rc, "ended_s": _since_process_start(), "seconds": {k: round(v, 3) for k, v in secs.items()},
            "cpu_seconds": {k: round(v, 3) for k, v in cpu.items()},
            "peak_rss_mib": {k: round(v) for k, v in steps.peak_mib.items()},
            "beside": steps.beside,
            "vmhwm_mib": round(hwm / 1024)}


# ------------------------------------------------------------------------- parent
def timed(cmd, env):
    """Wall seconds, peak RSS (MiB), stdout and CPU seconds (user + system) of `cmd`, by
    GNU time."""
    res = subprocess.run(["/usr/bin/time", "-f", "TIME %e %M %U %S", *map(str, cmd)], env=env,
                         capture_output=True, text=True, check=False)
    line = [s for s in res.stderr.splitlines() if s.startswith("TIME ")]
    if res.returncode != 0 or not line:
        raise RuntimeError(f"{cmd[:4]} failed ({res.returncode}): {res.stderr[-2000:]}")
    _, sec, kib, user, system = line[-1].split()
    return float(sec), int(kib) / 1024, res.stdout, float(user) + float(system)


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = f"{SRC}{os.pathsep}{env.get('PYTHONPATH', '')}".rstrip(os.pathsep)
    return env


def errors(out_path, truth_path):
    """Total error of the output's class 2 (and 11, road) as ground against the truth."""
    import laspy

    with laspy.open(out_path) as r:
        cls = r.read().classification
    truth = np.load(truth_path)
    ground = (np.asarray(cls) == 2) | (np.asarray(cls) == 11)
    return float(np.mean(ground != truth))


def run_size(n, folder, repeats, env, skip_peers, profile, variants=(), io_floor=False):
    inp, truth = write_cloud(n, folder)
    out_l, out_c = folder / f"moments_{n}.las", folder / f"csf_{n}.las"
    lid_cmd = [sys.executable, "-m", "lidarstat", "moments", inp, out_l, "--no-report", "-q"]
    csf_cmd = [sys.executable, __file__, "--child", "csf", inp, out_c]
    extra = {}  # name -> (command, its output, the moments options)
    for name, opts in variants:
        out = folder / f"{name}_{n}.las"
        extra[name] = ([*lid_cmd[:-3], out, *lid_cmd[-2:], *opts], out, opts)
    if io_floor:
        out = folder / f"io_{n}.las"
        extra["io_floor"] = ([sys.executable, __file__, "--child", "io", inp, out], out, [])
    rows = {"lidarstat": [], "csf": [], **{name: [] for name in extra}}
    for _ in range(repeats):  # alternating
        rows["lidarstat"].append(timed(lid_cmd, env))
        if not skip_peers:
            rows["csf"].append(timed(csf_cmd, env))
        for name, (cmd, _, _) in extra.items():
            rows[name].append(timed(cmd, env))
    med = {k: (float(np.median([r[0] for r in v])), float(max(r[1] for r in v)),
               float(np.median([r[3] for r in v])))
           for k, v in rows.items() if v}
    row = {"points": n, "lidarstat_s": round(med["lidarstat"][0], 2),
           "lidarstat_all_s": [r[0] for r in rows["lidarstat"]],
           "lidarstat_cpu_s": round(med["lidarstat"][2], 2),
           "lidarstat_peak_rss_mib": round(med["lidarstat"][1]),
           "lidarstat_total_error": round(errors(out_l, truth), 6)}
    if "csf" in med:
        row.update(csf_s=round(med["csf"][0], 2), csf_all_s=[r[0] for r in rows["csf"]],
                   csf_cpu_s=round(med["csf"][2], 2),
                   csf_peak_rss_mib=round(med["csf"][1]),
                   csf_total_error=round(errors(out_c, truth), 6),
                   ratio=round(med["lidarstat"][0] / med["csf"][0], 2),
                   cpu_ratio=round(med["lidarstat"][2] / med["csf"][2], 2))
    if extra:  # the same command with options, and the I/O floor, in the same alternation
        row["variants"] = {}
        for name, (_, out, opts) in extra.items():
            row["variants"][name] = {
                "options": list(opts),
                "s": round(med[name][0], 2), "all_s": [r[0] for r in rows[name]],
                "cpu_s": round(med[name][2], 2), "peak_rss_mib": round(med[name][1]),
                "total_error": round(errors(out, truth), 6)}
    for mode in ("profile", "profile_no_trim")[:profile]:
        wall, peak, stdout, _ = timed([sys.executable, __file__, "--child", mode, inp,
                                       out_l], env)
        prof = json.loads(stdout.strip().splitlines()[-1])
        prof["seconds"]["exit"] = round(wall - prof.pop("ended_s"), 3)
        prof.update(wall_s=wall, gnu_time_peak_rss_mib=round(peak))
        row[mode] = prof
    return row


def print_rows(rows):
    print("\n| command | points | lidarstat wall / CPU | CSF 1 m wall / CPU, same run | "
          "CPU ratio | wall ratio | peak MiB (lidarstat / CSF) |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for r in rows:
        peer = f"{r['csf_s']:.1f} s / {r['csf_cpu_s']:.1f} s" if "csf_s" in r else "-"
        print(f"| `moments` | {r['points']:,} | {r['lidarstat_s']:.1f} s / "
              f"{r['lidarstat_cpu_s']:.1f} s | {peer} | "
              f"{r.get('cpu_ratio', float('nan')):.2f} | {r.get('ratio', float('nan')):.2f} | "
              f"{r['lidarstat_peak_rss_mib']} / {r.get('csf_peak_rss_mib', '-')} |")
        for name, v in r.get("variants", {}).items():
            what = ("laspy read + write, no filter" if name == "io_floor"
                    else "`moments " + " ".join(v["options"]) + "`")
            print(f"| {what} | {r['points']:,} | {v['s']:.1f} s / {v['cpu_s']:.1f} s | | | | "
                  f"{v['peak_rss_mib']} MiB, total error {100 * v['total_error']:.4f} % |")
    for r, mode in ((r, m) for r in rows for m in ("profile", "profile_no_trim")):
        p = r.get(mode)
        if not p:
            continue
        print(f"\n{mode}, {r['points']:,} points (peak {p['vmhwm_mib']} MiB):")
        for k, v in p["seconds"].items():
            print(f"  {k:44s} {v:7.2f} s  {p['cpu_seconds'].get(k, 0):7.2f} s CPU  "
                  f"{p['peak_rss_mib'].get(k, 0):6d} MiB")
        for k, v in p.get("beside", {}).items():
            print(f"  beside, in its thread: {k:18s} {v['seconds']:7.2f} s  "
                  f"{v['thread_cpu_seconds']:7.2f} s CPU of its thread")


def _variant(text):
    """``NAME=OPTIONS`` -> (name, [option, ...])."""
    import shlex

    name, sep, opts = text.partition("=")
    if not sep or not name.isidentifier():
        raise SystemExit(f"bench_moments.py: --variant {text!r}: expected NAME=OPTIONS")
    return name, shlex.split(opts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="200,000 points, one repeat")
    ap.add_argument("--points", type=int, nargs="+", default=[10_000_000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--profile", action="count", default=0,
                    help="also the per-step profile (twice: also one without handing freed "
                         "memory back between the steps)")
    ap.add_argument("--skip-peers", action="store_true", help="no CSF")
    ap.add_argument("--work", default=None, help="folder of the clouds (default: a temp dir)")
    ap.add_argument("--out", default=None, help="JSON of the results (rows stored under "
                    "--label; other labels already in the file are kept)")
    ap.add_argument("--label", default="current", help="name of this run in --out")
    ap.add_argument("--note", default=None, help="what code the run measured (stored in --out)")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=OPTIONS",
                    help="also time `moments` with these options in the same alternation "
                         "(e.g. --variant 'core=--no-terrain --no-continuity'); repeatable")
    ap.add_argument("--io-floor", action="store_true",
                    help="also time a process that only reads and writes the file with laspy")
    ap.add_argument("--child", nargs=3, metavar=("MODE", "IN", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        mode, inp, out = args.child
        if mode == "csf":
            child_csf(inp, out)
        elif mode == "io":
            child_io(inp, out)
        else:
            print(json.dumps(child_profile(inp, out, trim=mode != "profile_no_trim")))
        return
    sizes, repeats = ([200_000], 1) if args.quick else (args.points, args.repeats)
    folder = Path(args.work or tempfile.mkdtemp(prefix="bench_moments_"))
    folder.mkdir(parents=True, exist_ok=True)
    env = _env()
    warm, _ = write_cloud(20_000, folder)  # compile or load the kernels once, untimed
    subprocess.run([sys.executable, "-m", "lidarstat", "moments", warm, folder / "warm.las",
                    "--no-report", "-q"], env=env, check=True)
    rows = []
    for n in sizes:
        rows.append(run_size(n, folder, repeats, env, args.skip_peers, args.profile,
                             [_variant(v) for v in args.variant], args.io_floor))
        print(json.dumps({k: v for k, v in rows[-1].items() if not k.startswith("profile")}),
              flush=True)
    print_rows(rows)
    if args.out:
        out = Path(args.out)
        old = json.loads(out.read_text()) if out.exists() else {}
        runs = old.get("runs") if isinstance(old.get("runs"), dict) else {}
        runs[args.label] = {"repeats": repeats, "load_average": os.getloadavg(),
                            "rows": rows, **({"code": args.note} if args.note else {})}
        out.write_text(json.dumps({
            "what": "whole process (start, read LAS, classify, write LAS), median of "
                    "alternating repeats; peak RSS by GNU time; profile: one more run "
                    "with every named step timed (wall, CPU of all threads, peak RSS); "
                    "profile_no_trim: the same without handing freed memory back between "
                    "the steps",
            "command": "lidarstat moments IN OUT --no-report -q",
            "peer": "CSF (cloth_simulation_filter) cloth 1 m, slope smoothing, laspy read "
                    "and write",
            "machine_shared": True, "cpus": os.cpu_count(),
            "python": platform.python_version(), "runs": runs}, indent=1) + "\n")


if __name__ == "__main__":
    import warnings

    warnings.simplefilter("ignore")
    main()
