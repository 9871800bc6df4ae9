"""The tile functions of ``segment`` on a catalogue (``buffer``, ``prepare``, ``fields``
as for the other commands in ``_catalogue_methods``).

Segmentations couple points further than any buffer. A scale the method chooses from the
data is chosen once for the area (:func:`segment_scale`): the SAR bandwidth, the
curvature ladder (and noise), the ridges' radius. Each tile is segmented with a buffer
(default: the method's neighbourhood reach times :data:`SEGMENT_REACHES`, so that the
segments near a tile's border grow over the neighbours' points as on the whole area);
the segments of neighbouring tiles are then joined where they hold the same points of
the tiles' overlap (:func:`lidarstat.pipeline.process_catalogue` with ``labels``, the
rule of ``--tile`` on one file), so a surface crossing tile borders keeps one id over
the area. Ids are numbered 1.. over the area.
"""

from __future__ import annotations

from pathlib import Path

from ._catalogue_methods import (
    _cached,
    _ladder_text,
    _largest,
    _lines_in_tile,
    _outputs,
    _say,
    _scalar_sigma,
    area_ladder,
    curvature_ladder,
    jet_ladder,
    knn_reach,
    sample_tiles,
)

__all__ = ["SEGMENT", "SEGMENT_REACHES", "segment_decide", "segment_runner", "segment_scale"]

#: Buffer of a segmentation, in neighbourhood reaches.
SEGMENT_REACHES = 4.0


