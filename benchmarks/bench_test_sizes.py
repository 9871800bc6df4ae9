"""Size and power of the curvature tests by simulation, and the agpart figures of the docs.

Writes ``benchmarks/results_curvature_tests.json`` and prints the markdown tables of
docs/methods/curvature.md:

    python benchmarks/bench_test_sizes.py [--replicates 4000]
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

from lidarstat.features import (Test, Weight, curvature, curvature_tests, fit_jets,
                                fit_quadrics, height_variance, jet_tests, optimal_bandwidth)
from lidarstat.neighbors import radius_neighbors
from lidarstat.report._demo import face_radius_table
from lidarstat.synth import make_agpart
from lidarstat.synth._replicates import make_replicates

SIGMA, ALPHA = 0.01, 0.05
HERE = Path(__file__).resolve().parent


def simulate(kind, test, n, seed, **kw):
    pts, centres = make_replicates(kind, n_replicates=n, sigma=SIGMA, rng=seed, **kw)
    fit = fit_quadrics(pts, radius_neighbors(pts, 1.0, query=centres),
                       covariance="paper" if test == Test.PAPER else "sandwich")
    out = dict(status=fit.status, npts=fit.neighbors, beta=fit.beta, cof=fit.cofactor,
               frames=fit.frame, stats=np.c_[fit.q, fit.sum_w, fit.trace_b, fit.trace_b2])
    return curvature_tests(out, sigma2=height_variance(fit.frame, SIGMA), alpha=ALPHA, test=test)


def jet_rejections(kind, weight, n, seed, **kw):
    """Share of independent neighbourhoods whose degree-4 jet the chi-square rejects."""
    pts, centres = make_replicates(kind, n_replicates=n, sigma=SIGMA, rng=seed, **kw)
    fit = fit_jets(pts, radius_neighbors(pts, 1.0, query=centres), degree=4, weight=weight)
    fields = jet_tests(fit, height_variance(fit.frame, SIGMA), ALPHA)
    ok = fit.status == 0
    return float(1.0 - fields["chi2_pass"][ok].mean())


def rate(res, what):
    if what == "chi2":
        return 1.0 - res["chi2_pass"].mean()
    key, lvl = {"planarity": ("planar_p", ALPHA), "K": ("K_p", ALPHA / 2),
                "H": ("H_p", ALPHA / 2)}[what]
    return float(np.mean(res[key] < lvl))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--replicates", type=int, default=4000)
    ap.add_argument("--out", default=str(HERE / "results_curvature_tests.json"))
    args = ap.parse_args()
    n = args.replicates
    res = {"replicates": n, "alpha": ALPHA, "sigma": SIGMA, "radius": 1.0, "spacing": 0.2,
           "machine": platform.platform(), "size": [], "power": [], "agpart": []}
    print(f"### Size under each null ({n} independent neighbourhoods, alpha = {ALPHA})\n")
    print("| null (surface) | test | nominal | calibrated | paper |\n|---|---|---|---|---|")
    for kind, what, lvl in [("quadric", "chi2", ALPHA), ("plane", "planarity", ALPHA),
                            ("cylinder", "K", ALPHA / 2), ("minimal_saddle", "H", ALPHA / 2)]:
        c = rate(simulate(kind, "calibrated", n, 1), what)
        p = rate(simulate(kind, "paper", n, 1), what)
        res["size"].append(dict(null=kind, test=what, nominal=lvl, calibrated=c, paper=p))
        print(f"| {kind} | {what} | {lvl:.3f} | {c:.4f} | {p:.4f} |")
    print(f"\n### Power ({n} neighbourhoods, noise {SIGMA}, radius 1)\n")
    print("| alternative | test | calibrated | paper |\n|---|---|---|---|")
    for c in (0.05, 0.1, 0.2):
        a = rate(simulate("ridge", "calibrated", n, 2, curvature=c), "chi2")
        b = rate(simulate("ridge", "paper", n, 2, curvature=c), "chi2")
        res["power"].append(dict(alternative=f"crease, slopes +-{c}", test="chi2",
                                 calibrated=a, paper=b))
        print(f"| crease, slopes +-{c} | chi-square | {a:.3f} | {b:.3f} |")
    for c in (0.01, 0.02, 0.05, 0.1):
        a = rate(simulate("cylinder", "calibrated", n, 3, curvature=c), "planarity")
        b = rate(simulate("cylinder", "paper", n, 3, curvature=c), "planarity")
        res["power"].append(dict(alternative=f"cylinder, curvature {c}", test="planarity",
                                 calibrated=a, paper=b))
        print(f"| cylinder, curvature {c} | planarity | {a:.3f} | {b:.3f} |")
    print("\n### agpart-like scan: recovered radii and acceptance\n")
    print("| noise | radius b | test | accepted | shaft (1.1) | disk (2.0) | bore (0.28) |")
    print("|---|---|---|---|---|---|---|")
    for sigma in (0.0, 0.015):
        scene = make_agpart(sigma=sigma, rng=0)
        for b in (0.2, 0.15):
            for test in Test:
                out = curvature(scene.xyz, radius=b, sigma=max(sigma, 1e-3), test=test,
                                frame="z")  # the paper's experiment, in its frame
                radii = {name: r for name, _, r, _ in face_radius_table(scene, out)}
                acc = float(out["chi2_pass"].mean())
                res["agpart"].append(dict(noise=sigma, radius=b, test=str(test), accepted=acc,
                                          shaft=radii["shaft_side"], disk=radii["disk_side"],
                                          bore=radii["bore_side"]))
                print(f"| {sigma} | {b} | {test} | {100 * acc:.1f}% | "
                      f"{radii['shaft_side']:.3f} | {radii['disk_side']:.3f} | "
                      f"{radii['bore_side']:.3f} |")
    print(f"\n### Chi-square test of the degree-4 jet ({n} neighbourhoods, alpha = {ALPHA})\n")
    print("| weight | size (quadric) | power (crease, slopes +-0.1) |\n|---|---|---|")
    res["jets"] = []
    for w in Weight:
        size = jet_rejections("quadric", w, n, 1)
        power = jet_rejections("ridge", w, n, 2, curvature=0.1)
        res["jets"].append(dict(weight=str(w), size=size, power_crease_0_1=power))
        print(f"| {w} | {size:.4f} | {power:.3f} |")
    # the bandwidth design of eq. 19-21 for the agpart shaft (H0 = -1/(2 R), R = 1.1 dm)
    density = 1 / (0.02 * 0.0168)
    res["bandwidth"] = {str(t): optimal_bandwidth(K0=0, H0=-1 / 2.2, sigma=0.015,
                                                  density=density, test=t).radius
                        for t in Test}
    print(f"\nbandwidth for the agpart shaft (sigma 0.015 dm): {res['bandwidth']}")
    Path(args.out).write_text(json.dumps(res, indent=2))
    print(f"\nwritten {args.out}")


if __name__ == "__main__":
    main()
