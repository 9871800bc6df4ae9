"""ISPRS filter test: Type I / II / total error of `moments` and its peers, one parameter set.

Every `moments` run here is without the terrain step (``terrain=False``), so that the
table measures the window cut and what each departure from the paper is worth to it;
``benchmarks/ground_filters.py`` measures the defaults (terrain step on) against CSF and
SMRF.

Every method runs on the same seven reference samples (``isprs_filtertest/joined``: manual
bare-earth / object labels, last-pulse intensity) in the same run, with ONE parameter set
for all samples (no tuning per sample):

* lidarstat ``moments`` with its defaults (the command-line defaults);
* lidarstat ``moments --method skewness-balancing`` (Bartels & Wei's rule in the same tiles);
* CSF (``cloth-simulation-filter``): cloth resolution 1 m, slope smoothing on, the other
  parameters at their defaults (rigidness 3, class threshold 0.5 m, 500 iterations);
* CSF with the cloth resolution set to twice the mean point spacing of each sample (a
  data-driven, not tuned, choice: 1 m cloth cells are finer than the spacing of these
  0.2-1 pts/m2 samples, so the cloth falls through between points);
* the departures of ``moments`` from the paper, each switched off alone (``VARIANTS``:
  the paper's kurtosis-plateau rule, no ground-spread bound, no raised-patch check, no
  low-noise removal), so docs/methods/moments.md can say what each one is worth.

Errors are the definitions of Sithole & Vosselman (2004). The numbers do not depend on the
CPU, so the quick mode (two samples) and the full mode (seven) give the same per-sample
figures.

Usage::

    python benchmarks/isprs_filtertest.py --quick
    python benchmarks/isprs_filtertest.py --out benchmarks/results_isprs_moments.json
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

from lidarstat.classify import filter_errors, moments  # noqa: E402
from lidarstat.errors import LidarstatWarning  # noqa: E402
from lidarstat.io import read  # noqa: E402

DATA = Path(os.environ.get("LIDARSTAT_SHARED_DATA", HERE.parent.parent / "shared" / "data"))
SAMPLES = ["11", "21", "31", "41", "51", "61", "71"]
#: The peers of the main table.
MAIN = ["moments", "skewness_balancing", "csf_1m", "csf_2spacing"]
#: `moments` with one departure from the paper switched off (keyword arguments).
VARIANTS = {"plateau_rule": {"elevation_rule": "plateau"},
            "no_ground_spread": {"ground_spread": 0.0},
            "no_continuity": {"continuity": False},
            "no_low_noise": {"low_noise": False}}


def csf_ground(xyz, resolution):
    """Ground mask of CSF with slope smoothing on and the given cloth resolution."""
    import CSF

    csf = CSF.CSF()
    csf.params.bSloopSmooth = True
    csf.params.cloth_resolution = float(resolution)
    csf.setPointCloud(np.ascontiguousarray(xyz - xyz.min(axis=0)))
    g, o = CSF.VecInt(), CSF.VecInt()
    devnull = os.open(os.devnull, os.O_WRONLY)  # CSF prints progress on stdout
    saved = os.dup(1)
    try:
        os.dup2(devnull, 1)
        csf.do_filtering(g, o, False)
    finally:
        os.dup2(saved, 1)
        os.close(devnull)
        os.close(saved)
    mask = np.zeros(len(xyz), bool)
    mask[np.asarray(list(g), dtype=np.int64)] = True
    return mask


def spacing(xyz):
    """Mean point spacing: sqrt(bounding-box area / points)."""
    span = np.ptp(xyz[:, :2], axis=0)
    return float(np.sqrt(span[0] * span[1] / len(xyz)))


def run(samples):
    rows = []
    for s in samples:
        path = DATA / "isprs_filtertest" / "joined" / f"samp{s}_ref_intensity.laz"
        c = read(path)
        ref = np.asarray(c["classification"]) == 2
        row = {"sample": f"samp{s}", "points": len(c), "ground": int(ref.sum()),
               "spacing_m": spacing(c.xyz)}
        methods = {
            "moments": lambda: moments(
                c.xyz, c["intensity"], number_of_returns=None, return_number=None,
                terrain=False).ground,
            "skewness_balancing": lambda: moments(
                c.xyz, c["intensity"], method="skewness-balancing").ground,
            "csf_1m": lambda: csf_ground(c.xyz, 1.0),
            "csf_2spacing": lambda: csf_ground(c.xyz, 2 * row["spacing_m"]),
            **{name: (lambda kw=kw: moments(c.xyz, c["intensity"], terrain=False,
                                            **kw).ground)
               for name, kw in VARIANTS.items()},
        }
        for name, fn in methods.items():
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LidarstatWarning)
                g = fn()
            e = filter_errors(g, ref)
            row[name] = {"type_i": e.type_i, "type_ii": e.type_ii, "total": e.total,
                         "kappa": e.kappa, "seconds": time.perf_counter() - t}
            print(f"samp{s} {name:<20} I {100 * e.type_i:6.2f}  II {100 * e.type_ii:6.2f}  "
                  f"total {100 * e.total:6.2f}  kappa {e.kappa:.3f}", flush=True)
        rows.append(row)
    return rows


def table(rows, names=MAIN):
    out = ["| sample | " + " | ".join(f"{n} I / II / total (%)" for n in names) + " |",
           "|---|" + "---|" * len(names)]
    for r in rows:
        cells = [f"{100 * r[n]['type_i']:.2f} / {100 * r[n]['type_ii']:.2f} / "
                 f"**{100 * r[n]['total']:.2f}**" for n in names]
        out.append(f"| {r['sample']} | " + " | ".join(cells) + " |")
    means = []
    for n in names:
        m = [np.mean([r[n][k] for r in rows]) for k in ("type_i", "type_ii", "total")]
        means.append(f"{100 * m[0]:.2f} / {100 * m[1]:.2f} / **{100 * m[2]:.2f}**")
    out.append("| mean | " + " | ".join(means) + " |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two samples (21 and 51)")
    ap.add_argument("--out", default=None, help="results JSON (full mode)")
    args = ap.parse_args(argv)
    samples = ["21", "51"] if args.quick else SAMPLES
    rows = run(samples)
    md = table(rows) + "\n\n" + table(rows, ["moments", *VARIANTS])
    print(md)
    if args.out and not args.quick:
        Path(args.out).write_text(json.dumps({"rows": rows, "markdown": md}, indent=1))
        Path(args.out).with_suffix(".md").write_text(md + "\n")


if __name__ == "__main__":
    main()
