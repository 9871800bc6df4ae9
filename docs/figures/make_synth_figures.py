"""Figures of docs/methods/synthetic.md: the synthetic scenes and their truth.

Run from the repository root: ``PYTHONPATH=src python docs/figures/make_synth_figures.py``
(about 20 s); writes ``docs/figures/synth_*.png``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap

from lidarstat.synth import (
    make_als_town,
    make_hip_roof_scene,
    make_tls_building,
    make_tls_plant,
    point_class_truth,
)

OUT = Path(__file__).resolve().parent
CLASS_COLORS = {1: "#e41a1c", 2: "#a6761d", 3: "#b8e186", 4: "#4dac26", 5: "#1b7837",
                6: "#d95f02", 7: "#000000", 11: "#636363"}
CLASS_NAMES = {1: "cars/other", 2: "ground", 3: "low veg.", 4: "medium veg.",
               5: "high veg.", 6: "building", 7: "noise", 11: "road"}


def _scanner_view(ax, c, values, cmap, title, vmin=None, vmax=None):
    """The scan as the scanner sees it: azimuth (decreasing to the right) x elevation."""
    st = c.fields["station"] == 0
    g = c.meta["grids"][0]
    img = np.full(g["shape"], np.nan)
    img[c.fields["row"][st], c.fields["col"][st]] = values[st]
    ax.imshow(img[::-1, ::-1], cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    ax.set_title(title, fontsize=10)
    ax.set_axis_off()


def tls(scene, name):
    c = scene(rng=0)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.6), dpi=100)
    rng = np.random.default_rng(1)
    perm = rng.permutation(len(c.meta["face_names"]))
    _scanner_view(axes[0], c, perm[c.face].astype(float), "tab20",
                  f"{name}: faces ({len(np.unique(c.face))} visible)")
    cls = point_class_truth(c, 0.10).astype(float)
    cmap = ListedColormap(["#c7c7c7", "#1f77b4", "#d62728"])
    _scanner_view(axes[1], c, cls, cmap,
                  "truth at r = 0.10 m: surface (grey), edge (blue), boundary (red)",
                  vmin=0.5, vmax=3.5)
    fig.tight_layout()
    fig.savefig(OUT / f"synth_{name}.png")
    plt.close(fig)


def _raster(xyz, values, cell):
    """Value of the highest point of every cell (NaN where empty): a top view."""
    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(0)) / cell).astype(int)
    shape = ij.max(0) + 1
    img = np.full((shape[1], shape[0]), np.nan)
    o = np.argsort(xyz[:, 2])  # later (higher) points overwrite
    img[ij[o, 1], ij[o, 0]] = values[o]
    ext = (xyz[:, 0].min(), xyz[:, 0].min() + shape[0] * cell,
           xyz[:, 1].min(), xyz[:, 1].min() + shape[1] * cell)
    return img, ext


def als(c, name, title, cell):
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.4), dpi=90)
    cls = c.attributes["classification"]
    codes = sorted(CLASS_COLORS)
    img, ext = _raster(c.xyz, np.searchsorted(codes, cls).astype(float), cell)
    cmap = ListedColormap([CLASS_COLORS[k] for k in codes])
    axes[0].imshow(img, origin="lower", extent=ext, cmap=cmap, vmin=-0.5,
                   vmax=len(codes) - 0.5, interpolation="nearest")
    from matplotlib.patches import Patch

    axes[0].legend(handles=[Patch(color=CLASS_COLORS[k], label=CLASS_NAMES[k])
                            for k in sorted(set(cls.tolist()))], fontsize=7, loc="lower right")
    axes[0].set_title(f"{title}: ASPRS classes (truth, top view)", fontsize=10)
    rp = c.fields["roof_plane"]
    perm = np.random.default_rng(2).permutation(rp.max() + 1).astype(float)
    img, ext = _raster(c.xyz, np.where(rp > 0, perm[rp], np.nan), cell)
    axes[1].imshow(np.zeros_like(img), origin="lower", extent=ext, cmap="gray_r", vmin=0,
                   vmax=8)
    axes[1].imshow(img, origin="lower", extent=ext, cmap="tab20", interpolation="nearest")
    for b in c.meta["buildings"]:
        fp = np.vstack([b["footprint"], b["footprint"][:1]])
        axes[1].plot(fp[:, 0], fp[:, 1], "k-", lw=0.6)
    axes[1].set_title(f"roof planes ({len(c.meta['roof_planes']['id'])}) and footprints",
                      fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / f"synth_{name}.png")
    plt.close(fig)


if __name__ == "__main__":
    tls(make_tls_building, "tls_building")
    tls(make_tls_plant, "tls_plant")
    als(make_als_town(rng=0), "als_town", "als_town", 0.5)
    als(make_hip_roof_scene(rng=0), "hip_roof", "hip_roof (seed 002)", 0.3)
