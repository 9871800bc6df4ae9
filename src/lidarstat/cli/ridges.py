"""``lidarstat ridges IN OUT``: Monge coefficients, crest/ravine points and ridge lines."""

from __future__ import annotations

import time
from pathlib import Path

from .._shared._choices import Weight
from . import _options as opt
from ._app import Output, check_plan, progress, resolve_sensor, write_summary_json
from ._common import add_alpha, add_neighbourhood, add_noise, add_run_outputs, add_tiling

#: Fewest neighbours of a degree-4 jet: its 15 coefficients and one degree of freedom.
JET_NEIGHBORS = 16


def _lines_path(args, out: Path) -> Path:
    return Path(args.lines) if args.lines else out.with_name(out.stem + ".ridges.geojson")


def cmd_ridges(args):
    """Fit degree-4 jets, detect ridges, write OUT and the ridge lines."""
    from ..io import read, write
    from ..segment import ridges

    out = Path(args.output)
    lines_path = _lines_path(args, out)
    check_plan([args.input], Output("output", out),
               Output("--lines", lines_path, "lines", default=not args.lines),
               Output("--summary-json", args.summary_json, "json"))
    if args.tile is not None:
        return _ridges_tiled(args, out, lines_path)
    cloud = read(args.input)
    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    t0 = time.perf_counter()
    res = ridges(cloud.xyz, radius=args.radius, k=args.k, sigma=args.sigma, alpha=args.alpha,
                 weight=args.weight, sensor=args.sensor, noise=args.noise, ratio=args.ratio,
                 min_length=args.min_length, progress=progress(args.quiet))
    elapsed = time.perf_counter() - t0
    write(out, cloud, fields=res.to_fields())
    res.lines.write(lines_path, crs=cloud.crs)
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s)")
        print(res.summary())
        print(f"  lines: {lines_path}")
    if args.summary_json:
        r = res.fields["ridge"]
        meta = {"input": str(args.input), "output": str(out), "lines": str(lines_path),
                "seconds": elapsed, "sigma": res.jets.sigma,
                "sigma_estimated": res.jets.sigma_estimated, "crest_points": int((r == 1).sum()),
                "ravine_points": int((r == 2).sum()), "n_lines": len(res.lines),
                "scale": res.params.get("scale", "fixed"),
                "params": res.params}
        write_summary_json(args.summary_json, meta)
    return 0


def _ridges_tiled(args, out, lines_path):
    """``--tile``: the file in tiles with a halo of three jet radii (ridge counts streamed
    back from the output)."""
    from ._tiled import count_field, run_tiled

    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    facts = run_tiled(args, "ridges", out, lines=lines_path)
    counts = count_field(out, "ridge", args.chunk_points)
    crest, ravine = (int(counts[i]) if i < counts.size else 0 for i in (1, 2))
    if not args.quiet:
        print(f"{args.input} -> {out}  ({facts['seconds']:.2f} s)")
        print(f"  crest points {crest}, ravine points {ravine}, lines "
              f"{facts.get('n_lines', 0)}")
        print(f"  lines: {lines_path}")
    if args.summary_json:
        write_summary_json(args.summary_json, {
            "input": str(args.input), "output": str(out), "lines": str(lines_path),
            **facts, "crest_points": crest, "ravine_points": ravine})
    return 0


def add_jet_arguments(s):
    """Options shared by ``ridges`` and ``segment --method ridges``."""
    s.add_argument("--weight", choices=Weight.values(), default=Weight.TRICUBE.value,
                   help="tricube weights or CGAL's unweighted jet fit")
    s.add_argument("--ratio", type=opt.real(1, closed="left"), default=2.0,
                   help="a ridge's curvature must exceed RATIO times the other")
    s.add_argument("--min-length", type=opt.nonnegative_float, default=None,
                   help="shorter ridge lines are dropped (default: twice the jet radius)")


def register(sub):
    """Add the ``ridges`` subcommand."""
    s = sub.add_parser(
        "ridges", help="fourth-order Monge jets, crest/ravine points and ridge lines",
        description="Fit degree-4 jets in the Monge frame of every point, write k1, k2, "
        "their directions, b0..b3, c0..c4 with standard deviations, a chi-square test of "
        "the jet, the ridge class (1 crest, 2 ravine) and umbilics, and trace ridge lines.")
    s.add_argument("input")
    s.add_argument("output", help="output file; format from the suffix")
    add_neighbourhood(s, k_min=JET_NEIGHBORS,
                      k_help=f"k nearest neighbours (at least {JET_NEIGHBORS}, a degree-4 jet)",
                      radius_help="sphere radius of the jets (bandwidth); without --radius "
                      "and --k, the automatic scale: per point the smallest radius at which "
                      "the k'' of a ridge is significant (field 'radius')")
    add_noise(s)
    add_alpha(s, 0.01, help="level of the jet, curvature and k'' tests")
    add_jet_arguments(s)
    s.add_argument("--lines", default=None,
                   help="ridge lines (.geojson, .csv, .las/.laz; default OUT stem + "
                   ".ridges.geojson)")
    add_run_outputs(s)
    add_tiling(s, "three jet radii")
    s.set_defaults(func=cmd_ridges)
