"""``lidarstat moments IN OUT``: unsupervised classification by sequential moments (seed 004)."""

from __future__ import annotations

import time
from pathlib import Path

from . import _options as opt
from ._app import Output, check_plan, write_summary_json
from ._common import (add_alpha, add_noise, add_run_outputs, add_seed, add_workers,
                      deprecated_alias)


def _run(args):
    from ..classify import moments
    from ..io import linear_units, read, rewrite, write

    if not args.no_report:  # imported before the work: a missing plotting stack fails first
        from ..report import write_moments_report
    out = Path(args.output)
    folder = None
    if not args.no_report:
        folder = Path(args.report) if args.report else out.with_name(out.stem + "_report")
    check_plan([args.input], Output("output", out),
               Output("--report", folder, "folder", default=not args.report,
                      members=("report.json", "index.html")),
               Output("--dtm", args.dtm, "raster"),
               Output("--summary-json", args.summary_json, "json"))
    # LAS/LAZ in and out: the output is the input's records copied chunk by chunk with
    # the new fields, so only the attributes the classification reads are decoded (every
    # LAS point format has them)
    stream = {Path(args.input).suffix.lower(), out.suffix.lower()} <= {".las", ".laz"}
    cloud = read(args.input, fields=_READS if stream else None)
    if len(cloud) == 0:
        from ..errors import InvalidPointsError

        raise InvalidPointsError(f"{args.input}: the file holds no points")
    get = (lambda name: cloud[name] if name in cloud else None)
    units = linear_units(cloud.crs, units=args.units, scale=args.scale,
                         header=cloud.las_header, source=str(args.input))
    t0 = time.perf_counter()
    res = moments(
        cloud.xyz, None if args.no_intensity else get("intensity"),
        number_of_returns=get("number_of_returns"), return_number=get("return_number"),
        method=args.method, window=args.window, min_window=args.min_window,
        alpha=args.alpha, min_points=args.min_points, cycle=args.cycle,
        bandwidth=args.bandwidth, surface_cell=args.surface_cell,
        elevation_rule=args.elevation_rule, workers=args.workers, scheduler=args.scheduler,
        opening_window=args.opening_window, iterations=args.iterations, units=units,
        low_noise=not args.no_low_noise, road_rule=args.road_rule,
        ground_spread=args.ground_spread, continuity=not args.no_continuity, rng=args.seed,
        terrain=not args.no_terrain, source=str(args.input),
        building_alpha=args.building_alpha, sigma=args.sigma,
        # the streamed write copies the input's records: the coordinates read here are
        # needed again only by a terrain model, so the classification may reuse them
        overwrite_xyz=stream and not args.dtm,
        evidence=not args.no_report)  # the densities and window dips: the report's alone
    elapsed = time.perf_counter() - t0
    fields = res.to_fields()
    if stream:
        rewrite(args.input, out, lambda start, chunk: {
            name: a[start:start + len(chunk)] for name, a in fields.items()}, decode=False)
    else:
        write(out, cloud, fields=fields)
    del fields
    if args.dtm:
        from ..io import write_geotiff
        from ..pipeline import terrain_model

        dtm = terrain_model(cloud.xyz, res.classification,
                            resolution=args.dtm_resolution / units.horizontal, crs=cloud.crs)
        write_geotiff(args.dtm, dtm)
    report = None
    if folder is not None:
        report = write_moments_report(folder, res, input_path=args.input, output_path=out,
                                      seconds=elapsed)
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s; coordinates in {units.name}, "
              f"{units.horizontal:g} m, {units.source})")
        print(res.summary())
        if report:
            print(f"report: {report}")
    if args.summary_json:
        write_summary_json(args.summary_json, {"input": str(args.input), "output": str(out),
                                               "seconds": elapsed, "counts": res.counts(),
                                               "params": res.params,
                                               "units": units.to_dict()})
    return 0


#: Attributes of the input the classification reads.
_READS = ("intensity", "number_of_returns", "return_number")


#: Values of the enums ``MomentsMethod``, ``ElevationRule`` and ``RoadRule`` of
#: :mod:`lidarstat.classify` (a test keeps them equal). Spelled out here because importing
#: :mod:`lidarstat.classify` while the parser is built would load its compiled kernels on
#: every start of the program.
METHODS = ("moments", "skewness-balancing")
ELEVATION_RULES = ("symmetry", "plateau")
ROAD_RULES = ("antimode", "kurtosis-peak")


