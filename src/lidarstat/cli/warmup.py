"""``lidarstat warmup``: compile every command's Numba kernels into the cache, once.

A command's first run in a new installation compiles the kernels it uses (tens of seconds
per command); later runs load them from the cache. This runs each command once on a small
generated scene, in a fresh process as a user would, so that every later run starts at once.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: (label, argv after ``lidarstat``): {x} the generated scene, {o} an output prefix.
STEPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("synth", ("synth", "hip_roof", "{x}")),
    ("curvature", ("curvature", "{x}", "{o}.laz", "--radius", "1")),
    ("covariance", ("covariance", "{x}", "{o}.laz")),
    ("ridges", ("ridges", "{x}", "{o}.laz", "--radius", "2")),
    ("moments", ("moments", "{x}", "{o}.laz")),
    ("segment --method sar", ("segment", "{x}", "{o}.laz", "--method", "sar",
                              "--radius", "1")),
    ("segment --method covariance", ("segment", "{x}", "{o}.laz", "--method", "covariance")),
    ("segment --method curvature", ("segment", "{x}", "{o}.laz", "--method", "curvature",
                                    "--radius", "1")),
    ("segment --method ridges", ("segment", "{x}", "{o}.laz", "--method", "ridges",
                                 "--radius", "2")),
)


def _run(args):
    from ..errors import LidarstatError

    quiet = args.quiet
    start = time.perf_counter()
    if not quiet:
        import numba

        where = numba.config.CACHE_DIR or str(Path(__file__).resolve().parents[1])
        commands = sorted({argv[0] for _, argv in STEPS} - {"synth"})
        print(f"lidarstat warmup: compiling the Numba kernels of {', '.join(commands)} "
              f"into the cache under {where}, once (a few minutes); later runs of every "
              f"command start without compiling",
              file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory(prefix="lidarstat-warmup-") as tmp:
        x = Path(tmp) / "scene.laz"
        for i, (label, argv) in enumerate(STEPS, 1):
            argv = [a.format(x=x, o=Path(tmp) / f"out{i}") for a in argv]
            if not quiet:
                print(f"  [{i}/{len(STEPS)}] {label} ...", end="", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "lidarstat", *argv],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                if not quiet:
                    print(" failed", file=sys.stderr)
                last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
                last = last.removeprefix("lidarstat: ").removeprefix("error: ")
                raise LidarstatError(f"warmup step '{label}' failed: {last}")
            if not quiet:
                print(f" {time.perf_counter() - t0:5.1f} s", file=sys.stderr, flush=True)
    if not quiet:
        print(f"kernels compiled and cached in {time.perf_counter() - start:.0f} s; "
              f"commands now start without compiling", file=sys.stderr)
    return 0


def register(sub) -> None:
    s = sub.add_parser(
        "warmup", help="compile every command's kernels into the cache, once",
        description="Run each command once on a small generated scene so that its Numba "
                    "kernels are compiled and cached; later runs start without compiling. "
                    "Takes a few minutes; run it once after installing.")
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing")
    s.set_defaults(func=_run)
