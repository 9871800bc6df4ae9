"""Argument parsing and the subcommands. No numerics here: each command calls the library."""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import sys
import threading
import time
import traceback
from importlib import import_module
from pathlib import Path

from .. import __version__
from .._shared._atomic import output_group
from .._shared._outputs import Output, check_outputs
from .._shared._choices import Frame, Test
from ..errors import LidarstatError
from . import _options as opt
from ._common import add_alpha, add_noise, add_run_outputs, add_tiling
from ._notices import held_warnings

logger = logging.getLogger("lidarstat")

#: Subcommands that live in a module of their own (``cli/<name>.py``), each with a
#: ``register(subparsers)`` function. Add a command by adding its module here.
COMMAND_MODULES: tuple[str, ...] = ("segment", "covariance", "ridges", "moments", "evaluate",
                                     "warmup")


def check_output(path: str, src: str | None = None) -> Path:
    """Check one point-cloud output before any work (:func:`check_plan` with one output)."""
    return check_plan([src], Output("output", path))[0]


def check_plan(inputs, *outputs: Output) -> list[Path | None]:
    """Check a command's whole output plan before any work; the output paths in order.

    Refuses (naming the option and the path as typed) an output that is an input, two
    outputs that are one file, a missing or read-only folder or a suffix the output does
    not accept: see :mod:`lidarstat._shared._outputs`.
    """
    return check_outputs(inputs, outputs)


def resolve_sensor(sensor, path, quiet=False):
    """``--sensor`` when given, else the scanner position the input file carries.

    The file's position is an E57 scan pose or a ``<file>.sensor.json`` sidecar
    (:func:`lidarstat.io.read_sensor`); the choice is reported on stderr unless `quiet`.
    """
    if sensor is not None:
        return sensor
    from ..io import read_sensor

    found, source = read_sensor(path)
    if found is not None and not quiet:
        print(f"  sensor {found[0]:.4f} {found[1]:.4f} {found[2]:.4f} from {source}",
              file=sys.stderr)
    return found


#: ``--sensor`` help shared by the commands that orient toward a scanner.
SENSOR_HELP = ("scanner position; normals point to it and the range noise grows with the "
               "distance from it (default: the position the input carries, as an E57 scan "
               "pose or a FILE.sensor.json sidecar, else normals point up)")


def progress(quiet):
    """A ``progress(done, total)`` callback printing to a terminal, or None."""
    if quiet or not sys.stderr.isatty():
        return None
    start = time.perf_counter()

    def report(done, total):
        el = time.perf_counter() - start
        print(f"\r  {done}/{total} points  {el:6.1f} s", end="" if done < total else "\n",
              file=sys.stderr, flush=True)

    return report


def write_summary_json(path, meta: dict) -> None:
    """Write a command's run summary as JSON, atomically (``--summary-json``)."""
    from .._shared._atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(meta, indent=2, default=str))


# --------------------------------------------------------------------------- commands
def cmd_info(args):
    from ..io import describe, format_description
    from ._catalogue import _is_catalogue, run_info

    if _is_catalogue(args.file) or args.tindex:
        return run_info(args)
    args.file = args.file[0]
    d = describe(args.file)
    print(json.dumps(d, indent=2, default=str) if args.json else format_description(d))
    return 0


def cmd_curvature(args):
    from ..features import curvature
    from ..io import read, rewrite, write

    out, _ = check_plan([args.input], Output("output", args.output),
                        Output("--summary-json", args.summary_json, "json"))
    radius = _radius_arg(args.radius)
    args.sensor = resolve_sensor(args.sensor, args.input, args.quiet)
    opts = dict(alpha=args.alpha, test=args.test, frame=args.frame, sensor=args.sensor,
                noise=args.noise, min_neighbors=args.min_neighbors,
                minimal_detectable=args.minimal_detectable, power=args.power)
    # LAS/LAZ in and out: the output is the input's records copied as read with the new
    # fields, so only the coordinates are decoded
    stream = {Path(args.input).suffix.lower(), out.suffix.lower()} <= {".las", ".laz"}
    t0 = time.perf_counter()
    if args.tile is not None:
        res = _curvature_tiled(args, out, radius, opts)
    else:
        cloud = read(args.input, fields=() if stream else None)
        res = curvature(cloud.xyz, radius=radius, sigma=args.sigma,
                        progress=progress(args.quiet), **opts)
    elapsed = time.perf_counter() - t0
    if args.tile is None:
        fields = res.to_fields()
        if stream:
            del cloud
            # chunks of a few megabytes of records: each field is copied into records that
            # stay in the processor's cache
            rewrite(args.input, out, lambda start, chunk: {
                name: a[start:start + len(chunk)] for name, a in fields.items()},
                decode=False, points_per_chunk=1 << 15)
        else:
            write(out, cloud, fields=fields)
        del fields
    if not args.quiet:
        print(f"{args.input} -> {out}  ({elapsed:.2f} s)")
        print(res.summary())
    if args.summary_json:
        params = res.params
        meta = {"input": str(args.input), "output": str(out), "seconds": elapsed,
                **params, **res.counts(), "params": params}
        write_summary_json(args.summary_json, meta)
    args.exit_at_once = args.tile is None  # one process, no worker left (see main)
    return 0


