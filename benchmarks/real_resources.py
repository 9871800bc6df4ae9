#!/usr/bin/env python
"""Time and peak memory of every command on the real files of ``../shared/data``, and the
outliers: the file and command whose bytes a point or seconds a million points stand far
above the same command's median over the files and above the synthetic town's figures.

Each command runs as a user runs it (``python -m lidarstat.cli COMMAND IN OUT -q``, the
defaults, a fresh process: start, read, compute, write), one run at a time; wall time from
the parent, CPU seconds (user + system, every thread) and peak resident memory from
``os.wait4`` (``scaling.run``). A run that passes ``--timeout`` seconds or ``--max-mib`` of
resident memory is stopped and recorded as such; a run that fails is recorded with the
last line of its message. The Numba cache is the package's own (run ``lidarstat warmup``
first, so that no timed run compiles).

The files are a representative subset of the folder's (``FILES``, with what each stands
for); the others are named in ``SKIPPED`` with the reason, so that the sweep stays within
about half an hour on two shared cores. Writes ``benchmarks/results_real_resources.json``
(rows so far in ``OUT.partial`` after every run)::

    PYTHONPATH=src python benchmarks/real_resources.py
    PYTHONPATH=src python benchmarks/real_resources.py --files pdal_testdata/sample_c.las \\
        --commands curvature moments --out /tmp/quick.json      # a quick look
    PYTHONPATH=src python benchmarks/real_resources.py --outliers-only   # re-derive outliers

Files run side by side in two processes (``--files`` and ``--out`` each) are combined,
with their outliers, without running anything::

    PYTHONPATH=src python benchmarks/real_resources.py --merge a.json b.json.partial

An outlier is a run whose bytes a point (peak resident memory over the points) or CPU
seconds a million points, both above the command's fixed cost (its run on the file of
fewest points: interpreter, imports, compiled kernels), is more than ``FACTOR`` times the
command's median over the files that ran, and also above the synthetic town's
whole-process figure of the nearest size in ``results_scaling.json``; and every run the
caps stopped. Files of fewer than ``MIN_POINTS`` points are left out of the median test;
their runs are outliers when they hold more than ``SMALL_FILE_MIB`` above the fixed cost.
``CAUSES`` holds what a profile of each command's outliers found.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
DATA = HERE.parent.parent / "shared" / "data"

from scaling import COMMANDS as TOWN_COMMANDS
from scaling import _code_of_runs, run

#: The scaling table's single-file commands with their defaults, and `segment --method
#: ridges`.
COMMANDS = {name: argv for name, argv in TOWN_COMMANDS.items() if " --tile" not in name}
COMMANDS["segment-ridges"] = ["segment", "{i}", "{o}", "--method", "ridges"]

#: path under the data folder -> what it stands for
FILES = {
    "ahn3_delft_3dfier/ahn3_cropped_1.laz": "AHN3 Delft crop, 14 pts/m2, town with canals",
    "ign_lidarhd_samples/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz":
        "IGN St-Barthelemy, 25 pts/m2, dense small-building town on slopes",
    "e57_pump_tls/pump_scan.laz": "terrestrial scan of a pump room, 2-5 m ranges",
    "pdal_testdata/autzen_trim.laz": "Autzen (PDAL), US feet, stadium and houses",
    "lidR/Topography.laz": "forested relief (lidR), up to 6 returns",
    "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las": "IGN LiDAR HD, 11 pts/m2",
    "ahn3_amsterdam/ahn_2386_9702.laz": "AHN3 Amsterdam tile, 16 pts/m2",
    "isprs_filtertest/joined/samp11_ref_intensity.laz":
        "ISPRS sample 11, urban, 0.7 pts/m2 (sparse)",
    "isprs_filtertest/joined/samp51_ref_intensity.laz":
        "ISPRS sample 51, rural, 0.17 pts/m2 (very sparse)",
    "laspy_testdata/file_with_both_wkt_and_geotiff_vlrs.las":
        "house and trees, US feet, about 115 pts/m2 (very dense)",
    "pdal_testdata/sample_c.las": "one large roof and ground (PDAL)",
    "pdal_testdata/mvk-thin.las": "thinned 5 x 5 km, a few points per hectare",
    "lidR/dbh.laz": "a slice of a tree stem (terrestrial / mobile), 1,369 points",
}
#: path (or folder) -> why it is not in the sweep
SKIPPED = {
    "ahn3_delft_3dfier/ahn3_cropped_2.laz": "the same survey and area type as crop 1",
    "ahn3_delft_3dfier/derived/": "the crops with one extra field (the same points)",
    "ahn3_amsterdam/ahn_2397_9705.laz": "the neighbouring tile of the same survey",
    "isprs_filtertest/original_pdal_data/": "the site files (0.35-0.63 M points each, "
        "first and last pulse) are covered by the samples and the other airborne files "
        "within the sweep's half hour; the samples are the joined/ files",
    "isprs_filtertest/joined/ (samp21, 31, 41, 61, 71)": "samples 11 and 51 stand for "
        "the urban and the rural densities",
    "pdal_testdata/las_with_several_extra_byte_bloc.laz": "0.7 M points of open field, "
        "beyond the sweep's time on two shared cores",
    "pdal_testdata/warsaw_small.las": "3,000 points (below the outlier test's size)",
    "laspy_testdata/append-bug.laz": "LiDAR HD again (the IGN files)",
    "lidR/Megaplot.laz, lidR/MixedConifer.laz": "forest with normalised heights; "
        "Topography stands for the lidR forests",
    "e57_pump_tls/pump_scan.npz": "the same scan as pump_scan.laz",
}

FACTOR = 2.0
MIN_POINTS = 10_000

#: command -> the step an outlier of it was found in (resident memory and the stack
#: sampled every 10 ms in a run of the command on the outlier's file), its cause and what
#: would fix it; attached to the outliers of that command
CAUSES = {
    "ridges": {
        "profiled_on": [next(f for f in FILES if "St_Barth" in f),
                        "pdal_testdata/mvk-thin.las"],
        "step": "segment/_ridge_creases.py crease_points: query / fold_across / cosines",
        "cause": "the crease test queries k = max(32, 1.5 pi (reach / spacing)^2) nearest "
                 "neighbours (capped only at the points of the file) for every strongly "
                 "rejected point at once and holds them whole (int32 and float64 rows, "
                 "grown by concatenation, so twice at the moment of growth), then (rows, "
                 "k, 3) offsets in cosines. On St-Barthelemy many points are strongly "
                 "rejected (vegetation, small roofs on slopes): the table passes 3,000 MiB "
                 "at the query of line 146-149. On mvk-thin the crease reach is many "
                 "point spacings (a thinned file whose spacing comes from its clumps), so "
                 "k reaches the file's size and the tables are quadratic: 1,391 MiB at "
                 "cosines for 6,280 points.",
        "fix": "work the candidates in blocks (query, fold_across and cosines reduce to "
               "per-row results), or query by the reach (radius) rather than the largest "
               "k, into preallocated rows; not changed here (the ridges code is being "
               "profiled on the Delft crop separately)."},
    "segment-sar": {
        "profiled_on": [next(f for f in FILES if "samp11" in f),
                        next(f for f in FILES if "St_Barth" in f)],
        "step": "segment/_sar_units.py refine_raw_clusters: the per-unit fits and tests",
        "cause": "half of the CPU seconds on samp11 went to OpenBLAS handing tens of "
                 "thousands of small dense calls (a plane's basis, a unit's eigenvalues, "
                 "its refits) to its second thread and spinning between them; with BLAS "
                 "on one thread (the command runs so) 48.0 -> 24.1 CPU s, the outputs "
                 "identical (results_sar_speed.json). What remains is spread: 767 "
                 "likelihood fits on samp11, each about 20 evaluations of "
                 "log|I - rho W| (one sparse LU each above 150 points: 3,129 LUs, about "
                 "a tenth of the time; W's eigenvalues once per fit below), the power "
                 "series of the lag solve, the split's local normals and the "
                 "goodness-of-fit traces. The sparse samples have many small units a "
                 "point (0.17-0.7 points/m2: a roof is a few dozen points), each with "
                 "those fixed costs.",
        "fix": "fewer fits a unit (the final refit estimates rho again on a raw cluster "
               "the search stage has fitted, often unchanged) or a cheaper lag solve; the log-determinant is no "
               "longer the main cost (an LU costs 0.4-6.6 ms at 150-3,000 points, W's "
               "eigenvalues once cost less than 20 LUs only up to 600-1,200 points: "
               "results_sar_speed.json, key logdet)."},
}
#: a file below MIN_POINTS is an outlier when its run holds this much above the fixed cost
SMALL_FILE_MIB = 500.0


def _points(path: Path) -> int:
    import laspy

    with laspy.open(path) as f:
        return int(f.header.point_count)


def _synthetic(points: int) -> dict:
    """Bytes a point and CPU seconds a million points of each command on the synthetic
    town of the size nearest `points` (log scale), from ``results_scaling.json``."""
    stored = json.loads((HERE / "results_scaling.json").read_text())["commands"]
    out = {}
    for name in COMMANDS:
        rows = [r for r in stored.get(name, []) if r.get("seconds")]
        if not rows:
            continue
        r = min(rows, key=lambda r: abs(np.log(r["points"] / points)))
        out[name] = {"points": r["points"],
                     "bytes_per_point": round(r["peak_mib"] * 2**20 / r["points"]),
                     "cpu_seconds_per_million": round(r["cpu_seconds"] / (r["points"] / 1e6),
                                                      1)}
    return out


def _marginal(rows: dict) -> None:
    """Add to every run that finished the bytes a point and CPU seconds a million points
    above the command's fixed cost: the peak and CPU seconds of its run on the file of
    fewest points (interpreter, imports, compiled kernels), which dominate a small file's
    figures a point."""
    for name in COMMANDS:
        ok = [r for by in rows.values() for c, r in by.items()
              if c == name and r.get("status") == "ok"]
        if not ok:
            continue
        base = min(ok, key=lambda r: r["points"])
        for r in ok:
            extra = max(r["points"] - base["points"], 1)
            r["base_points"] = base["points"]
            r["bytes_per_point_above_base"] = round(
                max(r["peak_mib"] - base["peak_mib"], 0.0) * 2**20 / extra)
            r["cpu_seconds_per_million_above_base"] = round(
                max(r["cpu_seconds"] - base["cpu_seconds"], 0.0) / (extra / 1e6), 1)


def outliers(rows: dict) -> list:
    """Runs whose bytes a point or CPU seconds a million points above the fixed cost
    exceed FACTOR times the command's median over the files (of at least MIN_POINTS
    points), and the synthetic town's whole-process figure; and the runs stopped by the
    caps."""
    _marginal(rows)
    found = []
    for name in COMMANDS:
        ok = [(f, r) for f, by in rows.items() for c, r in by.items()
              if c == name and r.get("status") == "ok" and r["points"] >= MIN_POINTS]
        if len(ok) < 3:
            continue
        for key in ("bytes_per_point", "cpu_seconds_per_million"):
            med = float(np.median([r[key + "_above_base"] for _, r in ok]))
            for f, r in ok:
                syn = _synthetic(r["points"]).get(name, {})
                if r[key + "_above_base"] > FACTOR * med and r[key + "_above_base"] > syn.get(
                        key, 0):
                    found.append({"file": f, "command": name, "measure": key + "_above_base",
                                  "value": r[key + "_above_base"],
                                  "median_over_files": round(med, 1),
                                  "synthetic_town": syn.get(key),
                                  "synthetic_town_points": syn.get("points")})
    for f, by in rows.items():
        for c, r in by.items():
            if r.get("status", "ok") != "ok" and not r["status"].startswith("failed"):
                found.append({"file": f, "command": c, "measure": "stopped",
                              "value": r["status"]})
            elif (r.get("status") == "ok" and r["points"] < MIN_POINTS
                  and r["bytes_per_point_above_base"] * r["points"] > SMALL_FILE_MIB * 2**20):
                found.append({"file": f, "command": c, "measure": "peak_mib_above_base",
                              "value": round(r["bytes_per_point_above_base"] * r["points"]
                                             / 2**20), "small_file_limit_mib": SMALL_FILE_MIB})
    for o in found:
        if o["command"] in CAUSES:
            o["cause"] = CAUSES[o["command"]]
    return found


def table(results: dict) -> str:
    """Markdown: per command, the median and the largest bytes a point and CPU seconds a
    million points above the fixed cost over the files (of at least MIN_POINTS points),
    beside the synthetic town of 0.2 million points (whole process); the runs stopped or
    failed."""
    short = {f: Path(f).stem.split("_RGAF09")[0].split(".subset")[0] for f in results["files"]}
    town = results["synthetic_town"]["200000"]
    head = ("| command | bytes a point: median (largest, file) | CPU s a million points: "
            "median (largest, file) | town 0.2M | stopped or failed |")
    lines = [head, "|---|---|---|---|---|"]
    for name in COMMANDS:
        ok = [(f, by[name]) for f, by in results["files"].items()
              if name in by and by[name]["status"] == "ok" and by[name]["points"] >= MIN_POINTS]
        bad = [f"{short[f]}: {by[name]['status'].split(':')[0]}"
               for f, by in results["files"].items()
               if name in by and by[name]["status"] != "ok"]
        if not ok:
            continue
        cells = []
        for key in ("bytes_per_point", "cpu_seconds_per_million"):
            key += "_above_base"
            f, r = max(ok, key=lambda fr: fr[1][key])
            cells.append(f"{np.median([r[key] for _, r in ok]):,.0f} ({r[key]:,.0f}, "
                         f"{short[f]})")
        t = town.get(name)
        cells.append(f"{t['bytes_per_point']:,} B, {t['cpu_seconds_per_million']:,.0f} s"
                     if t else "")
        cells.append("; ".join(bad))
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", nargs="+", default=list(FILES))
    ap.add_argument("--commands", nargs="+", default=list(COMMANDS), choices=list(COMMANDS))
    ap.add_argument("--timeout", type=float, default=300.0,
                    help="seconds after which one run is stopped (default 300)")
    ap.add_argument("--max-mib", type=float, default=3000.0,
                    help="resident memory (MiB) at which one run is stopped (default 3000)")
    ap.add_argument("--out", default=str(HERE / "results_real_resources.json"))
    ap.add_argument("--outliers-only", action="store_true",
                    help="run nothing: recompute the outliers of --out")
    ap.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                    help="run nothing: combine the files of these results (or .partial) "
                         "files, run side by side, into --out with their outliers")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.merge:
        parts = [json.loads(Path(p).read_text()) for p in args.merge]
        results = dict(parts[0], files={}, merged_from=[Path(p).name for p in args.merge])
        for part in parts:  # a later part's run of a command on a file replaces it
            for name, runs in part["files"].items():
                results["files"].setdefault(name, {}).update(runs)
        _finish(results, out)
        return
    if args.outliers_only:
        results = json.loads(out.read_text())
        results["outliers"] = outliers(results["files"])
        out.write_text(json.dumps(results, indent=1) + "\n")
        print(json.dumps(results["outliers"], indent=1))
        return
    if not DATA.is_dir():
        print(f"real_resources: no data folder at {DATA}; nothing run")
        return
    results = {"machine": {"platform": platform.platform(), "cores": os.cpu_count(),
                           "python": platform.python_version(), "machine_shared": True,
                           "note": "two cores shared with other jobs (runs at nice 10): "
                                   "seconds are upper bounds; peak memory is not affected"},
               "code": _code_of_runs(), "timeout_seconds": args.timeout,
               "max_mib": args.max_mib, "outlier_factor": FACTOR,
               "outlier_min_points": MIN_POINTS,
               "skipped": SKIPPED, "files": {}}
    env = dict(os.environ)
    partial = Path(str(out) + ".partial")
    with tempfile.TemporaryDirectory() as tmp:
        for rel in args.files:
            src = DATA / rel
            n = _points(src)
            by = results["files"].setdefault(rel, {})
            for name in args.commands:
                dst = Path(tmp) / "out.laz"
                r = run([a.format(i=src, o=dst) for a in COMMANDS[name]], env,
                        args.timeout, args.max_mib)
                dst.unlink(missing_ok=True)
                r["points"] = n
                r["timeout_seconds"] = args.timeout
                if r.get("peak_mib"):
                    r["bytes_per_point"] = round(r["peak_mib"] * 2**20 / n)
                if r.get("cpu_seconds") and r["status"] == "ok":
                    r["cpu_seconds_per_million"] = round(r["cpu_seconds"] / (n / 1e6), 1)
                by[name] = r
                print(f"{rel:60s} {name:20s} {n:>8,d}  {r['seconds']} s  CPU "
                      f"{r.get('cpu_seconds')} s  {r['peak_mib']} MiB  {r['status']}",
                      flush=True)
                partial.write_text(json.dumps(results, indent=1) + "\n")
    _finish(results, out)
    partial.unlink(missing_ok=True)


def _finish(results: dict, out: Path) -> None:
    """Descriptions, the synthetic town's figures and the outliers; write `out`."""
    results["descriptions"] = {f: FILES.get(f, "") for f in results["files"]}
    results["synthetic_town"] = {str(p): _synthetic(p) for p in (200_000, 2_000_000)}
    results["outliers"] = outliers(results["files"])
    results["markdown"] = table(results)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(results["markdown"])
    print(json.dumps(results["outliers"], indent=1))


if __name__ == "__main__":
    main()
