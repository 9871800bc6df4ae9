"""Pictures of the covariance classes and segments in docs/figures/ (seed 003).

    PYTHONPATH=src python docs/figures/make_covariance_figures.py [--only pump|building|plant]

Writes ``docs/figures/covariance_{pump,tls_building,tls_plant}_{classes,segments}.png``: oblique
3-D views (matplotlib, Agg) of ``point_class`` (surface grey-blue, edge red, boundary
orange) and of the segments of ``segment --method covariance`` at the default parameters,
with the intersection lines in black. The pump scan is the real terrestrial scan in
``../shared/data/e57_pump_tls/pump_scan.laz`` (scanner at the origin); it is skipped when
absent.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

DOCS = Path(__file__).resolve().parent
PUMP = DOCS.parent.parent / ".." / "shared" / "data" / "e57_pump_tls" / "pump_scan.laz"
CLASS_COLORS = np.array(["#bdbdbd", "#7f9fbf", "#d62728", "#ff7f0e"])
CLASS_NAMES = ["undetermined", "surface", "edge", "boundary"]


def _axes(title, view):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 6.5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_axis_off()
    ax.set_title(title)
    return fig, ax, plt


def _equal(ax, xyz):
    lo, hi = np.percentile(xyz, [0.5, 99.5], axis=0)  # stray far points do not shrink it
    c = (lo + hi) / 2
    h = (hi - lo).max() / 2
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    ax.set_zlim(c[2] - h, c[2] + h)


def _save(fig, plt, path):
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    print("wrote", path)


def classes_png(path, xyz, pc, title, view):
    fig, ax, plt = _axes(title, view)
    size = max(0.05, min(1.5, 3e4 / len(xyz)))
    for c in (1, 3, 2, 0):
        m = pc == c
        ax.scatter(*xyz[m].T, s=size, c=CLASS_COLORS[c], linewidths=0,
                   label=f"{CLASS_NAMES[c]} ({100 * m.mean():.1f} %)")
    ax.legend(loc="upper left", markerscale=8, fontsize=8)
    _equal(ax, xyz)
    _save(fig, plt, path)


def segments_png(path, xyz, labels, lines, title, view):
    fig, ax, plt = _axes(title, view)
    size = max(0.05, min(1.5, 3e4 / len(xyz)))
    rng = np.random.default_rng(3)
    cmap = plt.get_cmap("tab20")
    palette = cmap(np.r_[0:14, 16:20])  # the greys (14, 15) are for "no segment"
    colors = palette[rng.permutation(max(labels.max(), 1) + 1) % len(palette)]
    none = labels == 0
    ax.scatter(*xyz[none].T, s=size * 0.5, c="#dddddd", linewidths=0)
    ax.scatter(*xyz[~none].T, s=size, c=colors[labels[~none]], linewidths=0)
    if lines is not None:
        for v in lines.vertices:
            ax.plot(*np.asarray(v).T, c="k", lw=1.5)
    _equal(ax, xyz)
    _save(fig, plt, path)


def _near_objects(cloud, margin=3.0):
    """Synthetic scenes: the points within `margin` (plan) of the box of all but the ground
    (the ground plane runs 80 m out and would shrink the objects to dots)."""
    names = np.array(cloud.meta["face_names"])[cloud.face].astype(str)
    obj = cloud.xyz[~np.char.startswith(names, "ground")]
    lo, hi = obj[:, :2].min(axis=0) - margin, obj[:, :2].max(axis=0) + margin
    return np.all((cloud.xyz[:, :2] >= lo) & (cloud.xyz[:, :2] <= hi), axis=1)


def run(name, xyz, sensor, view, extra="", show=None):
    from lidarstat.segment import segment_covariance

    t0 = time.perf_counter()
    from lidarstat.classify import covariance

    # the defaults of both commands (the automatic scale)
    cls = covariance(xyz, sensor=sensor, keep_neighbors=True)
    seg = segment_covariance(xyz, cls)
    dt = time.perf_counter() - t0
    pc = cls.point_class
    kq = np.percentile(cls.features["OptimalKNN"], [10, 50, 90])
    inseg = (seg.labels > 0).mean()
    print(f"{name}: {len(xyz)} points, {seg.n_segments} segments, {100 * inseg:.0f} % in "
          f"segments, {len(seg.lines) if seg.lines is not None else 0} lines, {dt:.1f} s")
    m = np.ones(len(xyz), dtype=bool) if show is None else show
    classes_png(DOCS / f"covariance_{name}_classes.png", xyz[m], pc[m],
                f"{name}{extra}: point_class (automatic scale, k {kq[0]:.0f}/{kq[1]:.0f}/"
                f"{kq[2]:.0f} at 10/50/90 %)", view)
    segments_png(DOCS / f"covariance_{name}_segments.png", xyz[m], seg.labels[m], seg.lines,
                 f"{name}{extra}: {seg.n_segments} segments (grey: none), "
                 f"{100 * inseg:.0f} % of the points; lines black", view)
    return seg


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", choices=("pump", "building", "plant"), default=None)
    a = p.parse_args(argv)
    from lidarstat.synth import make_tls_building, make_tls_plant

    if a.only in (None, "building"):
        sc = make_tls_building(rng=0)
        run("tls_building", sc.xyz, sc.scanner, (25, -115), show=_near_objects(sc))
    if a.only in (None, "plant"):
        sc = make_tls_plant(rng=0)
        run("tls_plant", sc.xyz, sc.scanner, (25, -110), show=_near_objects(sc))
    if a.only in (None, "pump"):
        if not PUMP.exists():
            print("skipped: no", PUMP)
            return
        from lidarstat.io import read

        cloud = read(PUMP)
        run("pump", cloud.xyz, np.zeros(3), (20, -60), extra=" (real scan)")


if __name__ == "__main__":
    main()
