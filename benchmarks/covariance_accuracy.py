"""Accuracy of the covariance classification and segmentation on scenes with exact truth.

    PYTHONPATH=src python benchmarks/covariance_accuracy.py [--quick] [--json OUT]

Scenes: the synthetic gable roof of the tests (40,000 points, noise 5 mm) and the
terrestrial scans ``tls_building`` and ``tls_plant`` (one station, default step and range
noise 0.002 + 5e-5 r, seed 0; ``--quick``: step 0.004). Parameters: the defaults - the
automatic scale (``--k K`` for a fixed one), range noise estimated along the rays from the
scanner position, height noise along z on the gable roof. Printed:

* edge and boundary precision / recall / F1 against three truths (boundary test: the
  default ``'grid'`` one, with its boundary errors by cause; the paper's ``'centroid'``
  test on the same features beside it): ``support`` - a point is an edge when its own
  neighbourhood (at its chosen size) holds a point of another face (:func:`neighborhood_class_truth`),
  a boundary when the end of the visible surface is within 0.5 of its own neighbourhood
  radius; ``band r_i`` - :func:`point_class_truth` zones of 0.7 (edge) / 0.5 (boundary)
  times the point's own neighbourhood radius; ``band median`` - the same with one
  radius, the median over the cloud;
* the edge errors against the support truth by cause (:func:`edge_errors`);
* Hoover et al. (1996) counts at T = 0.8 over faces of more than 200 points; the number
  of distinct scan rows on every face;
* the straight intersection lines with at least 50 supporting points and longer than
  1 m: the largest distance at 20, 50 and 80 % of their length from the nearest listed
  crease and from the crease of their own two faces; the curved lines (polylines of a
  cylinder against a plane) at their vertices and edge midpoints against the true arcs.
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

    nbh = used_neighbourhoods(res)
    pc = res.point_class
    rk = nbh.distances[nbh.indptr[1:] - 1]
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
    out["edge errors by cause (support truth)"] = edge_errors(cloud, nbh, pc, sup, names)
    return out


def edge_errors(cloud, nbh, pc, sup, names):
    """Counts of the support truth's edge errors by cause: false edges that are truth
    boundaries whose neighbourhood also straddles a crease ("corner": the truth lets the
    boundary win), other truth boundaries, truth surface on curved ("_side") or planar
    faces; missed edges labelled surface or boundary."""
    n = len(pc)
    rows = np.repeat(np.arange(n), np.diff(nbh.indptr))
    other = np.bincount(rows, weights=cloud.face[nbh.indices] != cloud.face[rows], minlength=n)
    side = np.char.endswith(names, "_side")
    fp = (pc == 2) & (sup != 2)
    fn = (sup == 2) & (pc != 2)
    return {"false edges": int(fp.sum()),
            "  truth boundary, crease in the neighbourhood (corner)":
                int((fp & (sup == 3) & (other > 0)).sum()),
            "  truth boundary, no crease": int((fp & (sup == 3) & (other == 0)).sum()),
            "  truth surface, curved face": int((fp & (sup == 1) & side).sum()),
            "  truth surface, planar face": int((fp & (sup == 1) & ~side).sum()),
            "missed edges": int(fn.sum()),
            "  labelled surface": int((fn & (pc == 1)).sum()),
            "  labelled boundary": int((fn & (pc == 3)).sum())}


def _face_plane(cloud, f):
    p = cloud.xyz[cloud.face == f]
    c = p.mean(axis=0)
    return np.linalg.svd(p - c, full_matrices=False)[2][2], c


def line_scores(cloud, seg, two_sigma):
    """Straight lines (n >= 50, longer than 1 m) at 20/50/80 % of their length, against two
    truths: the nearest crease of ``meta['edges']`` and the crease of
    the line's own two faces (the intersection of the planes fitted to the true faces'
    points; the dominant face of each segment); curved lines (a cylinder segment on one
    side) sampled at their vertices and edge midpoints against the true arcs of their two
    faces."""
    from lidarstat.synth._edges import distance_to_creases

    lines, labels = seg.lines, seg.labels
    names = cloud.meta["face_names"]
    cyl = seg.table["model"] == 2
    t = np.array([0.2, 0.5, 0.8])[:, None]
    nearest, pair, curved, no_crease = [], [], [], []
    for v, a, b, n in zip(lines.vertices, lines.attributes["segment_a"],
                          lines.attributes["segment_b"], lines.attributes["n_points"]):
        fa = int(np.bincount(cloud.face[labels == a]).argmax())
        fb = int(np.bincount(cloud.face[labels == b]).argmax())
        tag = f"{names[fa]} / {names[fb]}"
        if cyl[a - 1] or cyl[b - 1]:
            arcs = [c for c in cloud.meta["edges"] if set(c["faces"]) == {fa, fb}]
            q = np.concatenate([v[:-1], 0.5 * (v[:-1] + v[1:]), v[-1:]])
            if not arcs:
                no_crease.append({"faces": tag, "n_points": int(n)})
                continue
            d = distance_to_creases(q, arcs)
            curved.append({"faces": tag, "vertices": len(v),
                           "length (m)": round(float(np.linalg.norm(np.diff(v, axis=0),
                                                                    axis=1).sum()), 3),
                           "median (m)": round(float(np.median(d)), 5),
                           "max (m)": round(float(d.max()), 5),
                           "within 2 sigma": round(float(np.mean(d < two_sigma)), 3)})
            continue
        if n < 50 or np.linalg.norm(v[-1] - v[0]) <= 1.0:
            continue
        q = v[0] + t * (v[-1] - v[0])
        nearest.append(float(distance_to_creases(q, cloud.meta["edges"]).max()))
        (na, ca), (nb, cb) = _face_plane(cloud, fa), _face_plane(cloud, fb)
        cos = abs(float(na @ nb))
        if cos > np.cos(np.radians(5)):
            no_crease.append({"faces": tag, "n_points": int(n)})
            continue
        pair.append({"faces": tag, "max (m)": round(float(max(np.abs((q - ca) @ na).max(),
                                                               np.abs((q - cb) @ nb).max())), 5)})
    return {"lines": len(lines), "long straight lines": len(nearest),
            "worst distance, nearest listed crease (m)": round(max(nearest), 4)
            if nearest else None,
            "straight, own face pair": pair, "curved": curved,
            "lines between parallel faces or faces without a listed arc": no_crease,
            "2 sigma (m)": two_sigma}


def used_neighbourhoods(res):
    """The neighbourhoods the features were computed on: at the automatic scale the first
    ``neighbors`` points of each kept kNN row."""
    from lidarstat.neighbors import Neighborhoods

    f = res.features
    nbh = f.neighborhoods
    if f.k is not None or f.radius is not None:
        return nbh
    used = np.minimum(np.asarray(f.counts, dtype=np.int64), nbh.counts)
    indptr = np.zeros(used.size + 1, dtype=np.int64)
    np.cumsum(used, out=indptr[1:])
    pos = np.repeat(nbh.indptr[:-1] - indptr[:-1], used) + np.arange(indptr[-1])
    return Neighborhoods(indptr, nbh.indices[pos], nbh.distances[pos], nbh.n_points,
                         kind="knn")


def tls(name, step, k=None):
    from lidarstat.classify import covariance
    from lidarstat.segment import hoover, segment_covariance
    from lidarstat.synth import make_tls_building, make_tls_plant

    make = {"tls_building": make_tls_building, "tls_plant": make_tls_plant}[name]
    cloud = make(step=step, rng=0)
    t0 = time.perf_counter()
    res = covariance(cloud.xyz, sensor=cloud.scanner, k=k, keep_neighbors=True)
    seg = segment_covariance(cloud.xyz, res)
    dt = time.perf_counter() - t0
    h = hoover(seg.labels, cloud.face + 1, 0.8, min_points=200)
    names = cloud.meta["face_names"]
    missed = [names[i - 1] for i in h.missed_ids] + \
        [names[i - 1] for i in h.over_segmented] + \
        [names[i - 1] for m in h.under_segmented.values() for i in m]
    # scan rows across each face: per azimuth column of the scan grid, the number of
    # distinct elevation rows on the face (median and 90 % quantile over its columns)
    d = cloud.xyz - cloud.scanner
    rows = np.round(np.arcsin(d[:, 2] / np.linalg.norm(d, axis=1)) / step).astype(np.int64)
    cols = np.round(np.arctan2(d[:, 1], d[:, 0]) / step).astype(np.int64)
    big = np.flatnonzero(np.bincount(cloud.face) > 200)
    nrows = {}
    for f in big:
        m = cloud.face == f
        key = np.unique(np.c_[cols[m], rows[m]], axis=0)
        per_col = np.unique(key[:, 0], return_counts=True)[1]
        nrows[names[f]] = [float(np.median(per_col)), float(np.quantile(per_col, 0.9))]
    fields = seg.fields["reintegrated"]
    # the paper's centroid test on the same features
    from lidarstat.classify import classify_covariance
    from lidarstat.synth import neighborhood_class_truth

    sup = neighborhood_class_truth(cloud, used_neighbourhoods(res))
    cen = classify_covariance(res.features, points=cloud.xyz, boundary="centroid")
    out = {"points": len(cloud), "seconds": round(dt, 1), "classes": class_scores(cloud, res),
           "boundary errors by cause (grid test, the default)": grid_errors(
               cloud, res, res.classes, sup),
           "centroid test (the paper's), support truth": {
               "edge": prf(cen.point_class == 2, sup == 2),
               "boundary": prf(cen.point_class == 3, sup == 3)},
           "hoover": h.as_dict(), "not correct": missed,
           "scan rows across faces > 200 points (median, 90 %)": nrows,
           "points moved by the border refinement": int(np.sum(fields == 2)),
           "points in strip segments": int(np.sum(fields == 3)),
           "lines": line_scores(cloud, seg, 2 * (0.002 + 5e-5 * 30))}
    return out


def grid_errors(cloud, res, grid, sup):
    """The 'grid' test's boundary errors against the support truth, by the kind of the
    nearest estimated border, and split into false borders (the nearest estimated border
    belongs to a grid node the truth does not flag as next to a border: on tls_building
    mostly the step between a wall and a window or door back, where the jamb or sill
    between them received no grid sample although the truth's bisection between the two
    rays finds it visible, so the truth sees two creases and the grid a jump) and
    misplaced ones (a true border node, its border estimated too near)."""
    from lidarstat.classify import _grid_borders as V
    from lidarstat.classify._grid_boundary import grid_boundary
    from lidarstat.classify._scan_grid import grid_edges

    f = res.features
    a, b = grid.meta["range_noise"]
    along = a + b * f.ray_range
    cyl = None
    if "curvature_centre" in grid.meta:  # borders of curved-surface nodes on their cylinder
        from lidarstat.classify._covariance_tests import grid_cylinders

        with np.errstate(invalid="ignore"):
            on = ((grid.fields["plane_p"] < grid.alpha)
                  & (grid.fields["variation_p"] >= grid.meta["curved_alpha"]))
        cyl = grid_cylinders(grid.meta, on)
    gb = grid_boundary(cloud.xyz, cloud.scanner, f.normals, along,
                       grid=grid_edges(cloud.xyz, cloud.scanner, along),
                       jump_alpha=grid.meta["jump_alpha"], cylinders=cyl,
                       return_borders=True)
    _, node, kind, _ = gb["borders"]
    j = gb["nearest"]
    false_node = cloud.fields["boundary"][node[j]] == 0
    pc = grid.point_class
    fp = (pc == 3) & (sup != 3)
    fn = (pc != 3) & (sup == 3)
    out = {"false boundaries": int(fp.sum()), "missed boundaries": int(fn.sum())}
    for k, name in ((V.BORDER_WINDOW, "scan window"), (V.BORDER_MISSING, "no return"),
                    (V.BORDER_JUMP, "depth jump")):
        out[f"  false, nearest border: {name}"] = int((fp & (kind[j] == k)).sum())
        out[f"  false, nearest border: {name}, at a node the truth has no border"] = int(
            (fp & (kind[j] == k) & false_node).sum())
    keep = ~(fp & false_node)
    out["boundary F1 without the false border nodes"] = prf((pc == 3)[keep], (sup == 3)[keep])
    return out


def gable(rng, k=None):
    from scipy.spatial import cKDTree

    from lidarstat.classify import covariance

    n, sigma = 40000, 0.005
    xy = rng.uniform(0, 10, (n, 2))
    z = 5 - np.tan(np.radians(30)) * np.abs(xy[:, 0] - 5) + rng.normal(0, sigma, n)
    pts = np.c_[xy, z]
    ridge = np.abs(xy[:, 0] - 5) * np.cos(np.radians(30))
    border = np.minimum.reduce([xy[:, 0], 10 - xy[:, 0], xy[:, 1], 10 - xy[:, 1]])
    res = covariance(pts, k=k)
    if k is None:
        rk = float(np.median(res.features["OptimalRadius"]))
    else:
        d, _ = cKDTree(pts).query(pts[::50], k=k)
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
    p.add_argument("--k", type=int, default=None,
                   help="fixed neighbourhood size (default: the automatic scale)")
    p.add_argument("--json", default=None, help="write the figures here")
    a = p.parse_args(argv)
    step = 0.004 if a.quick else 0.0025
    res = {"step": step, "k": a.k if a.k is not None else "automatic",
           "gable": gable(np.random.default_rng(0), a.k)}
    for name in ("tls_building", "tls_plant"):
        res[name] = tls(name, step, a.k)
    print(json.dumps(res, indent=1))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
