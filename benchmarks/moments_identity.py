#!/usr/bin/env python
"""Field-by-field check of ``moments`` across two versions of the package.

``dump`` runs :func:`lidarstat.classify.moments` on a seed sweep of the synthetic airborne
cloud of ``bench_moments.py`` (quantised to the millimetre as a LAS file holds it) - with
intensity and returns, without intensity, in a frame with negative coordinates, with a few
low-noise echoes and with copies of points - and writes every per-point field, the
building fields and each analysis step's dip tests and cut to one ``.npz``; ``compare``
counts, per array, the values that differ (NaN equal to NaN) and writes the counts as
JSON. A speed change that claims identical results must count zeros. ``--files`` adds real
files of ``../shared/data`` (their classes, heights and tolerances, run as the command runs
them: intensity, returns and the file's units).

Usage::

    mkdir -p /tmp/old && git archive REV src | tar -x -C /tmp/old
    PYTHONPATH=/tmp/old/src python benchmarks/moments_identity.py dump /tmp/mom_old.npz
    PYTHONPATH=src python benchmarks/moments_identity.py dump /tmp/mom_new.npz
    python benchmarks/moments_identity.py compare /tmp/mom_old.npz /tmp/mom_new.npz \\
        --out benchmarks/results_moments_identity.json
"""

from __future__ import annotations

import argparse
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _clouds(n, seeds):
    """(name, xyz, intensity, number_of_returns, return_number) of the sweep."""
    sys.path.insert(0, str(HERE))
    from bench_moments import make_cloud

    for seed in range(seeds):
        xyz, inten, nret, rnum, _ = make_cloud(n, seed=seed)
        xyz = np.round(xyz, 3)  # millimetre coordinates, as read from a LAS file
        inten = np.clip(np.round(inten), 0, 65535).astype(np.uint16)
        yield f"als{seed}", xyz, inten, nret, rnum
        if seed == 0:
            yield "no_intensity", xyz, None, nret, rnum
        if seed == 1:  # negative x: the canonical order's comparison sort
            yield "negative", xyz - [500_400.0, 500_100.0, 0.0], inten, nret, rnum
        if seed == 2:  # low noise and copies of points
            g = np.random.default_rng(seed)
            low = g.choice(n, 40, replace=False)
            # in place: the clouds yielded before are classified by then (memory at 10M)
            xyz[low, 2] -= g.uniform(2.0, 8.0, low.size)
            copies = g.choice(n, n // 50, replace=False)
            idx = np.r_[np.arange(n), copies]
            xyz, inten, nret, rnum = (a[idx] for a in (xyz, inten, nret, rnum))
            yield "noise_copies", xyz, inten, nret, rnum


def _real(out, files):
    """The fields of `moments` on real files (relative to ``../shared/data``) into `out`."""
    import warnings

    from lidarstat.classify import moments
    from lidarstat.io import linear_units, read

    data = HERE.parents[1] / "shared" / "data"
    for f in files:
        cloud = read(data / f)
        a = cloud.attributes
        kw = {}
        if "number_of_returns" in a:
            kw = {"number_of_returns": a["number_of_returns"],
                  "return_number": a["return_number"]}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            units = linear_units(cloud.crs, header=cloud.las_header, source=str(data / f))
            r = moments(cloud.xyz, a.get("intensity"), source=str(data / f), units=units, **kw)
        for k, v in r.to_fields().items():
            out[f"{f}/{k}"] = np.asarray(v)
        print(f"{f}: {len(cloud.xyz):,} points", flush=True)


def dump(path, n=200_000, seeds=3, files=()):
    from lidarstat.classify import moments

    count = 0
    real = {}
    _real(real, files)
    # each cloud's arrays go to the archive as they are made (the layout of
    # ``np.savez_compressed``): at 10 million points a sweep's fields would not fit
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for k, v in real.items():
            with zf.open(k + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.ascontiguousarray(v), allow_pickle=False)
        count += len(real)
        del real
        for name, xyz, inten, nret, rnum in _clouds(n, seeds):
            r = moments(xyz, inten, number_of_returns=nret, return_number=rnum)
            out = {}
            for k, v in r.to_fields().items():
                out[f"{name}/{k}"] = np.asarray(v)
            for k, v in r.building_fields.items():
                out[f"{name}/building:{k}"] = np.asarray(v)
            dips = [(d["dip"], d["pvalue"]) for s in r.steps for d in s.dip.values()]
            out[f"{name}/steps:dips"] = np.array(dips, float).reshape(-1, 2)
            out[f"{name}/steps:cuts"] = np.array([s.choice.threshold for s in r.steps], float)
            out[f"{name}/windows:thresholds"] = np.array(
                [np.nan if w["threshold"] is None else w["threshold"] for w in r.windows],
                float)
            del r
            for k, v in out.items():
                with zf.open(k + ".npy", "w", force_zip64=True) as fh:
                    np.lib.format.write_array(fh, np.ascontiguousarray(v), allow_pickle=False)
            count += len(out)
            del out
            print(f"{name}: {len(xyz):,} points", flush=True)
    print(f"wrote {count} arrays to {path}")


def compare(a_path, b_path, out=None, note=None):
    a, b = np.load(a_path), np.load(b_path)
    counts, bad = {}, 0
    for k in sorted(set(a.files) | set(b.files)):
        if k not in a.files or k not in b.files:
            print(f"{k}: in one dump only")
            counts[k] = "missing"
            bad += 1
            continue
        x, y = a[k], b[k]
        if x.dtype != y.dtype or x.shape != y.shape:
            print(f"{k}: {x.dtype}{x.shape} against {y.dtype}{y.shape}")
            counts[k] = "shape or type"
            bad += 1
            continue
        same = (x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == "f" else x == y
        counts[k] = int(same.size - same.sum())
        if counts[k]:
            print(f"{k}: {counts[k]} of {x.size} differ")
            bad += 1
    print(f"{len(counts)} arrays compared, {bad} differ")
    if out:
        Path(out).write_text(json.dumps({
            "what": "values that differ between two dumps of benchmarks/moments_identity.py "
                    "(every per-point field, building field, dip test and cut of the "
                    "moments classification on a seed sweep of synthetic airborne clouds)",
            "a": str(a_path), "b": str(b_path), **({"code": note} if note else {}),
            "arrays": len(counts),
            "arrays_that_differ": bad, "differences": counts}, indent=1) + "\n")
    return 0 if bad == 0 else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--points", type=int, default=200_000)
    d.add_argument("--seeds", type=int, default=3)
    d.add_argument("--files", nargs="*", default=(),
                   help="real files too (paths under ../shared/data)")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--out", default=None, help="JSON of the counts")
    c.add_argument("--note", default=None, help="what code each dump ran (stored in --out)")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.points, args.seeds, args.files)
        return 0
    return compare(args.a, args.b, args.out, args.note)


if __name__ == "__main__":
    sys.exit(main())