def segment_scale(args, cat) -> dict:
    """What ``segment`` chooses from the data, chosen once for the area: options for
    every tile's run. Empty when the scale is given (``--radius``, ``--k``) or is
    local (the covariance method's per-point k).

    * ``sar``: the bandwidth ``radius`` by ``--criterion``, the median of its selection
      on a sample of tiles (:data:`AREA_SAMPLE_TILES`);
    * ``curvature``: the ladder ``scales`` (:func:`area_ladder` of
      :func:`lidarstat.features.scale_ladder`) and, without ``--sigma``, one noise
      sigma estimated on the largest tile at the ladder's middle radius;
    * ``ridges``: the jets' ``radius``, the smallest rung of the area's ladder
      (:func:`lidarstat.features.radius_ladder`), as the one-file run takes it from its
      cloud.
    """
    import numpy as np

    if args.radius is not None or getattr(args, "k", None) is not None:
        return {}
    if args.method == "sar":
        def select():
            from ..features import select_plane_bandwidth

            b = [select_plane_bandwidth(cat.tile_xyz(i),
                                        criterion=args.criterion, rng=0).bandwidth
                 for i in sample_tiles(cat)]
            return {"radius": float(np.median(b))}

        return _cached(args, "segment_scale", select)
    if args.method == "curvature":
        def ladder():
            scales = area_ladder(cat, curvature_ladder)
            out = {"scales": scales}
            if args.sigma is None:
                from ..features import estimate_sigma

                out["sigma"] = _scalar_sigma(estimate_sigma(
                    cat.tile_xyz(_largest(cat)), scales[len(scales) // 2],
                    noise=args.noise, frame=args.frame, sensor=args.sensor), "segment")
            return out

        return _cached(args, "segment_scale", ladder)
    if args.method == "ridges":
        return _cached(args, "segment_scale",
                       lambda: {"radius": area_ladder(cat, jet_ladder)[0]})
    return {}


def _segment_buffer(args, cat):
    from importlib import import_module

    from .segment import SEGMENT_METHODS

    method = import_module(SEGMENT_METHODS[args.method])
    area = segment_scale(args, cat)
    if args.radius is not None:
        reach = args.radius
    elif "radius" in area:
        reach = area["radius"]
    elif "scales" in area:
        reach = max(area["scales"])
    elif args.k is not None or hasattr(method, "DEFAULT_K"):
        reach = knn_reach(cat, args.k if args.k is not None else method.DEFAULT_K)
    else:  # the covariance method's automatic scale: at most OPTIMAL_K_MAX
        from ..features import OPTIMAL_K_MAX

        reach = knn_reach(cat, OPTIMAL_K_MAX)
    return SEGMENT_REACHES * reach


def _segment_prepare(args, cat):
    return {"outputs": _outputs(args, cat), "area": segment_decide(args, cat),
            "crs": cat.crs, "extents": [f.bounds2d for f in cat.files]}


def segment_decide(args, cat) -> dict:
    """:func:`segment_scale`, printed (options for every tile's run)."""
    area = segment_scale(args, cat)
    words = {"radius": lambda v: f"radius {v:.4g}", "sigma": lambda v: f"sigma {v:.4g}",
             "scales": lambda v: f"radii {_ladder_text(v)}"}
    if area:
        _say(args, "automatic scale: " + ", ".join(words[k](v) for k, v in area.items())
             + " decided for the area, used for every tile")
    return area


def segment_runner(args, area):
    """``run(xyz) -> Segmentation``: the method of ``--method`` with the area's decisions
    (:func:`segment_scale`) as if given on the command line."""
    from importlib import import_module

    from ..io import PointCloud
    from .segment import SEGMENT_METHODS

    method = import_module(SEGMENT_METHODS[args.method])
    area = dict(area)
    scales, run_args = area.pop("scales", None), args
    if area:  # the area's radius (and sigma) as if given on the command line
        from argparse import Namespace

        run_args = Namespace(**{**vars(args), **area})

    def run(xyz):
        if scales is None:
            return method.run(run_args, PointCloud(xyz))
        from ..features import curvature

        curv = curvature(xyz, sigma=run_args.sigma, alpha=args.alpha, frame=args.frame,
                         noise=args.noise, sensor=args.sensor, scales=scales)
        return method.run(run_args, PointCloud(xyz), curv=curv)

    return run


def _segment_fields(args, extra):
    """The tile function and the join of ``segment`` on a catalogue: ``(fields,
    {"labels", "collect", "finish"})`` for :func:`lidarstat.pipeline.process_catalogue`.

    Each tile's run keeps its segment table and its lines whose middle vertex lies in
    the tile; after the join every tile's table lists the segments of its points under
    their final ids, each row that of the segment's largest piece (the tile's run
    holding most of its points; the same row in every tile the segment crosses) with
    ``n_points`` its points over the area, and its lines (those whose middle vertex is
    nearest to the tile) name the final ids.
    """
    import numpy as np

    from ._tiled import _Lines, _segment_table

    run = segment_runner(args, extra.get("area", {}))
    files = list(extra["outputs"])
    tables: list = []  # per tile, in catalogue order: its table with nodes as ids
    lines: list = []

    def fields(tile):
        seg = run(tile.xyz)
        f = seg.to_fields()
        f["segment_id"] = np.asarray(f["segment_id"]).astype(np.uint32)
        table = {k: np.asarray(v) for k, v in seg.table.items() if np.ndim(v) == 1}
        core = f["segment_id"][:tile.n_core]
        index = files.index(tile.extent.path)
        return f, {"segments": int(np.unique(core[core > 0]).size), "table": table,
                   "lines": _lines_in_tile(seg.lines, tile.extent, extra["extents"], index)}

    def collect(index, info, bases):
        table = dict(info["table"])
        ids = table["segment_id"].astype(np.int64)
        table["segment_id"] = np.where(ids > 0, ids + bases["segment_id"], 0)
        tables.append(table)
        part = _Lines("segment_id", ("segment_a", "segment_b"))
        if info["lines"] is not None:
            part.add(info["lines"], bases)
        lines.append(part)

    def finish(maps):
        label_map = maps["segment_id"]
        rows = _segment_table(tables, label_map)
        where = np.zeros(int(rows["segment_id"].max(initial=0)) + 1, np.int64)
        where[rows["segment_id"]] = np.arange(rows["segment_id"].size)
        for path, table, part in zip(files, tables, lines):
            out = Path(extra["outputs"][path])
            stem = out.name.split(".")[0]
            nodes = table["segment_id"].astype(np.int64)
            mine = np.unique(label_map(nodes[label_map.core_points[nodes] > 0]))
            mine = mine[mine > 0]
            _write_table(out.with_name(stem + ".segments.csv"),
                         {k: v[where[mine]] for k, v in rows.items()})
            if part.present:
                part.polylines(label_map).write(out.with_name(stem + ".lines.geojson"),
                                                crs=extra.get("crs"))
        tables.clear()
        lines.clear()

    return fields, {"labels": {"segment_id": True}, "collect": collect, "finish": finish}


def _write_table(path, table):
    """The tile's rows of the segment table as CSV (scalar columns), atomically."""
    import csv

    import numpy as np

    from .._shared._atomic import atomic_path

    cols = {k: np.asarray(v) for k, v in table.items() if np.asarray(v).ndim == 1}
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(cols))
        for row in zip(*(c.tolist() for c in cols.values())):
            w.writerow(row)


SEGMENT = (_segment_buffer, _segment_fields, _segment_prepare)
