"""Benchmark of ``segment --method sar`` (seed 002) and of the SAR fit against PySAL spreg.

Full mode (a few minutes on an otherwise idle machine):

    python benchmarks/bench_sar.py

* the whole ``segment_sar`` on a synthetic airborne town scaled to ~1 million points
  (``make_als_town`` over 400 x 300 m at 8 pulses/m^2) with its defaults (automatic
  bandwidth, multi-scale windows, estimated noise), the SAR stage alone
  (``planes=False``: the second stage's planes are scored by
  ``tests/segment/test_sar_planes.py`` and ``benchmarks/real_sar.py``), with the Hoover
  scores of the roof planes and the normal errors of the correct ones;
* on the same run, PySAL ``spreg.ML_Lag`` (its default method 'full') and
  ``lidarstat.stats.sar_fit`` on the same 5,000-point cluster with the same W: time ratio
  and the agreement of rho and theta.

Writes ``benchmarks/results_sar.json`` and prints a markdown table. ``--quick`` runs a
small town and a 1,000-point cluster in seconds (to check the script works).

``--hip-roof`` runs only seed 002's first data set (``make_hip_roof_scene(rng=1)``, about
31,000 points, a minute): the paper's Table 6 in form (``n_s``, ``n_sa``, ``m`` of the four
hip planes) and the normal errors, written under ``"hip_roof"`` into
``benchmarks/results_sar.json`` (the other keys are kept), and the figures
``docs/figures/sar_hip_roof_scene.png`` (top view by segment) and
``docs/figures/sar_hip_fs_north.png`` (Forward Search monitoring of the North plane).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import warnings
from pathlib import Path

import numpy as np


def _town(extent, density, rng=1):
    from lidarstat.synth import make_als_town

    t = time.perf_counter()
    cloud = make_als_town(extent=extent, density=density, rng=rng)
    return cloud, time.perf_counter() - t


def _normal_errors(cloud, seg, min_points=30):
    """Per correctly found roof plane (Hoover 0.8, planes of at least `min_points` points):
    the angle (degrees) between its table normal and the truth, the propagated angular
    standard error ``normal_se_deg`` and ``t2``, the Mahalanobis distance of the true
    gradient (chi-square(2) when the plane is unbiased and its covariance right)."""
    rp = cloud.fields["roof_plane"].astype(int)
    planes = cloud.meta["roof_planes"]
    normals = np.c_[seg.table["normal_x"], seg.table["normal_y"], seg.table["normal_z"]]
    errors, ses, t2s = [], [], []
    for pid, n_true in zip(planes["id"], planes["normal"]):
        mine = rp == pid
        if mine.sum() < min_points:
            continue
        lab = seg.labels[mine]
        lab = lab[lab > 0]
        if lab.size == 0:
            continue
        s = int(np.bincount(lab).argmax())
        overlap = np.count_nonzero(seg.labels[mine] == s)
        if overlap < 0.8 * mine.sum() or overlap < 0.8 * np.count_nonzero(seg.labels == s):
            continue  # not a correct detection at tolerance 0.8
        c = min(1.0, abs(float(normals[s - 1] @ np.asarray(n_true))))
        errors.append(float(np.degrees(np.arccos(c))))
        cen = [seg.table["centroid_x"][s - 1], seg.table["centroid_y"][s - 1],
               seg.table["centroid_z"][s - 1]]
        se, _, t2 = seg.units[s - 1].normal_error(cen, n_true)
        ses.append(float(se[0]))
        t2s.append(float(t2[0]))
    return np.array(errors), np.array(ses), np.array(t2s)


def _normal_stats(err, se, t2):
    """The three normal figures: share within 0.5 degrees, calibration of the confidence
    cones (coverage at 95 % with its binomial 99 % interval, KS test of t2 ~ chi2(2)) and
    the share within 0.5 degrees where 0.5 degrees is at least 3 standard errors."""
    from scipy import stats

    if not err.size:
        return {}
    cover = int(np.count_nonzero(t2 <= stats.chi2.ppf(0.95, 2)))
    lo, hi = stats.binom.interval(0.99, t2.size, 0.95)
    ok = se < 0.5 / 3
    return {"normal_error_median_deg": round(float(np.median(err)), 3),
            "normal_error_max_deg": round(float(err.max()), 3),
            "normals_within_0.5_deg": round(float(np.mean(err < 0.5)), 4),
            "cone95_coverage": round(cover / t2.size, 4),
            "cone95_covered": cover, "cone95_planes": int(t2.size),
            "cone95_binomial99": [int(lo), int(hi)],
            "t2_mean": round(float(t2.mean()), 3),
            "t2_ks_pvalue_chi2_2": round(float(stats.kstest(t2, "chi2", args=(2,)).pvalue), 4),
            "normal_se_median_deg": round(float(np.median(se)), 3),
            "planes_se_below_0.167_deg": int(ok.sum()),
            "within_0.5_deg_where_se_below_0.167": round(float(np.mean(err[ok] < 0.5)), 4)
            if ok.any() else None}


def _clutter(cloud, seg, sigma):
    """Chimney/wall (building points off the roof planes) and vegetation points inside
    roof segments (segments whose majority is one roof plane), and how many of them lie
    farther than 3 sigma (vertically) from that roof plane."""
    rp = cloud.fields["roof_plane"].astype(int)
    cls = cloud.attributes["classification"]
    planes = cloud.meta["roof_planes"]
    row = {int(p): k for k, p in enumerate(planes["id"])}
    out = {}
    kinds = {"chimney_wall": (cloud.fields["building_id"] > 0) & (rp == 0),
             "vegetation": np.isin(cls, [3, 4, 5])}
    roof_of = np.zeros(seg.n_segments + 1, dtype=int)
    for s in range(1, seg.n_segments + 1):
        r = rp[seg.labels == s]
        r = r[r > 0]
        if r.size > 0.5 * np.count_nonzero(seg.labels == s):
            roof_of[s] = np.bincount(r).argmax()
    for name, sel in kinds.items():
        idx = np.flatnonzero(sel & (roof_of[seg.labels] > 0))
        far = 0
        for i in idx:
            k = row[int(roof_of[seg.labels[i]])]
            n = np.asarray(planes["normal"][k])
            dz = (cloud.xyz[i] @ n - planes["offset"][k]) / n[2]
            far += abs(dz) > 3 * sigma
        out[name] = {"points": int(sel.sum()), "in_roof_segments": int(idx.size),
                     "farther_than_3_sigma": int(far)}
    return out


def _outlier_rate(cloud, seg):
    """The outlier test's rate on true roof points: points of each segment's majority
    roof plane that it tested (not in the segment's raw cluster; every point of a
    segment made by a goodness-of-fit split), and how many of them it removed."""
    rp = cloud.fields["roof_plane"].astype(int)
    removed = seg.fields["surface_outlier"].astype(np.int64)
    split = seg.table.get("split", np.zeros(seg.n_segments, dtype=np.int64))
    key = np.where(seg.labels > 0, seg.labels, removed)
    order = np.argsort(key, kind="stable")
    starts = np.searchsorted(key[order], np.arange(seg.n_segments + 2))
    tested = rem = 0
    for s, unit in enumerate(seg.units, start=1):
        ids = order[starts[s]:starts[s + 1]]
        r = rp[ids]
        if not r.size or np.bincount(r).argmax() == 0:
            continue
        t = (r == np.bincount(r).argmax())
        if split[s - 1] == 0:
            t &= ~np.isin(ids, unit.raw)
        tested += int(t.sum())
        rem += int(np.count_nonzero(removed[ids[t]] == s))
    return {"tested_true_roof_points": tested, "removed": rem,
            "rate": round(rem / tested, 4) if tested else None}


def bench_segment(cloud, radius=None):
    from lidarstat.segment import hoover, segment_sar

    t = time.perf_counter()
    seg = segment_sar(cloud.xyz, radius=radius, planes=False)
    dt = time.perf_counter() - t
    rp = cloud.fields["roof_plane"].astype(int)
    h_all = hoover(seg.labels, rp, 0.8)
    h30 = hoover(seg.labels, rp, 0.8, min_points=30)
    err, se, t2 = _normal_errors(cloud, seg)
    return {"points": int(cloud.xyz.shape[0]), "seconds": round(dt, 2),
            "bandwidth": seg.params["radius"], "adaptive": seg.params["adaptive"],
            "sigma": seg.params["sigma"], "sigma_passes": seg.params["sigma_passes"],
            "segments": seg.n_segments,
            "roof_planes": int(np.unique(rp[rp > 0]).size),
            "hoover_correct": h_all.correct, "hoover_missed": h_all.missed,
            "hoover_correct_rate_min30": round(h30.correct_rate, 3),
            "hoover_correct_min30": h30.correct, "hoover_under_min30": h30.under,
            "hoover_over_min30": h30.over, "hoover_missed_min30": h30.missed,
            "roof_planes_min30": h30.n_truth,
            "gof_splits": seg.params.get("splits"),
            "gof_seconds": seg.params.get("gof_seconds"),
            "gof_rejected": int(np.count_nonzero(seg.table["gof_p"] < seg.params["gof_alpha"]))
            if "gof_p" in seg.table else None,
            "outlier_test": _outlier_rate(cloud, seg),
            **_normal_stats(err, se, t2),
            "outliers_removed": int(np.count_nonzero(seg.fields["surface_outlier"])),
            "clutter": _clutter(cloud, seg, float(cloud.sigma))}


def _cluster(n, rng):
    """A planar 5,000-point patch with SAR structure, and its row-standardised W."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl

    from lidarstat.neighbors import radius_neighbors
    from lidarstat.stats import weights_matrix

    side = np.sqrt(n / 8.0)
    xy = rng.uniform(0, side, (n, 2))
    nb = radius_neighbors(np.c_[xy, np.zeros(n)], 1.5 * np.sqrt(1 / 8.0), dim=2)
    W = weights_matrix(nb.indptr, nb.indices, n)
    A = np.c_[np.ones(n), xy]
    z = spl.spsolve(sp.csc_matrix(sp.identity(n) - 0.2 * W),
                    A @ [7.0, 0.4, -0.3] + rng.normal(0, 0.03, n))
    return xy, z, A, W


