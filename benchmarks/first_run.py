"""First-run (cold Numba cache) and cached-run wall time of each command, and the number of
compiled specialisations per kernel.

Every command runs in a fresh process with its own empty ``NUMBA_CACHE_DIR`` (the first
run, which compiles the kernels it uses), then again in a fresh process on the same cache
dir (the cached run). The process runs the command in-process through ``lidarstat.cli.main``
and then lists every Numba dispatcher of the ``lidarstat`` modules with its signatures, so
a kernel compiled for two argument types shows up with two. ``first_compile_s`` is the
time the first run spent in Numba's compiler (outermost compile events), ``first_cpu_s``
its CPU time (less sensitive than wall time to other jobs on a shared machine).

    PYTHONPATH=src python benchmarks/first_run.py [--out FILE] [--label NAME]

To measure another version of the package, point ``PYTHONPATH`` at its ``src``; the child
processes inherit it. ``--label`` names the entry in the results file (entries of other
labels are kept, so ``before`` and ``after`` sit side by side). ``--warmup`` runs
``lidarstat warmup`` once in a fresh cache dir first (its wall time is recorded) and then
every command's first run on that cache: what a user who follows the install
instructions waits.

``--suite ['PYTEST ARGS']`` (one quoted string) instead runs the test suite (or the given
test files) with pytest's options from ``pyproject.toml`` on a fresh ``NUMBA_CACHE_DIR`` (cold cache), then
``--suite-warm`` again on it, and stores under the ``suite`` key its wall time, the CPU
seconds of the whole process tree (user + sys, xdist workers included) and the Numba
compile seconds and compile CPU seconds that ``tests/conftest.py`` prints (the warm-up
the xdist controller runs before the workers included, and its wall time apart).
``LIDARSTAT_TEST_WARMUP=0`` or ``=1`` in the environment turns that warm-up off or on.
``--suite-cache DIR`` keeps the cold run's cache in DIR, for
``benchmarks/specialisations.py DIR`` (which kernels the suite compiled more than once);
``LIDARSTAT_COMPILE_LOG=FILE`` in the environment has ``tests/conftest.py`` list every
compilation with its CPU seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

# (name, argv after "lidarstat"; {x} is the input, {o} an output dir/file prefix)
COMMANDS = [
    ("curvature", ["curvature", "{x}", "{o}.laz", "--radius", "1"]),
    ("covariance", ["covariance", "{x}", "{o}.laz"]),
    ("ridges", ["ridges", "{x}", "{o}.laz", "--radius", "2"]),
    ("moments", ["moments", "{x}", "{o}.laz"]),
    ("segment-sar", ["segment", "{x}", "{o}.laz", "--method", "sar", "--radius", "1"]),
    ("segment-covariance", ["segment", "{x}", "{o}.laz", "--method", "covariance"]),
    ("segment-curvature", ["segment", "{x}", "{o}.laz", "--method", "curvature", "--radius", "1"]),
    ("segment-ridges", ["segment", "{x}", "{o}.laz", "--method", "ridges", "--radius", "2"]),
]

CHILD = r"""
import json, resource, sys, time
from numba.core import event
depth, compile_s = [0], [0.0]
class Compiles(event.Listener):
    def on_start(self, ev):
        if depth[0] == 0:
            self.t0 = time.perf_counter()
        depth[0] += 1
    def on_end(self, ev):
        depth[0] -= 1
        if depth[0] == 0:
            compile_s[0] += time.perf_counter() - self.t0
t0 = time.perf_counter()
with event.install_listener("numba:compile", Compiles()):
    from lidarstat.cli import main
    rc = main(sys.argv[2:])
wall = time.perf_counter() - t0
from numba.core.registry import CPUDispatcher
seen, kernels = set(), {}
for name, mod in list(sys.modules.items()):
    if not name.startswith("lidarstat"):
        continue
    for attr, obj in list(vars(mod).items()):
        if isinstance(obj, CPUDispatcher) and id(obj) not in seen:
            seen.add(id(obj))
            if obj.signatures:
                py = obj.py_func
                key = f"{py.__module__}.{py.__qualname__}"
                # a driver made per kernel (a closure): named by the kernels it closes over
                inner = [getattr(c.cell_contents, "py_func", None) for c in py.__closure__ or ()]
                inner = [f.__name__ for f in inner if f is not None]
                if inner:
                    key += "[" + ",".join(sorted(inner)) + "]"
                kernels[key] = [str(s) for s in obj.signatures]
cpu = resource.getrusage(resource.RUSAGE_SELF)
with open(sys.argv[1], "w") as fh:
    json.dump({"rc": rc, "inprocess_s": wall, "compile_s": compile_s[0],
               "cpu_s": cpu.ru_utime + cpu.ru_stime, "kernels": kernels}, fh)
