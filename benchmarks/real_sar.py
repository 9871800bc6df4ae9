"""SAR-FS roof segmentation on the real clouds of ../shared/data: figures and figures of merit.

    python benchmarks/real_sar.py [--out docs/figures]

For each file: ``segment_sar`` with the automatic bandwidth, a top view coloured by
segment (PNG in ``--out``), the number of segments, the share of producer building points
(class 6) that lie in a planar unit, and for AHN3 Amsterdam (BAG footprints) the share of
footprint area covered by roof segments (1 m cells whose centre is inside a footprint and
that hold a point of a segment lying mostly inside footprints; footprints drawn in black).

Writes ``benchmarks/results_real_sar.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FILES = {
    "ahn3_amsterdam_2386_9702": "ahn3_amsterdam/ahn_2386_9702.laz",
    "ahn3_amsterdam_2397_9705": "ahn3_amsterdam/ahn_2397_9705.laz",
    "ahn3_delft_cropped_2": "ahn3_delft_3dfier/ahn3_cropped_2.laz",
    "ign_lidarhd_870000_6618000": "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las",
    "pdal_sample_c": "pdal_testdata/sample_c.las",
}


def _footprints():
    import csv

    path = DATA / "ahn3_amsterdam" / "bag_buildings_demo.csv"
    with open(path) as fh:
        return [np.array(json.loads(r["polygon"])) for r in csv.DictReader(fh)]


def footprint_coverage(xyz, labels, polys, cell=1.0):
    """Share of footprint area (inside the cloud's extent) covered by roof segments."""
    from matplotlib.path import Path as MPath

    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0] + cell / 2, hi[0], cell),
                         np.arange(lo[1] + cell / 2, hi[1], cell))
    centres = np.c_[gx.ravel(), gy.ravel()]
    inside_cell = np.zeros(len(centres), bool)
    inside_pt = np.zeros(len(xyz), bool)
    for p in polys:
        if (p[:, 0].max() < lo[0] or p[:, 0].min() > hi[0] or p[:, 1].max() < lo[1]
                or p[:, 1].min() > hi[1]):
            continue
        mp = MPath(p)
        inside_cell |= mp.contains_points(centres)
        inside_pt |= mp.contains_points(xyz[:, :2])
    n = int(labels.max())
    frac = np.bincount(labels, weights=inside_pt, minlength=n + 1) / np.maximum(
        np.bincount(labels, minlength=n + 1), 1)
    roof = (labels > 0) & (frac[labels] > 0.5)
    ij = np.floor((xyz[roof, :2] - lo) / cell).astype(int)
    covered = np.zeros(gx.shape, bool)
    covered[np.clip(ij[:, 1], 0, gx.shape[0] - 1), np.clip(ij[:, 0], 0, gx.shape[1] - 1)] = True
    cov = covered.ravel()[inside_cell].mean() if inside_cell.any() else float("nan")
    return float(cov), float(inside_cell.sum() * cell * cell)


def figure(xyz, labels, path, title, polys=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(0)
    colours = rng.uniform(0.15, 0.95, (int(labels.max()) + 1, 3))
    colours[0] = (0.8, 0.8, 0.8)
    span = np.ptp(xyz[:, :2], axis=0)
    fig, ax = plt.subplots(figsize=(7, max(3.0, 7 * span[1] / max(span[0], 1e-9))), dpi=110)
    o = np.argsort(xyz[:, 2])
    ax.scatter(xyz[o, 0], xyz[o, 1], c=colours[labels[o]], s=0.6, linewidths=0)
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    for p in polys or []:
        if p[:, 0].max() < lo[0] or p[:, 0].min() > hi[0] or p[:, 1].max() < lo[1] \
                or p[:, 1].min() > hi[1]:
            continue
        ax.plot(p[:, 0], p[:, 1], color="k", linewidth=0.6)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def main(argv=None):
    from lidarstat import read
    from lidarstat.segment import segment_sar

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" /
                                         "figures"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    polys = _footprints()
    results = {}
    for name, rel in FILES.items():
        path = DATA / rel
        if not path.is_file():
            print(f"skip {name}: {path} not found")
            continue
        cloud = read(path)
        cls = cloud.attributes.get("classification")
        keep = np.ones(len(cloud.xyz), bool) if cls is None else ~np.isin(cls, [7, 18])
        xyz = cloud.xyz[keep]
        t = time.perf_counter()
        seg = segment_sar(xyz)
        dt = time.perf_counter() - t
        r = {"points": int(len(xyz)), "seconds": round(dt, 1), "segments": seg.n_segments,
             "bandwidth": round(seg.params["radius"], 3),
             "sigma": round(seg.params["sigma"], 4),
             "sigma_local": round(seg.params["sigma_local"], 4),
             "sigma_units": round(seg.params["sigma_units"], 4),
             "sigma_passes": seg.params["sigma_passes"],
             "in_segments": round(float(np.mean(seg.labels > 0)), 3),
             # goodness of fit: segments made by splits, segments still rejected, and
             # the median residual scale against the noise
             "gof_splits": seg.params.get("splits"),
             "gof_rejected": int(np.count_nonzero(seg.table["gof_p"] <
                                                  seg.params["gof_alpha"])),
             "scale_ratio_median": round(float(np.nanmedian(seg.table["scale_ratio"])), 3)
             if seg.n_segments else None,
             "outliers_removed": int(np.count_nonzero(seg.fields["surface_outlier"]))}
        if cls is not None:
            b = cls[keep] == 6
            r["building_points_in_segments"] = round(float(np.mean(seg.labels[b] > 0)), 3)
        if name.startswith("ahn3_amsterdam"):
            r["footprint_coverage"], r["footprint_area_m2"] = footprint_coverage(
                xyz, seg.labels, polys)
        amsterdam = name.startswith("ahn3_amsterdam")
        figure(xyz, seg.labels, out / f"sar_{name}.png",
               f"{name}: {seg.n_segments} SAR-FS units (b = {r['bandwidth']} m, "
               f"sigma = {r['sigma']} m)" + (", BAG footprints" if amsterdam else ""),
               polys if amsterdam else None)
        results[name] = r
        print(name, json.dumps(r), flush=True)
    Path(__file__).with_name("results_real_sar.json").write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
