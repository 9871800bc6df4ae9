"""Plan-view maps of per-point results, and hillshades of terrain models, as PNG.

A class map shows each cell of a grid in the colour of its *topmost* point's class, as the
area looks from above (a tree over the ground shows as vegetation); a flag map shows the
share of flagged points per cell (where a test was not significant, say); a hillshade
lights a terrain model from the north-west as GDAL's ``gdaldem hillshade`` does.
"""

from __future__ import annotations

import numpy as np

from ._views import _save, locked

__all__ = ["ASPRS_COLOURS", "class_grid", "hillshade", "plot_class_map", "plot_flag_map",
           "plot_hillshade", "plot_segment_map", "plot_value_map"]

#: ASPRS class -> (name, colour) of the maps.
ASPRS_COLOURS = {
    0: ("never classified", "#bdbdbd"), 1: ("unclassified", "#9e9e9e"),
    2: ("ground", "#a0522d"), 3: ("low vegetation", "#b5e61d"),
    4: ("medium vegetation", "#4caf50"), 5: ("high vegetation", "#1b5e20"),
    6: ("building", "#e53935"), 7: ("low noise", "#ff00ff"), 9: ("water", "#1e88e5"),
    11: ("road surface", "#424242"), 17: ("bridge deck", "#ff9800"),
    18: ("high noise", "#f06292"),
}


def _cells(xy, resolution, bounds=None):
    if bounds is None:
        bounds = (xy[:, 0].min(), xy[:, 1].min(), xy[:, 0].max(), xy[:, 1].max())
    x0, y0, x1, y1 = bounds
    cols = max(int(np.ceil((x1 - x0) / resolution)), 1)
    rows = max(int(np.ceil((y1 - y0) / resolution)), 1)
    c = np.clip(((xy[:, 0] - x0) / resolution).astype(np.int64), 0, cols - 1)
    r = np.clip(((y1 - xy[:, 1]) / resolution).astype(np.int64), 0, rows - 1)
    return r, c, rows, cols, (x0, x1, y0, y1)


def class_grid(xyz, classes, resolution, bounds=None):
    """The class of the topmost point of every cell (-1 where a cell has no point).

    Returns
    -------
    grid : ndarray of int64, shape (rows, cols)
        First row northmost.
    extent : (left, right, bottom, top)
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    classes = np.asarray(classes)
    r, c, rows, cols, extent = _cells(xyz[:, :2], resolution, bounds)
    grid = np.full(rows * cols, -1, dtype=np.int64)
    order = np.argsort(xyz[:, 2], kind="stable")  # later (higher) points overwrite
    grid[(r * cols + c)[order]] = classes[order]
    return grid.reshape(rows, cols), extent


def hillshade(values, resolution, *, azimuth=315.0, altitude=45.0):
    """Hillshade in [0, 1] of a raster: the cosine between the surface normal and the light.

    The light comes from `azimuth` (degrees clockwise from north) at `altitude` degrees
    above the horizon; rows of `values` run south. Gradients are central differences
    (one-sided at the edges); NaN stays NaN.
    """
    z = np.asarray(values, dtype=np.float64)
    d_row, d_col = np.gradient(z, resolution)
    fx, fy = d_col, -d_row  # slopes to the east and to the north
    az, alt = np.deg2rad(azimuth), np.deg2rad(altitude)
    light = (np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt))
    shade = (-fx * light[0] - fy * light[1] + light[2]) / np.sqrt(1.0 + fx**2 + fy**2)
    return np.clip(shade, 0.0, 1.0)


def _map_figure(title, extent):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h = extent[1] - extent[0], extent[3] - extent[2]
    aspect = h / w if w > 0 else 1.0
    fig, ax = plt.subplots(figsize=(8.0, max(2.5, min(8.0 * aspect, 12.0)) + 0.6), dpi=100)
    ax.set_title(title)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.ticklabel_format(useOffset=False, style="plain")
    return fig, ax, plt


@locked
def plot_class_map(path, xyz, classes, *, resolution, title="classes", names=None):
    """A PNG of the class of the topmost point per cell, with a legend of the classes present.

    Parameters
    ----------
    names : dict of int to (name, colour), optional
        Default: :data:`ASPRS_COLOURS`; classes not listed get a grey.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    names = ASPRS_COLOURS if names is None else names
    grid, extent = class_grid(xyz, classes, resolution)
    present = [int(v) for v in np.unique(grid) if v >= 0]
    lut = {v: i for i, v in enumerate(present)}
    index = np.full(grid.shape, np.nan)
    for v, i in lut.items():
        index[grid == v] = i
    colours = [names.get(v, (str(v), "#757575"))[1] for v in present] or ["#ffffff"]
    fig, ax, plt = _map_figure(title, extent)
    ax.imshow(index, extent=extent, cmap=ListedColormap(colours), vmin=-0.5,
              vmax=len(colours) - 0.5, interpolation="nearest")
    counts = np.bincount(np.searchsorted(present, grid[grid >= 0]), minlength=len(present))
    handles = [Patch(color=colours[i], label=f"{v} {names.get(v, (str(v),))[0]} "
                     f"({100 * counts[i] / max(counts.sum(), 1):.1f} % of cells)")
               for i, v in enumerate(present)]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    _save(fig, plt, path)