"""

def run(argv, cache_dir, tmp):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    report = Path(tmp) / "report.json"
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, str(report), *argv],
        env=env, capture_output=True, text=True,
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{argv}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    data = json.loads(report.read_text())
    if data["rc"] != 0:
        raise SystemExit(f"{argv}: command exit {data['rc']}\n{proc.stderr[-2000:]}")
    data["wall_s"] = round(wall, 2)
    for key in ("inprocess_s", "compile_s", "cpu_s"):
        data[key] = round(data[key], 2)
    return data


def measure(name, argv, tmp, cache=None):
    cache = cache or Path(tempfile.mkdtemp(prefix="numba-", dir=tmp))
    first = run(argv, cache, tmp)
    cached = run(argv, cache, tmp)
    kernels = first["kernels"]
    return {
        "first_s": first["wall_s"],
        "first_compile_s": first["compile_s"],
        "first_cpu_s": first["cpu_s"],
        "cached_s": cached["wall_s"],
        "cached_compile_s": cached["compile_s"],
        "kernels": len(kernels),
        "specialisations": sum(len(v) for v in kernels.values()),
        "signatures": kernels,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "results_first_run.json"))
    ap.add_argument("--label", default="current")
    ap.add_argument("--only", nargs="*", help="command names to run")
    ap.add_argument("--warmup", action="store_true",
                    help="run `lidarstat warmup` on the fresh cache before the commands")
    ap.add_argument("--machine-shared", action="store_true",
                    help="note in the results that other jobs ran on the machine")
    ap.add_argument("--suite", nargs="?", const="", metavar="'PYTEST ARGS'",
                    help="time pytest (the whole suite, or these arguments, one quoted "
                         "string) on a cold cache")
    ap.add_argument("--suite-warm", action="store_true",
                    help="with --suite: run it again on the same cache (warm)")
    ap.add_argument("--suite-cache", metavar="DIR",
                    help="with --suite: a new folder for the Numba cache, kept after the run "
                         "(for benchmarks/specialisations.py DIR); default a temporary one")
    ap.add_argument("--suite-log", metavar="PREFIX",
                    help="with --suite: write pytest's output to PREFIX.cold (and .warm)")
    args = ap.parse_args()
    if args.suite is not None:
        return suite(args)
    import lidarstat

    results = {"package": str(Path(lidarstat.__file__).parent), "commands": {},
               "cpus": os.cpu_count(), "machine_shared": args.machine_shared}
    with tempfile.TemporaryDirectory() as tmp:
        shared = None
        if args.warmup:
            shared = Path(tempfile.mkdtemp(prefix="numba-", dir=tmp))
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "lidarstat", "warmup", "-q"], check=True,
                           env=dict(os.environ, NUMBA_CACHE_DIR=str(shared)))
            results["warmup_s"] = round(time.perf_counter() - t0, 1)
            print(f"warmup {results['warmup_s']:.0f} s", flush=True)
        x = Path(tmp) / "x.laz"
        synth = ["synth", "hip_roof", str(x)]
        results["commands"]["synth"] = measure("synth", synth, tmp, shared)
        for name, argv in COMMANDS:
            if args.only and name not in args.only:
                continue
            o = Path(tmp) / name
            argv = [a.format(x=x, o=o) for a in argv]
            results["commands"][name] = r = measure(name, argv, tmp, shared)
            print(f"{name:20s} first {r['first_s']:6.1f} s (compiling "
                  f"{r['first_compile_s']:5.1f} s, CPU {r['first_cpu_s']:5.1f} s)  cached {r['cached_s']:5.1f} s  "
                  f"kernels {r['kernels']:3d}  specialisations {r['specialisations']:3d}",
                  flush=True)
            save(args, results)  # each command as it ends: a long run stopped keeps them
    save(args, results)


_NUMBA_LINE = re.compile(r"Numba: (\d+) compilations, (\d+) s compiling \((\d+) s CPU\)")
_WARMUP_LINE = re.compile(r"Warm-up before the workers: (\d+) processes, (\d+) s")


def suite_run(pytest_args, cache_dir, log=None):
    """One pytest run on `cache_dir`: wall, CPU of the process tree, compile figures.

    `log`, a path, receives pytest's whole output (the durations, when asked for)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           *pytest_args], cwd=HERE.parent, env=env, capture_output=True,
                          text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if log:
        Path(log).write_text(proc.stdout + proc.stderr)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    tail = proc.stdout.strip().splitlines()[-3:]
    m = _NUMBA_LINE.search(proc.stdout)
    w = _WARMUP_LINE.search(proc.stdout)
    return {"rc": proc.returncode, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
            "compilations": int(m.group(1)) if m else 0,
            "compile_s": int(m.group(2)) if m else 0,
            "compile_cpu_s": int(m.group(3)) if m else 0,
            "warmup_processes": int(w.group(1)) if w else 0,
            "warmup_wall_s": int(w.group(2)) if w else 0, "summary": tail}


def suite(args):
    """The suite (or the given tests) on a cold cache, then optionally warm."""
    pytest_args = shlex.split(args.suite)
    results = {"pytest_args": pytest_args, "cpus": os.cpu_count(),
               "machine_shared": args.machine_shared}
    with tempfile.TemporaryDirectory() as tmp:
        if args.suite_cache:
            tmp = Path(args.suite_cache)
            tmp.mkdir(parents=True)  # a new folder: the run starts on a cold cache
        results["cold"] = suite_run(pytest_args, tmp, args.suite_log and f"{args.suite_log}.cold")
        print("cold", results["cold"], flush=True)
        if args.suite_warm:
            results["warm"] = suite_run(pytest_args, tmp, args.suite_log and f"{args.suite_log}.warm")
            print("warm", results["warm"], flush=True)
    out = Path(args.out)
    store = json.loads(out.read_text()) if out.exists() else {}
    store.setdefault("suite", {})[args.label] = results
    out.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")


def save(args, results):
    """Summarise the specialisations over the commands run and store under the label."""
    union = {}
    for r in results["commands"].values():
        for k, sigs in r["signatures"].items():
            union.setdefault(k, set()).update(sigs)
    results["total_kernels"] = len(union)
    results["total_specialisations"] = sum(len(v) for v in union.values())
    results["multi"] = {k: sorted(v) for k, v in union.items() if len(v) > 1}
    print(f"all commands so far: {results['total_kernels']} kernels, "
          f"{results['total_specialisations']} specialisations; "
          f"{len(results['multi'])} kernels with more than one", flush=True)
    out = Path(args.out)
    store = json.loads(out.read_text()) if out.exists() else {}
    store[args.label] = results
    out.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
