#!/usr/bin/env python
"""Bit-identity check of the covariance features, classes and segmentation across versions.

``dump`` writes every output of ``covariance(..., keep_neighbors=True)`` (all feature and
class fields, centroids, axes, kept neighbourhoods) and of ``segment_covariance`` (labels,
fields, plane table, lines; also the run that classifies by itself) on three clouds -
``tls_building`` and ``tls_plant`` (step 0.004, with their scanner) and the 200k-point
airborne-like cloud of ``bench_curvature.py`` - to one ``.npz`` per cloud; ``compare``
says which arrays differ between two dumps (``numpy.array_equal``, NaN equal to NaN).
A speed change that claims identical results must print ``ALL IDENTICAL``.

Usage::

    mkdir -p /tmp/s5 && git archive REV src | tar -x -C /tmp/s5
    PYTHONPATH=/tmp/s5/src NUMBA_CACHE_DIR=/tmp/s5/numba \\
        python benchmarks/covariance_identity.py dump /tmp/ident_old
    PYTHONPATH=src python benchmarks/covariance_identity.py dump /tmp/ident_new
    python benchmarks/covariance_identity.py compare /tmp/ident_old /tmp/ident_new
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
NAMES = ("tls_building", "tls_plant", "als200k")


def _cloud(name):
    if name == "als200k":
        sys.path.insert(0, str(HERE))
        from bench_curvature import make_cloud

        return make_cloud(200_000)[0], None
    from lidarstat.synth import make_tls_building, make_tls_plant

    make = {"tls_building": make_tls_building, "tls_plant": make_tls_plant}[name]
    cloud = make(step=0.004, rng=0)
    return cloud.xyz, cloud.scanner


def dump(out, names=NAMES):
    from lidarstat.classify import covariance
    from lidarstat.segment import segment_covariance

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        t0 = time.perf_counter()
        xyz, sensor = _cloud(name)
        res = covariance(xyz, sensor=sensor, k=50, keep_neighbors=True)
        feats = res.features
        d = {f"feat_{k}": v for k, v in feats.fields.items()}
        for a in ("centroid", "major", "offset_uv", "mean_variation", "ray_range", "ray_cos",
                  "scan_boundary"):
            if getattr(feats, a) is not None:
                d[f"feat_{a}"] = getattr(feats, a)
        nb = feats.neighborhoods
        d.update(nbh_indptr=nb.indptr, nbh_indices=nb.indices, nbh_distances=nb.distances)
        d.update({f"cls_{k}": np.asarray(v) for k, v in res.classes.fields.items()})
        d["cls_point_class"] = res.classes.point_class
        seg = segment_covariance(xyz, res)
        d["seg_labels"] = seg.labels
        d.update({f"segf_{k}": np.asarray(v) for k, v in seg.fields.items()})
        d.update({f"segt_{k}": np.asarray(v) for k, v in seg.table.items()})
        if seg.lines is not None:
            d.update({f"line_{i}": v for i, v in enumerate(seg.lines.vertices)})
            d.update({f"linea_{k}": np.asarray(v) for k, v in seg.lines.attributes.items()})
        d["seg2_labels"] = segment_covariance(
            xyz, covariance(xyz, sensor=sensor, keep_neighbors=True)).labels
        np.savez(out / f"{name}.npz", **d)
        print(f"{name}: {len(xyz)} points, {len(d)} arrays, {seg.n_segments} segments, "
              f"{0 if seg.lines is None else len(seg.lines.vertices)} lines "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)


def compare(a_dir, b_dir, names=NAMES):
    bad = 0
    for name in names:
        a, b = np.load(Path(a_dir) / f"{name}.npz"), np.load(Path(b_dir) / f"{name}.npz")
        if set(a.files) != set(b.files):
            print(f"{name}: the arrays differ: {sorted(set(a.files) ^ set(b.files))}")
            bad += 1
        diff = [k for k in sorted(set(a.files) & set(b.files))
                if a[k].dtype != b[k].dtype or a[k].shape != b[k].shape
                or not np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind in "fc")]
        bad += len(diff)
        print(f"{name}: {len(set(a.files) & set(b.files))} arrays compared, "
              f"{len(diff)} differ{': ' + ', '.join(diff) if diff else ''}")
    print("ALL IDENTICAL" if bad == 0 else f"{bad} differences")
    return bad


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("dump")
    p.add_argument("out")
    p = sub.add_parser("compare")
    p.add_argument("a")
    p.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out)
        return 0
    return 1 if compare(args.a, args.b) else 0


if __name__ == "__main__":
    sys.exit(main())
