"""Tile catalogues: agreement with the whole-area run, and memory and time at scale.

Two measurements, each a ``lidarstat`` process as a user runs it:

* ``--agreement``: the AHN3 Delft crop (``../shared/data``, 640k points, 192 x 228 m) cut
  into tiles of 80 m (``lidarstat.pipeline.write_tiles``); ``moments`` on the catalogue with several buffers against
  ``moments`` on the whole file: the share of points with the same class, and with the
  same ground (2, 11) / object decision. ``curvature`` likewise, whose answer is local
  (its share must be 1 with the default buffer, the radius). ``segment --method
  covariance`` on the tiles (default buffer, segments joined across the tiles) against
  the whole file: purity and completeness of the segments.
* ``--segments``: that segment measurement alone (merged into ``agreement``).
* ``--reach``: how far the refits of the ground surface carry the edge of a buffer: one
  tile's classes against the whole file's for ``--iterations`` 0, 1 and 4.
* ``--points N``: a synthetic airborne catalogue of N points in tiles of
  ``--tile-points`` points (10 points/m2: the cloud of ``bench_moments.py``), classified
  by ``lidarstat moments tiles/ out/ --dtm dtm/``: wall time, seconds per million
  points, and the peak memory of the process (GNU time), which must not grow with N.

Usage::

    python benchmarks/catalogue.py --agreement --out benchmarks/results_catalogue.json
    python benchmarks/catalogue.py --segments --out benchmarks/results_catalogue.json
    python benchmarks/catalogue.py --reach --out benchmarks/results_catalogue.json
    python benchmarks/catalogue.py --points 50000000 --out benchmarks/results_catalogue.json

Results are merged into the JSON file (one key per measurement).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE))

from lidarstat.io import PointCloud, read, write
from lidarstat.pipeline import write_tiles

DELFT = HERE.parent.parent / "shared" / "data" / "ahn3_delft_3dfier" / "ahn3_cropped_1.laz"


def lidarstat(*args) -> tuple[float, float]:
    """Run ``lidarstat ARGS`` under GNU time: (seconds, peak RSS in MiB)."""
    cmd = ["/usr/bin/time", "-f", "%e %M", sys.executable, "-m", "lidarstat", *map(str, args)]
    env = {**os.environ, "PYTHONPATH": str(HERE.parent / "src")}
    run = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if run.returncode != 0:
        raise SystemExit(f"lidarstat {' '.join(map(str, args))} failed:\n{run.stderr}")
    seconds, kib = re.findall(r"([\d.]+) (\d+)\s*$", run.stderr)[-1]
    return float(seconds), int(kib) / 1024


def _keyed(xyz):
    return np.round(xyz * 1000).astype(np.int64)


def _classes(paths, field):
    xyz, cls = [], []
    for p in paths:
        c = read(p, fields=[field])
        xyz.append(_keyed(c.xyz))
        cls.append(np.asarray(c.attributes[field]))
    xyz, cls = np.concatenate(xyz), np.concatenate(cls)
    order = np.lexsort(xyz.T[::-1])
    return xyz[order], cls[order]


def agreement(tmp: Path) -> dict:
    if not DELFT.is_file():
        raise SystemExit(f"real data not found: {DELFT}")
    src = read(DELFT)
    write_tiles(src, tmp / "tiles", size=80.0)  # 3 x 3 tiles of 80 m
    rows = {}
    secs, mem = lidarstat("moments", DELFT, tmp / "whole.laz", "--no-report", "-q")
    wx, wc = _classes([tmp / "whole.laz"], "classification")
    rows["moments whole file"] = {"seconds": secs, "peak_mib": mem}
    for buffer in (0, 32, 64, 128, 192):
        out = tmp / f"moments_{buffer}"
        secs, mem = lidarstat("moments", tmp / "tiles", out, "--buffer", buffer,
                              "--no-report", "-q")
        tx, tc = _classes(sorted(out.glob("*.laz")), "classification")
        assert np.array_equal(tx, wx)
        ground = np.isin(tc, (2, 11)) == np.isin(wc, (2, 11))
        rows[f"moments buffer {buffer} m"] = {
            "seconds": secs, "peak_mib": mem, "same_class": float((tc == wc).mean()),
            "same_ground_object": float(ground.mean()),
            "same_class_road_as_ground": float((np.where(tc == 11, 2, tc)
                                                == np.where(wc == 11, 2, wc)).mean())}
    secs, mem = lidarstat("curvature", DELFT, tmp / "whole_c.laz", "--radius", "1.5", "-q")
    wx, wc = _classes([tmp / "whole_c.laz"], "surface_type")
    rows["curvature whole file"] = {"seconds": secs, "peak_mib": mem}
    # one sigma for the area: the whole file's estimate, given to both runs
    secs, mem = lidarstat("curvature", DELFT, tmp / "whole_c.laz", "--radius", "1.5",
                          "--sigma", "0.03", "-q")
    wx, wc = _classes([tmp / "whole_c.laz"], "surface_type")
    secs, mem = lidarstat("curvature", tmp / "tiles", tmp / "curv", "--radius", "1.5",
                          "--sigma", "0.03", "-q")
    tx, tc = _classes(sorted((tmp / "curv").glob("*.laz")), "surface_type")
    rows["curvature buffer = radius"] = {"seconds": secs, "peak_mib": mem,
                                         "same_class": float((tc == wc).mean())}
    rows.update(segment_agreement(tmp))
    return {"data": str(DELFT.relative_to(DELFT.parents[2])),
            "tiles": len(list((tmp / "tiles").glob("*.laz"))),
            "points": len(src.xyz), "runs": rows}


def _best_overlap(a, b):
    """Share of points in the segment of `b` that overlaps most with their segment of
    `a` (points in no segment in both agree)."""
    pairs, counts = np.unique(np.c_[a, b], axis=0, return_counts=True)
    best = {}
    for (x, y), c in zip(pairs.tolist(), counts.tolist()):
        if x == 0 or y == 0:
            best[("none", x)] = best.get(("none", x), 0) + (c if x == y else 0)
        else:
            best[x] = max(best.get(x, 0), c)
    return sum(best.values()) / len(a)


def segment_agreement(tmp: Path) -> dict:
    """``segment --method covariance`` on the tiles against the whole file: purity (a
    catalogue segment lies in one whole-file segment) and completeness (a whole-file
    segment lies in one catalogue segment: the join across the tiles)."""
    opts = ["--method", "covariance", "--radius", "1.5", "--sigma", "0.03"]
    secs, mem = lidarstat("segment", DELFT, tmp / "whole_s.laz", *opts, "-q")
    wx, wc = _classes([tmp / "whole_s.laz"], "segment_id")
    rows = {"segment whole file": {"seconds": secs, "peak_mib": mem}}
    secs, mem = lidarstat("segment", tmp / "tiles", tmp / "seg", *opts, "-q")
    tx, tc = _classes(sorted((tmp / "seg").glob("*.laz")), "segment_id")
    assert np.array_equal(tx, wx)
    rows["segment tiles, default buffer"] = {
        "seconds": secs, "peak_mib": mem, "purity": _best_overlap(tc, wc),
        "completeness": _best_overlap(wc, tc),
        "same_in_a_segment": float(((tc > 0) == (wc > 0)).mean()),
        "segments": int(np.unique(tc[tc > 0]).size),
        "whole_file_segments": int(np.unique(wc[wc > 0]).size),
        "machine_shared": True}
    _unjoined(tmp / "tiles", tmp / "seg_cut", opts)
    tx, tc = _classes(sorted((tmp / "seg_cut").glob("*.laz")), "segment_id")
    assert np.array_equal(tx, wx)
    rows["segment tiles, default buffer, not joined"] = {
        "purity": _best_overlap(tc, wc), "completeness": _best_overlap(wc, tc),
        "same_in_a_segment": float(((tc > 0) == (wc > 0)).mean()),
        "segments": int(np.unique(tc[tc > 0]).size)}
    return rows


def _unjoined(tiles: Path, out: Path, opts: list) -> None:
    """The catalogue run of ``segment`` (in this process) with its segments left as the
    tiles' runs found them: ids unique over the area, not joined across the tiles, so
    the difference from the joined run is the join's."""
    from lidarstat.cli import _catalogue_segment as seg
    from lidarstat.cli._app import build_parser
    from lidarstat.pipeline import Catalogue, process_catalogue

    args = build_parser("segment").parse_args(["segment", str(tiles), str(out), *opts, "-q"])
    args.input = str(tiles)
    cat = Catalogue(tiles)
    fields, join = seg._segment_fields(args, seg._segment_prepare(args, cat))
    process_catalogue(fields, cat, out, buffer=seg._segment_buffer(args, cat),
                      labels={"segment_id": False}, collect=join["collect"],
                      finish=join["finish"])


