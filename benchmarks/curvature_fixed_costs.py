#!/usr/bin/env python
"""The part of a whole ``lidarstat curvature`` run that does not depend on the fit, against
CloudCompare's.

On the 2-million-point cloud of ``bench_curvature.py --whole`` (made again here, same
seed), whole processes, alternating, median of ``--repeats``, wall and CPU seconds:

* ``python_start``: ``python -c pass``, the interpreter's start and exit;
* ``lidarstat_fixed``: what ``lidarstat curvature IN.las OUT.las`` does apart from the
  index, the fits and the statistics: the command's imports and parser, the read of the
  coordinates, Numba's start (one cached kernel loaded and run), and the LAS output of
  its 20 fields (zeros of the fields' types) by the command's own writer;
* ``cloudcompare_io``: CloudCompare 2.11 opening the binary PLY and saving it again
  (``-O IN.ply -SAVE_CLOUDS``, no ``-CURV``): its start, read and write.

Where ``lidarstat_fixed``'s wall time beyond its CPU time goes, from the child itself at its
end (``wall_beyond_cpu``): the time its threads waited for a processor while ready to run
(``/proc/self/task/*/schedstat``, second field), its voluntary context switches (each a
wait: I/O, a lock, a sleep), page faults and the bytes it wrote (``/proc/self/io``).

Writes the key ``fixed_costs`` of ``results_curvature_floor.json``::

    nice -n 10 python benchmarks/curvature_fixed_costs.py --shared
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_curvature import (_median_run, make_cloud, run_external_cpu,  # noqa: E402
                             write_ply)

FIXED_CHILD = r"""
import sys
import numpy as np
from lidarstat.cli import _app
_app.build_parser(_app.command_of(["curvature"]))
from lidarstat.features import _curvature_result as result
from lidarstat.io import read, rewrite
from lidarstat.neighbors import find_duplicates
src, dst = sys.argv[1], sys.argv[2]
xyz = read(src, fields=()).xyz
find_duplicates(xyz[:1000])  # Numba's start: one cached kernel loaded and run
n = xyz.shape[0]
fields = {k: np.zeros(n, dtype=t) for k, (t, _) in result.FIELDS.items()}
del xyz
rewrite(src, dst, lambda start, chunk: {k: a[start:start + len(chunk)]
                                        for k, a in fields.items()},
        decode=False, points_per_chunk=1 << 15)
import json, os, resource
wait = 0.0
for t in os.listdir("/proc/self/task"):
    with open(f"/proc/self/task/{t}/schedstat") as f:
        wait += int(f.read().split()[1]) / 1e9
with open("/proc/self/io") as f:
    io = dict(line.split(": ") for line in f.read().strip().splitlines())
ru = resource.getrusage(resource.RUSAGE_SELF)
with open(sys.argv[3], "w") as f:
    json.dump(dict(runqueue_wait_seconds=wait, voluntary_switches=ru.ru_nvcsw,
                   involuntary_switches=ru.ru_nivcsw, major_faults=ru.ru_majflt,
                   minor_faults=ru.ru_minflt, write_bytes=int(io["write_bytes"]),
                   wchar=int(io["wchar"])), f)
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--shared", action="store_true",
                    help="record that other jobs ran on the machine meanwhile")
    ap.add_argument("--out", default=str(HERE / "results_curvature_floor.json"))
    args = ap.parse_args(argv)
    from lidarstat.io import PointCloud, write

    tmp = Path(tempfile.mkdtemp(prefix="lidarstat_fixed_"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba_cache"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    xyz, _ = make_cloud(args.points)
    las, ply = tmp / "cloud.las", tmp / "cloud.ply"
    write(las, PointCloud(xyz=xyz))
    write_ply(ply, xyz - np.floor(xyz.min(0)))
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    cmds = {"python_start": [sys.executable, "-c", "pass"],
            "lidarstat_fixed": [sys.executable, "-c", FIXED_CHILD, str(las),
                                str(tmp / "out.las"), str(tmp / "probe.json")]}
    if exe:
        cmds["cloudcompare_io"] = [exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP",
                                   "-O", "-GLOBAL_SHIFT", "AUTO", str(ply), "-C_EXPORT_FMT",
                                   "PLY", "-SAVE_CLOUDS", "FILE", str(tmp / "cc_out.ply")]
    cc_env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    run_external_cpu(cmds["lidarstat_fixed"], env=env)  # the kernel's cache, once
    runs = {k: [] for k in cmds}
    probes = []
    for _ in range(args.repeats):
        for k, cmd in cmds.items():
            runs[k].append(run_external_cpu(cmd, env=cc_env if k == "cloudcompare_io" else env))
            if k == "lidarstat_fixed":
                probe = json.loads((tmp / "probe.json").read_text())
                probe["wall_minus_cpu_seconds"] = (runs[k][-1]["seconds"]
                                                   - runs[k][-1]["cpu_seconds"])
                probes.append(probe)
    res = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "machine_shared": bool(args.shared), "points": int(xyz.shape[0]),
           "repeats": args.repeats,
           "how": "see the module docstring of benchmarks/curvature_fixed_costs.py; "
                  "whole processes, alternating, medians; cpu_seconds = user + system",
           "rows": {k: _median_run(v) for k, v in runs.items()}}
    res["rows"]["lidarstat_fixed"]["wall_beyond_cpu"] = {
        k: float(np.median([p[k] for p in probes])) for k in probes[0]}
    res["rows"]["lidarstat_fixed"]["wall_beyond_cpu"]["all"] = probes
    for k, r in res["rows"].items():
        print(f"{k}: {r['seconds']:.2f} s (cpu {r['cpu_seconds']:.2f} s)")
    for p in probes:
        print(f"  lidarstat_fixed: wall - cpu {p['wall_minus_cpu_seconds']:.2f} s, waiting "
              f"for a processor {p['runqueue_wait_seconds']:.2f} s, "
              f"{p['voluntary_switches']} voluntary switches, {p['major_faults']} major "
              f"faults, {p['write_bytes'] / 1e6:.0f} MB written")
    path = Path(args.out)
    whole = json.loads(path.read_text()) if path.exists() else {}
    whole["fixed_costs"] = res
    path.write_text(json.dumps(whole, indent=1) + "\n")
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"wrote {path} (key fixed_costs)")


if __name__ == "__main__":
    main()
