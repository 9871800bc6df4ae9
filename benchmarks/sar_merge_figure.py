"""Roof planes of the SAR second stage before and after the tested merge of adjacent grown
planes, on a 40 x 40 m crop of AHN3 Amsterdam 2386_9702.

    python benchmarks/sar_merge_figure.py [--out docs/figures/sar_plane_merge.png]

``segment_sar`` with its defaults is run as its two stages (the SAR units, then the
planes in their own frame, :func:`lidarstat.segment._sar_stages.add_planes`) with the
merge off (``merge_alpha=None``) and on (the default); the producer's building points
(class 6) are drawn coloured by unit. Writes ``benchmarks/results_sar_merge.json``: per
run the units that are mostly building points, the share of building points in them,
their purity and the merges.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"
FILE = "ahn3_amsterdam/ahn_2386_9702.laz"
BOX = (119295.0, 485115.0, 119335.0, 485155.0)  # E, N min and max of the crop (m)


def main(argv=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from real_sar import roof_score

    from lidarstat import read
    from lidarstat.segment import segment_sar
    from lidarstat.segment._sar_stages import add_planes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE.parent / "docs" / "figures" /
                                         "sar_plane_merge.png"))
    args = ap.parse_args(argv)
    path = DATA / FILE
    if not path.is_file():
        print(f"skip: {path} not found")
        return None
    cloud = read(path)
    cls = np.asarray(cloud.attributes["classification"])
    xyz = cloud.xyz
    box = ((xyz[:, 0] >= BOX[0]) & (xyz[:, 1] >= BOX[1]) & (xyz[:, 0] < BOX[2])
           & (xyz[:, 1] < BOX[3]) & ~np.isin(cls, [7, 18]))
    xyz, building = xyz[box], cls[box] == 6
    sar = segment_sar(xyz, planes=False)
    su = sar.params["sigma_units"]
    kw = {"sigma": su if np.isfinite(su) else sar.params["sigma"],
          "alpha": sar.params["alpha"], "edge_alpha": sar.params["edge_alpha"],
          "min_points": sar.params["min_points"], "gof_alpha": sar.params["gof_alpha"]}
    runs = {"no_merge": add_planes(xyz, sar, merge_alpha=None, **kw),
            "merge": add_planes(xyz, sar, **kw)}
    results = {"file": FILE, "box": BOX, "points": len(xyz),
               "building_points": int(building.sum())}
    before, after = runs["no_merge"].labels, runs["merge"].labels
    # the units the merge made: an after-unit holding points of two or more before-units
    pairs = np.unique(np.c_[after, before][(after > 0) & (before > 0)], axis=0)
    joined = np.flatnonzero(np.bincount(pairs[:, 0], minlength=after.max() + 1) >= 2)
    show = np.isin(after, joined) & building
    results["units_made_by_merges"] = int(joined.size)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6))
    o = np.flatnonzero(building)
    for ax, (key, seg) in zip(axes, runs.items()):
        score, _ = roof_score(seg.labels, building)
        results[key] = {**score, "merged": seg.params.get("planes_merged", 0)}
        colours = np.random.default_rng(1).uniform(0.1, 0.9, (int(seg.labels.max()) + 1, 3))
        col = np.where(show[o, None], colours[seg.labels[o]], 0.85)
        ax.scatter(xyz[o, 0] - BOX[0], xyz[o, 1] - BOX[1], c=col, s=2, linewidths=0)
        ax.set_aspect("equal")
        ax.set_xlabel("E (m)")
        ax.set_title(f"{'merge' if key == 'merge' else 'no merge'}: {score['planes']} units, "
                     f"{score['building_share']:.1%} of building points, purity "
                     f"{score['purity']:.1%}", fontsize=9)
    axes[0].set_ylabel("N (m)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    out = HERE / "results_sar_merge.json"
    results["machine_shared"] = True
    out.write_text(json.dumps(results, indent=2))
    print(json.dumps(results))
    return results


if __name__ == "__main__":
    main()