def segments_only(tmp: Path) -> dict:
    """:func:`segment_agreement` on the tiles of :func:`agreement`."""
    if not DELFT.is_file():
        raise SystemExit(f"real data not found: {DELFT}")
    write_tiles(read(DELFT), tmp / "tiles", size=80.0)
    return segment_agreement(tmp)


def iteration_reach(tile=(1061, 5595), size=80.0, buffer=128.0) -> dict:
    """How far the ground refits carry the buffer's edge: ``moments`` (in this process)
    on one tile of the Delft crop with its buffer against the whole file, for several
    ``iterations``; the tile is the one at the crop's north edge that differs most at a
    128 m buffer. The road cut is switched off in both runs, so that only the ground
    differs."""
    from lidarstat.classify import moments

    src = read(DELFT)
    xyz = src.xyz
    att = {k: np.asarray(src.attributes[k])
           for k in ("intensity", "number_of_returns", "return_number")}
    key = np.floor(xyz[:, :2] / size).astype(np.int64)
    core = np.all(key == np.asarray(tile), axis=1)
    lo, hi = np.asarray(tile) * size - buffer, (np.asarray(tile) + 1) * size + buffer
    win = np.all((xyz[:, :2] >= lo) & (xyz[:, :2] <= hi), axis=1)
    idx = np.r_[np.flatnonzero(core), np.flatnonzero(win & ~core)]
    n = int(core.sum())
    rows = {}
    for it in (0, 1, 4):
        runs = []
        for rows_ in (slice(None), idx):
            a = {k: v[rows_] for k, v in att.items()}
            runs.append(moments(xyz[rows_], a.pop("intensity"), iterations=it,
                                road_threshold=float("-inf"), **a).classification)
        whole, tiled = runs[0][idx[:n]], runs[1][:n]
        ground = np.isin(tiled, (2, 11)) == np.isin(whole, (2, 11))
        rows[f"iterations {it}"] = {"same_class": float((tiled == whole).mean()),
                                    "same_ground_object": float(ground.mean())}
    return {"tile": list(tile), "tile_points": n, "buffer": buffer,
            "points_with_buffer": int(idx.size), "runs": rows}


