#!/usr/bin/env python
"""Field-by-field check of ``curvature`` across two versions of the package.

``dump`` runs :func:`lidarstat.features.curvature` on a seed sweep - the agpart-like scan
(automatic scale; a fixed radius in the ``pca``, ``z`` and ``auto`` frames, ``paper`` and
``calibrated`` tests, minimal detectable curvatures), analytic surfaces with a scanner
(noise along the range), the airborne-like cloud of ``bench_curvature.py`` (60k points,
one and two radii) and a cloud with copies - and writes every field and the sigma used to
one ``.npz``; ``compare`` prints, per field, the largest difference between two dumps
(relative above 1, absolute below) and counts the integer fields and NaN patterns that
differ. A speed change that claims identical results must print zeros.

Usage::

    mkdir -p /tmp/old && git archive REV src | tar -x -C /tmp/old
    PYTHONPATH=/tmp/old/src NUMBA_CACHE_DIR=/tmp/old/numba \\
        python benchmarks/curvature_identity.py dump /tmp/curv_old.npz
    PYTHONPATH=src python benchmarks/curvature_identity.py dump /tmp/curv_new.npz
    python benchmarks/curvature_identity.py compare /tmp/curv_old.npz /tmp/curv_new.npz
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def dump(path, seeds=3):
    sys.path.insert(0, str(HERE))
    from bench_curvature import make_cloud

    from lidarstat.features import curvature
    from lidarstat.synth import make_agpart, make_surface

    out = {}

    def run(name, pts, **kw):
        r = curvature(pts, **kw)
        for k, v in r.fields.items():
            out[f"{name}/{k}"] = np.asarray(v)
        out[f"{name}/_sigma"] = np.array(r.sigma)

    for seed in range(seeds):
        a = make_agpart(sigma=0.015, rng=seed)
        run(f"agpart{seed}_auto", a.xyz)
        run(f"agpart{seed}_r", a.xyz, radius=0.15, sigma=0.015,
            frame=("pca", "z", "auto")[seed % 3], minimal_detectable=True,
            test=("calibrated", "paper", "calibrated")[seed % 3])
        c = make_surface(("cylinder", "sphere", "saddle_ridge")[seed % 3], sigma=0.002, rng=seed)
        run(f"surf{seed}", c.xyz, radius=0.2, sensor=(0.3, -0.2, 5.0))
        x, _ = make_cloud(60000, seed=seed)
        run(f"als{seed}", x, radius=0.9)
        run(f"als{seed}_multi", x, radius=[0.7, 1.2], sigma=0.02)
        run(f"dup{seed}", np.vstack([x[:20000], x[:500]]), radius=0.9, sigma=0.02)
    np.savez_compressed(path, **out)
    print(f"wrote {len(out)} arrays to {path}")


def compare(a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    if set(a.files) != set(b.files):
        print("different arrays:", sorted(set(a.files) ^ set(b.files)))
        return 1
    worst, bad = {}, 0
    for k in sorted(a.files):
        x, y = a[k], b[k]
        if x.dtype != y.dtype or x.shape != y.shape:
            print(f"{k}: {x.dtype}{x.shape} against {y.dtype}{y.shape}")
            bad += 1
            continue
        if x.dtype.kind in "iub":
            n = int((x != y).sum())
            if n:
                print(f"{k}: {n} of {x.size} differ")
                bad += 1
            continue
        nan = np.isnan(x) != np.isnan(y)
        if nan.any():
            print(f"{k}: NaN pattern differs at {int(nan.sum())}")
            bad += 1
        m = ~np.isnan(x) & ~np.isnan(y)
        d = np.abs(x[m] - y[m]) / np.maximum(1.0, np.abs(x[m])) if m.any() else np.zeros(1)
        f = k.split("/")[1]
        worst[f] = max(worst.get(f, 0.0), float(d.max()) if d.size else 0.0)
    print("largest |difference| / max(1, |value|) per field:")
    for f, v in sorted(worst.items()):
        print(f"  {f:<12s} {v:.1e}")
    print(f"integer fields or NaN patterns that differ: {bad}")
    return 0 if bad == 0 else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--seeds", type=int, default=3)
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.seeds)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
