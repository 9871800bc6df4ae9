"""Accuracy of the covariance classification and segmentation on scenes with exact truth.

    PYTHONPATH=src python benchmarks/covariance_accuracy.py [--quick] [--json OUT]

Scenes: the synthetic gable roof of the tests (40,000 points, noise 5 mm) and the
terrestrial scans ``tls_building`` and ``tls_plant`` (one station, default step and range
noise 0.002 + 5e-5 r, seed 0; ``--quick``: step 0.004). Parameters: k = 50, everything
automatic (range noise estimated along the rays from the scanner position). Printed:

* edge and boundary precision / recall / F1 against three truths (docs/methods/
  covariance.md argues which is sound): ``support`` - a point is an edge when its own
  k-neighbourhood holds a point of another face (:func:`neighborhood_class_truth`),
  a boundary when the end of the visible surface is within 0.5 of its own neighbourhood
  radius; ``band r_i`` - :func:`point_class_truth` zones of 0.7 (edge) / 0.5 (boundary)
  times the point's own neighbourhood radius; ``band median`` - the same with one
  radius, the median over the cloud (the figures of session 2);
* Hoover et al. (1996) counts at T = 0.8 over faces of more than 200 points;
* the intersection lines with at least 50 supporting points and longer than 1 m: the
  largest distance from the true creases at 20, 50 and 80 % of their length.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def prf(pred, truth):
    tp = int(np.count_nonzero(pred & truth))
    p = tp / max(int(pred.sum()), 1)
    r = tp / max(int(truth.sum()), 1)
    return {"precision": round(p, 3), "recall": round(r, 3),
            "f1": round(2 * tp / max(int(pred.sum() + truth.sum()), 1), 3)}


def class_scores(cloud, res):
    from lidarstat.synth import neighborhood_class_truth, point_class_truth

    nbh = res.features.neighborhoods
    pc = res.point_class
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
    out = {}
    sup = neighborhood_class_truth(cloud, nbh)
    out["support"] = {"edge": prf(pc == 2, sup == 2), "boundary": prf(pc == 3, sup == 3)}
    ed, bd = cloud.edge_distance, cloud.fields["boundary_distance"]
    tb = bd < 0.5 * rk
    out["band r_i"] = {"edge": prf(pc == 2, (ed < 0.7 * rk) & ~(bd < 0.7 * rk)),
                       "boundary": prf(pc == 3, tb)}
    med = float(np.median(rk))
    out["band median"] = {"edge": prf(pc == 2, point_class_truth(cloud, 0.7 * med) == 2),
                          "boundary": prf(pc == 3, point_class_truth(cloud, 0.5 * med) == 3)}
    names = np.array(cloud.meta["face_names"])[cloud.face].astype(str)
    curved = np.char.endswith(names, "_side") & (sup == 1)
    if curved.any():
        out["curved surface labelled edge"] = round(float((pc[curved] == 2).mean()), 4)
    return out


def line_scores(cloud, lines, two_sigma):
    from lidarstat.synth._edges import distance_to_creases

    t = np.array([0.2, 0.5, 0.8])[:, None]
    worst = []
    for v, n in zip(lines.vertices, lines.attributes["n_points"]):
        if n >= 50 and np.linalg.norm(v[-1] - v[0]) > 1.0:
            worst.append(float(distance_to_creases(v[0] + t * (v[-1] - v[0]),
                                                   cloud.meta["edges"]).max()))
    return {"lines": len(lines), "long lines": len(worst),
            "worst distance (m)": round(max(worst), 4) if worst else None,
            "2 sigma (m)": two_sigma}


def tls(name, step):
    from lidarstat.classify import covariance
    from lidarstat.segment import hoover, segment_covariance
    from lidarstat.synth import make_tls_building, make_tls_plant

    make = {"tls_building": make_tls_building, "tls_plant": make_tls_plant}[name]
    cloud = make(step=step, rng=0)
    t0 = time.perf_counter()
    res = covariance(cloud.xyz, sensor=cloud.scanner, k=50, keep_neighbors=True)
    seg = segment_covariance(cloud.xyz, sensor=cloud.scanner, result=res)
    dt = time.perf_counter() - t0
    h = hoover(seg.labels, cloud.face + 1, 0.8, min_size=200)
    names = cloud.meta["face_names"]
    missed = [names[i - 1] for i in h.missed_ids] + \
        [names[i - 1] for i in h.over_segmented] + \
        [names[i - 1] for m in h.under_segmented.values() for i in m]
    seg0 = segment_covariance(cloud.xyz, sensor=cloud.scanner, result=res,
                              adaptive_scale=False)
    h0 = hoover(seg0.labels, cloud.face + 1, 0.8, min_size=200)
    out = {"points": len(cloud), "seconds": round(dt, 1), "classes": class_scores(cloud, res),
           "hoover": h.as_dict(), "not correct": missed,
           "hoover without adaptive scale": h0.as_dict(),
           "lines": line_scores(cloud, seg.lines, 2 * (0.002 + 5e-5 * 30))}
    return out


def gable(rng):
    from scipy.spatial import cKDTree

    from lidarstat.classify import covariance

    n, sigma = 40000, 0.005
    xy = rng.uniform(0, 10, (n, 2))
    z = 5 - np.tan(np.radians(30)) * np.abs(xy[:, 0] - 5) + rng.normal(0, sigma, n)
    pts = np.c_[xy, z]
    ridge = np.abs(xy[:, 0] - 5) * np.cos(np.radians(30))
    border = np.minimum.reduce([xy[:, 0], 10 - xy[:, 0], xy[:, 1], 10 - xy[:, 1]])
    res = covariance(pts, k=50)
    d, _ = cKDTree(pts).query(pts[::50], k=50)
    rk = np.median(d[:, -1])
    pc = res.point_class
    out = {}
    for c in (0.5, 0.6, 0.75, 1.0):
        out[f"band {c}"] = {"edge": prf(pc == 2, (ridge < c * rk) & (border > ridge)),
                            "boundary": prf(pc == 3, (border < c * rk) & (ridge > border))}
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="coarse scans (step 0.004)")
    p.add_argument("--json", default=None, help="write the figures here")
    a = p.parse_args(argv)
    step = 0.004 if a.quick else 0.0025
    res = {"step": step, "gable": gable(np.random.default_rng(0))}
    for name in ("tls_building", "tls_plant"):
        res[name] = tls(name, step)
    print(json.dumps(res, indent=1))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
