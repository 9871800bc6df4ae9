"""``lidarstat covariance IN OUT``: covariance features and surface / edge / boundary classes."""

from __future__ import annotations

import time

from . import _options as opt
from ._app import SENSOR_HELP, Output, check_plan, progress, resolve_sensor, write_summary_json


def add_neighbourhood_arguments(s, *, k_default=50):
    """Options shared by ``covariance`` and ``segment --method covariance``."""
    s.add_argument("--eigen-mode", choices=("raw", "sqrt", "normalized"), default="raw",
                   help="eigen features from eigenvalues, their square roots (PDAL's default) "
                   "or normalised eigenvalues")
    s.add_argument("--boundary-alpha", type=opt.probability, default=None,
                   help="level of the boundary test [0.05 visible, 0.01 scan, 0.001 centroid]")
    s.add_argument("--curvature-threshold", type=opt.nonnegative_float, default=None,
                   help="SurfaceVariation above this is high curvature (replaces the "
                   "automatic plane test)")
    s.add_argument("--variance-threshold", type=opt.nonnegative_float, default=None,
                   help="CurvatureVariance above this is an edge (replaces the automatic "
                   "test; the paper used 0.0001)")
    s.add_argument("--curved", choices=("cylinder", "variation"), default="cylinder",
                   help="consistent-curvature test where the plane is rejected: a cylinder "
                   "fit (default) or the paper's variance of curvature")
    s.add_argument("--curved-alpha", type=opt.probability, default=None,
                   help="level of the consistent-curvature test (rejected -> edge) "
                   "[0.001 cylinder, --alpha variation]")
    s.add_argument("--noise-estimate", choices=("smooth", "median"), default=None,
                   help="range-noise estimate with a sensor when --sigma is not given: "
                   "residuals of the best smooth model (cylinder or plane, default) or "
                   "medians of the plane residuals")


def cmd_covariance(args):
    from ..classify import covariance
    from ..io import read, write

    out, _ = check_plan([args.input], Output("output", args.output),
                        Output("--summary-json", args.summary_json, "json"))
    cloud = read(args.input)
    t0 = time.perf_counter()
    sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    res = covariance(cloud.xyz, k=args.k, radius=args.radius, sensor=sensor,
                     sigma=args.sigma, alpha=args.alpha, boundary_alpha=args.boundary_alpha,
                     curvature_threshold=args.curvature_threshold,
                     variance_threshold=args.variance_threshold, curved=args.curved,
                     curved_alpha=args.curved_alpha, eigen_mode=args.eigen_mode,
                     progress=progress(args.quiet), boundary=args.boundary,
                     jump_alpha=args.jump_alpha, border_band=args.border_band,
                     noise_estimate=args.noise_estimate)
    elapsed = time.perf_counter() - t0
    write(out, cloud, fields=res.to_fields())
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s)")
        print(res.summary())
    if args.summary_json:

        c = res.classes
        meta = {"input": str(args.input), "output": str(out), "seconds": elapsed,
                "k": res.features.k, "radius": res.features.radius,
                "sigma": c.sigma if isinstance(c.sigma, float) else None,
                "sigma_estimated": c.sigma_estimated, "alpha": c.alpha,
                "boundary_alpha": c.boundary_alpha, "boundary": c.meta.get("boundary"),
                "jump_alpha": c.meta.get("jump_alpha"),
                "border_band": c.meta.get("border_band"),
                "curved": c.meta.get("curved"),
                "curved_alpha": c.meta.get("curved_alpha"), "point_class": c.counts()}
        write_summary_json(args.summary_json, meta)
    return 0


def register(sub):
    """Add the ``covariance`` subcommand."""
    s = sub.add_parser(
        "covariance", help="covariance features; surface, edge and boundary points",
        description="Covariance of every point's neighbourhood (k nearest or a sphere), its "
        "eigen features, and a tested surface / edge / boundary class (Bae and Lichti).")
    s.add_argument("input")
    s.add_argument("output", help="output file; format from the suffix")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--k", type=opt.int_at_least(3), default=50,
                   help="neighbours per point, itself included [50]")
    g.add_argument("--radius", type=opt.positive_float, default=None,
                   help="sphere radius instead of kNN")
    s.add_argument("--sensor", type=opt.finite_float, nargs=3, metavar=("X", "Y", "Z"), default=None,
                   help=SENSOR_HELP)
    s.add_argument("--sigma", type=opt.positive_float, default=None,
                   help="noise std across surfaces (default: estimated from the data)")
    s.add_argument("--alpha", type=opt.probability, default=0.05,
                   help="level of the plane and consistent-curvature tests [0.05]")
    add_neighbourhood_arguments(s)
    s.add_argument("--boundary", choices=("grid", "visible", "scan", "centroid"), default=None,
                   help="boundary test: 'grid' (default with a sensor): the end of the "
                   "visible surface on the scan grid (no return, scan window, or a tested "
                   "depth jump between two resolved surfaces) within --border-band of the "
                   "neighbourhood's reach; 'visible': the Hotelling test of "
                   "the visible disc, cut at depth jumps; 'scan': the complete disc of the kNN in scan "
                   "coordinates; 'centroid': the paper's test (eq. 6-8, on surface points; "
                   "the default without a sensor)")
    s.add_argument("--border-band", type=opt.positive_float, default=0.5,
                   help="'grid' test: a point is a boundary when the estimated end of its "
                   "visible surface is closer than this share of its neighbourhood's reach "
                   "[0.5]")
    s.add_argument("--jump-alpha", type=opt.probability, default=0.001,
                   help="level of the range-continuity test of a scan-grid edge (a depth "
                   "jump cuts the visible disc there) [0.001]")
    s.add_argument("--summary-json", default=None, help="write the summary as JSON here")
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(func=cmd_covariance)
