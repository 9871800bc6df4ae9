"""Ground filters on real data: `moments` against CSF and SMRF in the same run, one parameter set.

Two tables, every method on the same points in the same process:

* **ISPRS filter test**, the seven reference samples in ``isprs_filtertest/joined``
  (manual bare-earth / object labels): Type I, Type II and total error (Sithole and
  Vosselman 2004) and Cohen's kappa per sample, and their mean;
* **producer-classified files**: AHN3 Amsterdam 2386_9702 and 2397_9705, the AHN3 Delft
  crops 1 and 2, the IGN LiDAR HD myria3d tile and St-Barthelemy, scored against the
  producers' own classes with bare earth (2) and road (11) counted as ground; noise (7,
  18), water (9) and codes above 18 are left out, and on the two IGN files class 1 too
  (there it is "everything else", ground included: only the building class is validated).

Methods (one parameter set for every file):

* ``moments``: lidarstat ``moments`` with its defaults (the terrain step on);
* ``moments_no_terrain``: the same without the terrain step (``terrain=False``);
* ``csf``: CSF, the authors' ``cloth-simulation-filter`` (cloth 1 m, slope smoothing,
  the other parameters at their defaults);
* ``smrf``: SMRF (Pingel et al. 2013) as implemented by ``pysmrf`` (a third-party
  implementation, not the authors' code), with the paper's single parameter set (cell
  1 m, slope 0.15, largest window radius 18 m, elevation threshold 0.5 m, scaler 1.25).

``--figures`` also draws the hard cases before and after the terrain step
(``docs/figures/moments_terrain_*.png``).

Usage::

    python benchmarks/ground_filters.py --out benchmarks/results_ground.json --figures
    python benchmarks/ground_filters.py --quick          # samp21 and samp71 only
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE))

from isprs_filtertest import csf_ground

from lidarstat.classify import filter_errors, moments
from lidarstat.io import linear_units, read

DATA = Path(os.environ.get("LIDARSTAT_SHARED_DATA", HERE.parent.parent / "shared" / "data"))
ISPRS = [f"isprs_filtertest/joined/samp{s}_ref_intensity.laz"
         for s in ("11", "21", "31", "41", "51", "61", "71")]
from real_moments import PRODUCER_FILES as PRODUCER  # noqa: E402 (the same files)
METHODS = ["moments", "moments_no_terrain", "csf", "smrf"]
#: The hard cases drawn before / after the terrain step: sample, what it shows.
FIGURES = {"samp71": "ramps and embankments to a bridge", "samp61": "embankments",
           "samp21": "a bridge over a road", "samp41": "large flat roofs, a data gap",
           "samp11": "a steep terraced slope, stepped buildings",
           "ahn3_cropped_1_bgt.laz": "Delft: canals, courtyards, flat roofs"}
#: SMRF's single parameter set (Pingel et al. 2013, section 4).
SMRF = {"cellsize": 1.0, "windows": 18, "slope_threshold": 0.15, "elevation_threshold": 0.5,
            "elevation_scaler": 1.25}


def smrf_ground(xyz):
    """Ground mask of pysmrf with the paper's single parameter set."""
    import pysmrf

    o = xyz - xyz.min(axis=0)
    r = pysmrf.classify(o[:, 0], o[:, 1], xyz[:, 2], **SMRF)
    return np.asarray(r.classification) == 2


def load(rel):
    """Points, attributes, reference ground mask and the mask of scored points."""
    c = read(DATA / rel)
    a = c.attributes
    ref = np.asarray(a["classification"]).astype(int)
    keep = ~np.isin(ref, (7, 9, 18)) & (ref < 19)
    if rel.startswith("ign_"):
        keep &= ref != 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        units = linear_units(c.crs, header=c.las_header, source=str(rel))
    return c, a, np.isin(ref, (2, 11)), keep, units


def run_file(rel, figures=None):
    c, a, ref, keep, units = load(rel)
    kw = {"units": units}
    if "number_of_returns" in a:
        kw.update(number_of_returns=a["number_of_returns"], return_number=a["return_number"])
    inten = a.get("intensity")
    methods = {
        "moments": lambda: moments(c.xyz, inten, **kw).ground,
        "moments_no_terrain": lambda: moments(c.xyz, inten, terrain=False, **kw).ground,
        "csf": lambda: csf_ground(c.xyz, 1.0),
        "smrf": lambda: smrf_ground(c.xyz),
    }
    name = Path(rel).name.split("_ref")[0]
    row = {"file": rel, "name": name, "points": len(c), "scored": int(keep.sum()),
           "ground": int(ref[keep].sum())}
    masks = {}
    for m, fn in methods.items():
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = fn()
        masks[m] = g
        e = filter_errors(g[keep], ref[keep])
        row[m] = {"type_i": 100 * e.type_i, "type_ii": 100 * e.type_ii,
                  "total": 100 * e.total, "kappa": e.kappa,
                  "seconds": time.perf_counter() - t}
        print(f"{name:<48} {m:<20} I {100 * e.type_i:6.2f}  II {100 * e.type_ii:6.2f}  "
              f"total {100 * e.total:6.2f}  kappa {e.kappa:.3f}", flush=True)
    if figures is not None and name in FIGURES:
        figure(c.xyz, ref, masks["moments_no_terrain"], masks["moments"], name, figures)
    return row


