#!/usr/bin/env python
"""Where the dip tests of ``moments`` spend their CPU: the tests of one run and their parts.

Runs :func:`lidarstat.classify.moments` once on the synthetic cloud of ``bench_moments.py``
(after a 200,000-point run that compiles the kernels) and records every dip test the
window analyses make: its sample size, whether the caller passed the sorted values, and
its CPU seconds (of its thread: steps of ``moments`` run in threads beside it). Then, on up to ``--replay`` of the recorded samples, it times each part
of :func:`lidarstat.stats.dip_test` on its own, in the order the test runs them (CPU
seconds summed over the replayed samples, each part repeated ``--repeats`` times):

* ``subsample``: the seeded random subsample of samples above ``max_points``;
* ``sort``: the sort for the ties (skipped where the caller passed the sorted values);
* ``gaps``: ties and the smallest gap between distinct values;
* ``dequantize``: the uniform spread of the tied values;
* ``sort_dequantized``: the sort of the spread values;
* ``diptest_core``: the ``diptest`` package on the sorted sample (``sort_x=False``),
  statistic and interpolated p-value.

``repeated_tests`` counts the tests whose sample (the same values in the same order) an
earlier test of the run already took, and ``repeated_tests_cpu_s`` their CPU: what a
cache of the results by sample would save.

Usage::

    python benchmarks/moments_dip_parts.py --points 2000000 \\
        --out benchmarks/results_moments_dip_parts.json --label LABEL
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np
from _results import store

HERE = Path(__file__).resolve().parent


def _census(n):
    """Every dip test of one ``moments`` run: [(values, sorted given, CPU s)]."""
    sys.path.insert(0, str(HERE))
    from bench_moments import make_cloud

    import lidarstat.classify._moments_analysis as ma
    from lidarstat.classify import moments

    orig = ma.dip_test
    log = []

    def timed(values, **kw):
        t0 = time.thread_time()  # the test's own thread: other threads run beside it
        r = orig(values, **kw)
        cpu = time.thread_time() - t0
        log.append((np.array(values, dtype=np.float64), kw.get("sorted_values") is not None,
                    cpu))
        return r

    ma.dip_test = timed
    try:
        for size in (200_000, n):  # the first run compiles
            log.clear()
            xyz, inten, nret, rnum, _ = make_cloud(size, seed=0)
            t0 = time.process_time()
            moments(xyz, inten, number_of_returns=nret, return_number=rnum)
            total = time.process_time() - t0
    finally:
        ma.dip_test = orig
    return list(log), total


def _parts(samples, repeats, max_points=20000, seed=0):
    """CPU seconds of each part of the dip test summed over `samples`."""
    import diptest

    from lidarstat.stats import sort_values

    out = dict.fromkeys(("subsample", "sort", "gaps", "dequantize", "sort_dequantized",
                         "diptest_core"), 0.0)

    def clock(name, f):
        t0 = time.thread_time()
        for _ in range(repeats):
            r = f()
        out[name] += (time.thread_time() - t0) / repeats
        return r

    for x, presorted in samples:
        if x.size > max_points:
            x = clock("subsample", lambda: np.random.default_rng(seed).choice(
                x, size=max_points, replace=False))
            presorted = False
        xs = np.sort(x) if presorted else clock("sort", lambda: sort_values(x))
        gaps = clock("gaps", lambda: np.diff(xs))
        steps = gaps[gaps > 0]
        if steps.size < gaps.size and steps.size:
            q = float(np.min(steps))
            g = np.random.default_rng(seed)
            y = clock("dequantize", lambda: x + g.uniform(-0.5 * q, 0.5 * q, size=x.size))
            xs = clock("sort_dequantized", lambda: sort_values(y))
        if xs.size >= 4:
            clock("diptest_core", lambda: diptest.diptest(xs, sort_x=False))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--replay", type=int, default=200, help="samples whose parts are timed")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default="current")
    a = ap.parse_args(argv)
    log, total = _census(a.points)
    sizes = np.array([v.size for v, _, _ in log])
    cpu = np.array([c for _, _, c in log])
    given = np.array([s for _, s, _ in log])
    big = sizes > 20000
    seen, repeated = set(), np.zeros(len(log), bool)
    for i, (v, _, _) in enumerate(log):
        key = hashlib.blake2b(v.tobytes(), digest_size=16).digest()
        repeated[i] = key in seen
        seen.add(key)
    g = np.random.default_rng(0)
    pick = np.sort(g.choice(len(log), size=min(a.replay, len(log)), replace=False))
    parts = _parts([(log[i][0], log[i][1]) for i in pick], a.repeats)
    scale = len(log) / pick.size
    row = {
        "points": a.points, "machine_shared": True,
        "moments_cpu_s": round(total, 3),
        "dip_tests": int(sizes.size), "dip_tests_cpu_s": round(float(cpu.sum()), 3),
        "subsampled_tests": int(big.sum()),
        "subsampled_tests_cpu_s": round(float(cpu[big].sum()), 3),
        "tests_with_sorted_values": int(given.sum()),
        "repeated_tests": int(repeated.sum()),
        "repeated_tests_cpu_s": round(float(cpu[repeated].sum()), 3),
        "size_percentiles_10_50_90": np.percentile(sizes, [10, 50, 90]).round().tolist(),
        "replayed_tests": int(pick.size), "replay_repeats": a.repeats,
        "parts_cpu_s_scaled_to_all_tests": {k: round(v * scale, 4) for k, v in parts.items()},
    }
    print(json.dumps(row, indent=1))
    if a.out:
        store(a.out, a.label, row)


if __name__ == "__main__":
    main()