def bench_sar_fit(n, methods):
    from lidarstat.stats import sar_fit

    rng = np.random.default_rng(5)
    xy, z, A, W = _cluster(n, rng)
    sar_fit(z[:300], A[:300], W[:300, :300])  # warm-up
    t = time.perf_counter()
    ours = sar_fit(z, A, W)
    t_ours = time.perf_counter() - t
    out = {"n": n, "lidarstat_seconds": round(t_ours, 3), "lidarstat_logdet": ours.logdet_method,
           "rho": ours.rho}
    try:
        import libpysal
        import spreg
    except ImportError:
        out["spreg"] = "not installed"
        return out
    w = libpysal.weights.WSP(W.tocsr()).to_W(silence_warnings=True)
    w.transform = "r"
    for method in methods:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = spreg.ML_Lag(z[:, None], xy, w, method=method)
        dt = time.perf_counter() - t
        out[f"spreg_{method}_seconds"] = round(dt, 3)
        out[f"spreg_{method}_ratio"] = round(dt / t_ours, 1)
        out[f"spreg_{method}_drho"] = float(abs(float(ref.rho) - ours.rho))
        out[f"spreg_{method}_dtheta"] = float(np.max(np.abs(ref.betas.ravel()[:3] - ours.theta)))
    return out


def bench_forward_search(n=2000):
    from lidarstat.segment import forward_search

    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 20, (n, 2))
    y = 5 + 0.5 * xy[:, 0] + rng.normal(0, 0.05, n)
    y[xy[:, 0] > 15] -= xy[xy[:, 0] > 15, 0] - 15
    A = np.c_[np.ones(n), xy]
    init = xy[:, 0] < 5
    forward_search(A[:200], y[:200], init[:200])  # warm-up
    t = time.perf_counter()
    res = forward_search(A, y, init)
    return {"n": n, "seconds": round(time.perf_counter() - t, 3), "m": res.m}


