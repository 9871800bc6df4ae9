"""Picture of the ridges found with the defaults on the real pump scan (seed 000).

    PYTHONPATH=src python docs/figures/make_ridge_figures.py

Runs :func:`lidarstat.segment.ridges` with its defaults (the automatic scale, sigma
estimated, noise along the range from the scanner at the origin: the scan's pose is the
identity) on ``../shared/data/e57_pump_tls/pump_scan.laz`` and writes
``docs/figures/ridges_pump.png`` (oblique view: crest points red, ravine points blue,
the other points grey; and the chosen radius per point) and the key ``pump`` of
``benchmarks/results_ridges.json`` (counts, radii, seconds). Skipped when the scan is
absent.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

DOCS = Path(__file__).resolve().parent
PUMP = DOCS.parent.parent / ".." / "shared" / "data" / "e57_pump_tls" / "pump_scan.laz"
RESULTS = DOCS.parent.parent / "benchmarks" / "results_ridges.json"


def main():
    if not PUMP.exists():
        print("pump scan not found:", PUMP)
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarstat.io import read
    from lidarstat.segment import ridges

    cloud = read(PUMP)
    xyz = cloud.xyz
    t0 = time.perf_counter()
    res = ridges(xyz, sensor=(0.0, 0.0, 0.0), creases=False)
    dt = time.perf_counter() - t0
    print(res.summary())
    r = res["ridge"]
    rad = res["radius"]
    fig = plt.figure(figsize=(13, 6.5), dpi=110)
    for p, (title, colour) in enumerate([
            ("ridges with the defaults: crest red, ravine blue", None),
            ("radius chosen per point (automatic scale), m", rad)]):
        ax = fig.add_subplot(1, 2, p + 1, projection="3d")
        ax.view_init(elev=25, azim=-60)
        ax.set_axis_off()
        ax.set_title(title)
        if colour is None:
            ax.scatter(*xyz[r == 0].T, s=0.05, c="#c8c8c8", lw=0)
            ax.scatter(*xyz[r == 1].T, s=0.6, c="#d62728", lw=0)
            ax.scatter(*xyz[r == 2].T, s=0.6, c="#1f77b4", lw=0)
        else:
            sc = ax.scatter(*xyz.T, s=0.05, c=colour, cmap="viridis", lw=0)
            fig.colorbar(sc, ax=ax, shrink=0.6)
        lo, hi = np.percentile(xyz, [0.5, 99.5], axis=0)
        c, h = (lo + hi) / 2, (hi - lo).max() / 2
        ax.set_xlim(c[0] - h, c[0] + h)
        ax.set_ylim(c[1] - h, c[1] + h)
        ax.set_zlim(c[2] - h, c[2] + h)
    out = DOCS / "ridges_pump.png"
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)
    print("wrote", out)
    data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    data["pump"] = dict(points=int(len(xyz)), seconds=round(dt, 1),
                        sigma=res.jets.sigma, crest_points=int((r == 1).sum()),
                        ravine_points=int((r == 2).sum()), lines=len(res.lines),
                        umbilic=int(res["umbilic"].sum()),
                        radius_median=float(np.nanmedian(rad)),
                        radii=res.params["radii"],
                        points_per_radius=res.params["points_per_radius"],
                        status=np.bincount(res["status"], minlength=4).tolist())
    RESULTS.write_text(json.dumps(data, indent=1, default=float))
    print("written", RESULTS)


if __name__ == "__main__":
    main()
