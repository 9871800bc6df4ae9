#!/usr/bin/env python
"""Ridges with their defaults on the roofs of a real AHN3 tile, and the picture.

Runs :func:`lidarstat.segment.ridges` with its defaults (the automatic scale, sigma
estimated, noise along z) on the building points (ASPRS class 6) of
``../shared/data/ahn3_amsterdam/ahn_2386_9702.laz`` and writes
``docs/figures/ridges_ahn3.png`` (top view: crest points red, ravine points blue, crease
points green, the
other roof points grey; and the radius chosen per point) and the key ``ahn3`` of
``benchmarks/results_ridges.json``. Skipped when the tile is absent.

    PYTHONPATH=src python benchmarks/ridge_ahn3.py
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TILE = HERE.parent.parent / "shared" / "data" / "ahn3_amsterdam" / "ahn_2386_9702.laz"
FIGURE = HERE.parent / "docs" / "figures" / "ridges_ahn3.png"
RESULTS = HERE / "results_ridges.json"


def main():
    if not TILE.exists():
        print("AHN3 tile not found:", TILE)
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarstat.io import read
    from lidarstat.segment import ridges

    cloud = read(TILE)
    cls = np.asarray(cloud.attributes["classification"])
    xyz = cloud.xyz[cls == 6]
    t0, c0 = time.perf_counter(), time.process_time()
    res = ridges(xyz)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(res.summary(), f"\n{dt:.1f} s")
    r = res["ridge"]
    rad = res["radius"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2), dpi=110)
    ax = axes[0]
    ax.scatter(*xyz[r == 0, :2].T, s=0.3, c="#c8c8c8", lw=0)
    ax.scatter(*xyz[r == 1, :2].T, s=1.5, c="#d62728", lw=0, label="crest")
    ax.scatter(*xyz[r == 2, :2].T, s=1.5, c="#1f77b4", lw=0, label="ravine")
    ax.scatter(*xyz[r == 3, :2].T, s=1.5, c="#2ca02c", lw=0, label="crease")
    ax.set_title("AHN3 roofs, ridges with the defaults")
    ax.legend(loc="upper right", markerscale=6)
    sc = axes[1].scatter(*xyz[:, :2].T, s=0.3, c=rad, cmap="viridis", lw=0)
    axes[1].set_title("radius chosen per point (automatic scale), m")
    fig.colorbar(sc, ax=axes[1], shrink=0.8)
    for ax in axes:
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.savefig(FIGURE, bbox_inches="tight")
    plt.close(fig)
    print("wrote", FIGURE)
    data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    data["ahn3"] = dict(tile=TILE.name, points=int(len(xyz)), seconds=round(dt, 1),
                        sigma=round(res.jets.sigma, 5), crest_points=int((r == 1).sum()),
                        ravine_points=int((r == 2).sum()),
                        crease_points=int((r == 3).sum()), lines=len(res.lines),
                        crease_lines=int(np.sum(res.lines.attributes["ridge"] == 3)),
                        crease_length=round(float(res.lines.attributes["length"][
                            res.lines.attributes["ridge"] == 3].sum()), 1),
                        crease_radius=res.params.get("crease_radius"),
                        cpu_seconds=round(cpu, 1),
                        radius_median=round(float(np.nanmedian(rad)), 3),
                        radii=[round(x, 3) for x in res.params["radii"]],
                        points_per_radius=res.params["points_per_radius"],
                        status=np.bincount(res["status"], minlength=4).tolist(),
                        machine_shared=True)
    RESULTS.write_text(json.dumps(data, indent=1, default=float))
    print("written", RESULTS)


if __name__ == "__main__":
    main()
