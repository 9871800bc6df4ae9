#!/usr/bin/env python
"""Field-by-field check of ``curvature`` across two versions of the package.

``dump`` runs :func:`lidarstat.features.curvature` on a seed sweep - the agpart-like scan
(automatic scale; a fixed radius in the ``pca``, ``z`` and ``auto`` frames, ``paper`` and
``calibrated`` tests, minimal detectable curvatures), analytic surfaces with a scanner
(noise along the range), the airborne-like cloud of ``bench_curvature.py`` (60k points,
one and two radii) and a cloud with copies - and writes every field and the sigma used to
one ``.npz``; ``compare`` prints, per field, the largest difference between two dumps
(relative above 1, absolute below) and counts the integer fields and NaN patterns that
differ. A speed change that claims identical results must print zeros. ``compare
--above N`` repeats the comparison over the points with more than N neighbours (a fit
with 7 or 8 neighbours has one or two residual degrees of freedom: its traces tr(B),
tr(B^2) are differences of nearly equal numbers and move with any change of rounding).
``dump --permute`` feeds every scene's points in a random order and puts the fields back
in input order: the same version's own spread under a reordering, to set a change's
differences against (the estimated sigma also moves: its sample depends on the order).

Usage::

    mkdir -p /tmp/old && git archive REV src | tar -x -C /tmp/old
    PYTHONPATH=/tmp/old/src NUMBA_CACHE_DIR=/tmp/old/numba \\
        python benchmarks/curvature_identity.py dump /tmp/curv_old.npz
    PYTHONPATH=src python benchmarks/curvature_identity.py dump /tmp/curv_new.npz
    python benchmarks/curvature_identity.py compare /tmp/curv_old.npz /tmp/curv_new.npz

``compare --store FILE KEY`` also writes the figures under ``KEY`` of the results file
(entry ``all``, or ``above_N`` with ``--above N``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def dump(path, seeds=3, permute=False):
    sys.path.insert(0, str(HERE))
    from bench_curvature import make_cloud

    from lidarstat.features import curvature
    from lidarstat.synth import make_agpart, make_surface

    out = {}

    def run(name, pts, **kw):
        if permute:
            perm = np.random.default_rng(len(out)).permutation(pts.shape[0])
            r = curvature(pts[perm], **kw)
            back = np.empty_like(perm)
            back[perm] = np.arange(perm.size)
        else:
            r, back = curvature(pts, **kw), slice(None)
        for k, v in r.fields.items():
            out[f"{name}/{k}"] = np.asarray(v)[back]
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


def compare(a_path, b_path, above=None, store=None):
    a, b = np.load(a_path), np.load(b_path)
    if above is not None:
        rc, worst, bad = _compare_above(a, b, above)
        _store(store, f"above_{above}", worst, bad)
        return rc
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
    _store(store, "all", worst, bad)
    return 0 if bad == 0 else 1


def _compare_above(a, b, above):
    """Largest differences and differing integer values over the points with more than
    `above` neighbours (in the first dump), per field."""
    worst, bad = {}, 0
    for k in sorted(a.files):
        scene, f = k.split("/")
        if f.startswith("_") or a[k].ndim != 1:
            continue
        keep = a[f"{scene}/neighbors"] > above
        x, y = a[k][keep], b[k][keep]
        if x.dtype.kind in "iub":
            bad += int((x != y).sum())
            continue
        bad += int((np.isnan(x) != np.isnan(y)).sum())
        m = ~np.isnan(x) & ~np.isnan(y)
        if m.any():
            d = np.abs(x[m] - y[m]) / np.maximum(1.0, np.abs(x[m]))
            worst[f] = max(worst.get(f, 0.0), float(d.max()))
    print(f"points with more than {above} neighbours, largest |difference| / max(1, |value|):")
    for f, v in sorted(worst.items()):
        print(f"  {f:<12s} {v:.1e}")
    print(f"integer values or NaN patterns that differ: {bad}")
    return (0 if bad == 0 else 1), worst, bad


def _store(store, name, worst, bad):
    """Write one comparison to ``store = (results file, key)``: under ``key`` of the JSON
    file, entry `name` (``all`` or ``above_N``), keeping the file's other keys."""
    if store is None:
        return
    path, key = Path(store[0]), store[1]
    res = json.loads(path.read_text()) if path.exists() else {}
    entry = res.setdefault(key, {})
    entry["how"] = ("python benchmarks/curvature_identity.py dump (main, then this version), "
                    "compare [--above N]: largest |difference| / max(1, |value|) per field "
                    "over the seed sweep; integer fields and NaN patterns that differ")
    entry[name] = {
        "largest_difference": {f: float(f"{v:.1e}") for f, v in sorted(worst.items())},
        "integer_or_nan_differences": int(bad)}
    path.write_text(json.dumps(res, indent=1) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--seeds", type=int, default=3)
    d.add_argument("--permute", action="store_true",
                   help="feed each scene's points in a random order (fields put back)")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--above", type=int, default=None, metavar="N",
                   help="only the points with more than N neighbours")
    c.add_argument("--store", nargs=2, default=None, metavar=("FILE", "KEY"),
                   help="also write the figures under KEY of the results file FILE")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.seeds, args.permute)
        return 0
    return compare(args.a, args.b, args.above, args.store)


if __name__ == "__main__":
    sys.exit(main())
