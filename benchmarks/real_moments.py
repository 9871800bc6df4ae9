#!/usr/bin/env python
"""`moments` on the producer-classified real files, scored against the producers' classes.

For every file: ground/object Type I, Type II and total error against the producer's
ground class (2), building and vegetation recall/precision where the producer has those
classes, and run time. On AHN3 Delft (derived/ files with the BGT map layer) the road
class is scored against the map: among producer-ground points inside the BGT crop on
road (layer 2), vegetated (4) or unvegetated (5) land, the reference road is layer 2.
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

from lidarstat.classify import classify_moments, filter_errors
from lidarstat.io import linear_units, read
from lidarstat.segment import binary_scores

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FILES = [
    "ahn3_amsterdam/ahn_2386_9702.laz",
    "ahn3_amsterdam/ahn_2397_9705.laz",
    "ahn3_delft_3dfier/derived/ahn3_cropped_1_bgt.laz",
    "ahn3_delft_3dfier/derived/ahn3_cropped_2_bgt.laz",
    "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las",
    "ign_lidarhd_samples/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz",
    "laspy_testdata/file_with_both_wkt_and_geotiff_vlrs.las",
    "pdal_testdata/autzen_trim.laz",
    "pdal_testdata/las_with_several_extra_byte_bloc.laz",
    "lidR/Topography.laz",
]
LEFT_OUT = (7, 9, 18)


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
        res = classify_moments(cloud.xyz, a.get("intensity"), source=str(path), units=units,
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
    if "bgt_layer" in a:
        layer = np.asarray(a["bgt_layer"]).astype(int)
        sel = (ref == 2) & np.isin(layer, (2, 4, 5))
        r = binary_scores(cls[sel] == 11, layer[sel] == 2)
        row.update(road_points=int(sel.sum()), road_precision=_pct(r["precision"]),
                   road_recall=_pct(r["recall"]), road_f1=_pct(r["f1"]))
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--files", nargs="+", default=FILES,
                    help="files under ../shared/data to score (default: all of them)")
    args = ap.parse_args()
    rows = []
    for rel in args.files:
        path = DATA / rel
        if not path.is_file():
            print(f"skipped (not found): {path}")
            continue
        rows.append(score(path))
        print(json.dumps(rows[-1]), flush=True)
    print("\n| file | points | Type I % | Type II % | total % | kappa | building P/R % |"
          " vegetation P/R % | road P/R/F1 % | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        bld = (f"{r['building_precision']}/{r['building_recall']}"
               if "building_recall" in r else "-")
        veg = (f"{r['vegetation_precision']}/{r['vegetation_recall']}"
               if "vegetation_recall" in r else "-")
        road = (f"{r['road_precision']}/{r['road_recall']}/{r['road_f1']}"
                if "road_f1" in r else "-")
        print(f"| {r['file']} | {r['points']:,} | {r['type_i']} | {r['type_ii']} | "
              f"{r['total']} | {r['kappa']} | {bld} | {veg} | {road} | {r['seconds']} |")
    if args.out:
        out = Path(args.out)
        if out.is_file() and set(args.files) != set(FILES):  # a subset updates its rows
            new = {r["file"]: r for r in rows}
            old = [new.pop(r["file"], r) for r in json.loads(out.read_text())]
            rows = old + list(new.values())
        out.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
