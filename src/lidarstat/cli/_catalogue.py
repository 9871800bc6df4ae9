"""Tile catalogues on the command line: IN may be a folder, a glob or several files.

``lidarstat moments tiles/ classified/`` processes every LAS/LAZ/COPC file of ``tiles/``
as one area: each tile with a buffer read from its neighbours, one output per tile in
``classified/`` (``--template``), finished tiles skipped on a rerun (``--overwrite`` to
redo them), tiles in threads or on a Dask cluster (``--scheduler dask --address``).
With one file, a command runs as always and the catalogue options are refused.

A command takes catalogues when :data:`TILE_METHODS` has an entry for it: the buffer it
needs (its neighbourhood's reach) and the function computing its fields on a
:class:`lidarstat.pipeline.BufferedTile`. :func:`install` adapts the parsers.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from . import _catalogue_methods as _methods
from . import _catalogue_segment as _segment
from . import _options as opt
from ._catalogue_moments import MOMENTS, area_report
from ._catalogue_reports import REPORTS, write_area_report, write_report

__all__ = ["CATALOGUE_OPTIONS", "TILE_METHODS", "install"]

#: Options that only make sense with a catalogue (destinations).
CATALOGUE_OPTIONS = ("template", "buffer", "address", "overwrite")


def _is_catalogue(inputs) -> bool:
    if len(inputs) != 1:
        return True
    text = inputs[0]
    return Path(text).is_dir() or any(c in text for c in "*?[")


def _progress(quiet):
    """``progress(done, total)`` for tiles on a terminal, or None."""
    if quiet or not sys.stderr.isatty():
        return None
    start = time.perf_counter()

    def report(done, total):
        bar = "#" * round(30 * done / max(total, 1))
        print(f"\r  tiles [{bar:<30}] {done}/{total}  {time.perf_counter() - start:6.1f} s",
              end="" if done < total else "\n", file=sys.stderr, flush=True)

    return report


# ----------------------------------------------------------------- per-command methods
def _curvature_scales(args, cat):
    """The radii of the run: ``--radius``, or the automatic ladder decided once for the
    area (:func:`lidarstat.cli._catalogue_methods.area_ladder`)."""
    if args.radius is not None:
        return list(args.radius)
    if getattr(args, "_scales", None) is None:
        args._scales = list(_methods.area_ladder(cat, _methods.curvature_ladder))
        if not args.quiet:
            print("  automatic scale: radii "
                  f"{', '.join(f'{r:.4g}' for r in args._scales)} decided on "
                  f"{len(_methods.sample_tiles(cat))} tiles, used for every tile")
    return args._scales


def _curvature_buffer(args, cat):
    return max(_curvature_scales(args, cat))


def _curvature_prepare(args, cat):
    """One noise estimate (and automatic ladder) for the whole area, so that no tile's
    answer depends on its own."""
    extra = {} if args.radius is not None else {"scales": _curvature_scales(args, cat)}
    if args.sigma is not None:
        return extra
    from ..features import estimate_sigma

    first = max(range(len(cat)), key=lambda i: cat.files[i].n_points)
    radii = sorted(_curvature_scales(args, cat))
    est_radius = radii[len(radii) // 2] if args.radius is None else radii[0]
    sigma = estimate_sigma(cat.tile_xyz(first), est_radius, noise=args.noise,
                           frame=args.frame, sensor=args.sensor)
    if not args.quiet:
        print(f"  sigma {sigma:.4g} estimated on {cat.files[first].path.name}, used for "
              "every tile")
    return {**extra, "sigma": sigma}


def _curvature_fields(args, extra):
    from ..features import curvature

    radius = None if args.radius is None else (
        args.radius if len(args.radius) > 1 else args.radius[0])
    sigma = extra.get("sigma", args.sigma)
    opts = dict(alpha=args.alpha, test=args.test, frame=args.frame, sensor=args.sensor,
                noise=args.noise, min_neighbors=args.min_neighbors,
                minimal_detectable=args.minimal_detectable, power=args.power,
                scales=extra.get("scales"))

    def fields(tile):
        return curvature(tile.xyz, radius=radius, sigma=sigma, **opts).to_fields(), {}

    return fields


#: command -> (buffer(args, catalogue), fields(args, extra) -> tile function,
#: prepare(args, catalogue) -> extra). The buffer is the default of ``--buffer``.
TILE_METHODS = {
    "curvature": (_curvature_buffer, _curvature_fields, _curvature_prepare),
    "moments": MOMENTS,
    "covariance": _methods.COVARIANCE,
    "ridges": _methods.RIDGES,
    "segment": _segment.SEGMENT,
}

#: Options of every catalogue run (destinations), whatever the command.
_RUN_OPTIONS = frozenset({*CATALOGUE_OPTIONS, "scheduler", "workers", "summary_json", "quiet",
                          "report", "verbose", "tile", "chunk_points", "lines"})

#: Options of one file's run that a catalogue replaces by files beside each tile's output.
_ONE_FILE_ONLY = {"ridges": ("lines",), "segment": ("table", "lines", "diagnostics")}


# ------------------------------------------------------------------------ the command
def _refuse(args, names, why):
    given = getattr(args, "_given", set())
    options = getattr(args, "_option_names", {})
    for dest in names:
        if dest in given:
            from ..errors import InvalidParameterError

            raise InvalidParameterError(f"{options.get(dest, dest)}: {why}")


def _run_catalogue(args, command):
    from ..errors import InvalidParameterError, PointCloudWriteError
    from ..pipeline import Catalogue, process_catalogue

    _refuse(args, ("tile", "chunk_points"),
            "not with a catalogue of tiles (the catalogue is already tiled)")
    _refuse(args, _ONE_FILE_ONLY.get(command, ()),
            "not with a catalogue of tiles (each tile's is written beside its output)")
    if command in _methods.TILE_OPTIONS:
        passed = _methods.TILE_OPTIONS[command] | _RUN_OPTIONS
        _refuse(args, sorted(set(getattr(args, "_given", ())) - passed),
                "not supported with a catalogue of tiles")
    cat = Catalogue(args.input)
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise PointCloudWriteError(f"{args.output}: with a catalogue of tiles the output "
                                   "is a folder (one file per tile)")
    buffer_of, fields_of, prepare = TILE_METHODS[command]
    buffer = args.buffer if args.buffer is not None else buffer_of(args, cat)
    if args.address is not None and args.scheduler != "dask":
        raise InvalidParameterError("--address: needs --scheduler dask")
    cat.outputs(out, args.template)  # every output checked before any work
    report = dtm = None
    if command == "moments":
        if not args.no_report:
            report = Path(args.report) if args.report else out / "report"
        if args.dtm:
            dtm = Path(args.dtm)
            if dtm.exists() and not dtm.is_dir():
                raise PointCloudWriteError(f"{args.dtm}: with a catalogue of tiles --dtm "
                                           "is a folder (one GeoTIFF per tile and dtm.vrt)")
    extra = prepare(args, cat) if prepare is not None else {}
    if not args.quiet:
        print(f"{len(cat)} tiles, {cat.n_points} points, buffer {buffer:g} -> {out}/")
    t0 = time.perf_counter()
    tile_func, join = fields_of(args, extra), {}
    if isinstance(tile_func, tuple):  # labels joined across the tiles (segment)
        tile_func, join = tile_func
        join = {**join, "run_key": _run_key(command, args, extra)}
    runs = process_catalogue(tile_func, cat, out, buffer=buffer,
                             template=args.template, resume=not args.overwrite,
                             scheduler=args.scheduler, workers=args.workers,
                             address=args.address, progress=_progress(args.quiet), **join)
    if not args.quiet:
        for r in runs:
            what = ("skipped: output exists" if r.status == "skipped" else
                    "resumed: its run kept from a stopped run" if r.status == "resumed"
                    else f"{r.n_points} points + {r.n_buffer} buffer, {r.seconds:.1f} s")
            print(f"  {r.input.name} -> {r.output.name}  ({what})")
        done = sum(r.status == "done" for r in runs)
        print(f"{done} tiles processed, {len(runs) - done} skipped  "
              f"({time.perf_counter() - t0:.1f} s)")
    seconds = time.perf_counter() - t0
    mosaic = None
    if dtm is not None:
        from .._shared._atomic import output_group
        from ..io import write_vrt

        tiles = [dtm / f"{r.output.stem}.tif" for r in runs]
        with output_group(defer=False):  # the report reads it back
            mosaic = write_vrt(dtm / "dtm.vrt", [t for t in tiles if t.exists()])
        if not args.quiet:
            print(f"terrain model: {mosaic}")
    if report is None and getattr(args, "report", None) and command in REPORTS:
        report = Path(args.report)
    if report is not None:
        if command == "moments":
            page = area_report(report, args, cat, runs, buffer, seconds, mosaic)
        else:
            page = write_area_report(report, args, cat, runs, buffer, seconds)
        if not args.quiet:
            print(f"report: {page}")
    if args.summary_json:
        from ._app import write_summary_json

        write_summary_json(args.summary_json, {
            "input": str(args.input), "output": str(out), "buffer": buffer,
            "seconds": seconds, "tiles": [
                {"input": str(r.input), "output": str(r.output), "status": r.status,
                 "points": r.n_points, "buffer_points": r.n_buffer, "seconds": r.seconds}
                for r in runs]})
    return 0


def _run_key(command, args, extra) -> str:
    """The method and every option that shapes its results, and what it chose from the
    data: a pending tile's record is resumed only by a run with the same key."""
    skip = _RUN_OPTIONS | {"input", "output"}
    options = {k: v for k, v in vars(args).items()
               if not k.startswith("_") and k not in skip and not callable(v)}
    return repr(_plain([command, options, extra]))


