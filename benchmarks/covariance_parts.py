"""Covariance on the independent machined parts, and the automatic scale's speed.

Accuracy: ``tests/independent/indep_parts.py`` (flanged and bored parts, range images with
z noise, terrestrial scans with range noise), seeds 0..N-1, with the defaults (automatic
scale, default noise model) and with ``k=50``: edge precision / recall pooled over the
sweep (``indep_parts.edge_scores``'s definitions) and Hoover correct detections at T = 0.8
of the faces of at least 300 points.

Speed: covariance features of one noisy plane-and-ridge cloud, alternating in one process
(``--points``, best of ``--repeat``): lidarstat at the automatic scale (kNN 50 + minimum
eigenentropy from 20 to 50 + features), lidarstat at k = 50, the classes (features and
tests) at the automatic (tested) scale and at k = 50, pgeof
``compute_features_optimal`` (Weinmann's optimal neighbourhood from 20, on the same kNN
50 rows; its kNN search timed apart) when installed.

    python benchmarks/covariance_parts.py --json benchmarks/results_covariance_parts.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from _parts import ip, scenes


def accuracy(seeds, k):
    from lidarstat.classify import covariance
    from lidarstat.segment import hoover, segment_covariance

    rows = []
    for seed, scene, kind, scan, truth in scenes(seeds):
        res = covariance(scan.points, k=k, sensor=scan.sensor, keep_neighbors=True)
        seg = segment_covariance(scan.points, res)
        nbh = res.features.neighborhoods
        reach = (res.features["OptimalRadius"] if k is None
                 else nbh.distances[nbh.indptr[1:] - 1])
        edge = res.point_class == 2
        other = ip.other_face_distance(scan)
        near = (scan.crease_distance < scan.spacing) & (other < 2 * scan.spacing)
        h = hoover(seg.labels, truth, 0.8)
        rows.append(dict(seed=seed, scene=scene, part=kind,
                         points=int(len(edge)), flagged=int(edge.sum()),
                         flagged_right=int((other[edge] <= reach[edge]).sum()),
                         near=int(near.sum()), near_found=int(edge[near].sum()),
                         hoover_correct=h.correct, surfaces=h.n_truth))
    tot = {key: sum(r[key] for r in rows) for key in
           ("flagged", "flagged_right", "near", "near_found", "hoover_correct", "surfaces")}
    return dict(k=k, precision=tot["flagged_right"] / tot["flagged"],
                recall=tot["near_found"] / tot["near"],
                hoover=tot["hoover_correct"] / tot["surfaces"], **tot, scenes=rows)


def speed(n, repeat):
    from lidarstat.features import covariance_features

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, np.sqrt(n) * 0.1, (n, 2))
    z = np.abs(xy[:, 0] - xy[:, 0].mean()) * 0.5 + rng.normal(0, 0.003, n)
    pts = np.c_[xy, z]
    from lidarstat.classify import covariance

    covariance_features(pts[:5000])
    covariance_features(pts[:5000], k=50)
    covariance(pts[:5000])
    covariance(pts[:5000], k=50)
    runs = {"lidarstat automatic": lambda: covariance_features(pts),
            "lidarstat k=50": lambda: covariance_features(pts, k=50),
            "lidarstat classes automatic": lambda: covariance(pts),
            "lidarstat classes k=50": lambda: covariance(pts, k=50)}
    try:
        import pgeof

        xyz = pts.astype(np.float32)
        t0 = time.perf_counter()
        knn, _ = pgeof.knn_search(xyz, xyz, 50)
        knn_s = time.perf_counter() - t0
        nn = knn.astype(np.uint32).ravel()
        ptr = (np.arange(n + 1) * 50).astype(np.uint32)
        runs["pgeof compute_features_optimal (after its kNN)"] = \
            lambda: pgeof.compute_features_optimal(xyz, nn, ptr, k_min=1, k_step=1,
                                                   k_min_search=20)
    except ImportError:
        knn_s = None
    best = {name: np.inf for name in runs}
    for _ in range(repeat):
        for name, run in runs.items():  # alternating
            t0 = time.perf_counter()
            run()
            best[name] = min(best[name], time.perf_counter() - t0)
    out = {"points": n, "repeat": repeat, "seconds": best, "pgeof_knn_seconds": knn_s,
           "ratio_automatic_over_k50": best["lidarstat automatic"] / best["lidarstat k=50"],
           "ratio_classes_automatic_over_k50": (best["lidarstat classes automatic"]
                                                / best["lidarstat classes k=50"])}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--points", type=int, default=500_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None)
    ap.add_argument("--accuracy-only", action="store_true",
                    help="recompute the accuracy and keep the speed entry of --json")
    a = ap.parse_args(argv)
    res = {"machine": "2 cores shared with other jobs (timings are noisy; ratios in one run)",
           "machine_shared": True,
           "automatic": accuracy(a.seeds, None), "k50": accuracy(a.seeds, 50)}
    if a.accuracy_only and a.json and os.path.exists(a.json):
        with open(a.json) as fh:
            res["speed"] = json.load(fh)["speed"]
    else:
        res["speed"] = speed(a.points, a.repeat)
    for key in ("automatic", "k50"):
        r = res[key]
        print(f"{key:9s} edge precision {r['precision']:.3f} recall {r['recall']:.3f} "
              f"Hoover {r['hoover_correct']}/{r['surfaces']}")
    print(json.dumps(res["speed"], indent=1))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
