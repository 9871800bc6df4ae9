#!/usr/bin/env python
"""CPU seconds and peak memory of ``segment --method sar`` with BLAS on one thread, against
the same command with BLAS on all cores, and the outputs compared field by field.

    PYTHONPATH=src python benchmarks/sar_speed.py --before /tmp/before/src
    PYTHONPATH=src python benchmarks/sar_speed.py --before /tmp/before/src --parts calls

(``--parts``: any of ``calls logdet counts runs``, default all; the other keys of the
results file are kept.)

``--before`` is a source tree of lidarstat that runs the command with BLAS on every core
(e.g. ``git archive <commit> src | tar -x -C /tmp/before``); the other runs use the
lidarstat this script imports. Each file runs as a user runs it (``python -m
lidarstat.cli segment IN OUT --method sar -q``, a fresh process, ``scaling.run``: CPU
seconds user + system of every thread and peak resident memory from ``os.wait4``), the
two versions alternating (before first on even repeats, after first on odd), each with
its own Numba cache (warm both first: one run on a small file). Files: the sparse ISPRS
samples 11 and 51, IGN St-Barthelemy, the AHN3 Delft crop and the synthetic town of 0.2
million points (``scaling.write_cloud``). Every per-point field of the two outputs is
compared: the count of values that differ and the largest difference.

``calls`` times, in this process, two calls the SAR stage makes by the thousand: a plane's
orthogonal basis at 1,000 points (a 3 x 3 triangular solve with 1,000 right-hand sides)
and the eigenvalues of a 150 x 150 symmetric matrix, CPU microseconds a call with BLAS on
its default threads and on one thread. ``logdet`` times one sparse LU of ``I - rho W``
against W's eigenvalues by unit size; ``counts`` tallies the likelihood fits and
evaluations of one run on ISPRS sample 11.

Writes ``benchmarks/results_sar_speed.json``. The machine is shared: figures are of one
loaded 2-core machine and the two versions are compared within a file, never across.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
DATA = HERE.parent.parent / "shared" / "data"

from scaling import _code_of_runs, run, write_cloud

FILES = {
    "samp11": "isprs_filtertest/joined/samp11_ref_intensity.laz",
    "samp51": "isprs_filtertest/joined/samp51_ref_intensity.laz",
    "st_barth": "ign_lidarhd_samples/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz",
    "delft_cropped_1": "ahn3_delft_3dfier/ahn3_cropped_1.laz",
    "town_200k": None,
}


def compare(a_path, b_path):
    """Per field: how many values differ between two outputs, and the largest difference."""
    import laspy

    a, b = laspy.read(a_path), laspy.read(b_path)
    names = list(a.point_format.dimension_names)
    if names != list(b.point_format.dimension_names):
        return {"fields_differ": [names, list(b.point_format.dimension_names)]}
    out = {"fields": len(names), "points": len(a.points), "differing": {}}
    for nm in names:
        x, y = np.asarray(a[nm]), np.asarray(b[nm])
        if x.dtype.kind == "f":
            same = (x == y) | (np.isnan(x) & np.isnan(y))
        else:
            same = x == y
        if not same.all():
            diff = np.abs(x[~same].astype(np.float64) - y[~same].astype(np.float64))
            out["differing"][nm] = {"count": int((~same).sum()),
                                    "max_abs": float(np.nanmax(diff)) if np.isfinite(
                                        diff).any() else None}
    return out


def calls(repeat_seconds=0.5):
    """CPU microseconds of a 3 x 3 triangular solve and a 150 x 150 eigvalsh, BLAS on its
    default threads and on one."""
    from scipy import linalg as sla
    from threadpoolctl import threadpool_info, threadpool_limits

    rng = np.random.default_rng(0)
    R = np.triu(rng.normal(size=(3, 3))) + 5 * np.eye(3)
    b = rng.normal(size=(3, 1000))
    S = rng.normal(size=(150, 150))
    S = S + S.T
    # a plane's basis at 1,000 points (PolynomialBasis.__call__) and a unit's eigenvalues
    jobs = {"solve_triangular_3x3_by_1000": lambda: sla.solve_triangular(R, b, trans="T"),
            "eigvalsh_150": lambda: sla.eigvalsh(S)}

    def per_call(f):
        t, k = time.process_time(), 0
        while time.process_time() - t < repeat_seconds or k < 3:
            f()
            k += 1
        return round((time.process_time() - t) / k * 1e6, 1)

    res = {"default_threads": max((i["num_threads"] for i in threadpool_info()
                                   if i["user_api"] == "blas"), default=None)}
    for name, f in jobs.items():
        res[name] = {"default_us": per_call(f)}
        with threadpool_limits(limits=1, user_api="blas"):
            res[name]["one_thread_us"] = per_call(f)
    return res


def logdet_costs(sizes=(150, 300, 600, 1200, 3000), seconds=0.5, seed=0):
    """CPU milliseconds of one sparse LU of ``I - rho W`` (what each likelihood evaluation
    above ``EIG_MAX`` points costs) and of W's eigenvalues (once per fit, through the
    symmetric similar matrix), on uniform points with W the unit's row-standardised
    adjacency within 1.5 spacings, BLAS on one thread."""
    import scipy.sparse as sp
    from threadpoolctl import threadpool_limits

    from lidarstat.segment._sar_refine import _adjacency, _standardised
    from lidarstat.stats import LogDet

    def per_call(f):
        t, k = time.process_time(), 0
        while time.process_time() - t < seconds or k < 2:
            f()
            k += 1
        return (time.process_time() - t) / k * 1e3

    rng = np.random.default_rng(seed)
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for n in sizes:
            xy = rng.uniform(0, np.sqrt(n), (n, 2))
            W = sp.csr_matrix(_standardised(_adjacency(xy, 1.5)))
            lu = LogDet(W, "lu")
            rows.append({"n": n, "lu_ms": round(per_call(lambda lu=lu: lu(0.37)), 3),
                         "eigenvalues_ms": round(per_call(lambda W=W: LogDet(W, "eig")), 3)})
    return rows


def counts(path):
    """Likelihood fits, log-determinants and evaluations of one in-process run of
    ``segment_sar`` with its defaults (the CLI's) on `path`, by log-determinant method
    and unit size."""
    from lidarstat import read
    from lidarstat.segment import segment_sar
    from lidarstat.stats import _sar_logdet

    tally = {}
    init, call = _sar_logdet.LogDet.__init__, _sar_logdet.LogDet.__call__

    def counted_init(self, W, method="auto", **kw):
        init(self, W, method, **kw)
        size = "n<=150" if self.n <= 150 else ("n<=600" if self.n <= 600 else "n>600")
        row = tally.setdefault(f"{self.method} {size}", {"fits": 0, "evaluations": 0})
        row["fits"] += 1
        self._row = row

    def counted_call(self, rho):
        self._row["evaluations"] += 1
        return call(self, rho)

    _sar_logdet.LogDet.__init__, _sar_logdet.LogDet.__call__ = counted_init, counted_call
    try:
        pc = read(path)
        t = time.process_time()
        seg = segment_sar(pc.xyz)
        cpu = time.process_time() - t
    finally:
        _sar_logdet.LogDet.__init__, _sar_logdet.LogDet.__call__ = init, call
    for row in tally.values():
        row["evaluations_per_fit"] = round(row["evaluations"] / max(row["fits"], 1), 1)
    return {"file": str(path.relative_to(DATA)), "segments": int(seg.labels.max()),
            "cpu_seconds_in_process": round(cpu, 1), "by_logdet": tally,
            "note": "one log-determinant per fit, one evaluation per likelihood "
                    "evaluation; an 'lu' evaluation factorises I - rho W anew"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="src folder of the previous lidarstat")
    ap.add_argument("--files", nargs="+", default=list(FILES), choices=list(FILES))
    ap.add_argument("--before-code", default=None,
                    help="what --before holds (e.g. its commit), stored with the runs")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--out", default=str(HERE / "results_sar_speed.json"))
    ap.add_argument("--parts", nargs="+", default=["calls", "logdet", "counts", "runs"],
                    choices=["calls", "logdet", "counts", "runs"],
                    help="what to measure; the other keys of --out are kept")
    args = ap.parse_args(argv)
    import lidarstat

    after_src = str(Path(lidarstat.__file__).resolve().parents[1])
    out = Path(args.out)
    results = json.loads(out.read_text()) if out.exists() else {}
    results.update({"machine": {"platform": platform.platform(), "cores": os.cpu_count(),
                                "python": platform.python_version(), "machine_shared": True,
                                "note": "two cores shared with other jobs (runs at nice "
                                        "10): compare the two versions within a file"},
                    "command": "segment IN OUT --method sar"})
    if args.before_code:
        results["before_code"] = args.before_code
    results.setdefault("code", {})
    for part in args.parts:
        results["code"][part] = _code_of_runs()
    if "calls" in args.parts:
        results["calls"] = calls()
        print(json.dumps(results["calls"]), flush=True)
    if "logdet" in args.parts:
        results["logdet"] = logdet_costs()
        print(json.dumps(results["logdet"]), flush=True)
    if "counts" in args.parts:
        results["counts"] = counts(DATA / FILES["samp11"])
        print(json.dumps(results["counts"]), flush=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    if "runs" not in args.parts:
        return
    results["files"] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for key in args.files:
            if FILES[key] is None:
                src = tmp / "town_200000.laz"
                write_cloud(src, 200_000)
            else:
                src = DATA / FILES[key]
            rows = {"file": FILES[key] or "synthetic town, 200,000 points (scaling.py)",
                    "before": [], "after": []}
            for r in range(args.repeats):
                order = ("before", "after") if r % 2 == 0 else ("after", "before")
                for which in order:
                    env = dict(os.environ, PYTHONPATH=args.before if which == "before"
                               else after_src)
                    dst = tmp / f"{which}.laz"
                    res = run(["segment", str(src), str(dst), "--method", "sar"], env,
                              args.timeout)
                    rows[which].append(res)
                    print(f"{key:16s} {which:6s} {res['seconds']} s  CPU "
                          f"{res.get('cpu_seconds')} s  {res['peak_mib']} MiB  "
                          f"{res['status']}", flush=True)
                if all((tmp / f"{w}.laz").exists() for w in ("before", "after")):
                    rows.setdefault("outputs", []).append(
                        compare(tmp / "before.laz", tmp / "after.laz"))
                for w in ("before", "after"):
                    (tmp / f"{w}.laz").unlink(missing_ok=True)
            ok = [[x["cpu_seconds"] for x in rows[w] if x["status"] == "ok"]
                  for w in ("before", "after")]
            if all(ok):
                rows["cpu_ratio_after_before"] = round(min(ok[1]) / min(ok[0]), 3)
            results["files"][key] = rows
            out.write_text(json.dumps(results, indent=1) + "\n")
    out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
