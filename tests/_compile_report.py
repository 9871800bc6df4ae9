"""Run the warm-up commands in fresh processes and report each command's kernel signatures.

Used twice by the suite:

* ``tests/conftest.py``, in the xdist controller before the workers start, runs the
  commands of :data:`lidarstat.cli.warmup.STEPS` split into :data:`GROUPS` (one process
  per core): every kernel the commands use is compiled once, into the cache the workers
  and the CLI subprocesses then load from, instead of by whichever processes need it
  first (at the same time, on a cold cache). The report it writes is what
  ``tests/cli/test_compilation.py`` checks.
* ``tests/cli/test_compilation.py`` runs the same when no report was made (``-n 0``,
  a subset of the suite).

Each process runs its commands in-process through ``lidarstat.cli.main``. Before each
command every lidarstat dispatcher forgets the specialisations it holds in memory, so the
command asks for its own again, loading them from the disk cache, as in a process of its
own (a kernel used by two commands with two dtypes is not a repeat). On a warm cache the
kernels called from Python are loaded with the signatures the command asks for; on a cold
one, the helpers that kernels call show as well.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

#: The warm-up commands (labels of ``STEPS``) in groups that share few kernels, one
#: process each: the covariance family with ridges, and the quadric family (curvature and
#: the segmentations built on it) with moments last (its kernels shared with covariance
#: are cached by then): with moments in the first group, a cold cache took about 200 s
#: of CPU in the first and 129 s in the second. Steps of ``STEPS`` named in no group
#: join the last one; ``synth`` (the scene) starts every group.
GROUPS = (
    ("covariance", "segment --method covariance", "ridges", "segment --method ridges"),
    ("curvature", "segment --method curvature", "segment --method sar", "moments"),
)

_SCRIPT = r"""
import gc, json, os, sys, time
T0 = time.perf_counter()
from pathlib import Path
from numba.core.registry import CPUDispatcher

compiles = {"seconds": 0.0, "cpu": 0.0, "count": 0, "kernels": []}
from _compile_listener import count_compiles
count_compiles(compiles, compiles["kernels"])

from lidarstat.cli import main
from lidarstat.cli.warmup import STEPS

def dispatchers():
    return [obj for obj in gc.get_objects() if isinstance(obj, CPUDispatcher)
            and getattr(obj.py_func, "__module__", "").startswith("lidarstat")]

def signatures():
    found = {}
    for obj in dispatchers():
        if obj.signatures:
            py = obj.py_func
            # a driver made per kernel (a closure) is named by what it closes over
            inner = [getattr(c.cell_contents, "py_func", None) for c in py.__closure__ or ()]
            inner = ",".join(sorted(f.__name__ for f in inner if f is not None))
            key = f"{py.__module__}.{py.__qualname__}" + (f"[{inner}]" if inner else "")
            found.setdefault(key, set()).update(str(s) for s in obj.signatures)
    return {key: sorted(sigs) for key, sigs in found.items()}

out, tmp, labels = Path(sys.argv[1]), Path(sys.argv[2]), json.loads(sys.argv[3])
report = {}
stdout, stderr = sys.stdout, sys.stderr
for i, (label, argv) in enumerate(STEPS):
    if label not in labels:
        continue
    argv = [a.format(x=tmp / "x.laz", o=tmp / f"o{i}") for a in argv]
    for obj in dispatchers():
        obj._reset_overloads()
    sys.stdout = sys.stderr = open(os.devnull, "w")
    code = main(argv)
    sys.stdout, sys.stderr = stdout, stderr
    assert code == 0, f"{label} failed"
    report[label] = signatures()
import resource
usage = resource.getrusage(resource.RUSAGE_SELF)
out.write_text(json.dumps({"report": report, "compiles": compiles, "group": {
    "steps": labels, "wall_s": round(time.perf_counter() - T0, 1),
    "cpu_s": round(usage.ru_utime + usage.ru_stime, 1)}}))
"""


def groups(n: int) -> list[list[str]]:
    """`GROUPS` for `n` processes (at least 1), every step of ``STEPS`` in one of them."""
    from lidarstat.cli.warmup import STEPS

    labels = [label for label, _ in STEPS if label != "synth"]
    chosen = [[s for s in g if s in labels] for g in GROUPS]
    named = {s for g in chosen for s in g}
    chosen[-1] += [s for s in labels if s not in named]
    while len(chosen) > max(n, 1):  # fewer processes: merge the last two groups
        last = chosen.pop()
        chosen[-1] += last
    return [["synth", *g] for g in chosen if g]


def run(n: int = 1, env: dict | None = None) -> dict:
    """Run the warm-up commands in `n` processes at once; the merged report.

    Returns ``{"report": {label: {kernel: [signatures]}}, "compiles": {...}, "wall_s",
    "processes", "groups" (each process's steps, wall and CPU seconds),
    "errors": [stderr tails of failed processes]}``. ``compiles`` sums the Numba compile
    events of the processes (outermost ones, as the summary of ``tests/conftest.py``).
    """
    env = dict(os.environ if env is None else env)
    # the package, and this folder for the compile listener the script imports
    env["PYTHONPATH"] = os.pathsep.join([str(SRC), str(Path(__file__).resolve().parent),
                                         env.get("PYTHONPATH", "")])
    merged = {"report": {}, "errors": [], "groups": [],
              "compiles": {"seconds": 0.0, "cpu": 0.0, "count": 0, "kernels": []}}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lidarstat-compile-report-") as tmp:
        procs = []
        merged["processes"] = len(groups(n))
        for i, labels in enumerate(groups(n)):
            work = Path(tmp) / f"g{i}"
            work.mkdir()
            out = work / "report.json"
            # stderr to a file, not a pipe: a process that fills a pipe no one reads yet
            # would wait for the one before it
            with open(work / "stderr.txt", "w") as err:
                procs.append((out, work / "stderr.txt", subprocess.Popen(
                    [sys.executable, "-c", _SCRIPT, str(out), str(work), json.dumps(labels)],
                    stdout=subprocess.DEVNULL, stderr=err, env=env)))
        for out, err, proc in procs:
            proc.wait()
            if proc.returncode != 0 or not out.is_file():
                merged["errors"].append(err.read_text()[-2000:])
                continue
            got = json.loads(out.read_text())
            merged["report"].update(got["report"])
            merged["groups"].append(got["group"])
            for key in ("seconds", "cpu", "count", "kernels"):
                merged["compiles"][key] += got["compiles"][key]
    merged["wall_s"] = round(time.perf_counter() - t0, 1)
    return merged
