"""Top views of per-point fields as PNG files (matplotlib, no screen needed)."""

from __future__ import annotations

import functools
import threading

import numpy as np

from .._shared._atomic import atomic_path

#: pyplot and matplotlib's text layout are not thread-safe: every figure of the package is
#: drawn under this lock, so that tiles processed in threads can write their pictures.
PLOT_LOCK = threading.RLock()


def locked(func):
    """Decorator: `func` draws under :data:`PLOT_LOCK`."""

    @functools.wraps(func)
    def call(*args, **kwargs):
        with PLOT_LOCK:
            return func(*args, **kwargs)

    return call

#: Colours of the HK surface types 0..8 (0 grey).
TYPE_COLORS = ["#bdbdbd", "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
               "#e377c2", "#17becf"]
TYPE_LABELS = ["not classified", "planar", "parabolic ridge", "parabolic valley",
               "elliptic peak", "elliptic pit", "saddle ridge", "saddle valley",
               "minimal saddle"]


def _figure(xyz, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    span = np.ptp(xyz[:, :2], axis=0)
    aspect = span[1] / span[0] if span[0] > 0 else 1.0
    fig, ax = plt.subplots(figsize=(8, max(3.0, min(8 * aspect, 12))), dpi=110)
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    order = np.argsort(xyz[:, 2])  # draw low points first so the visible top wins
    size = max(0.2, min(4.0, 4e4 / max(xyz.shape[0], 1)))
    return fig, ax, plt, order, size


def _save(fig, plt, path, *, tight=True):
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight" if tight else None)
    plt.close(fig)


@locked
def plot_field(path, xyz, values, *, title, cmap="viridis", symmetric=False, clip=(2, 98)):
    """Write a top view of `values` (per point) coloured by `cmap` to PNG `path`.

    Colour limits are the `clip` percentiles of the finite values (symmetric about zero
    for signed quantities like K and H when `symmetric`); NaN points are grey.
    """
    fig, ax, plt, order, size = _figure(xyz, title)
    v = np.asarray(values, dtype=np.float64)
    fin = np.isfinite(v)
    if fin.any():
        lo, hi = np.percentile(v[fin], clip)
        if symmetric:
            m = max(abs(lo), abs(hi)) or 1.0
            lo, hi = -m, m
    else:
        lo, hi = 0.0, 1.0
    o = order[~fin[order]]
    ax.scatter(xyz[o, 0], xyz[o, 1], s=size, c="#cccccc", linewidths=0)
    o = order[fin[order]]
    sc = ax.scatter(xyz[o, 0], xyz[o, 1], s=size, c=v[o], cmap=cmap, vmin=lo, vmax=hi,
                    linewidths=0)
    fig.colorbar(sc, ax=ax, shrink=0.8)
    _save(fig, plt, path)


@locked
def plot_surface_types(path, xyz, surface_type, *, title="surface type"):
    """Write a top view of HK surface types (codes 0-8) with a legend to PNG `path`."""
    fig, ax, plt, order, size = _figure(xyz, title)
    st = np.asarray(surface_type)
    colors = np.array(TYPE_COLORS)[st[order]]
    ax.scatter(xyz[order, 0], xyz[order, 1], s=size, c=colors, linewidths=0)
    from matplotlib.patches import Patch

    present = np.unique(st)
    handles = [Patch(color=TYPE_COLORS[t], label=f"{t} {TYPE_LABELS[t]}") for t in present]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    _save(fig, plt, path)
