"""What ``parallel=True`` costs in compile time and gains in run time, per kernel.

Two measurements, each in fresh processes on a fresh ``NUMBA_CACHE_DIR`` (a cold cache):

``--compile``: the steps of ``lidarstat warmup`` in one process with the kernels as
declared, then in another with every ``parallel=True`` kernel compiled serially; the compile
CPU of each kernel is the compiling thread's CPU time over its outermost ``numba:compile``
events, so the figures hold on a shared machine (wall times there do not).

``--runtime``: commands run in-process on a synthetic town of ``--points`` points (the
cloud of ``benchmarks/scaling.py``); every ``parallel=True`` kernel called from Python is
wrapped, and at its largest call the wrapper times a serial and a parallel build of the
same function on copies of the real arguments (alternating, best of ``--repeat``: wall and
process CPU, all threads), and the compile CPU of each build for those argument types (after
a first serial build has compiled the helpers the kernel calls). A kernel whose run time gains less than
1.3 times from two threads is cheaper serial: it compiles in a fraction of the time.

The serial builds are made by monkeypatching ``numba.njit`` before lidarstat is imported
(the package has no switch for it).

    PYTHONPATH=src python benchmarks/parallel_compile.py --compile [--machine-shared]
    PYTHONPATH=src python benchmarks/parallel_compile.py --runtime [--points N]
        [--only NAME ...] [--warm-cache] [--machine-shared]

Stored under the ``parallel_compile`` and ``parallel_runtime`` keys of
``benchmarks/results_first_run.json`` (``--runtime`` merges its kernels into what is there,
so runs of different commands add up).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

# Every parallel=True kernel serial when LIDARSTAT_BENCH_SERIAL=1 (this benchmark only).
PATCH = r"""
import os, numba
_njit = numba.njit
PARALLEL = {}
def _patched(*a, **kw):
    if kw.get("parallel") and not a:
        serial = os.environ.get("LIDARSTAT_BENCH_SERIAL") == "1"
        def wrap(f):
            PARALLEL[f"{f.__module__}.{f.__qualname__}"] = f
            return _njit(**{**kw, "parallel": not serial})(f)
        return wrap
    return _njit(*a, **kw)
numba.njit = _patched
"""

COMPILE_CHILD = PATCH + r"""
import json, resource, sys, tempfile, time
from pathlib import Path
from numba.core import event
per, depth, t0, who = {}, [0], [0.0], [None]
class Compiles(event.Listener):
    def on_start(self, ev):
        if depth[0] == 0:
            t0[0] = time.thread_time()
            py = getattr(ev.data.get("dispatcher"), "py_func", None)
            who[0] = f"{getattr(py, '__module__', '?')}.{getattr(py, '__qualname__', '?')}"
        depth[0] += 1
    def on_end(self, ev):
        depth[0] -= 1
        if depth[0] == 0:
            per[who[0]] = per.get(who[0], 0.0) + time.thread_time() - t0[0]
event.register("numba:compile", Compiles())
from lidarstat.cli import main
from lidarstat.cli.warmup import STEPS
tmp = Path(tempfile.mkdtemp())
steps = {}
for i, (label, argv) in enumerate(STEPS):
    argv = [a.format(x=tmp / "x.laz", o=tmp / f"o{i}") for a in argv]
    c, w = time.process_time(), time.perf_counter()
    assert main(argv) == 0, label
    steps[label] = {"cpu_s": round(time.process_time() - c, 2),
                    "wall_s": round(time.perf_counter() - w, 2)}
r = resource.getrusage(resource.RUSAGE_SELF)
json.dump({"cpu_s": round(r.ru_utime + r.ru_stime, 1),
           "compile_cpu_s": round(sum(per.values()), 1), "steps": steps,
           "parallel_kernels": sorted(PARALLEL),
           "kernels": {k: round(v, 2) for k, v in sorted(per.items(), key=lambda kv: -kv[1])}},
          open(sys.argv[1], "w"), indent=1)
"""

RUNTIME_CHILD = PATCH + r"""
import importlib, json, pkgutil, sys, time
import numpy as np
from numba.core.registry import CPUDispatcher
import lidarstat
for m in pkgutil.walk_packages(lidarstat.__path__, "lidarstat."):
    if not m.name.endswith("__main__"):
        importlib.import_module(m.name)
