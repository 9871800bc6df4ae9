#!/usr/bin/env python
"""`lidarstat curvature` and `lidarstat covariance` with their defaults (no scale, no noise
option) on real airborne tiles: classes, chosen scales, times, and pictures for the method
pages.

    PYTHONPATH=src python benchmarks/real_defaults.py

Data (skipped, with a message, when ``../shared/data`` is absent): the AHN3 tile
``ahn3_amsterdam/ahn_2386_9702.laz`` and the IGN LiDAR HD tile
``ign_lidarhd_samples/870000_6618000.subset.50mx100m.las``. Each command runs as a user
would run it (``python -m lidarstat ... --summary-json``, a fresh process); the output file
is read back for the per-point fields. Writes ``benchmarks/results_real_defaults.json`` and
``docs/figures/{curvature,covariance}_{ahn3,ign}.png`` (top views). The pump scan's pictures
come from ``benchmarks/curvature_pump.py`` and ``docs/figures/make_covariance_figures.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"
FIGURES = HERE.parent / "docs" / "figures"
TILES = {"ahn3": ("AHN3 tile ahn_2386_9702 (Amsterdam)", "ahn3_amsterdam/ahn_2386_9702.laz"),
         "ign": ("IGN LiDAR HD tile 870000_6618000 (50 x 100 m)",
                 "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las")}
TYPE_COLORS = ["#bdbdbd", "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
               "#e377c2", "#17becf"]
CLASS_COLORS = ["#bdbdbd", "#7f9fbf", "#d62728", "#ff7f0e"]
CLASS_NAMES = ["undetermined", "surface", "edge", "boundary"]


def run(command, src, tmp):
    out = Path(tmp) / f"{command}.laz"
    js = Path(tmp) / f"{command}.json"
    env = dict(os.environ)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "lidarstat", command, str(src), str(out),
                    "--summary-json", str(js), "-q"], check=True, env=env)
    seconds = time.perf_counter() - t0
    from lidarstat.io import read

    cloud = read(out)
    return cloud, json.loads(js.read_text()), seconds


def _field(cloud, name):
    return np.asarray(cloud[name])


def picture(path, xyz, values, colors, names, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    size = max(0.1, min(2.0, 4e4 / len(xyz)))
    order = np.argsort(xyz[:, 2])  # higher points drawn last (roofs over ground)
    xy = xyz[order, :2] - xyz[:, :2].min(axis=0)
    v = values[order]
    for c, name in enumerate(names):
        m = v == c
        if m.any():
            ax.scatter(*xy[m].T, s=size, c=colors[c], label=f"{name} ({m.mean():.0%})",
                       linewidths=0)
    ax.set_aspect("equal")
    ax.set_xlabel("m")
    ax.set_title(title, fontsize=10)
    ax.legend(markerscale=8 / max(size, 0.1) ** 0.5, loc="upper right", fontsize=8)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    print("wrote", path)


def main():
    from lidarstat.features import SurfaceType

    if not DATA.is_dir():
        print(f"skipped: {DATA} not found")
        return
    results = {"machine_shared": True,
               "note": "2 cores shared with other jobs: the seconds are noisy",
               "tiles": {}}
    type_names = [t.name.lower() for t in SurfaceType]
    for key, (title, rel) in TILES.items():
        src = DATA / rel
        if not src.is_file():
            print(f"skipped: {src} not found")
            continue
        entry = {"file": rel}
        with tempfile.TemporaryDirectory() as tmp:
            cloud, summ, sec = run("curvature", src, tmp)
            xyz = np.asarray(cloud.xyz)
            st = _field(cloud, "surface_type").astype(int)
            entry["points"] = int(len(xyz))
            entry["curvature"] = {
                "seconds": round(sec, 1), "params": summ.get("params", summ),
                "surface_type_share": {n: round(float(np.mean(st == i)), 4)
                                       for i, n in enumerate(type_names)}}
            picture(FIGURES / f"curvature_{key}.png", xyz, st, TYPE_COLORS, type_names,
                    f"{title}: lidarstat curvature, defaults (surface type)")
            cloud, summ, sec = run("covariance", src, tmp)
            pc = _field(cloud, "point_class").astype(int)
            kopt = _field(cloud, "OptimalKNN")
            entry["covariance"] = {
                "seconds": round(sec, 1), "params": summ.get("params", summ),
                "class_share": {n: round(float(np.mean(pc == i)), 4)
                                for i, n in enumerate(CLASS_NAMES)},
                "OptimalKNN_p10_p50_p90": [float(q) for q in np.percentile(kopt, [10, 50, 90])],
                "OptimalKNN_share_50": round(float(np.mean(kopt == kopt.max())), 4)}
            picture(FIGURES / f"covariance_{key}.png", np.asarray(cloud.xyz), pc,
                    CLASS_COLORS, CLASS_NAMES,
                    f"{title}: lidarstat covariance, defaults (class)")
        results["tiles"][key] = entry
        print(json.dumps(entry, indent=1, default=str))
    (HERE / "results_real_defaults.json").write_text(json.dumps(results, indent=1, default=str))


if __name__ == "__main__":
    main()
