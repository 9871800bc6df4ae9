#!/usr/bin/env python
"""This machine's arithmetic and memory limits, against which the curvature kernel's time is set.

Measured with Numba (the compiler of the library's kernels), one thread and all threads,
best of ``--repeats``:

* ``flops_fma``: ``a = a * x + y`` over 64 independent elements in the L1 cache, many
  times: the compiler's vector instructions, multiply and add fused (``fastmath``
  contraction): the double-precision peak a Numba loop reaches;
* ``flops_mul_add``: the same loop without contraction (a multiply and an add, as the
  library's kernels compile: ``fastmath=False``, IEEE rounding of every operation);
* ``sqrt``, ``div``: independent square roots and divisions over a stream, ns each;
* ``copy``, ``triad``: streaming ``b[:] = a`` and ``c = a + s b`` over 256 MiB arrays,
  bytes moved per second (reads and writes counted).

The arithmetic rates are per CPU second of the process (user + system), so other jobs on
the machine lower them less than wall time; the streams are wall time (bandwidth is
shared by every job).

Then the arithmetic of the curvature kernel (``FLOPS``: floating-point operations per
neighbour and per point, counted from the source of ``_quadric_kernels._fit_one``, the
grid scan and ``_frame_kernels``; a multiply, add, divide or square root is one) is set
against the kernel's own time on one thread (key ``stages`` of the same file,
``curvature_floor.py --stages``): the rate it reaches and its fraction of this
machine's rates.

Writes the key ``machine_limits`` of ``results_curvature_floor.json`` (other keys kept)::

    nice -n 10 python benchmarks/machine_limits.py --shared
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np
from numba import prange

HERE = Path(__file__).resolve().parent

_LANES = 64  # independent elements per task: eight 8-wide vectors, in the L1 cache


def _lanes_body(x, y, out, reps):
    for i in prange(out.shape[0] // _LANES):
        a = out[i * _LANES:(i + 1) * _LANES].copy()
        for _ in range(reps):
            for k in range(_LANES):
                a[k] = a[k] * x + y
        out[i * _LANES] = a.sum()


fma_kernel = numba.njit(parallel=True, fastmath={"contract"})(_lanes_body)
mul_add_kernel = numba.njit(parallel=True, fastmath=False)(_lanes_body)


#: Floating-point operations of the curvature kernel, counted from its source:
#: per neighbour by step (search per candidate, times the candidates a neighbour costs),
#: and once per point (the 6 x 6 inverse, the solve, the traces, the sandwich cofactor,
#: the closed-form frame).
FLOPS = {
    "per_candidate_search": 8,  # 3 differences, 3 squares, 2 adds (the distance test)
    "per_neighbour": {
        "search_sqrt": 1,  # the neighbour's distance
        "offsets_weights": 9,  # 3 differences; tricube: a divide, 4 multiplies, 1 subtract
        "frame": 28,  # weighted mean (7), centred covariance (3 + 18)
        "to_frame": 17,  # 3 x 3 rotation (15), tangent scaling (2)
        "moment_sums": 117,  # 15 monomial and weight products, 51 multiply-adds (102)
        "residual": 14,  # quadric at (u, v) (10), residual (1), w r^2 accumulated (3)
    },
    "tested_share_per_neighbour": 76,  # the w^2, w^3 sums (2 + 60) and the residual pass
    "per_point": 1700,  # inverse 550, solve 72, traces 144, N2 Ninv 432, tr 72, sandwich
                        # 252, eigenpairs in closed form about 180
}


def kernel_arithmetic(stages, peak_gflops):
    """Flops per point of the kernel at each neighbour count of `stages` (the key of
    ``curvature_floor.py --stages``), the rate its ``fit`` stage reaches on one thread and
    that rate's share of `peak_gflops` (per core)."""
    out = {}
    for key, row in stages["rows"].items():
        k = row["mean_neighbours"]
        cand = row.get("candidates_per_neighbour", 2.9)
        per_nb = sum(FLOPS["per_neighbour"].values()) + FLOPS["per_candidate_search"] * cand
        flops = per_nb * k + FLOPS["per_point"]
        ns = row["stages"]["fit"]["cpu_ns_per_point"]
        rate = flops / ns  # flops per ns = GFLOP/s
        out[key] = {"mean_neighbours": k, "flops_per_neighbour": per_nb,
                    "flops_per_point": flops, "fit_cpu_ns_per_point": ns,
                    "gflops_per_core": rate,
                    "share_of_numba_peak": {n: rate / g for n, g in peak_gflops.items()},
                    "tested_share_of_flops": FLOPS["tested_share_per_neighbour"] * k / flops}
    return out