from lidarstat._shared._jit import _DEFAULTS
out_path, repeat, argvs = sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[3])
found = {}

def nbytes(args):
    return sum(a.nbytes for a in args if isinstance(a, np.ndarray))

def copies(args):
    return [a.copy(order="K") if isinstance(a, np.ndarray) else a for a in args]

def build(py, parallel, args):
    d = _njit(**{**_DEFAULTS, "cache": False, "parallel": parallel})(py)
    sig = tuple(numba.typeof(a) for a in args)
    t = time.thread_time()
    d.compile(sig)
    return d, time.thread_time() - t

def measure(key, py, args):
    build(py, False, args)  # compiles the helpers it calls: neither timed build pays for them
    ser, c_ser = build(py, False, args)
    par, c_par = build(py, True, args)
    best = {"serial": float("inf"), "parallel": float("inf")}
    cpu = {"serial": float("inf"), "parallel": float("inf")}
    for _ in range(repeat):
        for mode, d in (("serial", ser), ("parallel", par)):
            a = copies(args)
            t, c = time.perf_counter(), time.process_time()
            d(*a)
            best[mode] = min(best[mode], time.perf_counter() - t)
            cpu[mode] = min(cpu[mode], time.process_time() - c)
    return {"compile_cpu_parallel_s": round(c_par, 2), "compile_cpu_serial_s": round(c_ser, 2),
            "run_parallel_s": round(best["parallel"], 4), "run_serial_s": round(best["serial"], 4),
            "run_cpu_parallel_s": round(cpu["parallel"], 4),
            "run_cpu_serial_s": round(cpu["serial"], 4),
            "speedup": round(best["serial"] / max(best["parallel"], 1e-9), 2),
            "arg_mib": round(nbytes(args) / 2**20, 1)}

def wrapper(key, disp):
    def call(*args, **kw):
        size = nbytes(args)
        if not kw and size > 1.5 * found.get(key, {}).get("_bytes", 0) and found.get(key, {}).get("_n", 0) < 3:
            r = measure(key, disp.py_func, args)
            r["_bytes"], r["_n"] = size, found.get(key, {}).get("_n", 0) + 1
            r["command"] = current[0]
            found[key] = r
        return disp(*args, **kw)
    return call

wrapped = set()
for name, mod in list(sys.modules.items()):
    if not name.startswith("lidarstat"):
        continue
    used_by_kernels = set()
    for obj in vars(mod).values():
        if isinstance(obj, CPUDispatcher):
            used_by_kernels.update(obj.py_func.__code__.co_names)
    for attr, obj in list(vars(mod).items()):
        if isinstance(obj, CPUDispatcher):
            key = f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"
            if key in PARALLEL and attr not in used_by_kernels:
                setattr(mod, attr, wrapper(key, obj))
                wrapped.add(key)

from lidarstat.cli import main
current = [None]
commands = {}
for label, argv in argvs:
    current[0] = label
    t = time.perf_counter()
    assert main(argv) == 0, label
    commands[label] = round(time.perf_counter() - t, 1)
    json.dump({"kernels": found, "commands": commands, "wrapped": sorted(wrapped),
               "not_wrapped": sorted(set(PARALLEL) - wrapped)}, open(out_path, "w"), indent=1)