FIGURES = Path(__file__).resolve().parents[1] / "docs" / "figures"


def _top_view(xyz, labels, path, title):
    """Top view coloured by segment (a qualitative palette), unsegmented points grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    palette = plt.get_cmap("tab10").colors
    colours = np.array([(0.82, 0.82, 0.82)] + [palette[(k - 1) % 10]
                                               for k in range(1, int(labels.max()) + 1)])
    fig, ax = plt.subplots(figsize=(6, 6), dpi=80)
    o = np.argsort(xyz[:, 2])
    ax.scatter(xyz[o, 0], xyz[o, 1], c=colours[labels[o]], s=3, linewidths=0)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def bench_hip_roof(figures=FIGURES):
    """Seed 002's first data set: Table 6 of the four hip planes, normals, clutter."""
    from lidarstat.report import plot_forward_search
    from lidarstat.segment import hoover, segment_sar
    from lidarstat.synth import make_hip_roof_scene

    cloud = make_hip_roof_scene(rng=1)
    t = time.perf_counter()
    seg = segment_sar(cloud.xyz, planes=False)
    dt = time.perf_counter() - t
    rp = cloud.fields["roof_plane"].astype(int)
    planes = cloud.meta["roof_planes"]
    normals = np.c_[seg.table["normal_x"], seg.table["normal_y"], seg.table["normal_z"]]
    rows = {}
    for name, pid in cloud.meta["hip_planes"].items():
        lab = seg.labels[rp == pid]
        s = int(np.bincount(lab[lab > 0]).argmax())
        n_true = np.asarray(planes["normal"][list(planes["id"]).index(pid)])
        rows[name] = {"true_points": int(np.count_nonzero(rp == pid)),
                      "n_s": int(seg.table["n_s"][s - 1]),
                      "n_sa": int(seg.table["n_sa"][s - 1]), "m": int(seg.table["m"][s - 1]),
                      "final": int(np.count_nonzero(seg.labels == s)),
                      "rho": round(float(seg.table["rho"][s - 1]), 3),
                      "normal_error_deg": round(float(np.degrees(np.arccos(
                          min(1.0, abs(normals[s - 1] @ n_true))))), 3),
                      "paper_n_s_n_sa_m": list(cloud.meta["paper_table6"][name])}
        if name.lower().startswith("n"):
            u = seg.units[s - 1]
            plot_forward_search(u.fs, figures / "sar_hip_fs_north.png",
                                title=f"North plane of the hip roof: n_s={u.n_s}, "
                                f"n_sa={u.n_sa}, m={u.m}, stop: {u.fs.stop_reason}")
    cls = cloud.attributes["classification"]
    clutter = ((cloud.fields["building_id"] > 0) & (rp == 0)) | np.isin(cls, [3, 4, 5])
    roof_units = {int(np.bincount(seg.labels[rp == p][seg.labels[rp == p] > 0]).argmax())
                  for p in np.unique(rp[rp > 0])}
    h = hoover(seg.labels, rp, 0.8)
    _top_view(cloud.xyz, seg.labels, figures / "sar_hip_roof_scene.png",
              f"make_hip_roof_scene(rng=1): {seg.n_segments} SAR-FS units "
              f"(b = {seg.params['radius']:.2f} m; grey: no unit)")
    return {"points": int(cloud.xyz.shape[0]), "seconds": round(dt, 2),
            "bandwidth": round(seg.params["radius"], 3),
            "sigma": round(seg.params["sigma"], 4), "segments": seg.n_segments,
            "roof_planes": int(np.unique(rp[rp > 0]).size), "hoover_correct": h.correct,
            "clutter_points_in_roof_units": int(np.isin(seg.labels[clutter],
                                                        list(roof_units)).sum()),
            "hip_planes": rows}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="seconds: small town and cluster")
    ap.add_argument("--hip-roof", action="store_true",
                    help="only seed 002's hip-roof scene (Table 6, two figures)")
    ap.add_argument("--out", default=str(Path(__file__).with_name("results_sar.json")))
    args = ap.parse_args(argv)
    if args.hip_roof:
        hip = bench_hip_roof()
        out = Path(args.out)
        result = json.loads(out.read_text()) if out.is_file() else {}
        result["hip_roof"] = hip
        out.write_text(json.dumps(result, indent=2))
        print(json.dumps(hip, indent=1))
        return result
    if args.quick:
        extent, density, n_fit, methods = (70.0, 60.0), 8.0, 1000, ["full"]
    else:
        extent, density, n_fit, methods = (400.0, 300.0), 8.0, 5000, ["full"]
    cloud, t_gen = _town(extent, density)
    seg = bench_segment(cloud)  # automatic bandwidth, multi-scale windows
    hip = None if args.quick else bench_hip_roof()
    fit = bench_sar_fit(n_fit, methods)
    fs = bench_forward_search()
    result = {"machine": platform.platform(), "python": platform.python_version(),
              "quick": args.quick, "generate_seconds": round(t_gen, 1), "segment_sar": seg,
              "sar_fit": fit, "forward_search_2000": fs, "hip_roof": hip}
    print("| measure | value |\n|---|---|")
    print(f"| segment_sar on {seg['points']:,} points | {seg['seconds']} s |")
    print(f"| automatic bandwidth b, noise sigma | {seg['bandwidth']:.3f} m, "
          f"{seg['sigma']:.4f} m |")
    print(f"| roof planes correct (Hoover 0.8, planes >= 30 points) | "
          f"{seg['hoover_correct_min30']} ({seg['hoover_correct_rate_min30']:.1%}) |")
    print(f"| under- / over-segmented / missed roof planes (>= 30 points) | "
          f"{seg['hoover_under_min30']} / {seg['hoover_over_min30']} / "
          f"{seg['hoover_missed_min30']} of {seg['roof_planes_min30']} |")
    print(f"| goodness-of-fit: segments made by splits, still rejected (test + splits: s) | "
          f"{seg['gof_splits']}, {seg['gof_rejected']} ({seg['gof_seconds']} s) |")
    ot = seg["outlier_test"]
    print(f"| outlier test on true roof points (level 0.01) | {ot['removed']} of "
          f"{ot['tested_true_roof_points']} ({ot['rate']}) |")
    print(f"| normals of correct planes within 0.5 deg | {seg['normals_within_0.5_deg']} "
          f"(median {seg['normal_error_median_deg']}, max {seg['normal_error_max_deg']} deg) |")
    print(f"| 95 % normal cones covering the truth | {seg['cone95_covered']} / "
          f"{seg['cone95_planes']} (binomial 99 % interval {seg['cone95_binomial99']}; "
          f"KS t2 ~ chi2(2) p = {seg['t2_ks_pvalue_chi2_2']}) |")
    print(f"| within 0.5 deg where the angular SE < 0.5/3 deg | "
          f"{seg['within_0.5_deg_where_se_below_0.167']} of "
          f"{seg['planes_se_below_0.167_deg']} planes |")
    for name, c in seg["clutter"].items():
        print(f"| {name} points in roof segments (> 3 sigma from the plane) | "
              f"{c['in_roof_segments']} of {c['points']:,} ({c['farther_than_3_sigma']}) |")
    print(f"| sar_fit, {fit['n']} points ({fit['lidarstat_logdet']}) | "
          f"{fit['lidarstat_seconds']} s |")
    for m in methods:
        if f"spreg_{m}_seconds" in fit:
            print(f"| spreg ML_Lag '{m}' / lidarstat | {fit[f'spreg_{m}_ratio']}x "
                  f"(|d rho| {fit[f'spreg_{m}_drho']:.1e}) |")
    print(f"| Forward Search over {fs['n']} points | {fs['seconds']} s |")
    if not args.quick:
        Path(args.out).write_text(json.dumps(result, indent=2))
        print(f"written {args.out}")
    return result


if __name__ == "__main__":
    main()