def _plain(value):
    """`value` as nested lists of numbers and strings, dicts sorted by key."""
    if isinstance(value, dict):
        return sorted((str(k), _plain(v)) for k, v in value.items())
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value if isinstance(value, (int, float, bool, type(None))) else str(value)


def _dispatch(run_one, command):
    def run(args):
        inputs = args.input
        if _is_catalogue(inputs):
            args.input = inputs[0] if len(inputs) == 1 else inputs
            return _run_catalogue(args, command)
        args.input = inputs[0]
        _refuse(args, CATALOGUE_OPTIONS, "only with a catalogue of tiles (IN a folder, a "
                "glob or several files)")
        folder = getattr(args, "report", None) if command in REPORTS else None
        if folder is not None and getattr(args, "tile", None) is not None:
            _refuse(args, ("report",), "not with --tile (the report reads the whole output "
                    "back into memory)")
        if folder is not None:
            from .._shared._outputs import Output
            from ._app import check_plan

            check_plan([args.input], Output("--report", Path(folder), "folder",
                                            members=("index.html",)))
        t0 = time.perf_counter()
        if folder is None:
            return run_one(args)
        from .._shared._atomic import output_group

        with output_group(defer=False):  # the report reads the output back
            status = run_one(args)
        if status == 0 and folder is not None:
            page = write_report(folder, args, Path(args.output),
                                seconds=time.perf_counter() - t0)
            if not args.quiet:
                print(f"report: {page}")
        return status

    return run


