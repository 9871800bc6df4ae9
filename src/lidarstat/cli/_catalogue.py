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

from . import _options as opt

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
def _curvature_buffer(args, cat):
    return max(args.radius)


def _curvature_prepare(args, cat):
    """One noise estimate for the whole area, so that no tile's answer depends on its own."""
    if args.sigma is not None:
        return {}
    from ..features import estimate_sigma
    from ..io import read

    first = max(range(len(cat)), key=lambda i: cat.files[i].n_points)
    sigma = estimate_sigma(read(cat.files[first].path).xyz, min(args.radius),
                           frame=args.frame, sensor=args.sensor)
    if not args.quiet:
        print(f"  sigma {sigma:.4g} estimated on {cat.files[first].path.name}, used for "
              "every tile")
    return {"sigma": sigma}


def _curvature_fields(args, extra):
    from ..features import curvature

    radius = args.radius if len(args.radius) > 1 else args.radius[0]
    sigma = extra.get("sigma", args.sigma)
    opts = dict(alpha=args.alpha, test=args.test, frame=args.frame, sensor=args.sensor,
                noise=args.noise, min_neighbors=args.min_neighbors,
                minimal_detectable=args.minimal_detectable)

    def fields(tile):
        return curvature(tile.xyz, radius=radius, sigma=sigma, **opts).to_fields(), {}

    return fields


def _moments_prepare(args, cat):
    """Where each tile's terrain model and report go (named after its output)."""
    outputs = cat.outputs(args.output, args.template)
    if args.dtm:
        Path(args.dtm).mkdir(parents=True, exist_ok=True)
    report = None
    if not args.no_report:
        report = Path(args.report) if args.report else Path(args.output) / "report"
    return {"outputs": {f.path: p for f, p in zip(cat.files, outputs)}, "report": report}


def _moments_buffer(args, cat):
    from ..io import linear_units

    units = linear_units(cat.crs, units=args.units, scale=args.scale, source="catalogue")
    return args.window / units.horizontal


def _moments_fields(args, extra):
    from ..classify import moments
    from ..io import linear_units, write_geotiff
    from ..pipeline import terrain_model
    from ..report import write_moments_report

    def fields(tile):
        core = tile.core
        units = linear_units(core.crs, units=args.units, scale=args.scale,
                             header=core.las_header, source=str(tile.extent.path))
        res = moments(
            tile.xyz, None if args.no_intensity else tile.attribute("intensity"),
            number_of_returns=tile.attribute("number_of_returns"),
            return_number=tile.attribute("return_number"), method=args.method,
            window=args.window, min_window=args.min_window, alpha=args.alpha,
            min_points=args.min_points, cycle=args.cycle, bandwidth=args.bandwidth,
            surface_cell=args.surface_cell, elevation_rule=args.elevation_rule,
            workers=1, scheduler="sync", opening_window=args.opening_window,
            iterations=args.iterations, units=units, low_noise=not args.no_low_noise,
            road_rule=args.road_rule, ground_spread=args.ground_spread,
            continuity=not args.no_continuity, rng=args.seed, source=str(tile.extent.path),
            building_alpha=args.building_alpha, sigma=args.sigma)
        stem = Path(extra["outputs"][tile.extent.path]).stem
        if args.dtm:  # the tile's extent, from the ground of the tile and its buffer
            e = tile.extent
            dtm = terrain_model(tile.xyz, res.classification,
                                resolution=args.dtm_resolution / units.horizontal,
                                bounds=(e.xmin, e.ymin, e.xmax, e.ymax), crs=core.crs)
            write_geotiff(Path(args.dtm) / f"{stem}.tif", dtm)
        if extra.get("report") is not None:
            write_moments_report(extra["report"] / "tiles" / stem, res, max_plots=12,
                                 input_path=tile.extent.path)
        return res.to_fields(), {}

    return fields


#: command -> (buffer(args, catalogue), fields(args, extra) -> tile function,
#: prepare(args, catalogue) -> extra). The buffer is the default of ``--buffer``.
TILE_METHODS = {
    "curvature": (_curvature_buffer, _curvature_fields, _curvature_prepare),
    "moments": (_moments_buffer, _moments_fields, _moments_prepare),
}


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
    runs = process_catalogue(fields_of(args, extra), cat, out, buffer=buffer,
                             template=args.template, resume=not args.overwrite,
                             scheduler=args.scheduler, workers=args.workers,
                             address=args.address, progress=_progress(args.quiet))
    if not args.quiet:
        for r in runs:
            what = ("skipped: output exists" if r.status == "skipped" else
                    f"{r.n_points} points + {r.n_buffer} buffer, {r.seconds:.1f} s")
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
    if report is not None:
        page = _area_report(report, args, cat, runs, buffer, seconds, mosaic)
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


def _area_report(folder, args, cat, runs, buffer, seconds, mosaic=None):
    """One page for the area: the classes of every tile on one map, shares per tile, the
    terrain model's hillshade, and each tile's moment analyses behind a link."""
    import numpy as np

    from ..io import read, read_geotiff
    from ..report import ASPRS_COLOURS, write_run_report

    step = max(1, -(-cat.n_points // 1_500_000))  # at most ~1.5M points on the map
    xyz, cls, rows, links = [], [], [], {}
    for r in runs:
        c = read(r.output, fields=["classification"])
        k = np.asarray(c.attributes["classification"])
        xyz.append(c.xyz[::step])
        cls.append(k[::step])
        codes, n = np.unique(k, return_counts=True)
        row = {"tile": r.input.name, "points": len(k)}
        page = folder / "tiles" / r.output.stem / "index.html"
        if page.exists():
            links[f"{r.input.name}: moment analyses"] = f"tiles/{r.output.stem}/index.html"
        row.update({ASPRS_COLOURS.get(int(v), (str(v),))[0]: f"{100 * m / len(k):.1f} %"
                    for v, m in zip(codes, n)})
        rows.append(row)
    facts = {"input": str(args.input), "output": str(args.output), "tiles": len(cat),
             "points": cat.n_points, "buffer": buffer, "seconds": round(seconds, 1)}
    params = {k: v for k, v in vars(args).items()
              if not k.startswith("_") and k not in ("func", "input", "output")}
    return write_run_report(folder, title=f"lidarstat {args.command}", facts=facts,
                            params=params, xyz=np.concatenate(xyz),
                            classes=np.concatenate(cls), tiles=rows, links=links,
                            dtm=read_geotiff(mosaic) if mosaic is not None else None)


def _dispatch(run_one, command):
    def run(args):
        inputs = args.input
        if _is_catalogue(inputs):
            args.input = inputs[0] if len(inputs) == 1 else inputs
            return _run_catalogue(args, command)
        args.input = inputs[0]
        _refuse(args, CATALOGUE_OPTIONS, "only with a catalogue of tiles (IN a folder, a "
                "glob or several files)")
        return run_one(args)

    return run


def install(sub) -> None:
    """Let the commands of :data:`TILE_METHODS` take a catalogue (called by the parser)."""
    from ._common import add_workers

    for command in TILE_METHODS:
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
        g.add_argument("--address", default=None,
                       help="Dask distributed scheduler to run the tiles on "
                       "(tcp://host:8786; with --scheduler dask); every worker must see "
                       "IN and OUT")
        s.set_defaults(func=_dispatch(s.get_default("func"), command))
