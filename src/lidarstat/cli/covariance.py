"""``lidarstat covariance IN OUT``: covariance features and surface / edge / boundary classes."""

from __future__ import annotations

import time

from . import _options as opt
from ._app import Output, check_plan, progress, resolve_sensor, write_summary_json
from ._common import add_alpha, add_neighbourhood, add_noise, add_run_outputs, add_tiling


def add_classification_arguments(s):
    """The classification's options, shared by ``covariance`` and ``segment --method
    covariance`` (the segmentation grows regions on these classes)."""
    from ..classify import BoundaryTest, CurvedTest

    s.add_argument("--curvature-threshold", type=opt.nonnegative_float, default=None,
                   help="SurfaceVariation above this is high curvature (replaces the "
                   "automatic plane test)")
    s.add_argument("--variance-threshold", type=opt.nonnegative_float, default=None,
                   help="CurvatureVariance above this is an edge (replaces the automatic "
                   "test; the paper used 0.0001)")
    s.add_argument("--curved", choices=[c.value for c in CurvedTest], default="cylinder",
                   help="consistent-curvature test where the plane is rejected: a cylinder "
                   "fit (default) or the paper's variance of curvature")
    s.add_argument("--curved-alpha", type=opt.probability, default=None,
                   help="level of the consistent-curvature test (rejected -> edge) "
                   "[0.001 cylinder, --alpha variation]")
    s.add_argument("--boundary", choices=[b.value for b in BoundaryTest], default=None,
                   help="boundary test: 'grid' (default with a sensor): the end of the "
                   "visible surface estimated on the scan grid (no return, scan window, or "
                   "a tested depth jump) within --border-band of the neighbourhood's reach; "
                   "'centroid': the paper's centroid test (eq. 6-8; the default without a "
                   "sensor)")
    s.add_argument("--boundary-alpha", type=opt.probability, default=None,
                   help="level of the 'centroid' boundary test [0.001]")
    s.add_argument("--border-band", type=opt.positive_float, default=None,
                   help="'grid' test: a point is a boundary when the estimated end of its "
                   "visible surface is closer than this share of its neighbourhood's reach "
                   "[0.5]")
    s.add_argument("--jump-alpha", type=opt.probability, default=None,
                   help="'grid' test: level of the range-continuity test of a scan-grid "
                   "edge (a depth jump ends the visible surface there) [0.001]")


def classification_options(args, sensor):
    """Keyword arguments of :func:`lidarstat.classify.covariance` from the options; an
    option of the boundary test that does not run is refused."""
    from ..classify import BoundaryTest
    from ..errors import InvalidParameterError

    boundary = args.boundary or (BoundaryTest.GRID.value if sensor is not None else
                                 BoundaryTest.CENTROID.value)
    if boundary == "grid" and args.boundary_alpha is not None:
        raise InvalidParameterError(
            "argument --boundary-alpha: the 'grid' boundary test (the default with a "
            "sensor) does not use it; it is the level of --boundary centroid")
    if boundary == "centroid":
        for name in ("border_band", "jump_alpha"):
            if getattr(args, name) is not None:
                raise InvalidParameterError(
                    f"argument --{name.replace('_', '-')}: only the 'grid' boundary test "
                    "uses it (the default with a sensor)")
    kw = dict(boundary=args.boundary, boundary_alpha=args.boundary_alpha,
              curvature_threshold=args.curvature_threshold,
              variance_threshold=args.variance_threshold, curved=args.curved,
              curved_alpha=args.curved_alpha)
    if args.border_band is not None:
        kw["border_band"] = args.border_band
    if args.jump_alpha is not None:
        kw["jump_alpha"] = args.jump_alpha
    return kw


def cmd_covariance(args):
    from ..classify import covariance
    from ..io import read, write

    out, _ = check_plan([args.input], Output("output", args.output),
                        Output("--summary-json", args.summary_json, "json"))
    if args.tile is not None:
        return _covariance_tiled(args, out)
    cloud = read(args.input)
    t0 = time.perf_counter()
    sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    res = covariance(cloud.xyz, k=args.k, radius=args.radius, sensor=sensor,
                     sigma=args.sigma, noise=args.noise, alpha=args.alpha,
                     eigen_mode=args.eigen_mode,
                     progress=progress(args.quiet), **classification_options(args, sensor))
    elapsed = time.perf_counter() - t0
    write(out, cloud, fields=res.to_fields())
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s)")
        print(res.summary())
    if args.summary_json:
        meta = {"input": str(args.input), "output": str(out), "seconds": elapsed,
                **res.params, "point_class": res.classes.counts()}
        write_summary_json(args.summary_json, meta)
    return 0


def _covariance_tiled(args, out):
    """``--tile``: the file in tiles with a halo of twice the reach (point_class counts
    streamed back from the output)."""
    from ._tiled import count_field, run_tiled

    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    facts = run_tiled(args, "covariance", out)
    counts = count_field(out, "point_class", args.chunk_points)
    names = ("undetermined", "surface", "edge", "boundary")
    classes = {n: int(counts[i]) if i < counts.size else 0 for i, n in enumerate(names)}
    if not args.quiet:
        print(f"{args.input} -> {out}  ({facts['seconds']:.2f} s)")
        print("  " + ", ".join(f"{n} {c}" for n, c in classes.items()))
    if args.summary_json:
        write_summary_json(args.summary_json, {"input": str(args.input), "output": str(out),
                                               **facts, "point_class": classes})
    return 0


def register(sub):
    """Add the ``covariance`` subcommand."""
    from ..features import EigenMode

    s = sub.add_parser(
        "covariance", help="covariance features; surface, edge and boundary points",
        description="Covariance of every point's neighbourhood (k nearest or a sphere), its "
        "eigen features, and a tested surface / edge / boundary class (Bae and Lichti).")
    s.add_argument("input")
    s.add_argument("output", help="output file; format from the suffix")
    add_neighbourhood(s, k_help="neighbours per point, itself included (at least 3) "
                      "[automatic: per point, the smallest size from 20 to 50 whose "
                      "plane test detects a crease with power, else 50]")
    add_noise(s, sigma_help="noise std along --noise (default: estimated from the data)")
    add_alpha(s, help="level of the plane test (and of the variation test)")
    s.add_argument("--eigen-mode", choices=[m.value for m in EigenMode], default="raw",
                   help="eigen features from eigenvalues, their square roots (PDAL's default) "
                   "or normalised eigenvalues")
    add_classification_arguments(s)
    add_run_outputs(s)
    add_tiling(s, "twice the neighbourhood's reach")
    s.set_defaults(func=cmd_covariance)
