"""``--tile SIZE`` on one large file: ``ridges``, ``segment`` and ``covariance`` out of core.

The file is streamed into square tiles of side SIZE, each run with a halo as wide as the
buffer a catalogue of tile files gives the method (:mod:`lidarstat.cli._catalogue_methods`,
:mod:`lidarstat.cli._catalogue_segment`), by :func:`lidarstat.pipeline.process_file`:
memory holds the tiles in progress, not the file. What the area decides once (the noise
sigma, an automatic scale's ladder, the SAR bandwidth) is decided as a catalogue decides
it, on up to nine tiles of the file spread over it (:func:`lidarstat.pipeline.sample_file`),
and given to every tile.

* ``ridges``: every per-point field; ``ridge_line`` ids unique over the file, the lines
  file holding each tile's lines whose middle vertex lies in its core square.
* ``segment``: ``segment_id`` joined across tiles (a surface crossing a tile border keeps
  one id, see ``lidarstat.pipeline._stream_labels``); the table has one row per segment,
  its ``n_points`` the segment's points over the file and its other columns those of the
  segment's largest piece (the tile run holding most of its points); the lines between
  segments are each tile's lines whose middle vertex lies in its core square.
* ``covariance``: every per-point field.
"""

from __future__ import annotations

import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from . import _catalogue_methods as _methods
from . import _catalogue_segment as _segment

__all__ = ["TILED", "run_tiled"]

#: Options of every tiled run (destinations), whatever the command.
_RUN_OPTIONS = frozenset({"tile", "chunk_points", "scheduler", "workers", "summary_json",
                          "quiet", "verbose", "lines", "table"})

#: Options a tiled run cannot honour, per command, and why.
_REFUSED = {"segment": {"diagnostics": "the Forward Search diagnostics are a whole-cloud "
                                       "plot"}}


