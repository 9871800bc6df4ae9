"""``lidarstat segment IN OUT --method M``: one command, several segmentation methods.

A method is a module listed in :data:`SEGMENT_METHODS` that provides

- ``add_arguments(group)``: the options only this method has (argparse group);
- ``run(args, cloud) -> lidarstat.segment.Segmentation``.

Method modules are imported when the parser is built, so they must import their numerics
inside ``run``. The options every method shares are defined here.
"""

from __future__ import annotations

import time
from importlib import import_module
from pathlib import Path

from . import _options as opt
from ._app import SENSOR_HELP, Output, check_plan, resolve_sensor, write_summary_json

#: method name -> module path (``add_arguments``, ``run``). Add a method by adding it here.
SEGMENT_METHODS: dict[str, str] = {
    "sar": "lidarstat.cli._segment_sar",
    "curvature": "lidarstat.cli._segment_curvature",
    "covariance": "lidarstat.cli._segment_covariance",
    "ridges": "lidarstat.cli._segment_ridges",
}


def _default_path(out: Path, suffix: str) -> Path:
    return out.with_name(out.stem + suffix)


def cmd_segment(args):
    """Run the chosen method, write OUT (with ``segment_id``), the table and the lines."""
    from ..io import read, write

    out = Path(args.output)
    table = Path(args.table) if args.table else _default_path(out, ".segments.csv")
    lines = Path(args.lines) if args.lines else _default_path(out, ".lines.geojson")
    diagnostics = getattr(args, "diagnostics", None)
    check_plan([args.input], Output("output", out),
               Output("--table", table, "table", default=not args.table),
               Output("--lines", lines, "lines", default=not args.lines),
               Output("--summary-json", args.summary_json, "json"),
               Output("--diagnostics", diagnostics, "folder"))
    cloud = read(args.input)
    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    method = import_module(SEGMENT_METHODS[args.method])
    t0 = time.perf_counter()
    seg = method.run(args, cloud)
    elapsed = time.perf_counter() - t0
    if diagnostics is not None and getattr(seg, "units", None) is not None:
        from ..report import plot_forward_search_units

        plot_forward_search_units(diagnostics, seg.units)
    write(out, cloud, fields=seg.to_fields())
    seg.write_table(table)
    if seg.lines is not None:
        seg.lines.write(lines, crs=cloud.crs)
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s)")
        print(seg.summary())
        print(f"  table: {table}" + (f"\n  lines: {lines}" if seg.lines is not None else ""))
    if args.summary_json:
        meta = {"input": str(args.input), "output": str(out), "table": str(table),
                "lines": str(lines) if seg.lines is not None else None,
                "method": args.method, "seconds": elapsed, "n_segments": seg.n_segments,
                "params": seg.params}
        write_summary_json(args.summary_json, meta)
    return 0


def _method_neighbours(args):
    """``--method ridges`` fits degree-4 jets: ``--k`` needs at least 16 neighbours."""
    from .ridges import JET_NEIGHBORS

    if args.method == "ridges" and args.k is not None and args.k < JET_NEIGHBORS:
        return "--k", (f"invalid value '{args.k}': --method ridges needs at least "
                       f"{JET_NEIGHBORS} neighbours (a degree-4 jet)")
    return None


def register(sub):
    """Add the ``segment`` subcommand and every registered method's options."""
    s = sub.add_parser(
        "segment", help="group points into surface segments (--method ...)",
        description="Segment a point cloud into surface units and write segment_id per "
        "point, a table of segments and the lines where adjacent segments meet.")
    s.add_argument("input")
    s.add_argument("output", help="output file with segment_id; format from the suffix")
    s.add_argument("--method", required=True, choices=sorted(SEGMENT_METHODS),
                   help="segmentation method")
    s.add_argument("--k", type=opt.int_at_least(3), default=None,
                   help="neighbours per point (kNN)")
    s.add_argument("--radius", type=opt.positive_float, default=None,
                   help="neighbourhood radius")
    s.add_argument("--min-size", type=opt.int_at_least(1), default=None,
                   help="smallest segment kept (points); method default if omitted")
    s.add_argument("--sensor", type=opt.finite_float, nargs=3, metavar=("X", "Y", "Z"), default=None,
                   help=SENSOR_HELP)
    s.add_argument("--sigma", type=opt.positive_float, default=None,
                   help="measurement noise std (default: estimated from the data)")
    s.add_argument("--alpha", type=opt.probability, default=0.05,
                   help="significance level of tests")
    s.add_argument("--table", default=None,
                   help="segment table (.csv or .json; default OUT stem + .segments.csv)")
    s.add_argument("--lines", default=None,
                   help="lines between segments (.geojson, .csv, .las/.laz; "
                   "default OUT stem + .lines.geojson)")
    s.add_argument("--summary-json", default=None, help="write a run summary as JSON here")
    s.add_argument("-q", "--quiet", action="store_true")
    for name in sorted(SEGMENT_METHODS):
        group = s.add_argument_group(f"--method {name}")
        import_module(SEGMENT_METHODS[name]).add_arguments(group)
    s.set_defaults(func=cmd_segment)
    opt.add_check(s, _method_neighbours)
