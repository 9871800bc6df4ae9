"""SAR-FS roof segmentation on the real clouds of ../shared/data, with CloudCompare's RANSAC.

    python benchmarks/real_sar.py [--out docs/figures] [--files NAME ...] [--no-anchor]

For each file: ``segment_sar`` with its defaults (automatic bandwidth and noise), a top
view coloured by segment (PNG in ``--out``), the number of segments, the share of
producer building points (class 6) that lie in a planar unit, and for AHN3 Amsterdam
(BAG footprints) the share of footprint area covered by roof segments (1 m cells whose
centre is inside a footprint and that hold a point of a segment lying mostly inside
footprints; footprints drawn in black).

The roof table (the four AHN3 files, key ``roof``): the share of building points in
units that are mostly (> 50 %) building points, the purity of those units (their share
of building points), their number and the time, for lidarstat and, in the same run,
CloudCompare's RANSAC shape detection (qRANSAC_SD, Schnabel et al. 2007; planes only;
epsilon 0.05 m, bitmap epsilon 0.5 m, 30 support points, 25 degrees normal deviation,
probability 0.01: the noise and minimum size lidarstat uses, the spacing of AHN3; and
again with 12 support points, lidarstat's smallest tested plane), run headless by ``CloudCompare -SILENT`` under ``QT_QPA_PLATFORM=offscreen``; a figure per
file with both. ``causes`` breaks the building points lidarstat leaves out down by
cause. The machine may be shared: times are of one run.

Writes ``benchmarks/results_real_sar.json``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FILES = {
    "ahn3_amsterdam_2386_9702": "ahn3_amsterdam/ahn_2386_9702.laz",
    "ahn3_amsterdam_2397_9705": "ahn3_amsterdam/ahn_2397_9705.laz",
    "ahn3_delft_cropped_1": "ahn3_delft_3dfier/ahn3_cropped_1.laz",
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


#: CloudCompare RANSAC settings (see the module docstring).
RANSAC = {"EPSILON_ABSOLUTE": 0.05, "BITMAP_EPSILON_ABSOLUTE": 0.5, "SUPPORT_POINTS": 30,
          "MAX_NORMAL_DEV": 25, "PROBABILITY": 0.01}
#: The same with lidarstat's smallest tested plane (k = 12 points) as the support.
RANSAC_SMALL = {**RANSAC, "SUPPORT_POINTS": 12}


def roof_score(labels, building):
    """Share of building points in units mostly of building points, their purity, count."""
    labels = np.asarray(labels, dtype=np.int64)
    n = int(labels.max()) if labels.size else 0
    frac = np.bincount(labels, weights=building, minlength=n + 1) / np.maximum(
        np.bincount(labels, minlength=n + 1), 1)
    good = (labels > 0) & (frac[labels] > 0.5)
    return {"building_share": round(float(good[building].mean()), 3),
            "purity": round(float(building[good].mean()), 4) if good.any() else None,
            "planes": int(np.count_nonzero(frac[1:] > 0.5))}, good


def causes(xyz, building, labels, good, seg, stages=True):
    """Building points outside the building units, by cause: in a unit mostly of other
    points; on no local plane (its 12 nearest points) at the noise along the normal of
    the second stage (global sigma_z, sigma_h), steep (normal more than 60 degrees from
    vertical: walls, facade details, steep roofs) or not; on such a local plane but in
    no unit (steep or not)."""
    from lidarstat.neighbors import knn_neighbors
    from lidarstat.segment._sar_planes import _local_pca, noise_along_normal
    from lidarstat.stats import chi2_critical

    k = seg.params["planes_k"]
    P = xyz - xyz.min(axis=0)
    nbr = knn_neighbors(P, k).indices.reshape(-1, k)
    lam, vec = _local_pca(P, nbr)
    nz = np.abs(vec[:, 2, 0])
    sn = noise_along_normal(nz, seg.params["planes_sigma"], seg.params["planes_sigma_h"])
    planar = lam[:, 0] <= chi2_critical(seg.params["alpha"], k - 3) * sn ** 2
    steep = nz < np.cos(np.radians(60.0))
    out = building & ~good
    free = out & (labels == 0)
    nb = int(building.sum())
    r = {"building_points": nb, "left_out": int(out.sum()),
         "in_units_mostly_other": int((out & (labels > 0)).sum()),
         "not_planar_steep": int((free & ~planar & steep).sum()),
         "not_planar_other": int((free & ~planar & ~steep).sum()),
         "planar_steep_in_no_unit": int((free & planar & steep).sum()),
         "planar_gentle_in_no_unit": int((free & planar & ~steep).sum())}
    st = np.asarray(seg.table["stage"])
    s1 = int(np.count_nonzero(st == 1))
    if not stages:  # scoring the SAR stage alone
        return r
    r["stage1_share"] = round(float((good & (labels > 0) & (labels <= s1))[building].mean()), 3)
    r["stage2_share"] = round(float((good & (labels > s1))[building].mean()), 3)
    return r


def cloudcompare_ransac(xyz, workdir, settings=None):
    """Plane labels (0: none) of CloudCompare's RANSAC shape detection, and its seconds."""
    import glob
    import os
    import shutil
    import subprocess

    exe = shutil.which("CloudCompare")
    if exe is None:
        return None, None
    wd = Path(workdir)
    shutil.rmtree(wd, ignore_errors=True)
    (wd / "out").mkdir(parents=True)
    o = xyz.min(axis=0)
    np.savetxt(wd / "in.txt", np.c_[xyz - o, np.arange(len(xyz))], fmt="%.3f %.3f %.3f %d")
    args = [exe, "-SILENT", "-AUTO_SAVE", "OFF", "-C_EXPORT_FMT", "ASC", "-O",
            str(wd / "in.txt"), "-RANSAC"]
    for k, v in (settings or RANSAC).items():
        args += [k, str(v)]
    args += ["ENABLE_PRIMITIVE", "PLANE", "OUTPUT_INDIVIDUAL_SUBCLOUDS", "OUT_CLOUD_DIR",
             str(wd / "out")]
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    t = time.perf_counter()
    subprocess.run(args, env=env, check=True, capture_output=True, timeout=1800)
    dt = time.perf_counter() - t
    labels = np.zeros(len(xyz), np.int64)
    for i, f in enumerate(sorted(glob.glob(str(wd / "out" / "*.asc"))), start=1):
        a = np.loadtxt(f, comments="//", ndmin=2)
        labels[a[:, 6].astype(np.int64)] = i  # x y z r g b index nx ny nz
    shutil.rmtree(wd, ignore_errors=True)
    return labels, dt