def _radius_arg(radius):
    """``--radius`` as the library takes it: None (automatic), one radius or a list."""
    if radius is None:
        return None
    return radius if len(radius) > 1 else radius[0]


def _curvature_tiled(args, out, radius, opts):
    """Out-of-core curvature: noise (and the automatic ladder) from the first chunk, then
    tiles with a halo of the largest radius."""
    import numpy as np

    from ..features import CurvatureResult, curvature, estimate_sigma, resolve_noise, scale_ladder
    from ..io import iter_chunks
    from ..pipeline import process_file

    sigma, estimated = args.sigma, False
    first = None
    scales = None
    if radius is None:
        first = next(iter_chunks(args.input, args.chunk_points))
        scales = scale_ladder(first.xyz)
        opts = {**opts, "scales": scales}
    radii = scales if radius is None else (radius if isinstance(radius, list) else [radius])
    r_max = max(radii)
    noise = resolve_noise(opts["noise"], args.sensor, func="curvature")
    if sigma is None:
        first = first or next(iter_chunks(args.input, args.chunk_points))
        est_radius = sorted(radii)[len(radii) // 2] if radius is None else min(radii)
        sigma = estimate_sigma(first.xyz, est_radius, noise=noise, frame=args.frame,
                               sensor=args.sensor, min_neighbors=args.min_neighbors)
        estimated = True
    # The summary streams back a few small fields from the output, so the output appears
    # at once, not with the command's other outputs.
    with output_group(defer=False):
        process_file(lambda p: curvature(p, radius=radius, sigma=sigma, **opts), args.input,
                     out, size=args.tile, halo=r_max, scheduler=args.scheduler,
                     workers=args.workers, points_per_chunk=args.chunk_points,
                     progress=progress(args.quiet))
    names = ("status", "surface_type", "neighbors") + (("radius",) if radius is None else ())
    parts = [[c.attributes[k] for k in names] for c in iter_chunks(out, args.chunk_points)]
    fields = {k: np.concatenate([p[j] for p in parts]) for j, k in enumerate(names)}
    return CurvatureResult(fields=fields, radius=tuple(scales) if radius is None else radius,
                           sigma=sigma, sigma_estimated=estimated, alpha=args.alpha,
                           test=args.test, frame=args.frame, noise=str(noise),
                           min_neighbors=args.min_neighbors,
                           minimal_detectable=args.minimal_detectable,
                           automatic=radius is None,
                           power=args.power if radius is None else None)


def cmd_bandwidth(args):
    from ..features import optimal_bandwidth

    res = optimal_bandwidth(K0=args.K0, H0=args.H0, sigma=args.sigma, density=args.density,
                            alpha=args.alpha, power=args.power, test=args.test)
    print(res.summary())
    if args.summary_json:
        write_summary_json(args.summary_json, {"params": res.params, **res.params})
    return 0 if res.radius == res.radius else 1


def cmd_synth(args):
    from ..io import PointCloud, write
    from ..synth import SCENES

    out = check_output(args.output)
    kwargs = {"rng": args.seed}
    if args.sigma is not None:
        kwargs["sigma"] = args.sigma
    scene = SCENES[args.scene](**kwargs)
    cloud = PointCloud(xyz=scene.xyz, attributes=dict(scene.attributes))
    fields = scene.to_fields()
    fields.update(edge_distance=scene.edge_distance)
    write(out, cloud, fields=fields)
    print(f"{args.scene}: {len(scene.xyz)} points -> {out}")
    return 0


def cmd_demo(args):
    from ..report import DEMO_FILES, run_demo

    check_plan([], Output("outdir", args.outdir, "folder", members=DEMO_FILES))
    run_demo(Path(args.outdir), sigma=args.sigma, radius=args.radius, seed=args.seed)
    return 0


# --------------------------------------------------------------------------- parser
def _tile_exceeds_radius(args):
    """``--tile`` must exceed the largest ``--radius``, the halo every tile carries."""
    if args.tile is not None and args.radius is not None and args.tile <= max(args.radius):
        return "--tile", (f"invalid value '{args.tile:g}': must be larger than the largest "
                          f"--radius ({max(args.radius):g}), the halo of every tile")
    return None


#: The commands this module defines itself (the others are in :data:`COMMAND_MODULES`).
CORE_COMMANDS: tuple[str, ...] = ("info", "curvature", "bandwidth", "synth", "demo")


def command_of(argv) -> str | None:
    """The subcommand named in `argv` (its first word that is not an option), or None."""
    for word in argv:
        if not word.startswith("-"):
            return word
        if word == "--":
            return None
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``lidarstat`` parser with every subcommand, or with `command` alone.

    A run of one command parses with that subcommand alone, so that it does not import
    the packages the other commands need (their options' choices come from them):
    ``lidarstat curvature`` starts without SciPy's statistics, the segmentations or the
    classifications, ``lidarstat moments`` without the segmentations and the synthetic
    scenes.
    """
    only = command if command in CORE_COMMANDS + COMMAND_MODULES else None

    def want(name):
        return only is None or name == only

    p = opt.Parser(
        prog="lidarstat",
        description="Classify and segment point clouds with statistically tested geometry.",
    )
    p.add_argument("--version", action="version", version=f"lidarstat {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    if want("info"):
        s = sub.add_parser("info", help="describe a point-cloud file or a catalogue of tiles")
        s.add_argument("file", nargs="+", metavar="IN",
                       help="a file; or a folder, a glob or several LAS/LAZ/COPC files: a "
                       "catalogue of tiles (its tiles, extents, point counts and CRSs)")
        s.add_argument("--json", action="store_true", help="machine-readable output")
        s.add_argument("--tindex", default=None, metavar="FILE.geojson",
                       help="write the tile index (one rectangle per file with its name and "
                       "point count) as GeoJSON, as PDAL's tindex")
        s.set_defaults(func=cmd_info)

    if want("curvature"):
        s = sub.add_parser("curvature", help="tested local quadric, K, H and HK surface types",
                           description="Fit a tricube-weighted quadric in a sphere around every "
                           "point, test it, and write K, H, their tests and the surface type.")
        s.add_argument("input")
        s.add_argument("output", help="output file; format from the suffix")
        s.add_argument("--radius", type=opt.positive_float, nargs="+", default=None,
                       help="sphere radius (bandwidth); several radii = multi-scale (default: "
                       "automatic, per point the smallest radius of a ladder of 3 to 8.5 point "
                       "spacings whose tests detect the curvature seen, written to the field "
                       "'radius')")
        add_noise(s)
        add_alpha(s)
        s.add_argument("--test", choices=Test.values(), default=Test.CALIBRATED.value,
                       help="family of tests: calibrated to the weighted fit, or the paper's as "
                       "printed (default calibrated)")
        s.add_argument("--frame", choices=Frame.values(), default=Frame.PCA.value,
                       help="height axis of the local quadric: the neighbourhood's principal "
                       "axes (pca, any orientation), the coordinate axis closest to them (auto) "
                       "or z, the paper's (default pca)")
        s.add_argument("--min-neighbors", type=opt.int_at_least(7), default=7,
                       help="smallest neighbourhood a quadric is fitted on [7]")
        s.add_argument("--power", type=opt.real(0.5, 1, "left", what="probability"), default=0.9,
                       help="automatic scale: probability with which the chosen radius detects "
                       "the curvature seen [0.9]")
        s.add_argument("--minimal-detectable", action="store_true",
                       help="also write K_min and H_min (eq. 19)")
        add_run_outputs(s)
        add_tiling(s)
        s.set_defaults(func=cmd_curvature)
        opt.add_check(s, _tile_exceeds_radius)

    if want("bandwidth"):
        s = sub.add_parser("bandwidth", help="smallest radius whose tests detect K0 and H0")
        s.add_argument("--K0", type=opt.finite_float, required=True,
                       help="Gaussian curvature to detect")
        s.add_argument("--H0", type=opt.finite_float, required=True,
                       help="mean curvature to detect (not 0)")
        s.add_argument("--sigma", type=opt.positive_float, required=True,
                       help="measurement noise std")
        s.add_argument("--density", type=opt.positive_float, required=True,
                       help="points per unit area")
        add_alpha(s)
        s.add_argument("--power", type=opt.real(0.5, 1, "left", what="probability"), default=0.5,
                       help="probability of detecting K0 and H0 [0.5]")
        s.add_argument("--test", choices=Test.values(), default=Test.CALIBRATED.value,
                       help="covariance of the tests (default calibrated)")
        s.add_argument("--summary-json", default=None, metavar="FILE",
                       help="write the design (parameters and radius) as JSON here")
        s.set_defaults(func=cmd_bandwidth)

    if want("synth"):
        from ..synth import SCENES

        s = sub.add_parser("synth", help="write a synthetic scene with exact truth fields")
        s.add_argument("scene", choices=sorted(SCENES))
        s.add_argument("output")
        s.add_argument("--sigma", type=opt.nonnegative_float, default=None,
                       help="noise std (default: the scene's own; 0 for the analytic patches)")
        s.add_argument("--seed", type=opt.seed, default=0)
        s.set_defaults(func=cmd_synth)

    if want("demo"):
        s = sub.add_parser("demo", help="run curvature on a generated sample; LAS + PNG views")
        s.add_argument("outdir", nargs="?", default="lidarstat_demo")
        s.add_argument("--sigma", type=opt.nonnegative_float, default=0.015,
                       help="noise added (dm)")
        s.add_argument("--radius", type=opt.positive_float, default=None,
                       help="fixed curvature radius (dm) (default: the automatic scale)")
        s.add_argument("--seed", type=opt.seed, default=0)
        s.set_defaults(func=cmd_demo)

    for name in COMMAND_MODULES:
        if want(name):
            import_module(f".{name}", __package__).register(sub)
    from ._catalogue import install

    install(sub)  # IN may be a catalogue of tiles
    return p


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that the run unwinds like an exception.

    A KeyboardInterrupt, like Ctrl-C: ``except Exception`` in library code does not swallow
    it, code that lets interrupts through (the readers' conversion of foreign exceptions)
    lets it through too, and every ``finally`` (temporary files) runs.
    """


def _on_sigterm(signum, frame):
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends the process
    raise Terminated()


@contextlib.contextmanager
def _sigterm_unwinds():
    """Within the block, SIGTERM raises :class:`Terminated` (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _fail(text: str) -> None:
    print(f"lidarstat: {text}", file=sys.stderr, flush=True)


def _compile_notice():
    """One stderr line, on a terminal, when the run has to compile kernels (a cold cache)."""
    if not sys.stderr.isatty():
        return contextlib.nullcontext()
    from .._shared._jit import on_first_compile

    def notice():
        print("lidarstat: compiling this command's kernels for this installation, once "
              "(up to a minute); `lidarstat warmup` compiles all of them ahead",
              file=sys.stderr, flush=True)

    return on_first_compile(notice)


def main(argv=None) -> int:
    """Entry point of the ``lidarstat`` console script; returns the exit status.

    0 success; 1 an internal error (one line; ``-v`` adds the traceback); 2 a usage or
    data error (one line naming the file or option); 130 Ctrl-C; 143 SIGTERM. Temporary
    files are removed on every one of these exits. As the console script (`argv` None),
    a command that marks its arguments ``exit_at_once`` (every output written and closed,
    no thread or child process left) ends the process as soon as it returns, without the
    interpreter's teardown of the loaded kernels and modules.
    """
    done = {}
    code = _main(argv, done)
    if argv is None and getattr(done.get("args"), "exit_at_once", False):
        _exit_at_once(code)
    return code


def _exit_at_once(code):
    """End the process with `code` once the standard streams and log handlers are flushed,
    without the interpreter's teardown."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed or broken pipe: nothing more to deliver
            pass
    logging.shutdown()
    os._exit(code)


def _main(argv, done) -> int:
    """:func:`main`'s work; the parsed arguments go to ``done["args"]``."""
    verbose = False
    args = None
    try:
        with _sigterm_unwinds():
            parser = build_parser(command_of(sys.argv[1:] if argv is None else argv))
            try:
                args = parser.parse_args(argv)
            except SystemExit as exc:  # --help, --version or a usage error, already printed
                return exc.code
            done["args"] = args
            verbose = args.verbose
            # all of a command's outputs appear, or none; its warnings follow a success
            with held_warnings(verbose), output_group(), _compile_notice():
                for text in getattr(args, "_deprecations", ()):
                    logger.warning(text)
                return args.func(args)
    except Terminated:
        _fail("terminated (SIGTERM)")
        return 143
    except KeyboardInterrupt:
        _fail("interrupted")
        return 130
    except (LidarstatError, OSError) as exc:
        _fail(f"error: {opt.error_line(exc, args)}")
        return 2
    except MemoryError as exc:
        _fail(f"error: out of memory{f' ({exc})' if str(exc) else ''}")
        return 2
    except Exception as exc:  # noqa: BLE001 -- a bug: one line, the traceback with -v
        if verbose:
            traceback.print_exc()
        msg = str(exc).splitlines()[0] if str(exc) else ""
        _fail(f"internal error: {type(exc).__name__}: {msg} (run with -v for the traceback)")
        return 1