def install(sub) -> None:
    """Let the commands of :data:`TILE_METHODS` take a catalogue (called by the parser)."""
    from ._common import add_workers

    for command in TILE_METHODS:
        if command not in sub.choices:  # a parser built for one other command
            continue
        s = sub.choices[command]
        action = next(a for a in s._actions if a.dest == "input")
        action.nargs = "+"
        action.metavar = "IN"
        action.help = ("input file; or a folder, a glob or several LAS/LAZ/COPC files: a "
                       "catalogue of tiles, processed as one area (OUT is then a folder)")
        g = s.add_argument_group("tile catalogues")
        g.add_argument("--template", default="{stem}.laz",
                       help="output name of each tile in OUT: {stem} (the input's name "
                       "without suffix), {name} or {index} [{stem}.laz]")
        g.add_argument("--buffer", type=opt.nonnegative_float, default=None,
                       help="distance around each tile from which the neighbours' points "
                       "are read (default: the method's reach, so that the result does "
                       "not depend on the tiling)")
        g.add_argument("--overwrite", action="store_true",
                       help="process tiles whose output exists (default: skip them, so a "
                       "stopped run goes on where it stopped)")
        if not any(a.dest == "scheduler" for a in s._actions):
            add_workers(g)
        if command in REPORTS:
            s.add_argument("--report", default=None, metavar="DIR",
                           help="write an HTML report into DIR: a plan-view map of the "
                           "results, their fields and where the tests were not significant "
                           "(with a catalogue: one page for the area, one per tile)")
        g.add_argument("--address", default=None,
                       help="Dask distributed scheduler to run the tiles on "
                       "(tcp://host:8786; with --scheduler dask); every worker must see "
                       "IN and OUT")
        s.set_defaults(func=_dispatch(s.get_default("func"), command))


def run_info(args) -> int:
    """``lidarstat info`` of a catalogue: tiles, points, extents, CRS consistency, gaps
    and overlaps; ``--tindex FILE.geojson`` writes the tile index (PDAL's ``tindex``)."""
    import json

    from ..pipeline import Catalogue

    cat = Catalogue(args.file if len(args.file) > 1 else args.file[0], one_crs=False)
    d = cat.describe()
    if args.tindex:
        d["tindex"] = str(cat.write_tindex(args.tindex))
    if args.json:
        print(json.dumps(d, indent=2, default=str))
        return 0
    x0, y0, x1, y1 = d["bounds"]
    crs = ("one CRS" if d["crs_count"] == 1 else "no CRS" if d["crs_count"] == 0 else
           f"{d['crs_count']} different CRSs: not usable as one catalogue")
    extent = (f"  extent x {x0:.3f} .. {x1:.3f}, y {y0:.3f} .. {y1:.3f}, "
              f"z {d['zmin']:.3f} .. {d['zmax']:.3f}")
    cover = (f"  area of the bounding box covered by no tile "
             f"{100 * d['uncovered_share']:.1f} %, by several {100 * d['overlap_share']:.1f} %")
    lines = [f"catalogue: {d['tiles']} tiles, {d['points']} points ({d['copc_tiles']} COPC)",
             extent, f"  {crs}", cover]
    for f in d["files"]:
        b = f["bounds"]
        lines.append(f"  {Path(f['path']).name}: {f['points']} points, x {b[0]:.2f} .. "
                     f"{b[2]:.2f}, y {b[1]:.2f} .. {b[3]:.2f}")
    if args.tindex:
        lines.append(f"tile index: {d['tindex']}")
    print("\n".join(lines))
    return 0