def figure_pair(xyz, panels, path, polys=None, show=None):
    """Side-by-side top views (lidarstat, anchor) of the points `show` (the producer's
    building points), each coloured by unit (grey: in no unit that is mostly building)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    span = np.ptp(xyz[:, :2], axis=0)
    h = max(3.0, 6 * span[1] / max(span[0], 1e-9))
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), h), dpi=100)
    show = np.ones(len(xyz), bool) if show is None else show
    o = np.flatnonzero(show)[np.argsort(xyz[show, 2])]
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    for ax, (labels, title) in zip(np.atleast_1d(axes), panels):
        rng = np.random.default_rng(0)
        colours = rng.uniform(0.1, 0.9, (int(labels.max()) + 1, 3))
        _, good = roof_score(labels, show)
        lab = np.where(good, labels, 0)
        colours[0] = (0.8, 0.8, 0.8)
        ax.scatter(xyz[o, 0], xyz[o, 1], c=colours[lab[o]], s=1.2, linewidths=0)
        for p in polys or []:
            if p[:, 0].max() < lo[0] or p[:, 0].min() > hi[0] or p[:, 1].max() < lo[1] \
                    or p[:, 1].min() > hi[1]:
                continue
            ax.plot(p[:, 0], p[:, 1], color="k", linewidth=0.5)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=9)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


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
    from lidarstat.segment._sar_stages import add_planes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" /
                                         "figures"))
    ap.add_argument("--files", nargs="*", default=list(FILES), choices=list(FILES))
    ap.add_argument("--no-anchor", action="store_true", help="skip CloudCompare")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    polys = _footprints()
    results = {}
    res_path = Path(__file__).with_name("results_real_sar.json")
    if res_path.is_file():
        results = json.loads(res_path.read_text())
    for name in args.files:
        rel = FILES[name]
        path = DATA / rel
        if not path.is_file():
            print(f"skip {name}: {path} not found")
            continue
        cloud = read(path)
        cls = cloud.attributes.get("classification")
        keep = np.ones(len(cloud.xyz), bool) if cls is None else ~np.isin(cls, [7, 18])
        xyz = cloud.xyz[keep]
        t = time.perf_counter()
        # segment_sar with its defaults, run as its two stages to score the first alone:
        # the SAR units, then the planes in their own frame (as segment_sar does)
        sar = segment_sar(xyz, planes=False)
        t1 = time.perf_counter() - t
        su = sar.params["sigma_units"]
        seg = add_planes(xyz, sar, sigma=su if np.isfinite(su) else sar.params["sigma"],
                         alpha=sar.params["alpha"], edge_alpha=sar.params["edge_alpha"],
                         min_points=sar.params["min_points"],
                         gof_alpha=sar.params["gof_alpha"])
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
        r["planes_stage2"] = int(np.count_nonzero(seg.table["stage"] == 2))
        r["planes_sigma_h"] = round(seg.params["planes_sigma_h"], 4)
        if name.startswith("ahn3"):
            score, good = roof_score(seg.labels, b)
            roof = {"lidarstat": {**score, "seconds": r["seconds"]},
                    "sar_stage": {**roof_score(sar.labels, b)[0], "seconds": round(t1, 1)},
                    "causes": causes(xyz, b, seg.labels, good, seg)}
            sar_good = roof_score(sar.labels, b)[1]
            roof["causes_sar_stage"] = causes(xyz, b, sar.labels, sar_good, seg,
                                              stages=False)
            st = np.asarray(seg.table["stage"])
            inb = np.bincount(seg.labels, weights=b, minlength=seg.n_segments + 1)[1:] > \
                0.5 * np.bincount(seg.labels, minlength=seg.n_segments + 1)[1:]
            roof["lidarstat"]["plane_test_rejects"] = int(np.count_nonzero(
                inb & (np.asarray(seg.table["gof_p"]) < seg.params["gof_alpha"])))
            roof["lidarstat"]["planes_by_stage"] = [int(np.count_nonzero(inb & (st == 1))),
                                                    int(np.count_nonzero(inb & (st == 2)))]
            roof["lidarstat"]["normal_se_deg_median"] = round(float(np.nanmedian(
                np.asarray(seg.table["normal_se_deg"])[inb])), 3)
            panels = [(seg.labels, f"lidarstat: {score['building_share']:.1%} of building "
                                   f"points in {score['planes']} units, purity "
                                   f"{score['purity']:.1%}")]
            if not args.no_anchor:
                for key, settings in (("cloudcompare_ransac", RANSAC),
                                      ("cloudcompare_ransac_12", RANSAC_SMALL)):
                    cc, cc_dt = cloudcompare_ransac(
                        xyz, Path(tempfile.gettempdir()) / f"lidarstat_cc_{name}", settings)
                    if cc is None:
                        break
                    sc, _ = roof_score(cc, b)
                    roof[key] = {**sc, "seconds": round(cc_dt, 1), "settings": settings}
                    if key == "cloudcompare_ransac_12":
                        panels.append((cc, f"CloudCompare RANSAC (12 support points): "
                                           f"{sc['building_share']:.1%} in {sc['planes']} "
                                           f"planes, purity {sc['purity']:.1%}"))
            r["roof"] = roof
            figure_pair(xyz, panels, out / f"sar_roofs_{name}.png",
                        polys if name.startswith("ahn3_amsterdam") else None, show=b)
        if name.startswith("ahn3_amsterdam"):
            r["footprint_coverage"], r["footprint_area_m2"] = footprint_coverage(
                xyz, seg.labels, polys)
        if not name.startswith("ahn3"):  # the AHN3 files have their roof figure
            figure(xyz, seg.labels, out / f"sar_{name}.png",
                   f"{name}: {seg.n_segments} units (b = {r['bandwidth']} m, "
                   f"sigma = {r['sigma']} m)")
        results[name] = r
        results["machine_shared"] = True  # times are of one run on a shared machine
        print(name, json.dumps(r), flush=True)
        res_path.write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