def figure(xyz, ref, before, after, name, folder):
    """Plan view of the errors before and after the terrain step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5.2), sharex=True, sharey=True)
    x, y = xyz[:, 0] - xyz[:, 0].min(), xyz[:, 1] - xyz[:, 1].min()
    for ax, g, title in ((axes[0], before, "without the terrain step"),
                         (axes[1], after, "with the terrain step")):
        e = filter_errors(g, ref)
        ax.scatter(x, y, c=xyz[:, 2], s=0.6, cmap="gray", rasterized=True)
        t1, t2 = ref & ~g, ~ref & g
        ax.scatter(x[t1], y[t1], s=1.5, c="tab:red", label="ground missed (Type I)")
        ax.scatter(x[t2], y[t2], s=1.5, c="tab:blue", label="object as ground (Type II)")
        ax.set_title(f"{title}: total error {100 * e.total:.2f} %", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    axes[1].legend(loc="lower right", fontsize=8, markerscale=4)
    fig.suptitle(f"{name}: {FIGURES[name]} (grey: elevation)", fontsize=11)
    fig.tight_layout()
    folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(folder / f"moments_terrain_{name.split('.')[0]}.png", dpi=80)
    plt.close(fig)


def table(rows, names=METHODS):
    head = ("| file | " + " | ".join(f"{n}: I / II / **total** %, kappa" for n in names)
            + " |")
    out = [head, "|---|" + "---|" * len(names)]
    for r in rows:
        cells = [f"{r[n]['type_i']:.2f} / {r[n]['type_ii']:.2f} / **{r[n]['total']:.2f}**, "
                 f"{r[n]['kappa']:.3f}" for n in names]
        out.append(f"| {r['name']} | " + " | ".join(cells) + " |")
    means = []
    for n in names:
        m = [np.mean([r[n][k] for r in rows]) for k in ("type_i", "type_ii", "total", "kappa")]
        means.append(f"{m[0]:.2f} / {m[1]:.2f} / **{m[2]:.2f}**, {m[3]:.3f}")
    out.append("| mean | " + " | ".join(means) + " |")
    return "\n".join(out)


def totals_table(rows_i, rows_p, names=METHODS):
    """The method page's short table: total error % per file (kappa for `moments`), the
    ISPRS samples by their mean and worst sample."""
    out = ["| file | " + " | ".join(f"{n} total %" for n in names) + " |",
           "|---|" + "---:|" * len(names)]

    def cells(vals):
        return " | ".join(vals)

    if rows_i:
        mean = [f"{np.mean([r[n]['total'] for r in rows_i]):.2f}" for n in names]
        mean[0] += f" ({np.mean([r[names[0]]['kappa'] for r in rows_i]):.3f})"
        out.append(f"| ISPRS, mean of {len(rows_i)} samples (kappa) | {cells(mean)} |")
        worst = max(rows_i, key=lambda r: r[names[0]]["total"])
        out.append(f"| ISPRS, worst sample ({worst['name']}) | "
                   + cells(f"{worst[n]['total']:.2f}" for n in names) + " |")
    for r in rows_p:
        vals = [f"{r[n]['total']:.2f}" for n in names]
        vals[0] += f" ({r[names[0]]['kappa']:.3f})"
        out.append(f"| {r['name']} | {cells(vals)} |")
    if rows_p:
        mean = [f"{np.mean([r[n]['total'] for r in rows_p]):.2f}" for n in names]
        out.append(f"| producer files, mean | {cells(mean)} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="samp21 and samp71 only")
    ap.add_argument("--out", default=None, help="results JSON (full mode)")
    ap.add_argument("--isprs-only", action="store_true", help="skip the producer files")
    ap.add_argument("--figures", action="store_true",
                    help="draw the hard cases into docs/figures/")
    args = ap.parse_args(argv)
    figures = HERE.parent / "docs" / "figures" if args.figures else None
    isprs = [ISPRS[1], ISPRS[6]] if args.quick else ISPRS
    rows_i, rows_p = [], []

    def save():  # after every file, so a long run that is stopped keeps what it did
        md = table(rows_i) + ("\n\n" + table(rows_p) if rows_p else "")
        if args.out and not args.quick:
            Path(args.out).write_text(json.dumps(
                {"isprs": rows_i, "producer": rows_p, "smrf_parameters": SMRF,
                 "machine": "two cores shared with other jobs (seconds are indicative)",
                 "machine_shared": True,
                 "markdown": md, "markdown_totals": totals_table(rows_i, rows_p)},
                indent=1))
        return md

    for rel in isprs:
        rows_i.append(run_file(rel, figures))
        save()
    if not args.quick and not args.isprs_only:
        for rel in PRODUCER:
            if (DATA / rel).is_file():
                rows_p.append(run_file(rel, figures))
                save()
    print(save())


if __name__ == "__main__":
    main()