def tile_cloud(x0, y0, n, seed):
    """One tile of a continuous synthetic town (``bench_moments.make_cloud`` at an origin)."""
    from bench_moments import make_cloud

    xyz, inten, nret, rnum, _ = make_cloud(n, seed=seed, origin=(x0, y0))
    return PointCloud(xyz, {"intensity": np.clip(inten, 0, 65535).astype(np.uint16),
                            "number_of_returns": nret.astype(np.uint8),
                            "return_number": rnum.astype(np.uint8)})


def scale(tmp: Path, n: int, tile_points: int) -> dict:
    n_tiles = max(1, round(n / tile_points))
    side_tiles = math.ceil(math.sqrt(n_tiles))
    tile_side = math.sqrt(tile_points / 10.0)
    folder = tmp / "tiles"
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for k in range(n_tiles):  # each tile generated and written alone: memory of one tile
        a, b = divmod(k, side_tiles)
        write(folder / f"t_{a:03d}_{b:03d}.laz",
              tile_cloud(a * tile_side, b * tile_side, tile_points, 20261122 + k))
    made = time.perf_counter() - t0
    secs, mem = lidarstat("moments", folder, tmp / "out", "--dtm", tmp / "dtm", "-q")
    total = n_tiles * tile_points
    return {"points": total, "tiles": n_tiles, "tile_points": tile_points,
            "seconds": secs, "seconds_per_million": secs / (total / 1e6), "peak_mib": mem,
            "generation_seconds": made, "cores": os.cpu_count()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agreement", action="store_true")
    ap.add_argument("--segments", action="store_true",
                    help="the segment agreement alone, merged into 'agreement'")
    ap.add_argument("--reach", action="store_true",
                    help="the ground refits' reach on one tile (iterations 0, 1, 4)")
    ap.add_argument("--points", type=int, default=None)
    ap.add_argument("--tile-points", type=int, default=1_000_000)
    ap.add_argument("--out", default=None)
    ap.add_argument("--tmp", default=None, help="work folder (kept when given)")
    args = ap.parse_args(argv)
    results = {}
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        tmp = Path(tmp)
        if args.agreement:
            results["agreement"] = agreement(tmp / "agreement")
            print(json.dumps(results["agreement"], indent=1))
        if args.segments:
            seg = segments_only(tmp / "segments")
            print(json.dumps(seg, indent=1))
            results["agreement_segments"] = seg
        if args.reach:
            results["agreement_iterations"] = iteration_reach()
            print(json.dumps(results["agreement_iterations"], indent=1))
        if args.points:
            key = f"scale_{args.points}"
            results[key] = scale(tmp / "scale", args.points, args.tile_points)
            print(json.dumps(results[key], indent=1))
    if args.out:
        path = Path(args.out)
        old = json.loads(path.read_text()) if path.exists() else {}
        if "agreement_segments" in results:  # rows of the agreement runs
            old.setdefault("agreement", {"runs": {}})["runs"].update(
                results.pop("agreement_segments"))
        old.update(results)
        path.write_text(json.dumps(old, indent=1) + "\n")


if __name__ == "__main__":
    main()