@numba.njit(parallel=True, fastmath=False)
def sqrt_kernel(a, out):
    for i in prange(a.shape[0]):
        out[i] = np.sqrt(a[i])


@numba.njit(parallel=True, fastmath=False)
def div_kernel(a, out):
    for i in prange(a.shape[0]):
        out[i] = 1.0 / a[i]


@numba.njit(parallel=True, fastmath=False)
def copy_kernel(a, b):
    for i in prange(a.shape[0]):
        b[i] = a[i]


@numba.njit(parallel=True, fastmath=False)
def triad_kernel(a, b, c, s):
    for i in prange(a.shape[0]):
        c[i] = a[i] + s * b[i]


def _best(fn, repeats, clock=time.perf_counter):
    """Smallest `clock` time of `repeats` calls (after one warm call)."""
    fn()
    best = np.inf
    for _ in range(repeats):
        t0 = clock()
        fn()
        best = min(best, clock() - t0)
    return best


def measure(threads, repeats):
    numba.set_num_threads(threads)
    res = {}
    n_el, reps = _LANES * threads, 2_000_000
    out = np.random.default_rng(0).random(n_el)
    flops = 2.0 * n_el * reps
    for name, k in (("flops_fma", fma_kernel), ("flops_mul_add", mul_add_kernel)):
        t = _best(lambda: k(0.999999, 1e-7, out.copy(), reps), repeats, time.process_time)
        res[name] = {"gflops_per_core": flops / t / 1e9}
    a = np.random.default_rng(1).random(1 << 22) + 0.5  # 32 MiB: streams from memory
    o = np.empty_like(a)
    for name, k in (("sqrt", sqrt_kernel), ("div", div_kernel)):
        t = _best(lambda: k(a, o), repeats)
        res[name] = {"ns_per_op": t / a.size * 1e9 * threads}
    big = np.random.default_rng(2).random(1 << 25)  # 256 MiB each
    b = np.empty_like(big)
    c = np.empty_like(big)
    t = _best(lambda: copy_kernel(big, b), repeats)
    res["copy"] = {"gb_per_s": 2 * big.nbytes / t / 1e9}
    t = _best(lambda: triad_kernel(big, b, c, 1.5), repeats)
    res["triad"] = {"gb_per_s": 3 * big.nbytes / t / 1e9}
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--shared", action="store_true",
                    help="record that other jobs ran on the machine meanwhile")
    ap.add_argument("--out", default=str(HERE / "results_curvature_floor.json"))
    args = ap.parse_args(argv)
    cores = numba.config.NUMBA_NUM_THREADS
    rows = {"1": measure(1, args.repeats)}
    if cores > 1:
        rows[str(cores)] = measure(cores, args.repeats)
    for th, r in rows.items():
        print(f"{th} thread(s): " + ", ".join(
            f"{k} {next(iter(v.values())):.2f} {next(iter(v))}" for k, v in r.items()))
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    res = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "machine": {"platform": platform.platform(), "cpu": cpu, "cores": os.cpu_count(),
                       "numba": numba.__version__},
           "machine_shared": bool(args.shared), "repeats": args.repeats,
           "how": "see the module docstring of benchmarks/machine_limits.py; best of the "
                  "repeats, wall time",
           "threads": rows}
    path = Path(args.out)
    whole = json.loads(path.read_text()) if path.exists() else {}
    one = rows["1"]
    peaks = {"flops_fma": one["flops_fma"]["gflops_per_core"],
             "flops_mul_add": one["flops_mul_add"]["gflops_per_core"]}
    res["flops_counted"] = FLOPS
    if "stages" in whole:
        res["kernel"] = kernel_arithmetic(whole["stages"], peaks)
        for key, r in res["kernel"].items():
            print(f"about {key} neighbours: {r['flops_per_point']:.0f} flops a point in "
                  f"{r['fit_cpu_ns_per_point']:.0f} ns: {r['gflops_per_core']:.2f} GFLOP/s, "
                  + ", ".join(f"{v:.0%} of {n}" for n, v in r["share_of_numba_peak"].items()))
    whole["machine_limits"] = res
    path.write_text(json.dumps(whole, indent=1) + "\n")
    print(f"wrote {path} (key machine_limits)")


if __name__ == "__main__":
    main()
