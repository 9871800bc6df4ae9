#!/usr/bin/env python
"""Curvature at the automatic scale against fixed radii and CloudCompare ``-CURV MEAN``:
accuracy on the independent surface family and the agpart-like scan, speed on the
agpart-like scan and an airborne-like cloud, all in one run.

Accuracy: the share of interior points whose surface type equals the truth where the
tests have power (``tests/independent``), and the median relative error of |H| on the
curved interior points (CloudCompare gives no surface type, so only |H| for it). Speed:
wall time of the curvature step, median of `--repeats` runs, the methods alternating
within each repeat (the machine may be shared; compare the ratios).

Usage::

    python benchmarks/curvature_auto.py                  # writes results_curvature_auto.json
    python benchmarks/curvature_auto.py --seeds 1 --points 50000   # quick
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests" / "independent"))

from bench_curvature import make_cloud, write_ply
from indep_surfaces import KINDS, make_surface

from lidarstat.features import curvature, point_spacing
from lidarstat.synth import make_agpart

FIXED_SPACINGS = 6.0  # the fixed radius compared, in point spacings (a mid-ladder rung)


def _methods(spacing):
    r = FIXED_SPACINGS * spacing
    return {
        "auto": dict(),
        "fixed_pca": dict(radius=r),
        "fixed_z": dict(radius=r, frame="z"),
    }


def cloudcompare_h(xyz, radius, tmp):
    """|H| per point and the wall time of CloudCompare -CURV MEAN (None if unavailable)."""
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    xvfb = shutil.which("xvfb-run")
    if exe is None or xvfb is None:
        return None, None
    shift = np.floor(xyz.min(axis=0))
    src, dst = Path(tmp) / "cc_in.ply", Path(tmp) / "cc_out.asc"
    write_ply(src, xyz - shift)
    cmd = [xvfb, "-a", exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP", "-O", str(src),
           "-CURV", "MEAN", f"{radius:.8f}", "-C_EXPORT_FMT", "ASC", "-PREC", "10",
           "-SAVE_CLOUDS", "FILE", str(dst)]
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                        timeout=3600).returncode
    el = time.perf_counter() - t0
    if rc != 0 or not dst.exists():
        return None, None
    out = np.loadtxt(dst)
    # CloudCompare keeps the order of the points
    return np.abs(out[:, 3]), el


def cloudcompare_time(xyz, radius, tmp):
    """Wall time of load + -CURV MEAN minus a load-only run (the curvature step)."""
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    xvfb = shutil.which("xvfb-run")
    if exe is None or xvfb is None:
        return None
    src = Path(tmp) / "cc_time.ply"
    write_ply(src, xyz - np.floor(xyz.min(axis=0)))
    base = [xvfb, "-a", exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP", "-O", str(src)]
    t0 = time.perf_counter()
    subprocess.run(base, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    load = time.perf_counter() - t0
    t0 = time.perf_counter()
    subprocess.run(base + ["-CURV", "MEAN", f"{radius:.8f}"], stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, check=True)
    return max(time.perf_counter() - t0 - load, 0.0)


def _h_error(h_est, h_true, sel):
    sel = sel & np.isfinite(h_est) & (h_true != 0)
    if not sel.any():
        return float("nan")
    return float(np.median(np.abs(np.abs(h_est[sel]) - np.abs(h_true[sel])) / np.abs(h_true[sel])))


def accuracy_family(seeds, tmp):
    from test_indep_curvature import TOP, _powered

    rows = []
    for noise in ("z", "range"):
        for kind in KINDS:
            agg = {}
            for seed in range(seeds):
                s = make_surface(kind, 500 + seed, noise=noise, half=40)
                keep = (s.border > (TOP + 0.5) * s.spacing) & _powered(s)
                h_true = 0.5 * (s.k1 + s.k2)
                for name, kw in _methods(s.spacing).items():
                    res = curvature(s.xyz, sensor=s.sensor, **kw)
                    nrm = np.c_[res["NormalX"], res["NormalY"], res["NormalZ"]]
                    truth = s.oriented_types(nrm)
                    a = agg.setdefault(name, {"right": 0, "n": 0, "h_err": []})
                    a["right"] += int((res["surface_type"][keep] == truth[keep]).sum())
                    a["n"] += int(keep.sum())
                    a["h_err"].append(_h_error(res["H"], h_true,
                                               keep & (res["chi2_pass"] == 1)))
                h_cc, _ = cloudcompare_h(s.xyz, FIXED_SPACINGS * s.spacing, tmp)
                if h_cc is not None:
                    a = agg.setdefault("cloudcompare", {"right": None, "n": 0, "h_err": []})
                    a["h_err"].append(_h_error(h_cc, h_true, keep))
            for name, a in agg.items():
                errs = [e for e in a["h_err"] if e == e]
                rows.append({"kind": kind, "noise": noise, "method": name,
                             "type_right": None if a["right"] is None else a["right"] / max(a["n"], 1),
                             "points": a["n"],
                             "H_rel_error_median": float(np.median(errs)) if errs else None})
                print(f"{noise:5s} {kind:12s} {name:13s} type {rows[-1]['type_right']}"
                      f"  |H| err {rows[-1]['H_rel_error_median']}", flush=True)
    return rows


def accuracy_agpart(tmp):
    scene = make_agpart(sigma=0.015, rng=0)
    s = point_spacing(scene.xyz)
    out = {}
    for name, kw in _methods(s).items():
        res = curvature(scene.xyz, **kw)
        rad = res["radius"] if "radius" in res.fields else kw["radius"]
        inner = scene.edge_distance > rad
        out[name] = {"type_right": float(np.mean(res["surface_type"][inner]
                                                 == scene.surface_type[inner])),
                     "radius_median": float(np.median(rad))}
        print(f"agpart {name:10s} {out[name]}", flush=True)
    return out


def speed(points, repeats, tmp):
    clouds = {"agpart_34k": make_agpart(sigma=0.015, rng=0).xyz,
              f"airborne_{points // 1000}k": make_cloud(points)[0]}
    out = {}
    for cname, xyz in clouds.items():
        s = point_spacing(xyz)
        methods = _methods(s)
        sub = xyz[:5000]
        curvature(sub, radius=3 * s * np.sqrt(xyz.shape[0] / sub.shape[0]), sigma=0.01)
        curvature(sub, sigma=0.01)  # compile outside the timings
        times = {m: [] for m in list(methods) + ["cloudcompare"]}
        for _ in range(repeats):
            for name, kw in methods.items():
                t0 = time.perf_counter()
                curvature(xyz, **kw)
                times[name].append(time.perf_counter() - t0)
            t = cloudcompare_time(xyz, FIXED_SPACINGS * s, tmp)
            if t is not None:
                times["cloudcompare"].append(t)
        out[cname] = {"points": int(xyz.shape[0]), "spacing": s,
                      "fixed_radius": FIXED_SPACINGS * s,
                      **{m: float(np.median(v)) for m, v in times.items() if v}}
        print(f"speed {cname}: {out[cname]}", flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--points", type=int, default=200000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(HERE / "results_curvature_auto.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        results = {
            "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                        "note": "shared machine; compare ratios within this run"},
            "fixed_radius_spacings": FIXED_SPACINGS,
            "family": accuracy_family(args.seeds, tmp),
            "agpart": accuracy_agpart(tmp),
            "speed": speed(args.points, args.repeats, tmp),
        }
    Path(args.out).write_text(json.dumps(results, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
