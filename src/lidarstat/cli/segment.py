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
from ._app import Output, check_plan, resolve_sensor, write_summary_json

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
    if args.tile is not None:
        return _segment_tiled(args, out, table, lines)
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


def _segment_tiled(args, out, table, lines):
    """``--tile``: the file in tiles with a halo of four neighbourhood reaches, segments
    joined across the tiles."""
    from ._tiled import run_tiled

    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    facts = run_tiled(args, "segment", out, lines=lines, table=table)
    wrote_lines = "n_lines" in facts
    if not args.quiet:
        print(f"{args.input} -> {out}  ({facts['seconds']:.2f} s)")
        print(f"{args.method}: {facts['n_segments']} segments, "
              f"{facts['points_in_segments']} points in segments")
        print(f"  table: {table}" + (f"\n  lines: {lines}" if wrote_lines else ""))
    if args.summary_json:
        write_summary_json(args.summary_json, {
            "input": str(args.input), "output": str(out), "table": str(table),
            "lines": str(lines) if wrote_lines else None, "method": args.method, **facts})
    return 0


def _method_neighbours(args):
    """``--method ridges`` fits degree-4 jets: ``--k`` needs at least 16 neighbours."""
    from .ridges import JET_NEIGHBORS

    if args.method == "ridges" and args.k is not None and args.k < JET_NEIGHBORS:
        return "--k", (f"invalid value '{args.k}': --method ridges needs at least "
                       f"{JET_NEIGHBORS} neighbours (a degree-4 jet)")
    return None


#: Options every method shares (destinations), each used by the methods whose
#: module lists it in ``USES``.
SHARED = ("k", "radius", "min_points", "sensor", "sigma", "noise", "alpha")


def _refuse_unusable(owners):
    """A check refusing an option the chosen ``--method`` cannot use (never ignored)."""

    def check(args):
        method = import_module(SEGMENT_METHODS[args.method])
        names = getattr(args, "_option_names", {})
        for dest in sorted(getattr(args, "_given", ())):
            owner = owners.get(dest)
            if dest in SHARED and dest not in method.USES:
                users = sorted(m for m in SEGMENT_METHODS
                               if dest in import_module(SEGMENT_METHODS[m]).USES)
                return names.get(dest, dest), (
                    f"--method {args.method} does not use it (used by --method "
                    f"{', '.join(users) or 'none'})")
            if owner is not None and owner != args.method:
                return names.get(dest, dest), (
                    f"an option of --method {owner}, not of --method {args.method}")
        return None

    return check


def register(sub):
    """Add the ``segment`` subcommand and every registered method's options."""
    from ._common import add_noise, add_run_outputs, add_tiling, deprecated_alias

    s = sub.add_parser(
        "segment", help="group points into surface segments (--method ...)",
        description="Segment a point cloud into surface units and write segment_id per "
        "point, a table of segments and the lines where adjacent segments meet. An option "
        "the chosen method cannot use is refused.")
    s.add_argument("input")
    s.add_argument("output", help="output file with segment_id; format from the suffix")
    s.add_argument("--method", required=True, choices=sorted(SEGMENT_METHODS),
                   help="segmentation method")
    shared = s.add_argument_group("options of several methods (each says which)")

    def users(dest):
        return ", ".join(m for m in sorted(SEGMENT_METHODS)
                         if dest in import_module(SEGMENT_METHODS[m]).USES)

    shared.add_argument("--k", type=opt.int_at_least(3), default=None,
                        help=f"neighbours per point (kNN; {users('k')})")
    shared.add_argument("--radius", "--jet-radius", type=opt.positive_float, default=None,
                        dest="radius", help=f"neighbourhood radius ({users('radius')})")
    deprecated_alias(s, "--jet-radius", "--radius")
    shared.add_argument("--min-points", "--min-size", type=opt.int_at_least(1), default=None,
                        dest="min_points",
                        help="smallest segment kept, in points (method default if omitted)")
    deprecated_alias(s, "--min-size", "--min-points")
    add_noise(shared)
    shared.add_argument("--alpha", type=opt.probability, default=0.05,
                        help="significance level of the method's main test [0.05]")
    s.add_argument("--table", default=None,
                   help="segment table (.csv or .json; default OUT stem + .segments.csv)")
    s.add_argument("--lines", default=None,
                   help="lines between segments (.geojson, .csv, .las/.laz; "
                   "default OUT stem + .lines.geojson)")
    add_run_outputs(s)
    add_tiling(s, "four neighbourhood reaches; segments joined across tiles")
    owners = {}
    for name in sorted(SEGMENT_METHODS):
        group = s.add_argument_group(f"--method {name}")
        import_module(SEGMENT_METHODS[name]).add_arguments(group)
        for action in group._group_actions:
            owners.setdefault(action.dest, name)
    s.set_defaults(func=cmd_segment)
    opt.add_check(s, _method_neighbours)
    opt.add_check(s, _refuse_unusable(owners))