@locked
def plot_flag_map(path, xyz, flags, *, resolution, title):
    """A PNG of the share of flagged points per cell (white: no point)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    r, c, rows, cols, extent = _cells(xyz[:, :2], resolution)
    cell = r * cols + c
    total = np.bincount(cell, minlength=rows * cols).astype(float)
    hit = np.bincount(cell, weights=np.asarray(flags, dtype=float), minlength=rows * cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, hit / total, np.nan).reshape(rows, cols)
    fig, ax, plt = _map_figure(title, extent)
    im = ax.imshow(share, extent=extent, cmap="magma_r", vmin=0, vmax=1,
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, label="share of the cell's points", shrink=0.8)
    fig.tight_layout()
    _save(fig, plt, path)


@locked
def plot_hillshade(path, raster, *, title="terrain model"):
    """A PNG of a terrain model's hillshade with its heights in colour."""
    left, bottom, right, top = raster.bounds
    extent = (left, right, bottom, top)
    fig, ax, plt = _map_figure(title, extent)
    shade = hillshade(raster.values, raster.resolution)
    ax.imshow(shade, extent=extent, cmap="gray", vmin=0, vmax=1, interpolation="bilinear")
    im = ax.imshow(raster.values, extent=extent, cmap="terrain", alpha=0.45,
                   interpolation="bilinear")
    fig.colorbar(im, ax=ax, label="height", shrink=0.8)
    fig.tight_layout()
    _save(fig, plt, path)


@locked
def plot_segment_map(path, xyz, labels, *, resolution, title="segments"):
    """A PNG of the segment of the topmost point per cell, each segment in a colour of
    its own (a hash of its id, so that neighbours differ); grey: in no segment (id 0)."""
    from matplotlib.colors import hsv_to_rgb

    grid, extent = class_grid(xyz, np.asarray(labels, dtype=np.int64), resolution)
    ids = grid.astype(np.uint64)
    h = ((ids * np.uint64(2654435761)) % np.uint64(1000)).astype(float) / 1000.0
    s = 0.55 + 0.4 * (((ids * np.uint64(40503)) % np.uint64(7)).astype(float) / 6.0)
    rgb = hsv_to_rgb(np.dstack([h, s, np.full(h.shape, 0.9)]))
    rgb[grid == 0] = 0.75
    rgba = np.dstack([rgb, (grid >= 0).astype(float)])
    fig, ax, plt = _map_figure(title, extent)
    ax.imshow(rgba, extent=extent, interpolation="nearest")
    fig.tight_layout()
    _save(fig, plt, path)


@locked
def plot_value_map(path, xyz, values, *, resolution, title, symmetric=False):
    """A PNG of the median of a per-point value per cell (white: no finite value), its
    colour range the 2nd to 98th percentile (symmetric about 0 with `symmetric`)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    r, c, rows, cols, extent = _cells(xyz[:, :2], resolution)
    cell = (r * cols + c)[ok]
    v = v[ok]
    grid = np.full(rows * cols, np.nan)
    if v.size:
        order = np.lexsort((v, cell))
        cell, v = cell[order], v[order]
        starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
        ends = np.r_[starts[1:], cell.size]
        grid[cell[starts]] = 0.5 * (v[(starts + ends - 1) // 2] + v[(starts + ends) // 2])
    grid = grid.reshape(rows, cols)
    fin = grid[np.isfinite(grid)]
    lo, hi = (np.percentile(fin, [2, 98]) if fin.size else (0.0, 1.0))
    if symmetric:
        lo, hi = -max(abs(lo), abs(hi), 1e-300), max(abs(lo), abs(hi), 1e-300)
    fig, ax, plt = _map_figure(title, extent)
    im = ax.imshow(grid, extent=extent, cmap="RdBu_r" if symmetric else "viridis",
                   vmin=lo, vmax=hi if hi > lo else lo + 1e-12, interpolation="nearest")
    fig.colorbar(im, ax=ax, label="median per cell", shrink=0.8)
    fig.tight_layout()
    _save(fig, plt, path)
