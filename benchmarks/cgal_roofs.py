"""CGAL region growing of planes on the AHN3 roof clouds: an anchor of the roof table of
``benchmarks/real_sar.py``.

    python benchmarks/cgal_roofs.py [--files NAME ...]

Builds ``cgal_region_growing.cpp`` (CGAL's ``Shape_detection::Region_growing`` with
``Least_squares_plane_fit_region``, Debian ``libcgal-dev``; ``g++`` with Eigen), gives it
every point with the normal of the principal plane of its 12 nearest points, and scores
its regions as ``real_sar.roof_score`` does (share of the producer's building points in
regions mostly of building points, their purity, their number). Settings: the distance
and angle of the CloudCompare RANSAC anchor (0.05 m, 25 degrees), regions of 12 points
or more (lidarstat's smallest tested plane), 12 neighbours. The machine may be shared:
times are of one run. Writes ``benchmarks/results_cgal_roofs.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SETTINGS = {"max_distance": 0.05, "max_angle_deg": 25.0, "min_region_size": 12, "k": 12}


def build(tmp):
    exe = Path(tmp) / "cgal_region_growing"
    subprocess.run(["g++", "-O2", "-DNDEBUG", "-std=c++17", "-I/usr/include/eigen3",
                    str(HERE / "cgal_region_growing.cpp"), "-o", str(exe), "-lgmp",
                    "-lmpfr"], check=True)
    return exe


def cgal_planes(exe, xyz, tmp, settings=SETTINGS):
    """Region labels (0: none) and CGAL's seconds."""
    from lidarstat.neighbors import knn_neighbors
    from lidarstat.segment._sar_planes import _local_pca

    P = xyz - xyz.min(axis=0)
    nbr = knn_neighbors(P, settings["k"]).indices.reshape(-1, settings["k"])
    normals = _local_pca(P, nbr)[1][:, :, 0]
    src, dst = Path(tmp) / "in.bin", Path(tmp) / "out.bin"
    np.ascontiguousarray(np.c_[P, normals], dtype="<f8").tofile(src)
    out = subprocess.run([str(exe), str(src), str(dst), str(settings["max_distance"]),
                          str(settings["max_angle_deg"]), str(settings["min_region_size"]),
                          str(settings["k"])], check=True, capture_output=True, text=True)
    info = json.loads(out.stdout.strip().splitlines()[-1])
    return np.fromfile(dst, dtype="<i4").astype(np.int64), info["seconds"]


def main(argv=None):
    from real_sar import DATA, FILES, roof_score

    from lidarstat import read

    ahn3 = [f for f in FILES if f.startswith("ahn3")]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", nargs="*", default=ahn3, choices=ahn3)
    args = ap.parse_args(argv)
    out = HERE / "results_cgal_roofs.json"
    results = json.loads(out.read_text()) if out.is_file() else {}
    results.update({"settings": SETTINGS, "machine_shared": True})
    with tempfile.TemporaryDirectory() as tmp:
        exe = build(tmp)
        for name in args.files:
            path = DATA / FILES[name]
            if not path.is_file():
                print(f"skip {name}: {path} not found")
                continue
            cloud = read(path)
            cls = np.asarray(cloud.attributes["classification"])
            keep = ~np.isin(cls, [7, 18])
            labels, sec = cgal_planes(exe, cloud.xyz[keep], tmp)
            score, _ = roof_score(labels, cls[keep] == 6)
            results[name] = {**score, "seconds": round(sec, 1)}
            print(name, json.dumps(results[name]), flush=True)
            out.write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
