"""`segment --method curvature` on the independent machined parts, with its defaults.

``tests/independent/indep_parts.py`` (flanged and bored parts, range images with z noise
and terrestrial scans with range noise), seeds 0..N-1 (the same scenes as
``covariance_parts.py``): Hoover correct detections at T = 0.8 of the faces of at least
300 points, pooled over the sweep, with the merge tests (plane test for planar units,
quadric test for curved ones) at their default level and switched off (``merge_alpha``
so small that no union fails), in the same run.

    python benchmarks/curvature_parts.py --json benchmarks/results_curvature_parts.json
"""

from __future__ import annotations

import argparse
import json
import time

from _parts import MIN_SURFACE, scenes


def accuracy(seeds):
    from lidarstat.features import curvature
    from lidarstat.segment import hoover, segment_curvature

    rows = []
    for seed, scene, kind, scan, truth in scenes(seeds):
        curv = curvature(scan.points, sensor=scan.sensor)
        row = {"seed": seed, "scene": scene, "part": kind,
               "points": int(scan.points.shape[0])}
        for name, level in (("tested", None), ("untested", 1e-300)):
            kw = {} if level is None else {"merge_alpha": level}
            t0 = time.process_time()
            seg = segment_curvature(scan.points, sensor=scan.sensor, curv=curv, **kw)
            cpu = time.process_time() - t0
            h = hoover(seg.labels, truth, 0.8)
            row[name] = {"hoover_correct": h.correct, "surfaces": h.n_truth,
                         "merges_refused": seg.params["merges_refused"],
                         "merges_refused_curved": seg.params["merges_refused_curved"],
                         "cpu_seconds": cpu}
        rows.append(row)
        print(row, flush=True)
    out = {}
    for name in ("tested", "untested"):
        c = sum(r[name]["hoover_correct"] for r in rows)
        t = sum(r[name]["surfaces"] for r in rows)
        out[name] = {"hoover_correct": c, "surfaces": t, "hoover": c / t}
    return out, rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    pooled, rows = accuracy(a.seeds)
    res = {"machine": "2 cores shared with other jobs (CPU times are noisy)",
           "machine_shared": True, "seeds": a.seeds, "min_surface": MIN_SURFACE,
           "T": 0.8, **pooled, "scenes": rows}
    for key in ("tested", "untested"):
        r = res[key]
        print(f"merge tests {key:8s} Hoover {r['hoover_correct']}/{r['surfaces']} "
              f"= {r['hoover']:.3f}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
