#!/usr/bin/env python
"""Where the raised patches of ``moments`` spend their CPU: the parts of one call.

Runs :func:`lidarstat.classify.moments` once on the synthetic cloud of ``bench_moments.py``
(after a 200,000-point run that compiles the kernels), keeps the arguments of its
:func:`~lidarstat.classify._continuity.raised_patches` call (the window-ordered
coordinates and the ranks) and the call's own wall and thread CPU seconds (it runs in a
thread beside the window passes). Then, alone, it replays the call ``--repeats`` times
part by part, in the order the function runs them (process CPU seconds: the kNN search
runs on every core; the median over the repeats):

* ``grid``: the cells' keys, the counting sort, the rank order inside the cells, the
  sorted local coordinates (``_patch_grid``);
* ``gather_z``: the elevations in the grid's order;
* ``copies_check``: whether two points of a cell may share a location;
* ``knn_smooth``: the 8 nearest planimetric neighbours and the smooth flags (all cores);
* ``join``: the union-find over the smooth edges, the step edges gathered;
* ``components``: each point's patch id and each patch's lowest input index;
* ``step_counts``: the step edges' patches, the counts per patch, the raised patches;
* ``scatter``: the result back in the caller's order;

and the whole call (``whole``) in the same repeats, whose output must equal the run's.

Usage::

    python benchmarks/moments_patch_parts.py --points 2000000 \\
        --out benchmarks/results_moments_patch_parts.json --label LABEL
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _results import store

HERE = Path(__file__).resolve().parent


def _capture(n):
    """The arguments of the raised patches' call in one ``moments`` run, its result,
    wall and thread CPU seconds, and the run's process CPU seconds."""
    sys.path.insert(0, str(HERE))
    from bench_moments import make_cloud

    import lidarstat.classify._moments as mo
    from lidarstat.classify import moments

    orig = mo.raised_patches
    seen = {}

    def kept(xy, z, **kw):
        t0, c0 = time.perf_counter(), time.thread_time()
        r = orig(xy, z, **kw)
        seen.update(wall=time.perf_counter() - t0, cpu=time.thread_time() - c0,
                    xy=np.array(xy), z=np.array(z), kw=dict(kw), out=r.copy())
        if kw.get("rank") is not None:
            seen["kw"]["rank"] = np.array(kw["rank"])
        return r

    mo.raised_patches = kept
    try:
        for size in (200_000, n):  # the first run compiles
            seen.clear()
            xyz, inten, nret, rnum, _ = make_cloud(size)
            t0 = time.process_time()
            moments(xyz, inten, number_of_returns=nret, return_number=rnum)
            total = time.process_time() - t0
            del xyz, inten, nret, rnum
    finally:
        mo.raised_patches = orig
    return seen, total


def _parts(xy, z, kw, repeats):
    """Process CPU seconds of each part of ``raised_patches`` (median over `repeats`)."""
    import lidarstat.classify._continuity as co

    k, step, slope = 8, kw["step"], 1.0
    rank = kw.get("rank")
    rows = []
    for _ in range(repeats):
        t = {}

        def clock(name, f):
            t0 = time.process_time()
            r = f()
            t[name] = t.get(name, 0.0) + time.process_time() - t0
            return r

        grid, cell = clock("grid", lambda: co._patch_grid(xy, k, rank))
        zs = clock("gather_z", lambda: z[grid.pos])
        clock("copies_check", lambda: grid.may_have_copies(zs))
        n = z.size
        parent = np.arange(n, dtype=np.int64)
        ci, cj, cup = [], [], []
        for c0, c1 in grid.blocks(1_000_000):
            s0, s1 = grid.cell_start[c0], grid.cell_start[c1]
            nbr = np.empty((s1 - s0, k), np.int32)
            smooth = np.empty((s1 - s0, k), np.bool_)
            clock("knn_smooth", lambda: co._knn_smooth(
                c0, c1, grid.points, zs, grid.cell_keys, grid.cell_start, grid.dims, cell,
                k, cell, step, slope, nbr, smooth))
            i, j, up = clock("join", lambda: co._join_smooth(parent, zs, nbr, smooth, s0))
            ci.append(i)
            cj.append(j)
            cup.append(up)
        lab, ncomp, first = clock("components",
                                  lambda: co._component_labels(parent, grid.order))

        def counts():
            a, b, u = np.concatenate(ci), np.concatenate(cj), np.concatenate(cup)
            other = lab[a] != lab[b]
            li = lab[a[other]]
            n_above = np.bincount(li[u[other]], minlength=ncomp)
            n_step = np.bincount(li, minlength=ncomp)
            size = np.bincount(lab, minlength=ncomp)
            raised = (n_step > 0) & (n_above >= 0.95 * n_step) & (size >= 10)
            big = np.flatnonzero(size == size.max())
            raised[big[np.argmin(first[big])]] = False
            return raised

        raised = clock("step_counts", counts)

        def scatter():
            out = np.empty(n, bool)
            out[grid.pos] = raised[lab]
            return out

        parts_out = clock("scatter", scatter)
        whole_out = clock("whole", lambda: co.raised_patches(xy, z, **kw))
        if not np.array_equal(parts_out, whole_out):
            raise AssertionError("the replayed parts differ from the whole call")
        rows.append(t)
        del grid, parent, lab
    return {name: round(float(np.median([r[name] for r in rows])), 3) for name in rows[0]}, \
        whole_out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--label", default="current")
    ap.add_argument("--note", default=None, help="what code the run measured")
    a = ap.parse_args(argv)
    seen, total = _capture(a.points)
    parts, out = _parts(seen["xy"], seen["z"], seen["kw"], a.repeats)
    if not np.array_equal(out, seen["out"]):
        raise AssertionError("the replayed call differs from the run's")
    whole = parts.pop("whole")
    row = {
        "points": a.points, "machine_shared": True,
        "moments_cpu_s": round(total, 3),
        "in_run_wall_s": round(seen["wall"], 3),
        "in_run_thread_cpu_s": round(seen["cpu"], 3),
        "raised_points": int(out.sum()),
        "replay_repeats": a.repeats,
        "replay_whole_cpu_s": whole,
        "replay_parts_cpu_s": parts,
        "replay_parts_sum_cpu_s": round(sum(parts.values()), 3),
    }
    if a.note:
        row["note"] = a.note
    print(json.dumps(row, indent=1))
    if a.out:
        store(a.out, a.label, row)


if __name__ == "__main__":
    main()
