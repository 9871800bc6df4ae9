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

``--stages`` instead times the kernel's own steps one after the other on one thread
(``NUMBA_NUM_THREADS=1``), each stage adding one step to the previous (a serial loop of
the benchmark over the cells of the middle of the cloud calling the library's functions):

* ``search``: the candidates of the 27 cells gathered once per cell into contiguous
  columns, the squared distance to every candidate, the positions and squared
  distances of those inside;
* ``offsets``: + the tricube weights (square roots included) and offsets of the
  neighbours into four columns, and the weighted sums of the offsets and their products (the frame's
  covariance);
* ``frame``: + the PCA frame (covariance about the weighted mean, eigenpairs,
  orientation);
* ``moments``: + local coordinates and the 15 x 3 + 6 weighted moment sums;
* ``fit``: the whole per-point fit of the command (``_fit_local``: the above, the 6 x 6
  Cholesky inverse, the residual pass, the traces and the sandwich cofactor);
* ``driver``: the command's own call (``_run_cells``: the parallel driver on one thread,
  the per-block budget check, the outputs written to the block's arrays).

Stored under ``stages`` (per neighbour count) in the same file::

    NUMBA_NUM_THREADS=1 python benchmarks/curvature_floor.py --stages --neighbors 50 300

(``--key NAME`` stores the ``--stages`` or ``--against`` figures under NAME instead.)

``--half-cells`` times the grid search alone (one thread, the serial loop of ``--stages``
``search`` stage) on an index of cells of the radius (the 27 cells around a point's own)
and on one of cells of half the radius (the 125 within two cells), with the same query
radius: candidates per neighbour, the column ranges' cost (binary searches of the
occupied cells) and the whole search, ns a point; stored under ``half_cells``::

    NUMBA_NUM_THREADS=1 python benchmarks/curvature_floor.py --half-cells --neighbors 50 300

``--against SRC`` compares two versions of the package: the ``driver`` stage alone (the
command's search and fit of the same cells, one thread), in child processes that
alternate between the package found at SRC (a PYTHONPATH, e.g. main's ``src``) and this
one, each with its own Numba cache; stored under ``driver_against``::

    python benchmarks/curvature_floor.py --against /tmp/main/src --neighbors 50 300
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


STAGES = ("search", "offsets", "frame", "moments", "fit", "driver")


def _stage_kernel():
    """A serial loop over cells running the first `stage` steps of the command's fit."""
    from lidarstat._shared._jit import njit
    from lidarstat._shared._kernels import mirror3
    from lidarstat.features import _frame_kernels as fk
    from lidarstat.features import _quadric_cells as qc
    from lidarstat.features import _quadric_kernels as qk
    from lidarstat.neighbors import _kernels as nk
    from lidarstat.neighbors import grid_candidate_count

    @njit
    def run(stage, c0, c1, pts, cell_keys, cell_start, dims, radius):
        ws = qk._workspace()
        R, cov3, ev, evec, mom, rhs = ws[0], ws[1], ws[2], ws[3], ws[4], ws[11]
        ranges = np.empty((9, 2), dtype=np.int64)
        cap = 1024
        cand = np.empty((4, cap))
        cols = np.empty((4, cap))
        sel = np.empty(cap, dtype=np.int32)
        beta, cof, frm, st = (np.empty((1, 6)), np.empty((1, 6, 6)), np.empty((1, 3, 3)),
                              np.empty((1, 4)))
        sensor = np.zeros(3)
        r2 = radius * radius
        visits = 0
        check = 0.0
        for c in range(c0, c1):
            nr = nk._cell_ranges(c, cell_keys, cell_start, dims, 3, ranges)
            need = grid_candidate_count(ranges, nr)
            if need > cap:
                cap = max(need, 2 * cap)
                cand = np.empty((4, cap))
                cols = np.empty((4, cap))
                sel = np.empty(cap, dtype=np.int32)
            m = qc.gather(pts, ranges, nr, cand)
            for i in range(cell_start[c], cell_start[c + 1]):
                px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
                nkp = qc.within(px, py, pz, cand, m, r2, sel, cols[3])
                visits += nkp
                if stage == 0:
                    check += cols[3, 0]
                    continue
                p, b = qc.neighbour_columns(px, py, pz, cand, sel, nkp, radius, cols)
                if stage == 4:
                    qk._fit_local(cols, nkp, p, px, py, pz, b, fk.FRAME_PCA, sensor, False,
                                  7, qk.COV_SANDWICH, ws, 0, beta, cof, frm, st)
                    check += beta[0, 0]
                    continue
                sw, s0, s1, s2, c00, c01, c02, c11, c12, c22 = qk.frame_sums(
                    cols[0], cols[1], cols[2], cols[3], nkp)
                if stage == 1 or nkp < 6:
                    check += cols[0, 0] + c00 + c01 + c02 + c11 + c12 + c22 + s0 + s1 + s2
                    continue
                m0 = s0 / sw
                m1 = s1 / sw
                m2 = s2 / sw
                cov3[0, 0] = c00 - m0 * s0
                cov3[0, 1] = c01 - m0 * s1
                cov3[0, 2] = c02 - m0 * s2
                cov3[1, 1] = c11 - m1 * s1
                cov3[1, 2] = c12 - m1 * s2
                cov3[2, 2] = c22 - m2 * s2
                mirror3(cov3)
                fk.frame_from_covariance(cov3, px, py, pz, fk.FRAME_PCA, sensor, False, R, ev,
                                         evec, True)
                if stage == 2:
                    check += R[0, 0]
                    continue
                fk.to_frame(cols.T, nkp, R, 1.0 / radius)
                qk._moment_sums(cols[0], cols[1], cols[2], cols[3], nkp, mom, rhs)
                check += mom[0, 0]
        return visits, check

    return run


def _half_cells_kernel():
    """A serial loop over cells: the column ranges of the cells within `rad` cells (mode
    0), or those and the scan of every candidate (mode 1)."""
    from lidarstat._shared._jit import njit
    from lidarstat.neighbors import _kernels as nk
    from lidarstat.neighbors import grid_candidate_count
    from lidarstat.neighbors._grid_kernels import column_ranges

    @njit
    def run(mode, rad, c0, c1, pts, cell_keys, cell_start, dims, radius):
        m = 2 * rad + 1
        ranges = np.empty((m * m, 2), dtype=np.int64)
        cap = 1024
        idx = np.empty(cap, dtype=np.int32)
        dist = np.empty(cap)
        r2 = radius * radius
        cand = found = nrs = 0
        for c in range(c0, c1):
            key = cell_keys[c]
            iz0 = key % dims[2]
            rest = key // dims[2]
            nr = column_ranges(rest // dims[1], rest % dims[1], rad, max(iz0 - rad, 0),
                               min(iz0 + rad, dims[2] - 1), cell_keys, cell_start, dims,
                               ranges)
            nrs += nr
            if mode == 0:
                continue
            need = grid_candidate_count(ranges, nr)
            if need > cap:
                cap = max(need, 2 * cap)
                idx = np.empty(cap, dtype=np.int32)
                dist = np.empty(cap)
            for i in range(cell_start[c], cell_start[c + 1]):
                cand += need
                found += nk._scan(pts[i, 0], pts[i, 1], pts[i, 2], pts, ranges, nr, r2, 3,
                                  idx, dist, 0, nk.STORE_ALL)
        return cand, found, nrs

    return run


def _middle_cells(index, stage_points):
    """The cells ``[mid, c1)`` of the middle of the index's sorted order holding about
    `stage_points` points, and their number of points."""
    mid = index.n_cells // 2
    c1 = int(np.searchsorted(index.cell_start, index.cell_start[mid] + stage_points))
    c1 = min(max(c1, mid + 1), index.n_cells)
    return mid, c1, int(index.cell_start[c1] - index.cell_start[mid])


def half_cells(args):
    """``--half-cells``: the search on cells of the radius and of half the radius."""
    from lidarstat.neighbors import CellIndex

    xyz, _ = make_cloud(args.points)
    run = _half_cells_kernel()
    out = {}
    for target in args.neighbors:
        radius = float(calibrate_radius(xyz, target)[0])
        row = dict(radius=radius)
        for name, cell, rad in (("cells_of_radius", radius, 1),
                                ("cells_of_half_radius", radius / 2, 2)):
            index = CellIndex(xyz, cell)
            mid, c1, npts = _middle_cells(index, args.stage_points)
            call = (mid, c1, index.sorted_points, index.cell_keys, index.cell_start,
                    index.dims, radius)
            run(1, rad, mid, mid + 1, *call[2:])  # load or compile
            cpu = {0: [], 1: []}
            for _ in range(args.repeats):
                for mode in (0, 1):
                    c = time.process_time()
                    cand, found, nrs = run(mode, rad, *call)
                    cpu[mode].append(time.process_time() - c)
            row[name] = dict(points=npts, points_per_cell=npts / (c1 - mid),
                             neighbours_per_point=found / npts,
                             candidates_per_neighbour=cand / found,
                             column_ranges_per_point=nrs / npts,
                             ranges_cpu_ns_per_point=1e9 * min(cpu[0]) / npts,
                             search_cpu_ns_per_point=1e9 * min(cpu[1]) / npts)
            r = row[name]
            print(f"about {target} neighbours, {name}: {r['candidates_per_neighbour']:.2f} "
                  f"candidates a neighbour, ranges {r['ranges_cpu_ns_per_point']:.0f} ns, "
                  f"search {r['search_cpu_ns_per_point']:.0f} ns a point")
        out[str(target)] = row
    path = Path(args.out)
    res = json.loads(path.read_text()) if path.exists() else {}
    res["half_cells"] = dict(
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        machine_shared=bool(args.shared), cloud_points=int(xyz.shape[0]),
        repeats=args.repeats,
        how="single thread (NUMBA_NUM_THREADS=1), process CPU time, minimum of the "
            "repeats; the search (column ranges and the scan of every candidate, "
            "neighbours stored) of about --stage-points points of the middle of the cloud "
            "on CellIndex(xyz, radius) and CellIndex(xyz, radius / 2) with the same query "
            "radius; see the module docstring of benchmarks/curvature_floor.py",
        rows=out)
    path.write_text(json.dumps(res, indent=1) + "\n")


def stages(args):
    """``--stages``: single-thread CPU per neighbour and per point of the kernel's steps."""
    import numba

    from lidarstat.features import _quadric as quadric
    from lidarstat.neighbors import CellIndex

    xyz, _ = make_cloud(args.points)
    run = _stage_kernel()
    out = {}
    for target in args.neighbors:
        radius = float(calibrate_radius(xyz, target)[0])
        index = CellIndex(xyz, radius)
        mid, c1, npts = _middle_cells(index, args.stage_points)
        call = (mid, c1, index.sorted_points, index.cell_keys, index.cell_start, index.dims,
                radius)
        row = {}
        buffers = quadric._allocate(npts)

        def driver(c0, c1):
            quadric._run_cells(index, c0, c1, bandwidth=radius, frame="pca", sensor=None,
                               min_neighbors=7, covariance="sandwich", buffers=buffers)

        for k in range(len(STAGES) - 1):
            run(k, mid, mid + 1, *call[2:])  # load or compile
        driver(mid, mid + 1)
        cpu = {name: [] for name in STAGES}
        visits = 0
        for _ in range(args.repeats):  # alternating stages, minimum of the repeats
            for k, name in enumerate(STAGES):
                c = time.process_time()
                if name == "driver":
                    driver(mid, c1)
                else:
                    visits, _ = run(k, *call)
                cpu[name].append(time.process_time() - c)
        prev = 0.0
        for name in STAGES:
            t = min(cpu[name])
            row[name] = dict(cpu_ns_per_neighbour=1e9 * t / visits,
                             cpu_ns_per_point=1e9 * t / npts,
                             step_ns_per_point=1e9 * (t - prev) / npts, all_cpu=cpu[name])
            prev = t
        out[str(target)] = dict(radius=radius, points=npts, neighbour_visits=int(visits),
                                mean_neighbours=visits / npts, stages=row)
        print(f"about {target} neighbours ({visits / npts:.0f} per point, {npts} points):")
        for name, r in row.items():
            print(f"  {name:8s} {r['cpu_ns_per_neighbour']:6.1f} ns per neighbour, "
                  f"{r['cpu_ns_per_point']:7.0f} ns per point (step {r['step_ns_per_point']:6.0f})")
    path = Path(args.out)
    res = json.loads(path.read_text()) if path.exists() else {}
    res[args.key or "stages"] = dict(
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        machine_shared=bool(args.shared), threads=numba.config.NUMBA_NUM_THREADS,
        cloud_points=int(xyz.shape[0]), repeats=args.repeats,
        how="single thread (NUMBA_NUM_THREADS=1), process CPU time, minimum of the "
            "repeats, stages run alternately; each stage adds one step to the previous; "
            "see the module docstring of benchmarks/curvature_floor.py",
        rows=out)
    path.write_text(json.dumps(res, indent=1) + "\n")


def _driver_child(args):
    """``--child-driver``: CPU ns a point of the command's search and fit (the ``driver``
    stage) on one thread, minimum of --repeats, printed as JSON."""
    from lidarstat.features import _quadric as quadric
    from lidarstat.neighbors import CellIndex

    xyz, _ = make_cloud(args.points)
    radius = float(calibrate_radius(xyz, args.neighbors[0])[0])
    index = CellIndex(xyz, radius)
    mid = index.n_cells // 2
    c1 = int(np.searchsorted(index.cell_start, index.cell_start[mid] + args.stage_points))
    c1 = min(max(c1, mid + 1), index.n_cells)
    npts = int(index.cell_start[c1] - index.cell_start[mid])
    buffers = quadric._allocate(npts)

    def driver(c0, c1):
        quadric._run_cells(index, c0, c1, bandwidth=radius, frame="pca", sensor=None,
                           min_neighbors=7, covariance="sandwich", buffers=buffers)

    driver(mid, mid + 1)  # load or compile
    cpu = []
    for _ in range(args.repeats):
        c = time.process_time()
        driver(mid, c1)
        cpu.append(time.process_time() - c)
    print(json.dumps(dict(radius=radius, points=npts, cpu_ns_per_point=1e9 * min(cpu) / npts)))


def against(args):
    """``--against SRC``: the driver stage of SRC's package and of this one, alternating."""
    import subprocess
    import tempfile

    here = str(Path(__file__).resolve().parents[1] / "src")
    versions = {"against": args.against, "this": here}
    tmp = Path(tempfile.mkdtemp(prefix="curvature_floor_"))
    out = {}
    for target in args.neighbors:
        runs = {name: [] for name in versions}
        for k in range(args.rounds + 1):  # round 0 fills each version's cache
            for name, src in versions.items():
                env = dict(os.environ, PYTHONPATH=src, NUMBA_NUM_THREADS="1",
                           NUMBA_CACHE_DIR=str(tmp / name))
                r = subprocess.run(
                    [sys.executable, __file__, "--child-driver", "--points", str(args.points),
                     "--neighbors", str(target), "--repeats", str(args.repeats),
                     "--stage-points", str(args.stage_points)],
                    env=env, capture_output=True, text=True, check=True)
                if k:
                    runs[name].append(json.loads(r.stdout.strip().splitlines()[-1]))
        row = {name: dict(cpu_ns_per_point=float(np.median([r["cpu_ns_per_point"] for r in rs])),
                          all_cpu_ns_per_point=[r["cpu_ns_per_point"] for r in rs])
               for name, rs in runs.items()}
        row["radius"] = runs["this"][0]["radius"]
        row["points"] = runs["this"][0]["points"]
        row["ratio"] = row["this"]["cpu_ns_per_point"] / row["against"]["cpu_ns_per_point"]
        out[str(target)] = row
        print(f"about {target} neighbours: {row['against']['cpu_ns_per_point']:.0f} ns a "
              f"point ({args.against}), {row['this']['cpu_ns_per_point']:.0f} (this), "
              f"ratio {row['ratio']:.3f}")
    path = Path(args.out)
    res = json.loads(path.read_text()) if path.exists() else {}
    res[args.key or "driver_against"] = dict(
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        machine_shared=bool(args.shared), against=args.against, rounds=args.rounds,
        repeats=args.repeats, cloud_points=args.points,
        how="the driver stage (quadric._run_cells on the cells of the middle of the cloud, "
            "one thread, process CPU, minimum of the repeats) in child processes "
            "alternating between the two packages, median of the rounds; see the module "
            "docstring of benchmarks/curvature_floor.py",
        rows=out)
    path.write_text(json.dumps(res, indent=1) + "\n")


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
    ap.add_argument("--neighbors", type=int, nargs="+", default=[50])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--stages", action="store_true",
                    help="time the kernel's steps on one thread (stored under 'stages')")
    ap.add_argument("--half-cells", action="store_true",
                    help="time the search on cells of the radius and of half the radius "
                         "(stored under 'half_cells')")
    ap.add_argument("--stage-points", type=int, default=200_000,
                    help="with --stages, --half-cells: points of the middle of the cloud "
                         "to time")
    ap.add_argument("--shared", action="store_true",
                    help="record that other work ran on the machine meanwhile")
    ap.add_argument("--out", default=str(HERE / "results_curvature_floor.json"))
    ap.add_argument("--against", default=None, metavar="SRC",
                    help="compare the driver stage with the package at SRC, alternating")
    ap.add_argument("--rounds", type=int, default=3, help="with --against: rounds [3]")
    ap.add_argument("--key", default=None,
                    help="with --stages, --against: store under this key instead of "
                         "'stages' / 'driver_against'")
    ap.add_argument("--child-driver", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child_driver:
        return _driver_child(args)
    if args.against:
        return against(args)
    if args.stages:
        return stages(args)
    if args.half_cells:
        return half_cells(args)

    import numba

    from lidarstat.features import _quadric as quadric
    from lidarstat.neighbors import CellIndex
    from lidarstat.neighbors import _kernels as nk

    xyz, _ = make_cloud(args.points)
    radius = float(calibrate_radius(xyz, args.neighbors[0])[0])
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
    old = json.loads(Path(args.out).read_text()) if Path(args.out).exists() else {}
    if "stages" in old:
        res["stages"] = old["stages"]
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    for name, row in rows.items():
        print(f"{name:20s} {row['seconds']:6.2f} s  {row['cpu_seconds']:6.2f} s CPU  "
              f"{row['cpu_ns_per_neighbour']:5.1f} ns CPU per neighbour")


if __name__ == "__main__":
    main()