"""

# name -> argv after "lidarstat" ({i} input, {o} output file)
COMMANDS = {
    "covariance": ["covariance", "{i}", "{o}"],
    "segment-covariance": ["segment", "{i}", "{o}", "--method", "covariance"],
    "curvature": ["curvature", "{i}", "{o}", "--radius", "1"],
    "segment-sar": ["segment", "{i}", "{o}", "--method", "sar", "--radius", "1"],
    "ridges": ["ridges", "{i}", "{o}", "--radius", "2"],
    "segment-ridges": ["segment", "{i}", "{o}", "--method", "ridges", "--radius", "2"],
    "moments": ["moments", "{i}", "{o}"],
}


def run_compile(tmp):
    modes = {}
    for mode in ("parallel", "serial"):
        out = Path(tmp) / f"{mode}.json"
        env = dict(os.environ, NUMBA_CACHE_DIR=tempfile.mkdtemp(prefix=f"numba-{mode}-", dir=tmp),
                   LIDARSTAT_BENCH_SERIAL="1" if mode == "serial" else "0")
        subprocess.run([sys.executable, "-c", COMPILE_CHILD, str(out)], env=env, check=True,
                       stdout=subprocess.DEVNULL)
        modes[mode] = json.loads(out.read_text())
    par, ser = modes["parallel"], modes["serial"]
    return {
        "how": "benchmarks/parallel_compile.py --compile: the warm-up steps in one process, "
               "cold cache, kernels as declared vs every parallel=True kernel serial; compile "
               "CPU = compiling thread's CPU over outermost numba:compile events",
        "compile_cpu_ratio_serial_to_parallel": round(ser["compile_cpu_s"] / par["compile_cpu_s"], 3),
        **modes,
    }


def run_runtime(tmp, points, only, repeat, warm):
    sys.path.insert(0, str(HERE))
    from scaling import write_cloud

    cloud = Path(tmp) / "town.laz"
    write_cloud(cloud, points)
    argvs = [(name, [a.format(i=cloud, o=Path(tmp) / f"{name}.laz") for a in argv])
             for name, argv in COMMANDS.items() if not only or name in only]
    out = Path(tmp) / "runtime.json"
    env = dict(os.environ)
    if not warm:  # the commands' own kernels compile first: a cold cache costs minutes
        env["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="numba-rt-", dir=tmp)
    subprocess.run([sys.executable, "-c", RUNTIME_CHILD, str(out), str(repeat), json.dumps(argvs)],
                   env=env, check=True, stdout=subprocess.DEVNULL)
    got = json.loads(out.read_text())
    for r in got["kernels"].values():
        r.pop("_bytes"), r.pop("_n")
        r["points"] = points
    return got


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "results_first_run.json"))
    ap.add_argument("--machine-shared", action="store_true")
    ap.add_argument("--compile", action="store_true", help="compile CPU of the warm-up steps")
    ap.add_argument("--runtime", action="store_true", help="run time serial vs parallel")
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", nargs="*", choices=sorted(COMMANDS))
    ap.add_argument("--warm-cache", action="store_true",
                    help="--runtime on the package's own Numba cache (the run times do not "
                         "depend on it; the timed builds always compile)")
    args = ap.parse_args()
    out = Path(args.out)
    store = json.loads(out.read_text()) if out.exists() else {}
    note = {"machine_shared": args.machine_shared, "cpus": os.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        if args.compile:
            store["parallel_compile"] = {**note, **run_compile(tmp)}
            out.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")
            r = store["parallel_compile"]
            print(f"compile CPU: parallel {r['parallel']['compile_cpu_s']:.0f} s, serial "
                  f"{r['serial']['compile_cpu_s']:.0f} s", flush=True)
        if args.runtime:
            got = run_runtime(tmp, args.points, args.only, args.repeat, args.warm_cache)
            store = json.loads(out.read_text()) if out.exists() else {}
            prev = store.get("parallel_runtime", {})
            kernels = {**prev.get("kernels", {}), **got["kernels"]}
            store["parallel_runtime"] = {
                **note, "kernels": kernels,
                "commands": {**prev.get("commands", {}), **got["commands"]},
                "not_measured": sorted((set(prev.get("not_measured", [])) | set(got["not_wrapped"])
                                        | set(got["wrapped"])) - set(kernels)),
                "how": "benchmarks/parallel_compile.py --runtime: each parallel=True kernel "
                       "called from Python at its largest call in the commands, a serial and "
                       "a parallel build timed on copies of the real arguments (best of "
                       "--repeat, alternating); compile CPU of each build for those types"}
            out.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")
            for k, r in sorted(kernels.items(), key=lambda kv: kv[1]["speedup"]):
                print(f"{k:70s} x{r['speedup']:5.2f}  run {r['run_serial_s']:8.4f} / "
                      f"{r['run_parallel_s']:8.4f} s  compile {r['compile_cpu_serial_s']:5.2f} / "
                      f"{r['compile_cpu_parallel_s']:5.2f} s  ({r['command']}, {r['points']})",
                      flush=True)


if __name__ == "__main__":
    main()