def register(sub):
    """Add the ``moments`` subcommand."""
    from ..io import UNIT_NAMES

    s = sub.add_parser(
        "moments", help="classify ground/road/building/vegetation by sequential moments",
        description="Unsupervised classification by sequential skewness and kurtosis of "
        "elevation and intensity (Crosilla et al.); writes ASPRS codes to `classification`, "
        "the cluster to `cluster_id`, and a report folder (JSON, HTML, PNG).")
    s.add_argument("input")
    s.add_argument("output", help="output file; format from the suffix")
    s.add_argument("--method", choices=METHODS, default="moments",
                   help="sequential moments, or the skewness-balancing baseline in the same "
                   "windows [moments]")
    s.add_argument("--window", "--tile-size", dest="window", type=opt.positive_float,
                   default=64.0, help="side of the regular analysis windows, the paper's "
                   "tiles (metres) [64]")
    deprecated_alias(s, "--tile-size", "--window")
    s.add_argument("--min-window", "--min-tile-size", dest="min_window",
                   type=opt.positive_float, default=16.0,
                   help="smallest window side the progressive split reaches (metres) [16]")
    deprecated_alias(s, "--min-tile-size", "--min-window")
    add_alpha(s, help="level of the dip tests")
    s.add_argument("--min-points", "--min-cluster", dest="min_points",
                   type=opt.int_at_least(1), default=10,
                   help="smallest cluster a cut may leave on either side [10]")
    deprecated_alias(s, "--min-cluster", "--min-points")
    s.add_argument("--cycle", type=opt.int_at_least(0), default=None,
                   help="override the separating cycle of each window's first analysis")
    s.add_argument("--elevation-rule", choices=ELEVATION_RULES,
                   default="symmetry", help="rule choosing an elevation cut [symmetry]")
    s.add_argument("--bandwidth", default="silverman",
                   type=opt.one_of_or(("silverman", "scott"), opt.positive_float,
                                      "'silverman', 'scott' or a number > 0"),
                   help="density bandwidth: silverman, scott or a number (the paper's h)")
    s.add_argument("--surface-cell", type=opt.positive_float, default=4.0,
                   help="cell of the ground surface model, one median point per cell (metres)")
    s.add_argument("--opening-window", type=opt.positive_float, default=20.0,
                   help="window of the opening giving the first lower envelope (metres)")
    s.add_argument("--units", default="auto", choices=["auto", *UNIT_NAMES],
                   help="unit of the coordinates; auto reads it from the file's CRS (metres "
                   "without a CRS); every length option is in metres and converted")
    s.add_argument("--scale", type=opt.positive_float, default=None,
                   help="metres per coordinate unit (overrides --units), e.g. 0.3048")
    s.add_argument("--iterations", type=opt.int_at_least(0), default=4,
                   help="refits of the ground surface")
    s.add_argument("--ground-spread", type=opt.nonnegative_float, default=3.0,
                   help="a window's cut stays at least this many robust SDs above the "
                        "centre of the ground cluster it leaves (0: off)")
    s.add_argument("--no-continuity", action="store_true",
                   help="skip the raised-patch check of the ground (faster on large files)")
    s.add_argument("--no-terrain", action="store_true",
                   help="skip the terrain step (ground grown over embankments and ramps, "
                        "every point tested against the grown surface): the paper's cut alone")
    s.add_argument("--road-rule", choices=ROAD_RULES, default="antimode",
                   help="cut of the ground's intensity into road and the rest")
    s.add_argument("--no-intensity", action="store_true", help="analyse elevation only")
    s.add_argument("--no-low-noise", action="store_true",
                   help="do not flag isolated points under the terrain as low noise (7)")
    s.add_argument("--building-alpha", type=opt.probability, default=0.01,
                   help="level of the building tests: local plane, distance to a "
                        "neighbour's plane, share of non-last returns [0.01]")
    add_noise(s, sigma_help="noise std of the building tests in metres (default: estimated "
              "from the local planes of the ground)", noise=False, sensor=False)
    add_seed(s)
    add_workers(s, help_what="analysis windows")
    s.add_argument("--dtm", default=None, metavar="FILE.tif",
                   help="write a terrain model (GeoTIFF, the TIN of the ground and road "
                   "points) here; with a catalogue a folder, one GeoTIFF per tile and a "
                   "VRT mosaic dtm.vrt")
    s.add_argument("--dtm-resolution", type=opt.positive_float, default=1.0,
                   help="cell size of the terrain model (metres) [1]")
    s.add_argument("--report", default=None,
                   help="report folder (default: OUT stem + '_report')")
    s.add_argument("--no-report", action="store_true")
    add_run_outputs(s)
    s.set_defaults(func=_run)
