#!/usr/bin/env python
"""Time and peak memory of every command against the number of points (a log-log scaling plot).

Each command runs with its defaults (the automatic scale where it has one) on synthetic
airborne LAZ files of 0.2, 2 and 10 million points (``bench_moments.make_cloud``: a town
at 10 points/m2 with terrain, buildings, trees and roads; intensity and returns, so that
``moments`` sees what it reads from real files). Every run is a fresh process, whole
process: interpreter start, imports, read, compute, write. Its wall time is measured by the
parent, its CPU seconds (user + system) and peak resident memory come from ``os.wait4``.
One untimed run per command on a small file first fills a benchmark-private Numba cache,
so the timed runs load compiled kernels (the first-run compile cost is ``benchmarks/first_run.py``'s subject).

The 50-million-point catalogue (``moments`` over 50 tiles of one million points with a
64 m buffer) is ``benchmarks/catalogue.py --points 50000000``; ``--catalogue N`` runs it
from here, otherwise the entry stored in ``results_catalogue.json`` is plotted beside the
single-file runs.

A run that exceeds ``--timeout`` seconds, or whose resident memory passes ``--max-mib``,
is stopped and recorded as such (``null`` time, the CPU seconds and memory reached, the
limit in the table): a command whose cost grows faster than the others shows as a missing
point (a hollow triangle at the cap in the memory plot when the cap stopped it), not as a
stalled script or a machine out of memory. The figure plots CPU seconds
(user + system, every thread), which compare across machine loads where wall time does not.

Usage::

    python benchmarks/scaling.py --out benchmarks/results_scaling.json \\
        --figure docs/figures/scaling.png
    python benchmarks/scaling.py --sizes 200000 --commands curvature moments   # quick

An existing ``--out`` file keeps its rows of the sizes and commands not run again. Sizes
or commands run side by side in separate processes (each with its own ``--out``; the
rows so far are also in ``OUT.partial`` after every run) are combined without running
anything::

    python benchmarks/scaling.py --merge small.json big_a.json big_b.json \\
        --out benchmarks/results_scaling.json --figure docs/figures/scaling.png
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
sys.path.insert(0, str(HERE))

SIZES = (200_000, 2_000_000, 10_000_000)

# name -> argv after "lidarstat" ({i} input, {o} output file)
COMMANDS = {
    "curvature": ["curvature", "{i}", "{o}"],
    "covariance": ["covariance", "{i}", "{o}"],
    "ridges": ["ridges", "{i}", "{o}"],
    "moments": ["moments", "{i}", "{o}", "--no-report"],
    "segment-covariance": ["segment", "{i}", "{o}", "--method", "covariance"],
    "segment-curvature": ["segment", "{i}", "{o}", "--method", "curvature"],
    "segment-sar": ["segment", "{i}", "{o}", "--method", "sar"],
}
#: Out-of-core runs of one file (``--tile``: tiles of 200 m, about 400,000 points of the
#: town, each with its method's buffer): memory that does not grow with the file.
TILE = "200"
COMMANDS.update({
    f"ridges --tile {TILE}": [*COMMANDS["ridges"], "--tile", TILE],
    f"segment-covariance --tile {TILE}": [*COMMANDS["segment-covariance"], "--tile", TILE],
    f"segment-curvature --tile {TILE}": [*COMMANDS["segment-curvature"], "--tile", TILE],
    f"segment-sar --tile {TILE}": [*COMMANDS["segment-sar"], "--tile", TILE],
    f"covariance --tile {TILE}": [*COMMANDS["covariance"], "--tile", TILE],
})


def write_cloud(path: Path, n: int, seed: int = 20261126) -> None:
    """The synthetic town of ``bench_moments`` as a LAZ file of `n` points."""
    from bench_moments import make_cloud

    from lidarstat.io import PointCloud, write

    xyz, inten, nret, rnum, _ = make_cloud(n, seed=seed)
    write(path, PointCloud(xyz, {
        "intensity": np.clip(inten, 0, 65535).astype(np.uint16),
        "number_of_returns": nret.astype(np.uint8),
        "return_number": rnum.astype(np.uint8)}))


def _rss_mib(pid: int) -> float:
    """Resident memory of a running process (MiB), 0 once it has gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def run(argv: list[str], env: dict, timeout: float, max_mib: float | None = None) -> dict:
    """One whole-process run: wall seconds and peak RSS (MiB), or a timeout / memory stop /
    failure."""
    cmd = [sys.executable, "-m", "lidarstat.cli", *argv, "-q"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = t0 + timeout
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() > deadline:
            proc.kill()
            _, _, usage = os.wait4(proc.pid, 0)
            proc.stderr.close()
            return {"seconds": None, "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 2),
                    "peak_mib": round(usage.ru_maxrss / 1024.0, 1),
                    "status": f"timeout {timeout:.0f} s"}
        if max_mib is not None:
            rss = _rss_mib(proc.pid)
            if rss > max_mib:
                proc.kill()
                _, _, usage = os.wait4(proc.pid, 0)
                proc.stderr.close()
                return {"seconds": None, "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 2),
                        "stopped_after_seconds": round(time.perf_counter() - t0, 1),
                        "peak_mib": round(rss, 1), "status": f"stopped over {max_mib:.0f} MiB"}
        time.sleep(0.05)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode().strip()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        return {"seconds": None, "peak_mib": None, "status": "failed: " + err[-300:]}
    return {"seconds": round(wall, 2), "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 2),
            "peak_mib": round(usage.ru_maxrss / 1024.0, 1), "status": "ok"}


def measure(commands, sizes, tmp: Path, timeout: float, max_mib: float | None,
            partial: Path | None = None, cache: Path | None = None,
            code: str | None = None) -> dict:
    """Every command at every size; with `partial`, the rows so far are written there after
    each run (a long run stopped from outside keeps what it measured); `code` (the commit
    of the lidarstat that ran) is stored in every row."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache or tmp / "numba"))
    warm = tmp / "warm.laz"
    write_cloud(warm, 20_000)
    for name in commands:  # fill the Numba cache: the timed runs load compiled kernels
        out = run([a.format(i=warm, o=tmp / "warm_out.laz") for a in COMMANDS[name]],
                  env, timeout=1800)
        print(f"warm-up {name}: {out['status']}", flush=True)
    rows = {name: [] for name in commands}
    for n in sizes:
        src = tmp / f"town_{n}.laz"
        write_cloud(src, n)
        for name in commands:
            dst = tmp / f"out_{name}_{n}.laz"
            res = run([a.format(i=src, o=dst) for a in COMMANDS[name]], env, timeout, max_mib)
            dst.unlink(missing_ok=True)
            res["points"] = n
            if code:
                res["code"] = code
            if res["seconds"]:
                res["seconds_per_million"] = round(res["seconds"] / (n / 1e6), 2)
            rows[name].append(res)
            print(f"{name:20s} {n:>10,d}  {res['seconds']} s  CPU {res.get('cpu_seconds')} s  "
                  f"{res['peak_mib']} MiB  {res['status']}", flush=True)
            if partial is not None:
                partial.write_text(json.dumps({"commands": rows}, indent=1) + "\n")
        src.unlink()
    return rows


def table(results: dict) -> str:
    """Markdown: one row per command, wall and CPU time (s) and peak (MiB) per size; a
    stopped run shows why (the time limit or the memory cap)."""
    sizes = sorted({r["points"] for rows in results["commands"].values() for r in rows})
    head = "| command | " + " | ".join(f"{n / 1e6:g}M points" for n in sizes) + " |"
    lines = [head, "|---|" + "---|" * len(sizes)]
    for name, rows in results["commands"].items():
        by = {r["points"]: r for r in rows}
        cells = []
        for n in sizes:
            r = by.get(n)
            if r is None:
                cells.append("")
            elif r["seconds"] is None:  # timeout N s / stopped over N MiB / failed
                cells.append(r["status"].split(":")[0].replace("timeout", "stopped at"))
            else:
                cpu = f" (CPU {r['cpu_seconds']:.1f} s)" if "cpu_seconds" in r else ""
                cells.append(f"{r['seconds']:.1f} s{cpu}, {r['peak_mib']:.0f} MiB")
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    cat = results.get("catalogue")
    if cat:
        lines.append(f"\nCatalogue (`moments --dtm`, {cat['tiles']} tiles of "
                     f"{cat['tile_points'] / 1e6:g}M points): {cat['points'] / 1e6:g}M points "
                     f"in {cat['seconds']:.0f} s ({cat['seconds_per_million']:.1f} s per "
                     f"million), peak {cat['peak_mib']:.0f} MiB.")
    return "\n".join(lines)


def figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(10, 4.8))
    colours: dict[str, str] = {}  # a tiled run (dashed) in its command's colour
    for name, rows in results["commands"].items():
        base = name.split(" --tile")[0]
        colour = colours.setdefault(base, f"C{len(colours) % 10}")
        style = "o--" if base != name else "o-"
        ok = [r for r in rows if r["seconds"]]
        n = [r["points"] for r in ok]
        ax_t.plot(n, [r.get("cpu_seconds", np.nan) for r in ok], style, color=colour,
                  mfc="white" if base != name else colour, label=name)
        ax_m.plot(n, [r["peak_mib"] for r in ok], style, color=colour,
                  mfc="white" if base != name else colour, label=name)
        capped = [r for r in rows if r["status"].startswith("stopped over")]
        if capped:  # stopped at the memory cap: the need lies above the marker (side by
            # side, one command each, where several met the same cap)
            shift = 1.06 ** (list(COMMANDS).index(name) % 7 - 3) if name in COMMANDS else 1.0
            ax_m.plot([r["points"] * shift for r in capped], [r["peak_mib"] for r in capped],
                      "^", mfc="none", ms=9, color=colour)
    cat = results.get("catalogue")
    if cat:
        ax_t.plot([cat["points"]], [cat["seconds"]], "k*", ms=11,
                  label="catalogue (moments, wall time)")
        ax_m.plot([cat["points"]], [cat["peak_mib"]], "k*", ms=11, label="catalogue (moments)")
    ref = np.array([2e5, 5e7])
    ax_t.plot(ref, 10 * ref / 1e6, ":", color="0.6", label="linear (10 s per million)")
    for ax, label in ((ax_t, "CPU time, whole process (s)"), (ax_m, "peak memory (MiB)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("points")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    ax_m.axhline(4096, color="r", lw=0.8, ls="--")
    ax_m.text(2.2e5, 4300, "4 GB", color="r", fontsize=8)
    ax_m.plot([], [], "^", mfc="none", color="0.3", label="stopped at the memory cap")
    ax_m.legend(fontsize=6, loc="lower right", ncol=2)
    ax_t.legend(fontsize=6, loc="upper left", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _stored_catalogue(results: dict) -> None:
    """The largest catalogue entry of ``results_catalogue.json`` (the figure's star)."""
    stored = HERE / "results_catalogue.json"
    if stored.exists():
        entries = {k: v for k, v in json.loads(stored.read_text()).items()
                   if k.startswith("scale_")}
        if entries:
            results["catalogue"] = max(entries.values(), key=lambda e: e["points"])
            results["catalogue"]["source"] = "results_catalogue.json"


def merge(paths, out, fig) -> None:
    """The rows of several results files (a later file's row replaces an earlier one of the
    same command and size) as one results file, table and figure."""
    parts = [json.loads(Path(p).read_text()) for p in paths]
    results = {"machine": parts[0]["machine"], "commands": {}, "merged_from": list(paths)}
    for part in parts:
        for name, rows in part["commands"].items():
            by = {r["points"]: r for r in results["commands"].get(name, [])}
            by.update({r["points"]: r for r in rows})
            results["commands"][name] = [by[k] for k in sorted(by)]
        # a catalogue copied from results_catalogue.json is read from there again
        if "catalogue" in part and part["catalogue"].get("source") != "results_catalogue.json":
            results["catalogue"] = part["catalogue"]
    if "catalogue" not in results:
        _stored_catalogue(results)
    results["commands"] = {name: results["commands"][name]
                           for name in sorted(results["commands"],
                                              key=lambda c: list(COMMANDS).index(c))}
    results["markdown"] = table(results)
    print(results["markdown"])
    if out:
        Path(out).write_text(json.dumps(results, indent=1) + "\n")
    if fig:
        figure(results, Path(fig))


def _code_of_runs() -> str | None:
    """The commit of the lidarstat source the runs import (``git describe`` of its tree),
    None outside a git checkout."""
    import lidarstat

    try:
        out = subprocess.run(["git", "-C", str(Path(lidarstat.__file__).parent), "describe",
                              "--always", "--dirty"], capture_output=True, text=True,
                             timeout=30)
    except OSError:
        return None
    return out.stdout.strip() or None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--commands", nargs="+", default=list(COMMANDS), choices=list(COMMANDS))
    ap.add_argument("--timeout", type=float, default=1500.0,
                    help="seconds after which one run is stopped (default 1500)")
    ap.add_argument("--max-mib", type=float, default=None,
                    help="resident memory (MiB) at which one run is stopped (default: none)")
    ap.add_argument("--catalogue", type=int, default=None, metavar="N",
                    help="also run the N-point catalogue (benchmarks/catalogue.py --points N)")
    ap.add_argument("--out", default=None, help="results JSON")
    ap.add_argument("--figure", default=None, help="log-log PNG of time and memory")
    ap.add_argument("--tmp", default=None, help="work folder")
    ap.add_argument("--numba-cache", default=None, metavar="DIR",
                    help="Numba cache folder shared by runs side by side (default: one in the "
                         "work folder, filled by the untimed runs)")
    ap.add_argument("--code", default=None, metavar="LABEL",
                    help="commit of the lidarstat the runs import, stored in every row "
                         "(default: git describe of its source tree, when it is a checkout)")
    ap.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                    help="run nothing: combine the rows of these results files (of runs made "
                         "side by side, e.g. one per size) into --out, its table and figure")
    args = ap.parse_args(argv)
    if args.merge:
        return merge(args.merge, args.out, args.figure)

    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        tmp = Path(tmp)
        results = {"machine": {"platform": platform.platform(), "cores": os.cpu_count(),
                               "python": platform.python_version(),
                               "machine_shared": True,
                               "note": "two cores shared with other jobs: seconds are "
                                       "upper bounds; peak memory is not affected"},
                   "commands": measure(args.commands, args.sizes, tmp, args.timeout,
                                       args.max_mib,
                                       Path(args.out + ".partial") if args.out else None,
                                       Path(args.numba_cache) if args.numba_cache else None,
                                       args.code or _code_of_runs())}
        if args.catalogue:
            import catalogue

            results["catalogue"] = catalogue.scale(tmp / "catalogue", args.catalogue,
                                                   1_000_000)
    if "catalogue" not in results:
        _stored_catalogue(results)
    if args.out and Path(args.out).exists():  # keep the sizes and commands not rerun
        old = json.loads(Path(args.out).read_text()).get("commands", {})
        for name, rows in old.items():
            done = {r["points"] for r in results["commands"].get(name, [])}
            kept = [r for r in rows if r["points"] not in done]
            results["commands"][name] = sorted(kept + results["commands"].get(name, []),
                                               key=lambda r: r["points"])
    results["markdown"] = table(results)
    print(results["markdown"])
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    if args.figure:
        figure(results, Path(args.figure))


if __name__ == "__main__":
    main()
