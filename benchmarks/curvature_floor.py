#!/usr/bin/env python
"""Where `lidarstat curvature`'s search and fit time goes, against what a plain fit needs.

On the cloud of ``bench_curvature.py`` (synthetic airborne, 20 points per m^2) at the
radius of about 50 neighbours, in one process on a warm Numba cache, median of
``--repeats``, wall and CPU seconds of:

* ``search``: the fused grid search alone (every point's neighbours counted, none stored);
* ``search_plain_fit``: the same search driving a plain least-squares quadric in the z
  frame (15 moment sums and 6 right-hand sides per neighbour, a 6 x 6 solve): what a
  curvature estimate without a test needs, as a peer computes it;
* ``search_tested_fit``: the command's kernel at its defaults (``pca`` frame, tricube
  weights, the sums of X'WX, X'W^2X and X'W^3X that the exact null moments of the
  chi-square need, the residual pass).

The difference between the last two is the price of the tested statistics; the first is
the neighbour search every method pays. Writes ``results_curvature_floor.json``::

    python benchmarks/curvature_floor.py --points 2000000
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_curvature import calibrate_radius, make_cloud  # noqa: E402


def _plain_kernels():
    """A plain least-squares quadric h = b0 + b1 x + ... + b5 y^2 in the z frame, per point,
    in the protocol of ``lidarstat.neighbors.make_drivers`` (the benchmark's own kernel)."""
    from lidarstat._shared._jit import njit
    from lidarstat.neighbors import make_drivers

    @njit
    def workspace(params):
        return (np.empty((6, 6)), np.empty(6))

    @njit
    def fit_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs):
        a, g = ws
        m = np.zeros(15)
        for k in range(6):
            g[k] = 0.0
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        inv = 1.0 / params[0]
        for t in range(s, e):
            j = idx[t]
            u = (pts[j, 0] - px) * inv
            v = (pts[j, 1] - py) * inv
            h = pts[j, 2] - pz
            uu, uv, vv = u * u, u * v, v * v
            m[0] += 1.0
            m[1] += u
            m[2] += v
            m[3] += uu
            m[4] += uv
            m[5] += vv
            m[6] += uu * u
            m[7] += uu * v
            m[8] += u * vv
            m[9] += vv * v
            m[10] += uu * uu
            m[11] += uu * uv
            m[12] += uu * vv
            m[13] += uv * vv
            m[14] += vv * vv
            g[0] += h
            g[1] += h * u
            g[2] += h * v
            g[3] += h * uu
            g[4] += h * uv
            g[5] += h * vv
        mono = ((0, 1, 2, 3, 4, 5), (1, 3, 4, 6, 7, 8), (2, 4, 5, 7, 8, 9),
                (3, 6, 7, 10, 11, 12), (4, 7, 8, 11, 12, 13), (5, 8, 9, 12, 13, 14))
        for p in range(6):
            for q in range(6):
                a[p, q] = m[mono[p][q]]
        beta = outs[0]
        if e - s >= 6:
            beta[r] = np.linalg.solve(a + 1e-12 * np.eye(6), g)
        else:
            beta[r] = np.nan

    @njit
    def skip(r, outs):
        outs[0][r] = np.nan

    return make_drivers(fit_point, workspace, skip)


def _cpu():
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def _timed(fn, repeats):
    fn()  # load or compile
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), _cpu()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(_cpu() - c)
    k = int(np.argsort(walls)[len(walls) // 2])
    return dict(seconds=walls[k], cpu_seconds=cpus[k], all_seconds=walls, all_cpu=cpus)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--neighbors", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--shared", action="store_true",
                    help="record that other work ran on the machine meanwhile")
    ap.add_argument("--out", default=str(HERE / "results_curvature_floor.json"))
    args = ap.parse_args(argv)

    import numba

    from lidarstat.features import _quadric as quadric
    from lidarstat.neighbors import CellIndex
    from lidarstat.neighbors import _kernels as nk

    xyz, _ = make_cloud(args.points)
    radius = float(calibrate_radius(xyz, args.neighbors)[0])
    index = CellIndex(xyz, radius)
    ncell = index.cell_keys.size
    pts = index.sorted_points
    active = np.ones(index.n_points, dtype=np.uint8)
    plain = _plain_kernels()
    beta = np.empty((index.n_points, 6))

    def search():
        nk.count_radius(pts, pts, index.cell_keys, index.cell_start, index.cell, index.dims,
                        radius, 3)

    def plain_fit():
        plain.cells(0, ncell, pts, index.cell_keys, index.cell_start, index.dims, radius,
                    active, (radius,), (beta,))

    def tested_fit():
        quadric._run_cells(index, 0, ncell, bandwidth=radius, frame="pca", sensor=None,
                           min_neighbors=7, covariance="sandwich")

    rows = {"search": _timed(search, args.repeats),
            "search_plain_fit": _timed(plain_fit, args.repeats),
            "search_tested_fit": _timed(tested_fit, args.repeats)}
    visits = float(nk.count_radius(pts, pts, index.cell_keys, index.cell_start, index.cell,
                                   index.dims, radius, 3).sum())
    for row in rows.values():
        row["cpu_ns_per_neighbour"] = 1e9 * row["cpu_seconds"] / visits
    res = dict(
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        machine=dict(platform=platform.platform(), cores=os.cpu_count(),
                     python=platform.python_version(), numpy=np.__version__,
                     numba=numba.__version__),
        machine_shared=bool(args.shared), points=int(xyz.shape[0]), radius=radius,
        neighbour_visits=visits, repeats=args.repeats, rows=rows,
        how="one process, warm Numba cache, median of the repeats; the grid index is built "
            "once; see the module docstring of benchmarks/curvature_floor.py")
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    for name, row in rows.items():
        print(f"{name:20s} {row['seconds']:6.2f} s  {row['cpu_seconds']:6.2f} s CPU  "
              f"{row['cpu_ns_per_neighbour']:5.1f} ns CPU per neighbour")


if __name__ == "__main__":
    main()
