#!/usr/bin/env python
"""`moments` on the producer-classified real files, scored against the producers' classes.

For every file: ground/object Type I, Type II and total error against the producer's
ground class (2), building and vegetation recall/precision where the producer has those
classes, and run time. Roads (class 11) are scored against map layers, among the
producer's ground points:

* AHN3 Delft (derived/ files with the BGT map layer): among ground points inside the BGT
  crop on road (layer 2), vegetated (4) or unvegetated (5) land, the reference road is
  layer 2. In this crop 143 of the 151 BGT road polygons are *open* pavement (concrete
  pavers, fired-clay bricks, tiles; ``bgt/bgt_wegdeel.sqlite``, ``surfacematerial``),
  not asphalt, so the road is not much darker than the land around it;
* AHN3 Amsterdam: the reference road is every ground point inside a polygon of
  ``bgt_roads_demo.csv`` (carriageway, parking, cycle path; mostly asphalt), needs
  ``shapely``.

``oracle_f1`` is the best F1 any single threshold on the same smoothed intensity could
reach (chosen with the reference): the ceiling of an intensity split on that file.
Producer classes are not checked truth: they are the producer's semi-automatic labels.
Producer noise (7, 18), water (9) and withheld/overlap codes above 18 are left out.
All files run with the command's default parameters (one parameter set).

Usage::

    python benchmarks/real_moments.py --out benchmarks/results_real_moments.json
    python benchmarks/real_moments.py --files pdal_testdata/autzen_trim.laz   # one file
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from lidarstat.classify import filter_errors, moments
from lidarstat.io import linear_units, read
from lidarstat.segment import binary_scores

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: The producer-classified AHN3 and IGN files (ground, buildings: buildings.py and
#: ground_filters.py score the same files).
PRODUCER_FILES = [
    "ahn3_amsterdam/ahn_2386_9702.laz",
    "ahn3_amsterdam/ahn_2397_9705.laz",
    "ahn3_delft_3dfier/derived/ahn3_cropped_1_bgt.laz",
    "ahn3_delft_3dfier/derived/ahn3_cropped_2_bgt.laz",
    "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las",
    "ign_lidarhd_samples/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz",
]
FILES = PRODUCER_FILES + [
    "laspy_testdata/file_with_both_wkt_and_geotiff_vlrs.las",
    "pdal_testdata/autzen_trim.laz",
    "pdal_testdata/las_with_several_extra_byte_bloc.laz",
    "lidR/Topography.laz",
]
LEFT_OUT = (7, 9, 18)
AMSTERDAM_ROADS = "ahn3_amsterdam/bgt_roads_demo.csv"


def amsterdam_roads(xy) -> np.ndarray | None:
    """Points inside a BGT road polygon of the Amsterdam demo layer (None without shapely)."""
    try:
        import shapely
    except ImportError:
        return None
    import csv

    inside = np.zeros(len(xy), bool)
    pts = shapely.points(xy[:, 0], xy[:, 1])
    with open(DATA / AMSTERDAM_ROADS, newline="") as fh:
        for row in csv.DictReader(fh):
            inside |= shapely.contains(shapely.Polygon(json.loads(row["polygon"])), pts)
    return inside


def oracle_f1(values, truth) -> float:
    """Best F1 of ``values <= t`` against `truth` over every threshold t."""
    o = np.argsort(values, kind="stable")
    tp = np.cumsum(truth[o])
    fp = np.cumsum(~truth[o])
    f1 = 2 * tp / (tp + fp + truth.sum())
    return float(f1.max())


def road_scores(row, cls, xy, intensity, ground_ref, truth_road, scored):
    """Road precision / recall / F1 of class 11 among `scored` producer-ground points."""
    from lidarstat.classify._roads import cell_median

    sel = ground_ref & scored
    r = binary_scores(cls[sel] == 11, truth_road[sel])
    g = np.flatnonzero(ground_ref)
    smooth = cell_median(xy[g], intensity[g])
    in_sel = sel[g]
    row.update(road_points=int(truth_road[sel].sum()), road_precision=_pct(r["precision"]),
               road_recall=_pct(r["recall"]), road_f1=_pct(r["f1"]),
               road_oracle_f1=_pct(oracle_f1(smooth[in_sel], truth_road[g][in_sel])))


def _pct(x):
    return None if x != x else round(100.0 * x, 2)


def score(path: Path) -> dict:
    cloud = read(path)
    a = cloud.attributes
    ref = np.asarray(a["classification"]).astype(int)
    kw = {}
    if "number_of_returns" in a:
        kw = dict(number_of_returns=a["number_of_returns"], return_number=a["return_number"])
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        units = linear_units(cloud.crs, header=cloud.las_header, source=str(path))
        res = moments(cloud.xyz, a.get("intensity"), source=str(path), units=units,
                      **kw)
    seconds = time.perf_counter() - t0
    cls = res.classification.astype(int)
    keep = ~np.isin(ref, LEFT_OUT) & (ref < 19)
    e = filter_errors(res.ground[keep], ref[keep] == 2)
    row = {"file": str(path.relative_to(DATA)), "points": int(len(ref)),
           "scored": int(keep.sum()), "seconds": round(seconds, 2), "unit": units.name,
           "type_i": _pct(e.type_i), "type_ii": _pct(e.type_ii), "total": _pct(e.total),
           "kappa": round(e.kappa, 3)}
    if np.any(ref[keep] == 6):
        b = binary_scores(cls[keep] == 6, ref[keep] == 6)
        row.update(building_precision=_pct(b["precision"]), building_recall=_pct(b["recall"]))
    if np.any(np.isin(ref[keep], (3, 4, 5))):
        v = binary_scores(np.isin(cls[keep], (3, 4, 5)), np.isin(ref[keep], (3, 4, 5)))
        row.update(vegetation_precision=_pct(v["precision"]),
                   vegetation_recall=_pct(v["recall"]))
    inten = a.get("intensity")
    if "bgt_layer" in a and inten is not None:
        layer = np.asarray(a["bgt_layer"]).astype(int)
        road_scores(row, cls, cloud.xyz[:, :2], np.asarray(inten, float), ref == 2,
                    layer == 2, np.isin(layer, (2, 4, 5)))
    elif path.parent.name == "ahn3_amsterdam" and inten is not None:
        truth = amsterdam_roads(cloud.xyz[:, :2])
        if truth is not None:
            road_scores(row, cls, cloud.xyz[:, :2], np.asarray(inten, float), ref == 2,
                        truth, np.ones(len(ref), bool))
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--files", nargs="+", default=FILES,
                    help="files under ../shared/data to score (default: all of them)")
    ap.add_argument("--only", default=None, help="run only the files whose path holds this")
    args = ap.parse_args()
    rows = []
    for rel in args.files:
        if args.only and args.only not in rel:
            continue
        path = DATA / rel
        if not path.is_file():
            print(f"skipped (not found): {path}")
            continue
        rows.append(score(path))
        print(json.dumps(rows[-1]), flush=True)
    print("\n| file | points | Type I % | Type II % | total % | kappa | building P/R % |"
          " vegetation P/R % | road P/R/F1 (oracle F1) % | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        bld = (f"{r['building_precision']}/{r['building_recall']}"
               if "building_recall" in r else "-")
        veg = (f"{r['vegetation_precision']}/{r['vegetation_recall']}"
               if "vegetation_recall" in r else "-")
        road = (f"{r['road_precision']}/{r['road_recall']}/{r['road_f1']} "
                f"({r['road_oracle_f1']})" if "road_f1" in r else "-")
        print(f"| {r['file']} | {r['points']:,} | {r['type_i']} | {r['type_ii']} | "
              f"{r['total']} | {r['kappa']} | {bld} | {veg} | {road} | {r['seconds']} |")
    if args.out:
        out = Path(args.out)
        if out.is_file() and (set(args.files) != set(FILES) or args.only):  # a subset
            new = {r["file"]: r for r in rows}
            old = [new.pop(r["file"], r) for r in json.loads(out.read_text())]
            rows = old + list(new.values())
        out.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