def _in_square(lines, bounds, rename: dict):
    """The lines whose middle vertex lies in the core square `bounds` (half-open, so each
    line is kept by one tile), with the attributes of `rename` shifted (``name -> base``)."""
    if lines is None:
        return None
    if not len(lines):
        return SimpleNamespace(vertices=[], attributes={}, rename=rename)
    x0, y0, x1, y1 = bounds
    mid = np.array([v[len(v) // 2, :2] for v in lines.vertices]).reshape(-1, 2)
    keep = (mid[:, 0] >= x0) & (mid[:, 0] < x1) & (mid[:, 1] >= y0) & (mid[:, 1] < y1)
    attrs = {n: np.asarray(a)[keep] for n, a in lines.attributes.items()}
    return SimpleNamespace(vertices=[v for v, k in zip(lines.vertices, keep) if k],
                           attributes=attrs, rename=rename)


class _Lines:
    """Lines gathered from the tiles, their label attributes as nodes until the end."""

    def __init__(self, field: str, names: tuple):
        self.field, self.names = field, names
        self.vertices: list = []
        self.attributes: dict[str, list] = {}
        self.present = False  # a tile's run had lines (possibly none in its square)

    def add(self, part, bases) -> None:
        if part is None:
            return
        self.present = True
        if not part.vertices:
            return
        self.vertices += part.vertices
        for n, a in part.attributes.items():
            a = np.asarray(a)
            if n in self.names:  # a label of the tile's run: its node
                a = np.where(a > 0, a.astype(np.int64) + bases[self.field], 0)
            self.attributes.setdefault(n, []).append(a)

    def polylines(self, label_map):
        from ..segment import Polylines

        attrs = {n: np.concatenate(v) for n, v in self.attributes.items()}
        for n in self.names:
            if n in attrs:
                attrs[n] = label_map(attrs[n]).astype(np.int32)
        return Polylines(self.vertices, attrs)


# ------------------------------------------------------------------------------ ridges
def _ridges_tile(args, extra, side):
    from ..segment import ridges

    sigma = extra.get("sigma", args.sigma)
    lines = side["lines"] = _Lines("ridge_line", ("line_id",))

    def run(xyz, tile):
        res = ridges(xyz, radius=args.radius, k=args.k, sigma=sigma, alpha=args.alpha,
                     weight=args.weight, sensor=args.sensor, noise=args.noise,
                     ratio=args.ratio, min_length=args.min_length,
                     scales=extra.get("scales"))
        return res.to_fields(), _in_square(res.lines, tile.bounds, {})

    def collect(tile, part, bases):
        lines.add(part, bases)

    return run, {"ridge_line": False}, collect


# ----------------------------------------------------------------------------- segment
def _segment_tile(args, extra, side):
    run_segment = _segment.segment_runner(args, extra)
    lines = side["lines"] = _Lines("segment_id", ("segment_a", "segment_b"))
    tables = side["tables"] = []

    def run(xyz, tile):
        seg = run_segment(xyz)
        table = {k: np.asarray(v) for k, v in seg.table.items() if np.ndim(v) == 1}
        return seg.to_fields(), (table, _in_square(seg.lines, tile.bounds, {}))

    def collect(tile, info, bases):
        table, part = info
        table = dict(table)
        ids = table["segment_id"].astype(np.int64)
        table["segment_id"] = np.where(ids > 0, ids + bases["segment_id"], 0)
        tables.append(table)
        lines.add(part, bases)

    return run, {"segment_id": True}, collect


def _segment_table(tables, label_map):
    """One row per segment of the file: its largest piece's row, ``n_points`` its points
    over the file."""
    names = [n for n in tables[0] if all(n in t for t in tables)] if tables else \
        ["segment_id"]
    cols = {n: np.concatenate([t[n] for t in tables]) if tables else np.empty(0)
            for n in names}
    nodes = cols["segment_id"].astype(np.int64)
    final = label_map(nodes)
    size = label_map.core_points[nodes]
    order = np.lexsort((-size, final))
    order = order[final[order] > 0]
    first = order[np.r_[True, final[order][1:] != final[order][:-1]]] if order.size else order
    totals = np.bincount(label_map.final, weights=label_map.core_points,
                         minlength=int(final.max(initial=0)) + 1)
    out = {n: v[first] for n, v in cols.items()}
    out["segment_id"] = final[first].astype(np.int32)
    if "n_points" in out:
        out["n_points"] = totals[final[first]].astype(np.int64)
    return out


# -------------------------------------------------------------------------- covariance
def _covariance_tile(args, extra, side):
    from ..classify import covariance
    from .covariance import classification_options

    sigma = extra.get("sigma", args.sigma)
    opts = classification_options(args, args.sensor)

    def run(xyz, tile):
        return covariance(xyz, k=args.k, radius=args.radius, sensor=args.sensor,
                          sigma=sigma, noise=args.noise, alpha=args.alpha,
                          eigen_mode=args.eigen_mode, **opts).to_fields()

    return run, {}, None


#: command -> (buffer(args, sample), decide(args, sample) -> extra,
#: tile(args, extra, side) -> (func(xyz, tile), label fields, collect)).
TILED = {
    "ridges": (_methods.RIDGES[0], _methods.ridges_decide, _ridges_tile),
    "segment": (_segment.SEGMENT[0], _segment.segment_decide, _segment_tile),
    "covariance": (_methods.COVARIANCE[0], _methods.covariance_decide, _covariance_tile),
}


def _refuse(args, command):
    from ..errors import InvalidParameterError

    given = set(getattr(args, "_given", ()))
    names = getattr(args, "_option_names", {})
    for dest, why in _REFUSED.get(command, {}).items():
        if dest in given:
            raise InvalidParameterError(f"{names.get(dest, dest)}: not with --tile ({why})")
    if command in _methods.TILE_OPTIONS:
        for dest in sorted(given - _methods.TILE_OPTIONS[command] - _RUN_OPTIONS):
            raise InvalidParameterError(f"{names.get(dest, dest)}: not supported with --tile")


def run_tiled(args, command: str, out: Path, *, lines: Path | None = None,
              table: Path | None = None) -> dict:
    """Run `command` on ``args.input`` in tiles of ``args.tile``; write `out` (and the
    lines and table files given). Returns the run's facts for the summary."""
    from .._shared._atomic import output_group
    from ..errors import InvalidParameterError
    from ..pipeline import process_file, sample_file
    from ._app import progress

    _refuse(args, command)
    buffer_of, decide, tile_of = TILED[command]
    t0 = time.perf_counter()
    sample = sample_file(args.input, args.tile, points_per_chunk=args.chunk_points)
    buffer = buffer_of(args, sample)
    if args.tile <= buffer:
        raise InvalidParameterError(
            f"--tile: invalid value '{args.tile:g}': must be larger than the buffer "
            f"{buffer:.4g} of {command} (its reach), the halo of every tile")
    extra = decide(args, sample)
    n_points = sample.n_points
    del sample  # its tiles are not kept while the file's tiles run
    side: dict = {}
    func, labels, collect = tile_of(args, extra, side)
    maps: dict = {}
    if not args.quiet:
        print(f"  {n_points} points in tiles of {args.tile:g}, buffer {buffer:.4g}")
    # The summary streams fields back from the output: it appears at once.
    with output_group(defer=False):
        process_file(func, args.input, out, size=args.tile, halo=buffer,
                     scheduler=args.scheduler, workers=args.workers,
                     points_per_chunk=args.chunk_points, progress=progress(args.quiet),
                     with_tile=True, labels=labels, collect=collect, finish=maps.update)
    facts = {"tile": args.tile, "buffer": buffer, "seconds": time.perf_counter() - t0,
             "points": n_points,
             **{k: v for k, v in extra.items() if k in ("sigma", "radius")}}
    if "scales" in extra and extra["scales"] is not None:
        facts["scales"] = list(extra["scales"])
    label = next(iter(labels), None)
    if lines is not None and "lines" in side and side["lines"].present:
        poly = side["lines"].polylines(maps[label])
        poly.write(lines, crs=_crs(args.input))
        facts["n_lines"] = len(poly)
    if table is not None and "tables" in side:
        from ..segment import Segmentation

        rows = _segment_table(side["tables"], maps["segment_id"])
        Segmentation(labels=rows["segment_id"], table=rows).write_table(table)
        facts["n_segments"] = len(rows["segment_id"])
        facts["points_in_segments"] = int(maps["segment_id"].core_points[1:].sum())
    return facts


def _crs(path):
    from ..errors import PointCloudReadError
    from ..io import file_extent

    try:
        return file_extent(path).crs
    except PointCloudReadError:  # not LAS/LAZ: no CRS in a header
        return None


def count_field(path, name: str, points_per_chunk: int) -> np.ndarray:
    """Counts of the values of a small integer field of `path`, streamed."""
    from ..io import iter_chunks

    counts = np.zeros(1, np.int64)
    for c in iter_chunks(path, points_per_chunk):
        b = np.bincount(np.asarray(c.attributes[name]).astype(np.int64))
        if b.size > counts.size:
            b[:counts.size] += counts
            counts = b
        else:
            counts[:b.size] += b
    return counts
