#!/usr/bin/env python
"""Buildings of `moments` against the producers' building class (6), with the ground in
the same run.

For every AHN3 and IGN file: ground total error and kappa against the producer's ground
(2 and 11; scored as in ``ground_filters.py``), and building precision / recall / F1 of

* ``tested``: the classes `moments` writes (tested local planes, roof patches, roof
  cells: docs/methods/moments.md, "Buildings");
* ``cells``: the cell rule on the same run's ground and heights (objects at least 2 m
  high whose 2 m cell is not vegetation-like: more than half non-last returns or heights
  spread over 16 m; every non-last return vegetation), the rule the tests replace.

Producer noise (7, 18), water (9) and codes above 18 are left out. Producer classes are
the producers' semi-automatic (AHN3) or human-validated (IGN building) labels, not
checked truth. All files run with the default parameters (one parameter set).

Where a producer's class visibly leaves a building out (``REFERENCE_OMISSIONS``), the
score is also given without it (``tested_outside_omissions``). ``patch_evidence``
compares the false and true roof patches of every file (``building_evidence.py``);
``joint_evidence``, ``joint_rule_search`` and ``false_patches_rejected_by_reference`` (the
bound of any rule that rejects roof patches) measure them jointly (``building_joint.py``).
``missed_by_cause`` breaks the missed building points down by cause, with the F1 each
cause's perfect recovery would give, and ``recovery_rules`` the true and false points
that rules on the largest causes would add (``building_recall.py``), also once every
false patch is rejected (``recovery_rules_after_patch_bound``). ``echo_strip_evidence``
measures the roof patches' echoes, the returns under them and the overlap of flight
strips, ``echo_strip_rule_search`` every rule on them (``building_echoes.py``);
``mixed_false_patches`` the false patches that hold much of class 6, and
``false_patches_rejected_except_mixed`` the patch rules' bound without them (with the
recovery rules after it). ``point_rules`` scores per-point tests on the roof-cell points,
the roofs with no accepted plane and the walls; on St-Barthelemy ``no_plane_components``
describes the missed roofs with no accepted plane and ``learned_point_bound`` what a
classifier trained on the reference's own labels reaches on that per-point evidence
(``building_points.py``).

Usage::

    python benchmarks/buildings.py --out benchmarks/results_buildings.json --figures

``--figures`` draws the files of ``FIGURES`` (cell rule against tested planes), the
reference's omission, the patch evidence of ``EVIDENCE_FILES`` and St-Barthelemy's missed
building points by cause into ``docs/figures/``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))

from lidarstat.classify import _moments_objects, filter_errors, moments  # noqa: E402
from lidarstat.io import linear_units, read  # noqa: E402

DATA = HERE.parent.parent / "shared" / "data"
import building_echoes  # noqa: E402
import building_evidence  # noqa: E402
import building_joint  # noqa: E402
import building_points  # noqa: E402
import building_recall  # noqa: E402
from real_moments import PRODUCER_FILES as FILES  # noqa: E402 (the same files)
LEFT_OUT = (7, 9, 18)
FIGURE_FILE = "ahn3_amsterdam/ahn_2386_9702.laz"
IGN_FIGURE_FILE = "ign_lidarhd_samples/870000_6618000.subset.50mx100m.las"
SB_FIGURE_FILE = "ign_lidarhd_samples/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz"
#: The hard cases drawn: file -> (PNG under docs/figures, title).
FIGURES = {FIGURE_FILE: ("moments_buildings.png", "AHN3 Amsterdam 9702"),
           IGN_FIGURE_FILE: ("moments_buildings_ign.png", "IGN LiDAR HD myria3d tile"),
           SB_FIGURE_FILE: ("moments_buildings_stbarth.png",
                            "IGN St-Barthelemy (vegetation on and beside roofs)")}
#: Files whose roof patches are drawn (false against true) in the evidence figure.
EVIDENCE_FILES = {SB_FIGURE_FILE: "St-Barthelemy", FIGURE_FILE: "AHN3 9702",
                  "ahn3_delft_3dfier/derived/ahn3_cropped_1_bgt.laz": "AHN3 Delft 1",
                  "ahn3_delft_3dfier/derived/ahn3_cropped_2_bgt.laz": "AHN3 Delft 2"}
#: Buildings the producer's classes leave out (boxes E, N min and max, metres): on the
#: myria3d tile a house about 6 m high whose every point is class 1 (unclassified) and
#: which the tested planes take (``moments_buildings_ign_omission.png``). The score
#: ``tested_outside_omissions`` leaves these boxes out.
REFERENCE_OMISSIONS = {IGN_FIGURE_FILE: [(870214.0, 6617087.3, 870231.0, 6617107.3)]}


def scores(pred, truth):
    tp = float(np.sum(pred & truth))
    p = tp / max(float(pred.sum()), 1.0)
    r = tp / max(float(truth.sum()), 1.0)
    f1 = 2 * p * r / (p + r) if p + r > 0 else 0.0
    return {"precision": round(100 * p, 2), "recall": round(100 * r, 2),
            "f1": round(100 * f1, 2)}


def cell_rule(xy, height, ground, multi):
    """Buildings by the cell rule on the same ground and heights (metres)."""
    obj = ~ground & (height >= 0.5)
    veg = obj & _moments_objects.vegetation_like(xy, height, obj, multi, 4.0, 16.0)
    return obj & ~veg & (height >= 2.0)


def run(rel):
    path = DATA / rel
    cloud = read(path)
    a = cloud.attributes
    ref = np.asarray(a["classification"]).astype(int)
    nret, rnum = np.asarray(a["number_of_returns"]), np.asarray(a["return_number"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        units = linear_units(cloud.crs, header=cloud.las_header, source=str(path))
        t = time.perf_counter()
        res = moments(cloud.xyz, a.get("intensity"), number_of_returns=nret,
                      return_number=rnum, units=units, source=str(path))
        seconds = time.perf_counter() - t
    keep = ~np.isin(ref, LEFT_OUT) & (ref < 19)
    # the ground scored as in ground_filters.py: bare earth and road are ground; on the
    # IGN files class 1 is left out (there it is everything else, ground included)
    gk = keep & ~((ref == 1) & rel.startswith("ign_"))
    e = filter_errors(res.ground[gk], np.isin(ref[gk], (2, 11)))
    multi = (nret > 1) & (rnum < nret)
    old = cell_rule(cloud.xyz[:, :2], res.height, res.ground, multi)
    new = res.classification == 6
    truth = ref == 6
    b = res.params["buildings"]
    omit = np.zeros(len(ref), bool)
    for e0, n0, e1, n1 in REFERENCE_OMISSIONS.get(rel, []):
        omit |= ((cloud.xyz[:, 0] >= e0) & (cloud.xyz[:, 0] < e1) & (cloud.xyz[:, 1] >= n0)
                 & (cloud.xyz[:, 1] < n1))
    row = {"file": rel, "points": int(len(ref)), "scored": int(keep.sum()),
           "seconds": round(seconds, 2), "ground_total": round(100 * e.total, 2),
           "ground_kappa": round(e.kappa, 3), "building_points": int(truth[keep].sum()),
           "tested": scores(new[keep], truth[keep]), "cells": scores(old[keep], truth[keep]),
           "sigma": round(b["sigma"], 4), "roof_patches": b["n_roof_patches"],
           "missed_as_ground": int(np.sum(truth & keep & res.ground))}
    # what the disagreements are: false building points by reference class and by the
    # rule that decided (building_evidence: 1 roof patch, 2 roof cell), missed building
    # points by lidarstat class, and the quartiles of their heights above the ground
    ev = np.asarray(res.to_fields()["building_evidence"])
    false, missed = new & ~truth & keep, truth & ~new & keep
    row["false_by_reference_class"] = {int(c): int(n) for c, n in
                                       zip(*np.unique(ref[false], return_counts=True))}
    row["false_by_evidence"] = {int(c): int(n) for c, n in
                                zip(*np.unique(ev[false], return_counts=True))}
    row["missed_by_class"] = {int(c): int(n) for c, n in
                              zip(*np.unique(res.classification[missed], return_counts=True))}
    row["false_height_quartiles"] = ([round(float(q), 2) for q in
                                      np.quantile(res.height[false], [0.25, 0.5, 0.75])]
                                     if false.any() else None)
    row["missed_height_quartiles"] = ([round(float(q), 2) for q in
                                       np.quantile(res.height[missed], [0.25, 0.5, 0.75])]
                                      if missed.any() else None)
    fields = res.to_fields()
    row["false_and_true_evidence"] = evidence(cloud.xyz, ev, fields["building_patch"],
                                              multi, new & keep, truth, res.height)
    patches = building_evidence.patch_table(
        cloud.xyz, ev, np.asarray(fields["building_patch"]), fields, multi,
        a.get("intensity"), res.height, res.ground, new & keep, truth)
    row["patch_evidence"] = building_evidence.summarise(
        patches, cloud.xyz, ev, np.asarray(fields["building_patch"]), new & keep, truth)
    row["patch_evidence"]["relative_return_share_test"] = building_evidence.relative_share_test(
        cloud.xyz, ev, np.asarray(fields["building_patch"]), multi, new & keep, truth)
    # joint evidence: what surrounds and fills each roof patch (building_joint.py)
    joint = building_joint.patch_features(
        cloud.xyz, np.where(keep, ev, 0), np.asarray(fields["building_patch"]),
        np.asarray(fields["building_plane_p"]), multi, a.get("intensity"), res.height, truth)
    row["joint_evidence"] = building_joint.summarise(joint)
    tp = int(np.sum(new & truth & keep))
    row["counts"] = {"tp": tp, "fp": int(np.sum(new & ~truth & keep)),
                     "fn": int(np.sum(~new & truth & keep))}
    # the colour channels the file carries, with their largest value (0: not recorded)
    row["colour_channels"] = {c: int(np.max(a[c])) for c in ("red", "green", "blue", "nir")
                              if c in a}
    if omit.any():
        row["omitted_points"] = int(np.sum(omit & keep))
        row["tested_outside_omissions"] = scores(new[keep & ~omit], truth[keep & ~omit])
    ctx = (cloud.xyz, ev, np.asarray(fields["building_patch"]), multi, truth, keep)
    # the re-decision with nothing rejected gives the class written (a check of redecide)
    row["redecide_identity"] = bool(np.array_equal(
        building_joint.redecide(*ctx[:4], np.zeros(0, np.int64)), new))
    # the bound of any patch rule: every roof patch mostly outside class 6 rejected (the
    # reference's own labels), the roof cells decided again
    false_ids = joint[joint[:, 2] < 0.5, 0].astype(np.int64) if joint.size else []
    oracle = building_joint.redecide(*ctx[:4], false_ids)
    row["false_patches_rejected_by_reference"] = scores(oracle[keep], truth[keep])
    # where the missed building points are, by cause, and what rules on the largest
    # causes would add (building_recall.py)
    state = building_recall.candidate_state(cloud.xyz, fields, res.height, multi)
    row["missed_by_cause"], cause = building_recall.missed_causes(
        state, new, truth, keep, res.ground, res.height, b["sigma"])
    row["recovery_rules"] = building_recall.recovery_rules(state, new, truth, keep)
    # per-point rules on what is left (building_points.py): roof-cell points beside roofs,
    # roofs with no accepted plane, walls; on St-Barthelemy what bounds any such rule
    extra = building_points.point_evidence(state, cloud.xyz, b["sigma"])
    row["point_rules"] = building_points.point_rules(state, ev, new, truth, keep, b["sigma"],
                                                     extra)
    if rel == SB_FIGURE_FILE:
        row["no_plane_components"] = building_points.no_plane_components(
            cloud.xyz, cause, ref, multi, np.asarray(a["point_source_id"]))
        row["learned_point_bound"] = building_points.learned_bound(
            state, extra, fields, a.get("intensity"), new, truth, keep, b["sigma"])
    del extra
    # the same rules once every false patch is rejected (the patch rules' bound above):
    # do the low parts under the true roofs follow the reference then?
    state = building_recall.candidate_state(
        cloud.xyz, building_recall.without_patches(fields, false_ids, oracle), res.height,
        multi)
    row["recovery_rules_after_patch_bound"] = building_recall.recovery_rules(
        state, oracle, truth, keep)
    # echoes, returns under the patches, flight strips (building_echoes.py)
    evk = np.where(keep, ev, 0)
    patch = np.asarray(fields["building_patch"])
    echo, missing = building_echoes.patch_features(cloud.xyz, evk, patch, a, res.height,
                                                   b["sigma"], truth)
    row["echo_strip_evidence"] = building_echoes.summarise(echo, missing)
    effects = building_echoes.marginal_effects(cloud.xyz, evk, patch, multi, truth, keep,
                                               echo[:, 0].astype(np.int64))
    row["mixed_false_patches"] = building_echoes.mixed_patches(cloud.xyz, evk, patch, ref,
                                                               a, echo)
    mixed = [int(p) for p in row["mixed_false_patches"]]
    rest = np.setdiff1d(false_ids, mixed)
    partial = building_joint.redecide(*ctx[:4], rest)
    row["false_patches_rejected_except_mixed"] = scores(partial[keep], truth[keep])
    state = building_recall.candidate_state(
        cloud.xyz, building_recall.without_patches(fields, rest, partial), res.height,
        multi)
    row["recovery_rules_after_patch_bound_except_mixed"] = building_recall.recovery_rules(
        state, partial, truth, keep)
    del state
    return row, (cloud.xyz, truth, old, new, ref, patches, joint, ctx, cause, keep, echo,
                 effects, mixed, evk, patch)


def evidence(xyz, ev, patch, multi, pred, truth, height, k=30):
    """What tells false building points from true ones: quartiles, over each group and
    deciding rule (1 roof patch, 2 roof cell), of the share of non-last returns among
    the `k` nearest candidates, of the share of those on a roof patch, and (roof-patch
    points) the planimetric width of their patch (sqrt(12) times the std along its minor
    axis: a hedge is a narrow patch); and how many false and true roof-patch points lie
    on narrow, low patches (narrower than 2.5 m, median height under 3 m: a hedge's
    shape, and a shed's)."""
    from scipy.spatial import cKDTree

    cand = np.flatnonzero(ev > 0)
    if cand.size <= k:
        return {}
    _, nb = cKDTree(xyz[cand]).query(xyz[cand], k=k)
    multi_share = np.full(len(ev), np.nan)
    roof_share = np.full(len(ev), np.nan)
    multi_share[cand] = multi[cand][nb].mean(axis=1)
    roof_share[cand] = (ev[cand][nb] == 1).mean(axis=1)
    width = np.full(len(ev), np.nan)
    narrow_low = np.zeros(len(ev), bool)
    on = pred & (ev == 1)
    for p in np.unique(patch[on]):
        m = on & (patch == p)
        if m.sum() >= 3:
            s = np.linalg.svd(xyz[m, :2] - xyz[m, :2].mean(axis=0), compute_uv=False)
            width[m] = np.sqrt(12.0) * s[1] / np.sqrt(m.sum())
            narrow_low[m] = width[m][0] < 2.5 and np.median(height[m]) < 3.0
    out = {"narrow_low_patch_points": {"false": int(np.sum(narrow_low & ~truth)),
                                       "true": int(np.sum(narrow_low & truth))}}
    for group, sel in (("false", pred & ~truth), ("true", pred & truth)):
        for rule in (1, 2):
            m = sel & (ev == rule)
            if not m.any():
                continue
            q = {"points": int(m.sum())}
            for name, v in (("neighbour_multi_share", multi_share),
                            ("neighbour_roof_share", roof_share), ("patch_width_m", width)):
                if np.isfinite(v[m]).any():
                    q[name] = [round(float(x), 3) for x in np.nanquantile(v[m], [0.25, 0.5,
                                                                                  0.75])]
            out[f"{group}_{'roof_patch' if rule == 1 else 'roof_cell'}"] = q
    return out


def figure(data, out, name="AHN3 Amsterdam 9702"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz, truth, old, new = data[:4]
    xy = xyz[:, :2] - xyz[:, :2].min(axis=0)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.4), sharey=True)
    for ax, pred, title in ((axes[0], old, "cell rule"), (axes[1], new, "tested planes")):
        col = np.full((len(xy), 3), 0.86)
        col[truth & pred] = (0.15, 0.6, 0.2)
        col[truth & ~pred] = (0.85, 0.1, 0.1)
        col[~truth & pred] = (0.1, 0.2, 0.85)
        o = np.argsort(truth | pred, kind="stable")
        ax.scatter(xy[o, 0], xy[o, 1], c=col[o], s=0.6, linewidths=0)
        s = scores(pred, truth)
        ax.set_title(f"{title}: P {s['precision']:.1f} % R {s['recall']:.1f} % "
                     f"F1 {s['f1']:.1f} %", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.suptitle(f"{name}, building class: green found, red missed, blue false",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)


def omission_figure(data, box, out, margin=12.0):
    """The house the producer's classes leave out: plan view of the reference classes
    and of the tested building class around `box` (E, N min and max), and a section of
    the box's points along x coloured by the reference class."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz, _, _, new, ref = data[:5]
    e0, n0, e1, n1 = box
    near = ((xyz[:, 0] > e0 - margin) & (xyz[:, 0] < e1 + margin)
            & (xyz[:, 1] > n0 - margin) & (xyz[:, 1] < n1 + margin))
    inside = ((xyz[:, 0] >= e0) & (xyz[:, 0] < e1) & (xyz[:, 1] >= n0) & (xyz[:, 1] < n1))
    colours = {1: (0.55, 0.55, 0.55), 2: (0.75, 0.6, 0.4), 6: (0.85, 0.1, 0.1)}
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4))
    p = xyz[near]
    for ax, c, title in ((axes[0], np.array([colours.get(int(r), (0, 0, 0)) for r in
                                             ref[near]]), "reference: 6 red, 2 brown, 1 grey"),
                         (axes[1], np.where(new[near, None], (0.85, 0.1, 0.1),
                                            (0.75, 0.75, 0.75)), "lidarstat: building red")):
        ax.scatter(p[:, 0] - e0, p[:, 1] - n0, c=c, s=2, linewidths=0)
        ax.add_patch(matplotlib.patches.Rectangle((0, 0), e1 - e0, n1 - n0, fill=False,
                                                  ec="k", lw=0.8))
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    q = xyz[inside]
    axes[2].scatter(q[:, 1] - n0, q[:, 2], c=[colours.get(int(r), (0, 0, 0))
                                              for r in ref[inside]], s=2, linewidths=0)
    axes[2].set_xlabel("y in the box (m)")
    axes[2].set_ylabel("z (m)")
    axes[2].set_title("section of the box: a pitched roof on walls", fontsize=9)
    fig.suptitle("IGN myria3d tile: a house the reference leaves in class 1", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--figures", action="store_true",
                    help="draw the files of FIGURES into docs/figures/")
    args = ap.parse_args()
    rows = []
    tables = {}
    joint = {}
    contexts = {}
    echoes, effects = {}, {}
    for rel in FILES:
        if not (DATA / rel).is_file():
            print(f"skipped (not found): {DATA / rel}")
            continue
        row, data = run(rel)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if args.figures and rel in FIGURES:
            png, title = FIGURES[rel]
            figure(data, HERE.parent / "docs" / "figures" / png, title)
        if args.figures and rel == SB_FIGURE_FILE:
            building_recall.figure(data[0], data[8], data[3], data[1] & data[9], data[9],
                                   HERE.parent / "docs" / "figures"
                                   / "moments_buildings_missed_stbarth.png",
                                   "IGN St-Barthelemy")
        if args.figures and rel in REFERENCE_OMISSIONS:
            omission_figure(data, REFERENCE_OMISSIONS[rel][0],
                            HERE.parent / "docs" / "figures" / "moments_buildings_ign_omission.png")
        if rel in EVIDENCE_FILES:
            tables[EVIDENCE_FILES[rel]] = data[5]
        joint[rel] = data[6]
        contexts[rel] = data[7]
        echoes[rel], effects[rel] = data[10], data[11]
        if args.figures and rel == SB_FIGURE_FILE and data[12]:
            building_echoes.section_figure(data[0], data[13], data[14], data[4], data[12],
                                           HERE.parent / "docs" / "figures"
                                           / "moments_buildings_mixed_patches.png",
                                           "IGN St-Barthelemy, false roof patches that hold "
                                           "class 6")
    if args.figures and tables:
        building_evidence.figure(tables, HERE.parent / "docs" / "figures"
                                 / "moments_buildings_patch_evidence.png")
    search = echo_search = []
    if SB_FIGURE_FILE in joint:
        counts = {r["file"]: (r["counts"]["tp"], r["counts"]["fp"], r["counts"]["fn"])
                  for r in rows}
        search = building_joint.pair_search(joint, counts, SB_FIGURE_FILE)
        for rule in search:  # the roof cells decided again without the rejected patches
            rule["redecided"] = {}
            for rel, (xyz, ev, patch, multi, truth, keep) in contexts.items():
                b = building_joint.redecide(xyz, ev, patch, multi,
                                            building_joint.rejected(joint[rel], rule["terms"]))
                rule["redecided"][rel] = scores(b[keep], truth[keep])
        print("two-feature rules, best on St-Barthelemy:", json.dumps(search[:3]))
        echo_search = building_echoes.rule_search(echoes, effects, counts, SB_FIGURE_FILE)
        for rule in echo_search:  # the estimate checked: the roof cells decided again
            rule["redecided"] = {}
            for rel, (xyz, ev, patch, multi, truth, keep) in contexts.items():
                b = building_joint.redecide(xyz, ev, patch, multi, building_echoes.rejected(
                    echoes[rel], rule["terms"]))
                rule["redecided"][rel] = scores(b[keep], truth[keep])
        print("echo and strip rules, best on St-Barthelemy:", json.dumps(echo_search[:3]))
    if args.figures and joint:
        building_joint.figure({EVIDENCE_FILES[r]: joint[r] for r in EVIDENCE_FILES
                               if r in joint},
                              HERE.parent / "docs" / "figures"
                              / "moments_buildings_joint_evidence.png")
    print("\n| file | ground total % | building P/R/F1 % tested | cell rule | s |")
    print("|---|---|---|---|---|")
    for r in rows:
        t, c = r["tested"], r["cells"]
        print(f"| {Path(r['file']).name} | {r['ground_total']} | {t['precision']} / "
              f"{t['recall']} / {t['f1']} | {c['precision']} / {c['recall']} / {c['f1']} | "
              f"{r['seconds']} |")
    if rows:
        mean = {k: round(float(np.mean([r[k]["f1"] for r in rows])), 2)
                for k in ("tested", "cells")}
        print(f"mean F1: tested {mean['tested']}, cell rule {mean['cells']}")
    if args.out:
        Path(args.out).write_text(json.dumps({"files": rows, "joint_rule_search": search,
                                              "echo_strip_rule_search": echo_search,
                                              "machine": "shared, 2 cores",
                                              "machine_shared": True}, indent=2))


if __name__ == "__main__":
    main()
