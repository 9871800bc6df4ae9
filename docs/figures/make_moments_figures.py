"""Pictures of the moments classification in docs/methods/moments.md (seed 004).

    PYTHONPATH=src python docs/figures/make_moments_figures.py

Writes, from the ISPRS filter-test sample samp21 (``../shared/data/isprs_filtertest``)
classified by :func:`lidarstat.classify.moments` at the default parameters:

* ``moments_isprs_samp21_errors.png``: plan view of the ground/object errors against the
  manual reference (Type I red, Type II blue, correct grey);
* ``moments_isprs_samp21_cut.png``: the analysis of the window holding the most points:
  density of the heights above the ground model with the cut, and the sequential
  skewness and kurtosis against the removal cycle with the chosen cycle.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("LIDARSTAT_SHARED_DATA", HERE.parents[1].parent / "shared" / "data"))
SAMPLE = DATA / "isprs_filtertest" / "joined" / "samp21_ref_intensity.laz"


def main():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarstat.classify import filter_errors, moments
    from lidarstat.io import read

    c = read(SAMPLE)
    ref = np.asarray(c["classification"]) == 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = moments(c.xyz, c["intensity"])
    e = filter_errors(res.ground, ref)

    xy = c.xyz[:, :2] - c.xyz[:, :2].min(axis=0)
    t1 = ref & ~res.ground
    t2 = ~ref & res.ground
    ok = ~(t1 | t2)
    fig, ax = plt.subplots(figsize=(7.5, 6.5), dpi=110)
    ax.scatter(*xy[ok].T, s=1, c=np.where(ref[ok], "#c7c7c7", "#707070"), lw=0)
    ax.scatter(*xy[t1].T, s=3, c="#d62728", lw=0, label=f"Type I (ground -> object) "
               f"{100 * e.type_i:.2f} %")
    ax.scatter(*xy[t2].T, s=3, c="#1f77b4", lw=0, label=f"Type II (object -> ground) "
               f"{100 * e.type_ii:.2f} %")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"ISPRS samp21, moments at the defaults: total error {100 * e.total:.2f} %"
                 "\nlight grey ground, dark grey objects, both correct")
    ax.legend(loc="lower left", fontsize=8, markerscale=4)
    fig.tight_layout()
    fig.savefig(HERE / "moments_isprs_samp21_errors.png")
    plt.close(fig)

    cuts = [s for s in res.steps if s.category == "elevation" and isinstance(s.window, str)
            and s.choice.cycle is not None]
    rec = max(cuts, key=lambda s: s.n)
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(11, 3.8), dpi=110)
    de = rec.density
    a0.plot(de.grid, de.density, color="k")
    a0.axvline(rec.choice.threshold, color="r", ls="--",
               label=f"cut {rec.choice.threshold:.2f} m")
    a0.set_xlim(de.grid[0], min(de.grid[-1], 8.0))
    a0.set_yscale("log")
    a0.set_ylim(1e-3, None)
    a0.set_xlabel("height above the ground model (m)")
    a0.set_ylabel("density (log)")
    a0.legend(loc="upper right")
    cv = rec.curves
    a1.plot(cv["cycle"], cv["skewness"], label="skewness", color="tab:blue")
    a1.plot(cv["cycle"], cv["kurtosis"], label="kurtosis", color="tab:orange")
    a1.axvline(rec.choice.cycle, color="r", ls="--",
               label=f"cycle {rec.choice.cycle} ({rec.choice.rule})")
    a1.set_yscale("symlog")
    a1.set_xlabel("removal cycle (highest values removed)")
    a1.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"ISPRS samp21, window {rec.window}: {rec.n} heights, dip-test p = "
                 f"{rec.dip['elevation']['pvalue']:.3g}", fontsize=10)
    fig.tight_layout()
    fig.savefig(HERE / "moments_isprs_samp21_cut.png")
    plt.close(fig)
    print(f"samp21: total {100 * e.total:.2f} %, window {rec.window}, cycle "
          f"{rec.choice.cycle}, cut {rec.choice.threshold:.3f}")


if __name__ == "__main__":
    main()
