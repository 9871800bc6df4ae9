"""Analysis windows of the moments classification: the root windows and one pass over them.

The paper's analysis tiles are called windows here (a window of the analysis, not a
processing tile). The root windows are a regular grid of side ``window``; every pass runs
them through :func:`lidarstat._shared._tiles.map_tiles` (threads, sync or Dask: the same
result). The points are worked in root-window order, so each window is a contiguous block
and a pass copies slices; inside a window the input order is kept.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared._jit import njit
from .._shared._memory import release_freed
from .._shared._tiles import Tile, TileGrid, map_tiles
from ._moments_analysis import paper_clusters, progressive_cut
from ._moments_options import MomentsOptions
from ._surface import cell_order

__all__ = ["root_windows", "window_order", "window_pass"]


class _WindowOut:
    """What one root window gives back: per-point fields plus its report records."""

    def __init__(self, fields, ground_steps, infos, steps=(), n_ids=0):
        self.fields = fields
        self.ground_steps = ground_steps
        self.infos = infos
        self.steps = list(steps)
        self.n_ids = n_ids

    def to_fields(self):
        return self.fields


def window_order(roots):
    """Order of the points window by window (input order inside a window), and the root
    windows in that order: each window's points become the block of positions it
    occupies."""
    perm = np.concatenate([t.points for t in roots])
    out, start = [], 0
    for t in roots:
        m = t.points.size
        out.append(replace(t, points=np.arange(start, start + m)))
        start += m
    return perm, out


def root_windows(xy, size):
    """Root windows of side `size` over local planimetric coordinates `xy`, on the grid
    of multiples of `size` (the caller's origin is one, so all tiles of an area share it).

    Returns ``(perm, roots)``: the point order that makes every root window a contiguous
    block, and the windows (``Tile`` records, points as positions in that order).

    The windows are those of ``tile_grid(xyz, size, anchor=(0, 0))`` (no halo), found
    with one compiled pass for the window numbers and a counting sort (O(N)) instead of
    the general tiler's (N, 3) copy, per-point membership arrays and sort.
    """
    lo = size * np.floor(column_min(xy) / size)  # tile_grid's corner for anchor (0, 0)
    grid = TileGrid.covering(lo, column_max(xy), size, 0.0)
    key = _window_keys(np.ascontiguousarray(xy, dtype=np.float64), grid.origin[0],
                       grid.origin[1], float(size), grid.nrow)
    order, starts = cell_order(key)
    roots = []
    for a, b in itertools.pairwise(starts):
        flat = int(key[order[a]])
        roots.append(Tile(key=grid.key_of(flat), bounds=grid.bounds(flat),
                          points=order[a:b], core=np.ones(b - a, bool)))
    return window_order(roots)


@njit
def _window_keys(xy, ox, oy, size, nrow):  # pragma: no cover - compiled
    """Flat window number ``column * nrow + row`` of every point, the arithmetic of
    ``TileGrid.memberships`` (``floor((xy - origin) / size)``)."""
    key = np.empty(xy.shape[0], np.int64)
    for i in range(xy.shape[0]):
        key[i] = (np.int64(np.floor((xy[i, 0] - ox) / size)) * nrow
                  + np.int64(np.floor((xy[i, 1] - oy) / size)))
    return key


def _cut_window(xy, h, p, record, first=None):
    """Progressive cuts of one root window on heights `h` at planimetric coordinates `xy`:
    ground mask and each point's (sub-)window cut (inf where the root window found none).
    `first` receives the root window's own analysis (:func:`progressive_cut`)."""
    steps, infos = [], []
    parts = progressive_cut(xy, h, np.arange(h.size), p.window, np.inf, p, "", steps, infos,
                            record, first)
    if len(parts) == 1:  # the window kept whole: every position, in order
        thr = parts[0][1]
        return h <= thr, np.full(h.size, thr), steps, infos
    ground = np.zeros(h.size, bool)
    cut = np.empty(h.size)
    for idx, thr in parts:
        ground[idx] = h[idx] <= thr
        cut[idx] = thr
    return ground, cut, steps, infos


def _classify_window(attrs, p, record, final):
    """One root window (`attrs`: its ``xy``, heights ``h`` and ``intensity``): its ground
    cut, and on the final pass also the paper's clustering steps (cluster ids local,
    from 1)."""
    first = {} if final else None  # the heights' analysis: the clusters' first step
    h = attrs["h"]
    ground, cut, gsteps, infos = _cut_window(attrs["xy"], h, p, record, first)
    if not final:
        return _WindowOut({"ground": ground, "cut": cut}, gsteps, infos)
    inten = attrs.get("intensity")
    if inten is not None:  # the driver may hold integer intensity: float64, exactly
        inten = inten.astype(np.float64, copy=False)
    n = h.size
    steps = []
    if n < 2 * p.min_points:
        return _WindowOut({"ground": ground, "cut": cut, "cluster_id": np.ones(n, np.int32)},
                          gsteps, infos, steps, 1)
    cats = {"elevation": h}
    if inten is not None:
        cats["intensity"] = inten
    lab, next_id = paper_clusters(cats, p, -1, steps, 1, first)
    return _WindowOut({"ground": ground, "cut": cut, "cluster_id": lab}, gsteps, infos,
                      steps, next_id - 1)


def window_pass(xy, h, roots, p: MomentsOptions, inten, scheduler, workers, *, final):
    """Every root window's ground cut on heights `h` at planimetric coordinates `xy` (and
    on the `final` pass its clusters and records).

    Returns
    -------
    fields : dict
        ``ground``, ``cut`` (and ``cluster_id``, unique over windows, on the final pass)
        per point, in the order of `xy`.
    steps : list of MomentsStep
        The ground cuts' analyses, then the clustering analyses (final pass only).
    windows : list of dict
        Every window's box, size, cut and split decision (final pass only).
    """
    release_freed()  # what the previous step left free, before the windows allocate
    index = {t.key: i for i, t in enumerate(roots)}
    outs = [None] * len(roots)

    def keep(tile, res):
        outs[index[tile.key]] = res

    attrs = {"xy": xy, "h": h} if inten is None else {"xy": xy, "h": h, "intensity": inten}
    fields = map_tiles(lambda a: _classify_window(a, p, final, final), None,
                       tiles=roots, attributes=attrs, scheduler=scheduler, workers=workers,
                       collect=keep, views=True)
    steps, infos = [], []
    for i, o in enumerate(outs):
        o.fields = None  # assembled in `fields`; keep only the ids and records
        steps.extend(replace(s, window=f"{i}{s.window}") for s in o.ground_steps)
        infos.extend({**t, "window": f"{i}{t['window']}"} for t in o.infos)
    release_freed()  # the windows' own arrays
    if final:  # cluster ids unique in window order, records in window order
        first = 0
        for t, o in zip(roots, outs):
            fields["cluster_id"][t.points] += first
            first += o.n_ids
        for i, o in enumerate(outs):
            steps.extend(replace(rec, window=i) for rec in o.steps)
    return fields, steps, infos
