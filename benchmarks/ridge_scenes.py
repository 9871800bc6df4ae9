#!/usr/bin/env python
"""Direct (ridges) against indirect segmentation on the synthetic scenes with exact truth.

For every scene the script runs, in the same process:

* ``ridges`` (degree-4 jets, zero crossings of the extremalities, ridge lines) and the
  direct segmentation ``ridge_segments`` (ridge band + jets rejected by the chi-square
  test, barrier points assigned by the units' jets, unit boundaries as crease points);
* unless ``--skip-indirect``, the indirect segmentation where it applies: ``segment_curvature(refine=True)`` (tested
  curvature classes refined by SAR + Forward Search) on the range scans, ``segment_sar``
  (SAR + Forward Search on heights) on the airborne hip-roof scene (a 2.5-D method: it
  does not apply to the terrestrial scan's walls).

Scores: Hoover et al. (1996) at T = 0.8 against the scene's faces (range scans: also
against the connected parts of each face; TLS: faces of at least 200 points; ALS: the roof
planes); crease coverage (``lidarstat.segment.crease_coverage``): the share of the visible
true crease length with a detected point within one point spacing, for the ridge points,
the crease points (unit boundaries) and both; and the precision of those points (share
within one and 2.5 spacings of a true edge). Timings are wall seconds on whatever machine
runs it (compilation excluded by a warm-up on a small scene).

Usage::

    PYTHONPATH=src python benchmarks/ridge_scenes.py --quick   # column + hip roof, ~1 min
    PYTHONPATH=src python benchmarks/ridge_scenes.py           # all four scenes ->
                                                               # benchmarks/results_ridges.json
    PYTHONPATH=src python benchmarks/ridge_scenes.py --skip-indirect   # direct only
    PYTHONPATH=src python benchmarks/ridge_scenes.py --skip-indirect --scales auto k50

Each scene runs at its fixed radius (``fixed``), at the automatic scale (``auto``: no
radius; ``auto_curvature``: with the criterion of a significant curvature), at the
smallest radius of the ladder (``segment_default``: the default of ``segment --method
ridges``) and at ``k = 50`` (``k50``), sigma given; key ``scenes`` of the results file
(``ridge_family.py`` writes the key ``family``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))

from lidarstat.neighbors import knn_neighbors  # noqa: E402
from lidarstat.segment import (components, crease_coverage, hoover, ridge_segments,  # noqa: E402
                               ridges, segment_curvature, segment_sar)
from lidarstat.synth import (make_agpart, make_column, make_hip_roof_scene,  # noqa: E402
                             make_tls_building)

#: scene -> (factory kwargs, ridges kwargs, point spacing for the coverage tolerance)
SCENES = {
    "agpart": (dict(sigma=0.0015, rng=0), dict(radius=0.2, sigma=0.0015, alpha=0.01), 0.02),
    "column": (dict(sigma=0.0015, rng=0), dict(radius=0.2, sigma=0.0015, alpha=0.01), 0.02),
    # range noise 0.002 + 5e-5 r m: sigma given at about 30 m (the house's range)
    "tls_building": (dict(rng=0), dict(radius=0.3, sigma=0.0035, alpha=0.01), 0.05),
    "hip_roof": (dict(rng=1), dict(radius=1.5, sigma=0.03, alpha=0.01), 0.26),
}
FACTORY = dict(agpart=make_agpart, column=make_column, tls_building=make_tls_building,
               hip_roof=make_hip_roof_scene)


def connected_parts(xyz, face, k=8):
    """Truth units: the connected parts of each face over the k-NN graph."""
    nb = knn_neighbors(xyz, k)
    src = np.repeat(np.arange(len(xyz)), np.diff(nb.indptr))
    return components(nb, edge_ok=face[src] == face[nb.indices])


def score(labels, truth, min_size):
    h = hoover(labels, truth, 0.8, min_points=min_size)
    return dict(correct=h.correct, n_truth=h.n_truth, over=h.over, under=h.under,
                missed=h.missed, noise=h.noise)


def coverage(sc, mask, tol, creases, truth_face):
    xt = sc.meta.get("xyz_true", sc.xyz)
    cov = crease_coverage(creases, sc.xyz[mask], tol, points=xt, faces=truth_face)
    ed = sc.edge_distance[mask]
    return dict(coverage=round(cov.ratio, 4), visible_length=round(cov.length, 3),
                points=int(mask.sum()),
                within_1_spacing=round(float(np.mean(ed < tol)), 4) if mask.any() else None,
                within_2_5_spacings=round(float(np.mean(ed < 2.5 * tol)), 4)
                if mask.any() else None)


def scale_kwargs(rkw, scale, xyz):
    """The scene's ridges options at `scale`: 'fixed' (its radius), 'auto' (no radius: the
    automatic scale) or 'k50' (50 nearest neighbours); sigma and alpha as given."""
    rkw = dict(rkw)
    if scale != "fixed":
        rkw.pop("radius")
    if scale == "auto_curvature":
        from lidarstat.features import CURVATURE_SCALE

        rkw["scale_criterion"] = CURVATURE_SCALE
    if scale == "segment_default":
        from lidarstat.features import radius_ladder

        rkw["radius"] = float(radius_ladder(xyz)[0])
    if scale == "k50":
        rkw["k"] = 50
    return rkw


def run_scene(name, indirect=True, scale="fixed"):
    kw, rkw, tol = SCENES[name]
    sc = FACTORY[name](**kw)
    rkw = scale_kwargs(rkw, scale, sc.xyz)
    out = dict(scene=name, scale=scale, points=len(sc.xyz), spacing=tol,
               ridges_params={k: v for k, v in rkw.items() if k != "scale_criterion"})
    if name == "tls_building":
        rkw = dict(rkw, sensor=sc.scanner)
    t0 = time.perf_counter()
    res = ridges(sc.xyz, **rkw)
    out["seconds_ridges"] = round(time.perf_counter() - t0, 2)
    if scale.startswith("auto"):
        out["radius_median"] = res.params.get("radius_median")
        out["points_per_radius"] = dict(zip([round(r, 4) for r in res.params["radii"]],
                                            res.params["points_per_radius"]))
    t0 = time.perf_counter()
    seg = ridge_segments(sc.xyz, res)
    out["seconds_segments"] = round(time.perf_counter() - t0, 2)
    face = sc.face.astype(np.int64)
    if name == "hip_roof":
        truth = {"roof_planes": sc.fields["roof_plane"].astype(int)}
        min_size = 0
        creases = [c for cs in sc.meta["edges"].values() for c in cs]
    elif name == "tls_building":
        truth = {"faces": face + 1}
        min_size = 200
        creases = sc.meta["edges"]
    else:
        truth = {"faces": face + 1, "connected_parts": connected_parts(sc.xyz, face)}
        min_size = 50
        creases = sc.meta["creases"]
    out["hoover"] = {"direct": {t: score(seg.labels, v, min_size) for t, v in truth.items()}}
    ridge = seg.fields["ridge"] > 0
    crease = seg.fields["crease"] > 0
    cface = face if name != "hip_roof" else sc.face.astype(np.int64)
    out["crease_coverage"] = {
        "ridge_points": coverage(sc, ridge, tol, creases, cface),
        "crease_points": coverage(sc, crease, tol, creases, cface),
        "ridge_or_crease": coverage(sc, ridge | crease, tol, creases, cface),
        "barrier": coverage(sc, seg.fields["barrier"] > 0, tol, creases, cface)}
    out["n_segments"] = int(seg.n_segments)
    t0 = time.perf_counter()
    if not indirect or scale != "fixed":
        ind = None
        out["indirect"] = "not run (--skip-indirect)"
    elif name in ("agpart", "column"):
        ind = segment_curvature(sc.xyz, radius=0.2, sigma=0.0015, refine=True)
        out["indirect"] = "segment_curvature(radius=0.2, sigma=0.0015, refine=True)"
    elif name == "hip_roof":
        ind = segment_sar(sc.xyz)
        out["indirect"] = "segment_sar() (defaults, automatic bandwidth)"
    else:
        ind = None
        out["indirect"] = "none: SAR-FS models heights z = f(x, y), not walls"
    if ind is not None:
        out["seconds_indirect"] = round(time.perf_counter() - t0, 2)
        out["hoover"]["indirect"] = {t: score(ind.labels, v, min_size) for t, v in truth.items()}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="column and hip roof only, no JSON")
    ap.add_argument("--scenes", nargs="*", default=None)
    ap.add_argument("--out", default=str(HERE / "results_ridges.json"))
    ap.add_argument("--skip-indirect", action="store_true",
                    help="only the direct segmentation (the indirect methods take minutes)")
    ap.add_argument("--scales", nargs="*",
                    default=["fixed", "auto", "auto_curvature", "segment_default", "k50"],
                    help="jet scales to run: fixed (the scene's radius), auto, auto_curvature "
                    "(automatic with the curvature criterion), segment_default (the smallest "
                    "radius of the ladder, segment --method ridges' default), k50")
    args = ap.parse_args(argv)
    names = args.scenes or (["column", "hip_roof"] if args.quick else list(SCENES))
    # warm-up: compile the kernels on a small scene (not timed)
    ridge_segments(make_column(spacing=0.06, sigma=0.0015, rng=0).xyz,
                   ridges(make_column(spacing=0.06, sigma=0.0015, rng=0).xyz, radius=0.3,
                          sigma=0.0015))
    results = [run_scene(n, not args.skip_indirect, sc) for sc in args.scales for n in names]
    print("| scene | scale | points | Hoover direct | Hoover indirect | "
          "coverage ridge / crease / both | crease points within 1 / 2.5 spacings |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        h = r["hoover"]
        cells = []
        for key in ("direct", "indirect"):
            if key not in h:
                cells.append("-")
                continue
            parts = []
            for t, s in h[key].items():
                parts.append(f"{t} {s['correct']}/{s['n_truth']}")
            cells.append(", ".join(parts))
        c = r["crease_coverage"]
        cp = c["crease_points"]
        print(f"| {r['scene']} | {r['scale']} | {r['points']} | {cells[0]} | {cells[1]} | "
              f"{c['ridge_points']['coverage']:.3f} / {cp['coverage']:.3f} / "
              f"{c['ridge_or_crease']['coverage']:.3f} | {cp['within_1_spacing']} / "
              f"{cp['within_2_5_spacings']} |")
    if not args.quick:
        path = Path(args.out)
        data = json.loads(path.read_text()) if path.exists() else {}
        if isinstance(data, list):
            data = {}
        if len(args.scales) < 5:  # a partial rerun keeps the other scales' rows
            keep = [r for r in data.get("scenes", []) if r.get("scale") not in args.scales]
            results = keep + results
        data["scenes"] = results
        path.write_text(json.dumps(data, indent=1, default=float))
        print(f"written {args.out}")
    return results


if __name__ == "__main__":
    main()
