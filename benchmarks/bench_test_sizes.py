"""Size and power of the curvature tests by simulation, and the agpart figures of the docs.

Prints the markdown tables of docs/methods/curvature.md:

    python benchmarks/bench_test_sizes.py [--replicates 4000]
"""

from __future__ import annotations

import argparse

import numpy as np

from lidarstat.features import curvature, curvature_tests, fit_quadrics, height_variance
from lidarstat.neighbors import radius_neighbors
from lidarstat.report._demo import face_radius_table
from lidarstat.synth import make_agpart
from lidarstat.synth._replicates import make_replicates

SIGMA, ALPHA = 0.01, 0.05


def simulate(kind, test, n, seed, **kw):
    pts, centres = make_replicates(kind, n_replicates=n, sigma=SIGMA, rng=seed, **kw)
    fit = fit_quadrics(pts, radius_neighbors(pts, 1.0, query=centres),
                       covariance="paper" if test == "paper" else "sandwich")
    out = dict(status=fit.status, npts=fit.neighbors, beta=fit.beta, cof=fit.cofactor,
               frames=fit.frame, stats=np.c_[fit.q, fit.sum_w, fit.trace_b, fit.trace_b2])
    return curvature_tests(out, sigma2=height_variance(fit.frame, SIGMA), alpha=ALPHA, test=test)


def rate(res, what):
    if what == "chi2":
        return 1.0 - res["chi2_pass"].mean()
    key, lvl = {"planarity": ("planar_p", ALPHA), "K": ("K_p", ALPHA / 2),
                "H": ("H_p", ALPHA / 2)}[what]
    return float(np.mean(res[key] < lvl))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--replicates", type=int, default=4000)
    n = ap.parse_args().replicates
    print(f"### Size under each null ({n} independent neighbourhoods, alpha = {ALPHA})\n")
    print("| null (surface) | test | nominal | calibrated | paper |\n|---|---|---|---|---|")
    for kind, what, lvl in [("quadric", "chi2", ALPHA), ("plane", "planarity", ALPHA),
                            ("cylinder", "K", ALPHA / 2), ("minimal_saddle", "H", ALPHA / 2)]:
        c = rate(simulate(kind, "calibrated", n, 1), what)
        p = rate(simulate(kind, "paper", n, 1), what)
        print(f"| {kind} | {what} | {lvl:.3f} | {c:.4f} | {p:.4f} |")
    print(f"\n### Power ({n} neighbourhoods, noise {SIGMA}, radius 1)\n")
    print("| alternative | test | calibrated | paper |\n|---|---|---|---|")
    for c in (0.05, 0.1, 0.2):
        a = rate(simulate("ridge", "calibrated", n, 2, curvature=c), "chi2")
        b = rate(simulate("ridge", "paper", n, 2, curvature=c), "chi2")
        print(f"| crease, slopes +-{c} | chi-square | {a:.3f} | {b:.3f} |")
    for c in (0.01, 0.02, 0.05, 0.1):
        a = rate(simulate("cylinder", "calibrated", n, 3, curvature=c), "planarity")
        b = rate(simulate("cylinder", "paper", n, 3, curvature=c), "planarity")
        print(f"| cylinder, curvature {c} | planarity | {a:.3f} | {b:.3f} |")
    print("\n### agpart-like scan: recovered radii and acceptance\n")
    print("| noise | radius b | test | accepted | shaft (1.1) | disk (2.0) | bore (0.28) |")
    print("|---|---|---|---|---|---|---|")
    for sigma in (0.0, 0.015):
        scene = make_agpart(sigma=sigma, rng=0)
        for b in (0.2, 0.15):
            for test in ("calibrated", "paper"):
                res = curvature(scene.xyz, radius=b, sigma=max(sigma, 1e-3), test=test)
                radii = {name: r for name, _, r, _ in face_radius_table(scene, res)}
                print(f"| {sigma} | {b} | {test} | {100 * res['chi2_pass'].mean():.1f}% | "
                      f"{radii['shaft_side']:.3f} | {radii['disk_side']:.3f} | "
                      f"{radii['bore_side']:.3f} |")


if __name__ == "__main__":
    main()
