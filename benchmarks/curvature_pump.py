#!/usr/bin/env python
"""`curvature` with its defaults on the real pump scan (terrestrial, scanner at the
origin): surface types, the chosen radii and the time; a picture for the method page.

    PYTHONPATH=src python benchmarks/curvature_pump.py

Writes ``benchmarks/results_curvature_pump.json`` and
``docs/figures/curvature_pump_surface_type.png``; skipped (a message) when
``../shared/data/e57_pump_tls/pump_scan.laz`` is absent.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PUMP = HERE.parent.parent / "shared" / "data" / "e57_pump_tls" / "pump_scan.laz"
FIGURE = HERE.parent / "docs" / "figures" / "curvature_pump_surface_type.png"
COLORS = ["#bdbdbd", "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
          "#e377c2", "#17becf"]


def main():
    from lidarstat.features import SurfaceType, curvature
    from lidarstat.io import read

    if not PUMP.is_file():
        print(f"skipped: {PUMP} not found")
        return
    xyz = read(PUMP).xyz
    curvature(xyz[:5000], radius=0.05, sigma=0.001, sensor=(0.0, 0.0, 0.0))  # compile first
    t0 = time.perf_counter()
    res = curvature(xyz, sensor=(0.0, 0.0, 0.0))  # the defaults; the scanner is the origin
    seconds = time.perf_counter() - t0
    st = res["surface_type"]
    counts = {t.name.lower(): float(np.mean(st == t)) for t in SurfaceType}
    radii, n_at = np.unique(res["radius"], return_counts=True)
    out = {"file": "e57_pump_tls/pump_scan.laz", "points": int(xyz.shape[0]),
           "seconds": seconds, "params": res.params, "surface_type_share": counts,
           "radius_share": {f"{r:.4g}": float(c / st.size) for r, c in zip(radii, n_at)},
           "note": "shared machine (2 cores, other jobs running)"}
    (HERE / "results_curvature_pump.json").write_text(json.dumps(out, indent=1, default=str))
    print(json.dumps(out, indent=1, default=str))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 6.5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=20, azim=-120)
    ax.set_axis_off()
    ax.set_title("pump scan, lidarstat curvature with its defaults: surface type")
    for t in SurfaceType:
        m = st == t
        if m.any():
            ax.scatter(*xyz[m].T, s=0.15, c=COLORS[int(t)], label=t.name.lower(), linewidths=0)
    lo, hi = np.percentile(xyz, [0.5, 99.5], axis=0)
    c, h = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    ax.set_zlim(c[2] - h, c[2] + h)
    ax.legend(markerscale=20, loc="upper left", fontsize=8)
    fig.savefig(FIGURE, bbox_inches="tight")
    plt.close(fig)
    print("wrote", FIGURE)


if __name__ == "__main__":
    main()
