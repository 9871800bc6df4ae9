#!/usr/bin/env python
"""Benchmark of lidarstat's curvature core against peers, on a synthetic airborne-like cloud.

Every measurement runs in a fresh subprocess (``--child`` mode of this script); the parent
collects wall time (measured inside the child, file IO excluded unless stated) and the peak
RSS of that child (``os.wait4`` rusage, per child). Numba kernels are compiled into a
benchmark-private cache (``NUMBA_CACHE_DIR`` in the temp dir): one cold run compiles them,
the timed runs then only load the cache.

Usage::

    python benchmarks/bench_curvature.py --points 2000000 --repeats 3 --out results.json
    python benchmarks/bench_curvature.py --points 200000 --skip-peers   # quick
    python benchmarks/bench_curvature.py --whole --out benchmarks/results_curvature_speed.json
    python benchmarks/bench_curvature.py --whole --out benchmarks/results_curvature_speed.json \
        --key NAME --before OLD/src      # one more run beside the file's others

``--whole`` measures the commands as a user runs them, start to exit (interpreter start,
imports, read, compute, write): ``lidarstat curvature IN.las OUT.las --radius R`` against
CloudCompare ``-O IN.ply -CURV MEAN R -SAVE_CLOUDS`` (its Debian build reads and writes no
LAS; both read and write an uncompressed binary file), alternating, median of
``--repeats``; the automatic scale (the command's default) in the same run; and the
profile of the lidarstat process, piece by piece (``--child profile``).

See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DENSITY = 20.0  # points per m^2 (planimetric)
NOISE = 0.02  # m, along z
TARGETS = (50, 300)  # median neighbours wanted


# --------------------------------------------------------------------------- synthetic cloud

def terrain(x, y):
    """Gentle relief: a sum of sines (a few metres over a few hundred metres)."""
    return (3.0 * np.sin(2 * np.pi * x / 180.0) + 2.0 * np.sin(2 * np.pi * y / 130.0)
            + 0.8 * np.sin(2 * np.pi * (x + y) / 60.0)
            + 0.3 * np.sin(2 * np.pi * x / 23.0) * np.cos(2 * np.pi * y / 31.0))


def make_cloud(n, seed=20261122):
    """Airborne-like cloud: uniform planimetric sampling of terrain + box buildings with
    gable roofs (roof points replace ground points inside footprints, plus sparse wall
    points), z noise N(0, NOISE^2). Deterministic in `seed`."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(n / DENSITY)
    n_wall = n // 100  # 1 % of the points on facades (oblique scan angles)
    m = n - n_wall
    x = rng.uniform(0, side, m)
    y = rng.uniform(0, side, m)
    z = terrain(x, y)
    nb = max(3, int(round(side * side / 8000.0)))  # ~ one building per 0.8 ha
    walls = []
    bld = []
    for _ in range(nb):
        cx, cy = rng.uniform(0.1 * side, 0.9 * side, 2)
        w, ln = rng.uniform(10, 22), rng.uniform(15, 40)  # width across ridge, length
        ang = rng.uniform(0, np.pi)
        eave = rng.uniform(5, 12)
        pitch = np.tan(np.radians(rng.uniform(25, 40)))
        base = terrain(cx, cy)
        bld.append((cx, cy, w, ln, ang, eave, pitch, base))
        c, s = np.cos(ang), np.sin(ang)
        u = (x - cx) * c + (y - cy) * s  # along ridge
        v = -(x - cx) * s + (y - cy) * c  # across ridge
        inside = (np.abs(u) <= ln / 2) & (np.abs(v) <= w / 2)
        roof = base + eave + (w / 2 - np.abs(v[inside])) * pitch
        z[inside] = np.maximum(z[inside], roof)
    # facade points: distributed over buildings by perimeter x eave height
    area = np.array([2 * (b[2] + b[3]) * b[5] for b in bld])
    per = rng.multinomial(n_wall, area / area.sum())
    for (cx, cy, w, ln, ang, eave, pitch, base), k in zip(bld, per):
        t = rng.uniform(0, 2 * (w + ln), k)
        h = rng.uniform(0, eave, k)
        u = np.where(t < ln, t - ln / 2, np.where(t < ln + w, ln / 2,
                     np.where(t < 2 * ln + w, ln / 2 - (t - ln - w), -ln / 2)))
        v = np.where(t < ln, -w / 2, np.where(t < ln + w, -w / 2 + (t - ln),
                     np.where(t < 2 * ln + w, w / 2, w / 2 - (t - 2 * ln - w))))
        c, s = np.cos(ang), np.sin(ang)
        walls.append(np.column_stack([cx + u * c - v * s, cy + u * s + v * c, base + h]))
    xyz = np.column_stack([x, y, z])
    if walls:
        xyz = np.vstack([xyz] + walls)
    xyz[:, 2] += rng.normal(0, NOISE, xyz.shape[0])
    xyz[:, :2] += (500000.0, 5000000.0)  # UTM-like magnitudes
    return xyz[rng.permutation(xyz.shape[0])], nb


def calibrate_radius(xyz, target, sample=20000, seed=1):
    """Radius whose median 3-D neighbour count (self included) is ~`target`."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    local = xyz - xyz.min(0)
    tree = cKDTree(local)
    q = local[rng.choice(local.shape[0], min(sample, local.shape[0]), replace=False)]
    r = np.sqrt(target / (DENSITY * np.pi))
    for _ in range(3):
        med = float(np.median(tree.query_ball_point(q, r, return_length=True, workers=-1)))
        r *= np.sqrt(target / med)
    med = float(np.median(tree.query_ball_point(q, r, return_length=True, workers=-1)))
    return float(r), med


# --------------------------------------------------------------------------- child modes

def _load(args):
    return np.load(args.data)


def child_lidarstat(args):
    from lidarstat.features import curvature

    pts = _load(args)
    t0 = time.perf_counter()
    res = curvature(pts, radius=args.radius, sigma=NOISE, alpha=0.05, test="calibrated",
                    frame="z")
    t = time.perf_counter() - t0
    nb = res["neighbors"]
    return dict(seconds=t, median_neighbors=float(np.median(nb)),
                mean_neighbors=float(nb.mean()), counts=res.counts())


def child_pieces(args):
    """The block loop of :func:`lidarstat.features.curvature`, timed piece by piece.

    index: CellIndex build; search+fit: the fused Numba kernel (neighbour gathering and
    quadric fit); statistics: noise model, curvature tests, HK types; reorder: back to
    input order. `csr_query` times, separately, building the same neighbourhoods as CSR
    arrays (what `radius_neighbors` returns), for comparison with scipy's pair query.
    """
    from lidarstat.features import curvature_tests, height_variance
    from lidarstat.features._quadric import _run_cells
    from lidarstat.neighbors import CellIndex

    pts = _load(args)
    r = args.radius
    tt = dict(index=0.0, search_fit=0.0, statistics=0.0, reorder=0.0)
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    index = CellIndex(pts, r)
    blocks = index.cell_blocks(131072)
    tt["index"] = time.perf_counter() - t0
    n = pts.shape[0]
    sorted_fields = None
    pairs = 0
    for c0, c1 in blocks:
        t0 = time.perf_counter()
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        out = _run_cells(index, c0, c1, bandwidth=r, frame="z", sensor=None, min_neighbors=7,
                         covariance="sandwich")
        t1 = time.perf_counter()
        sigma2 = height_variance(out["frames"], NOISE, noise="z")
        res = curvature_tests(out, sigma2=sigma2, alpha=0.05, test="calibrated")
        if sorted_fields is None:
            sorted_fields = {k: np.empty(n, dtype=v.dtype) for k, v in res.items()}
        for k, v in res.items():
            sorted_fields[k][s0:s1] = v
        t2 = time.perf_counter()
        tt["search_fit"] += t1 - t0
        tt["statistics"] += t2 - t1
        pairs += int(out["npts"].sum())
    t0 = time.perf_counter()
    inverse = np.empty_like(index.order)
    inverse[index.order] = np.arange(n)
    _ = {k: np.take(v, inverse) for k, v in sorted_fields.items()}
    tt["reorder"] = time.perf_counter() - t0
    tt["total"] = time.perf_counter() - t_all
    t0 = time.perf_counter()
    for c0, c1 in blocks:
        index.query_cells(c0, c1)
    tt["csr_query"] = time.perf_counter() - t0
    return dict(seconds=tt["total"], pieces=tt, blocks=len(blocks), pairs=pairs)


def child_scipy_pairs(args):
    from scipy.spatial import cKDTree

    pts = _load(args)
    pts = pts - pts.min(0)
    t0 = time.perf_counter()
    tree = cKDTree(pts)
    tb = time.perf_counter() - t0
    p = tree.query_pairs(args.radius, output_type="ndarray")
    t = time.perf_counter() - t0
    return dict(seconds=t, build=tb, pairs=int(p.shape[0]),
                note="single-threaded; unordered pairs i<j (half of the CSR entries, no self)")


def child_scipy_ball(args):
    from scipy.spatial import cKDTree

    pts = _load(args)
    pts = pts - pts.min(0)
    t0 = time.perf_counter()
    tree = cKDTree(pts)
    lists = tree.query_ball_point(pts, args.radius, workers=args.workers)
    t = time.perf_counter() - t0
    return dict(seconds=t, pairs=int(sum(map(len, lists))),
                note=f"query_ball_point, workers={args.workers}, python lists")


def child_scipy_knn(args):
    from scipy.spatial import cKDTree

    pts = _load(args)
    pts = pts - pts.min(0)
    t0 = time.perf_counter()
    tree = cKDTree(pts)
    d, i = tree.query(pts, k=args.k, workers=args.workers)
    t = time.perf_counter() - t0
    if args.save_knn:
        np.save(args.save_knn, i.astype(np.int32))
    return dict(seconds=t, note=f"k={args.k}, workers={args.workers}")


def child_pgeof(args):
    import pgeof

    pts = _load(args)
    xyz = np.ascontiguousarray(pts - pts.min(0), dtype=np.float32)
    knn = np.load(args.knn)  # (N, k) int32 from cKDTree (self included)
    n, k = knn.shape
    nn = np.ascontiguousarray(knn.ravel().astype(np.uint32))
    nn_ptr = (np.arange(n + 1) * k).astype(np.uint32)
    t0 = time.perf_counter()
    f = pgeof.compute_features(xyz, nn, nn_ptr)
    t = time.perf_counter() - t0
    return dict(seconds=t, note=f"pgeof.compute_features, k={k} neighbours given, "
                f"version {getattr(pgeof, '__version__', '?')}, out {np.shape(f)}")


def child_jakteristics(args):
    import jakteristics

    pts = _load(args)
    xyz = np.ascontiguousarray(pts - pts.min(0), dtype=np.float64)
    t0 = time.perf_counter()
    f = jakteristics.compute_features(xyz, search_radius=args.radius,
                                      feature_names=["surface_variation", "verticality",
                                                     "nx", "ny", "nz"], num_threads=-1)
    t = time.perf_counter() - t0
    return dict(seconds=t, note=f"radius search + covariance features, out {f.shape}")


def child_cgal(args):
    # cgal_monge.cpp at jet degree 2, Monge degree 2: the quadric's CGAL counterpart
    t, rc, out, mb = run_external([args.cgal_exe, args.xyzbin, args.knn, args.outbin, "2", "2"])
    if rc:
        raise RuntimeError(out)
    inner = json.loads([ln for ln in out.splitlines() if ln.startswith("{")][-1])
    return dict(seconds=inner["fit_seconds"], process_seconds=t, external_peak_rss_mb=mb, **{
        k: v for k, v in inner.items() if k != "fit_seconds"})


# --------------------------------------------------------------------------- whole process

#: The pieces of ``lidarstat curvature`` the profile times: (module, attribute, piece).
#: Wrapped in place, so the command runs its own code path.
PROFILE_PIECES = (
    ("lidarstat.io", "read", "read"),
    ("lidarstat.io", "write", "write"),
    ("lidarstat.io", "rewrite", "write"),
    ("lidarstat.features._curvature", "find_duplicates", "duplicates"),
    ("lidarstat.neighbors._query", "CellIndex.may_have_copies", "duplicates"),
    ("lidarstat.features._curvature", "CellIndex", "index"),
    ("lidarstat.features._curvature", "estimate_sigma_index", "sigma"),
    ("lidarstat.features._curvature", "_run_cells", "search_fit"),
    ("lidarstat.features._curvature", "fit_height_variance", "statistics"),
    ("lidarstat.features._curvature", "fit_variance_and_spread", "statistics"),
    ("lidarstat.features._curvature", "_block_fields", "statistics"),
    ("lidarstat.features._curvature", "_single_radius", "_single_radius"),
    ("lidarstat.features._curvature_result", "CurvatureResult.to_fields", "fields"),
)


def child_profile(args):
    """``lidarstat curvature`` through :func:`lidarstat.cli.main`, its pieces timed.

    Wall and CPU seconds of: imports (the command's modules and the parser), read,
    duplicates, index, sigma (the estimate), search_fit (the fused Numba kernel),
    statistics (noise model, tests, types), assembly (the blocks' fields into input order),
    fields, write; the parent adds the interpreter's start and exit (process wall minus the
    time measured inside).
    """
    import importlib

    t_in, c_in = time.perf_counter(), time.process_time()
    tt = {}

    def add(key, w, c):
        a = tt.setdefault(key, [0.0, 0.0])
        a[0] += w
        a[1] += c

    from lidarstat.cli import _app

    if hasattr(_app, "command_of"):
        _app.build_parser(_app.command_of(["curvature"]))
    else:  # a version that builds every command's parser (--before)
        _app.build_parser()
    import lidarstat.features  # noqa: F401
    import lidarstat.io  # noqa: F401

    for name in ("lidarstat.features._curvature", "lidarstat.io._las"):  # loaded on first use
        try:
            importlib.import_module(name)
        except ImportError:
            pass

    add("imports", time.perf_counter() - t_in, time.process_time() - c_in)

    def wrap(owner, name, key):
        f = getattr(owner, name)

        def timed(*a, **kw):
            w0, c0 = time.perf_counter(), time.process_time()
            try:
                return f(*a, **kw)
            finally:
                add(key, time.perf_counter() - w0, time.process_time() - c0)

        setattr(owner, name, timed)

    for where, name, key in PROFILE_PIECES:
        owner = importlib.import_module(where)
        *path, name = name.split(".")
        for part in path:
            owner = getattr(owner, part)
        if hasattr(owner, name):
            wrap(owner, name, key)
    argv = ["curvature", args.input, args.output, "-q"]
    if args.radius:
        argv += ["--radius", repr(args.radius)]
    w0, c0 = time.perf_counter(), time.process_time()
    rc = _app.main(argv)
    if rc:
        raise RuntimeError(f"lidarstat curvature failed ({rc})")
    add("main", time.perf_counter() - w0, time.process_time() - c0)
    single = tt.pop("_single_radius", [0.0, 0.0])
    inner = [tt.get(k, [0.0, 0.0]) for k in ("search_fit", "statistics")]
    tt["assembly"] = [single[j] - inner[0][j] - inner[1][j] for j in range(2)]
    inside = [time.perf_counter() - t_in, time.process_time() - c_in]
    main = tt.pop("main")
    named = ("read", "duplicates", "index", "sigma", "search_fit", "statistics", "assembly",
             "fields", "write")
    tt["other"] = [main[j] - sum(tt.get(k, [0.0, 0.0])[j] for k in named) for j in range(2)]
    return dict(seconds=inside[0], cpu_seconds=inside[1],
                pieces={k: v[0] for k, v in tt.items()},
                pieces_cpu={k: v[1] for k, v in tt.items()})


def whole_lidarstat(inp, out, radius, env):
    """``lidarstat curvature`` as a user runs it: wall, CPU and peak RSS of the process."""
    cmd = [sys.executable, "-m", "lidarstat.cli", "curvature", str(inp), str(out), "-q"]
    if radius is not None:
        cmd += ["--radius", repr(radius)]
    return run_external_cpu(cmd, env=env)


def whole_cloudcompare(exe, ply, out, radius):
    """CloudCompare: open the PLY, -CURV MEAN at `radius`, save the cloud (binary PLY)."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    cmd = [exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP", "-O", "-GLOBAL_SHIFT", "AUTO",
           str(ply), "-CURV", "MEAN", f"{radius:.6f}", "-C_EXPORT_FMT", "PLY", "-SAVE_CLOUDS",
           "FILE", str(out)]
    return run_external_cpu(cmd, env=env)


def run_external_cpu(cmd, env=None):
    """Wall seconds, CPU seconds (user + system, children included) and peak RSS (MB)."""
    log = tempfile.TemporaryFile()
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    log.seek(0)
    text = log.read().decode(errors="replace")
    if code != 0:
        raise RuntimeError(f"{Path(cmd[0]).name} failed ({code}): {text.strip()[-400:]}")
    return dict(seconds=wall, cpu_seconds=ru.ru_utime + ru.ru_stime,
                peak_rss_mb=ru.ru_maxrss / 1024.0)


def _median_run(runs):
    secs = [r["seconds"] for r in runs]
    return dict(seconds=float(np.median(secs)), all_seconds=secs,
                cpu_seconds=float(np.median([r["cpu_seconds"] for r in runs])),
                all_cpu_seconds=[r["cpu_seconds"] for r in runs],
                peak_rss_mb=max(r["peak_rss_mb"] for r in runs))


def main_whole(args):
    """The issue's table: lidarstat against CloudCompare, whole process, same run."""
    tmp = Path(args.tmp or tempfile.mkdtemp(prefix="lidarstat_whole_"))
    tmp.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=args.numba_cache or str(tmp / "numba_cache"))
    # an installed package has its bytecode compiled (pip does it at install): the runs
    # must not compile the package's Python sources at every start
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    import numba

    from lidarstat.io import PointCloud, write

    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    xyz, nbuild = make_cloud(args.points)
    las, ply = tmp / "cloud.las", tmp / "cloud.ply"
    write(las, PointCloud(xyz=xyz))
    write_ply(ply, xyz - np.floor(xyz.min(0)))
    res = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               machine=dict(platform=platform.platform(), cpu=_cpu_name(), cores=os.cpu_count(),
                            python=platform.python_version(), numpy=np.__version__,
                            numba=numba.__version__, git=_git_rev()),
               machine_shared=bool(args.shared),
               points=int(xyz.shape[0]), repeats=args.repeats,
               cloud=dict(density_per_m2=DENSITY, noise_sigma=NOISE, buildings=nbuild,
                          las_bytes=las.stat().st_size, ply_bytes=ply.stat().st_size),
               how=("whole process, start to exit, each run a fresh process; lidarstat reads "
                    "LAS and writes LAS (its 20 result fields as extra bytes), CloudCompare "
                    "reads binary PLY (x, y, z as doubles) and writes binary PLY (x, y, z and "
                    "the mean curvature as floats): its Debian build has no LAS plug-in; "
                    "runs alternate lidarstat / CloudCompare; medians; cpu_seconds = user + "
                    "system of the process; Python bytecode cached, as installed"),
               rows={}, profile={}, skipped={})
    if exe is None:
        res["skipped"]["cloudcompare"] = "not installed (apt-get install -y cloudcompare)"
    print(f"work dir {tmp}; {xyz.shape[0]} points")
    warm = tmp / "warm.las"  # a small piece on which the first runs compile the kernels
    write(warm, PointCloud(xyz=xyz[xyz[:, 0] < xyz[:, 0].min() + 0.01 * np.ptp(xyz[:, 0])]))
    whole_lidarstat(warm, tmp / "warm_out.las", calibrate_radius(xyz, 50)[0], env)
    old_env = None
    if args.before:  # another version of the package, run alternately with this one
        old_env = dict(env, PYTHONPATH=args.before,
                       NUMBA_CACHE_DIR=str(tmp / "numba_cache_before"))
        whole_lidarstat(warm, tmp / "warm_out.las", calibrate_radius(xyz, 50)[0], old_env)
    for tgt in (() if args.skip_fixed else args.targets):
        r, med = calibrate_radius(xyz, tgt)
        ls_runs, cc_runs, old_runs = [], [], []
        for _ in range(args.repeats):
            ls_runs.append(whole_lidarstat(las, tmp / "out.las", r, env))
            if old_env is not None:
                old_runs.append(whole_lidarstat(las, tmp / "out_before.las", r, old_env))
            if exe:
                cc_runs.append(whole_cloudcompare(exe, ply, tmp / "cc_out.ply", r))
        row = dict(radius=r, median_neighbors_sample=med, lidarstat=_median_run(ls_runs))
        if old_runs:
            row["lidarstat_before"] = dict(_median_run(old_runs), version=args.before)
            row["same_output_as_before"] = _same_bytes(tmp / "out.las", tmp / "out_before.las")
        if cc_runs:
            row["cloudcompare"] = _median_run(cc_runs)
            row["ratio"] = row["lidarstat"]["seconds"] / row["cloudcompare"]["seconds"]
            row["ratio_cpu"] = row["lidarstat"]["cpu_seconds"] / row["cloudcompare"]["cpu_seconds"]
        res["rows"][str(tgt)] = row
        prof = run_child("profile", env, input=las, output=tmp / "prof.las", radius=r)
        prof["start_exit"] = prof["process_wall"] - prof["seconds"]
        res["profile"][str(tgt)] = prof
        if old_env is not None:
            # the same profile of the other version of the package, in the same run
            prof = run_child("profile", old_env, input=las, output=tmp / "prof.las", radius=r)
            prof["start_exit"] = prof["process_wall"] - prof["seconds"]
            prof["version"] = args.before
            res.setdefault("profile_before", {})[str(tgt)] = prof
        _print_row(tgt, row)
    if args.auto:
        runs = [whole_lidarstat(las, tmp / "auto.las", None, env) for _ in range(args.auto)]
        res["rows"]["auto"] = dict(lidarstat=_median_run(runs), note=(
            "the automatic scale, the command's default (no --radius): five rungs of 3 to "
            "12 point spacings, the points that do not stop early fitted at each"))
        _print_row("auto", res["rows"]["auto"])
    if args.key:  # one run among others in the same file
        out = Path(args.out)
        whole = json.loads(out.read_text()) if out.exists() else {}
        whole[args.key] = res
        out.write_text(json.dumps(whole, indent=1, default=str))
    else:
        Path(args.out).write_text(json.dumps(res, indent=1, default=str))
    print_whole(res)
    print(f"wrote {args.out}" + (f" (key {args.key})" if args.key else ""))


def _same_bytes(a, b):
    """Whether files `a` and `b` hold the same bytes."""
    with open(a, "rb") as fa, open(b, "rb") as fb:
        while True:
            x, y = fa.read(1 << 24), fb.read(1 << 24)
            if x != y:
                return False
            if not x:
                return True


def _print_row(tgt, row):
    ls = row["lidarstat"]
    cc = row.get("cloudcompare")
    text = f"  {tgt}: lidarstat {ls['seconds']:.2f} s (cpu {ls['cpu_seconds']:.2f} s)"
    if "lidarstat_before" in row:
        old = row["lidarstat_before"]
        text += (f", before {old['seconds']:.2f} s (cpu {old['cpu_seconds']:.2f} s, same "
                 f"output: {row['same_output_as_before']})")
    if cc:
        text += (f", CloudCompare {cc['seconds']:.2f} s (cpu {cc['cpu_seconds']:.2f} s), "
                 f"ratio {row['ratio']:.2f} (cpu {row['ratio_cpu']:.2f})")
    print(text, flush=True)


def print_whole(res):
    print(f"\n{res['points']} points, whole process, median of {res['repeats']}, "
          f"{res['machine']['cores']} cores{' (shared)' if res['machine_shared'] else ''}")
    print(f"{'neighbours':<12s} {'lidarstat s':>12s} {'CloudCompare s':>15s} {'ratio':>6s} "
          f"{'cpu ratio':>9s}")
    for tgt, row in res["rows"].items():
        cc = row.get("cloudcompare", {})
        print(f"{tgt:<12s} {row['lidarstat']['seconds']:12.2f} "
              f"{cc.get('seconds', float('nan')):15.2f} {row.get('ratio', float('nan')):6.2f} "
              f"{row.get('ratio_cpu', float('nan')):9.2f}")
    for tgt, prof in [(t, p) for t, p in res["profile"].items()] + [
            (f"{t} (before)", p) for t, p in res.get("profile_before", {}).items()]:
        print(f"profile, about {tgt} neighbours (wall s / cpu s): start+exit "
              f"{prof['start_exit']:.2f}; " + ", ".join(
                  f"{k} {v:.2f}/{prof['pieces_cpu'][k]:.2f}" for k, v in prof["pieces"].items()))


CHILDREN = dict(profile=child_profile, lidarstat=child_lidarstat, pieces=child_pieces, scipy_pairs=child_scipy_pairs,
                scipy_ball=child_scipy_ball, scipy_knn=child_scipy_knn, pgeof=child_pgeof,
                jakteristics=child_jakteristics, cgal=child_cgal)


# --------------------------------------------------------------------------- parent helpers

def run_child(mode, env, **kw):
    """Run this script in `mode` in a fresh process; returns its JSON plus peak RSS (MB)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", mode]
    for k, v in kw.items():
        cmd += [f"--{k.replace('_', '-')}", str(v)]
    out = tempfile.NamedTemporaryFile("w+", suffix=".json", delete=False)
    out.close()
    cmd += ["--child-out", out.name]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env)
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"child {mode} failed with code {p.returncode}")
    res = json.loads(Path(out.name).read_text())
    os.unlink(out.name)
    # ru_maxrss of a child spawned by (v)fork+exec is floored at the parent's RSS at the
    # time, so the child reports its own VmHWM; external programs are measured with
    # GNU time (inside the child) where available.
    res["wait4_maxrss_mb"] = ru.ru_maxrss / 1024.0
    res["peak_rss_mb"] = res.get("external_peak_rss_mb", res.get("vmhwm_mb"))
    res["process_wall"] = wall
    return res


def run_repeats(mode, repeats, env, **kw):
    runs = [run_child(mode, env, **kw) for _ in range(repeats)]
    secs = [r["seconds"] for r in runs]
    best = dict(runs[int(np.argsort(secs)[len(secs) // 2])])
    best["seconds"] = float(np.median(secs))
    best["all_seconds"] = secs
    best["peak_rss_mb"] = max(r["peak_rss_mb"] for r in runs)
    return best


def run_external(cmd, env=None, timeout=None):
    """Wall time, return code, output and peak RSS (MB, process tree) of an external command."""
    log = tempfile.TemporaryFile()
    gtime = shutil.which("time") or ("/usr/bin/time" if Path("/usr/bin/time").exists() else None)
    if gtime:
        cmd = [gtime, "-f", "MAXRSS_KB %M"] + list(cmd)
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        _, status, ru = os.wait4(p.pid, 0)
    except BaseException:
        p.kill()
        raise
    p.returncode = os.waitstatus_to_exitcode(status)
    t = time.perf_counter() - t0
    log.seek(0)
    out = log.read().decode(errors="replace")
    mb = float("nan")
    for line in out.splitlines():
        if line.startswith("MAXRSS_KB "):
            mb = int(line.split()[1]) / 1024.0
    return t, p.returncode, out, mb


def write_ply(path, xyz):
    """Binary little-endian PLY with double x, y, z (for CloudCompare)."""
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {xyz.shape[0]}\n"
                 "property double x\nproperty double y\nproperty double z\nend_header\n").encode())
        f.write(np.ascontiguousarray(xyz, dtype="<f8").tobytes())


# --------------------------------------------------------------------------- peers

def peer_cloudcompare(results, tmp, las, xyz, radii, repeats):
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    xvfb = shutil.which("xvfb-run")
    if exe is None:
        print("[skip] CloudCompare: not installed (apt-get install -y cloudcompare xvfb)")
        return
    if xvfb is None:
        print("[skip] CloudCompare: xvfb-run missing (apt-get install -y xvfb)")
        return
    base = [xvfb, "-a", exe, "-SILENT", "-AUTO_SAVE", "OFF", "-NO_TIMESTAMP"]
    # input format: LAS if this CloudCompare build reads it, else binary PLY
    src = None
    for cand in (str(las), None):
        if cand is None:
            ply = Path(tmp) / "cloud.ply"
            if not ply.exists():
                write_ply(ply, xyz - np.floor(xyz.min(0)))
            cand = str(ply)
        t, rc, out, _ = run_external(base + ["-O", "-GLOBAL_SHIFT", "AUTO", cand], timeout=900)
        if rc == 0 and "error" not in out.lower() and "unhandled" not in out.lower():
            src = cand
            load_t = t
            break
        print(f"[info] CloudCompare cannot open {cand} (rc {rc}): {out.strip()[-300:]}")
    if src is None:
        print("[skip] CloudCompare: could not open the cloud in any format")
        return
    loads = [load_t] + [run_external(base + ["-O", "-GLOBAL_SHIFT", "AUTO", src])[0]
                        for _ in range(max(0, repeats - 1))]
    load = float(np.median(loads))
    results["peers"]["cloudcompare_load_only"] = dict(
        seconds=load, all_seconds=loads, note=f"process: xvfb-run + load {Path(src).name}, nothing else")
    for target, r in radii.items():
        times, rss = [], []
        for _ in range(repeats):
            t, rc, out, mb = run_external(base + ["-O", "-GLOBAL_SHIFT", "AUTO", src, "-CURV", "MEAN",
                                                 f"{r:.6f}"], timeout=3600)
            if rc != 0:
                print(f"[skip] CloudCompare -CURV failed (rc {rc}): {out.strip()[-500:]}")
                return
            times.append(t)
            rss.append(mb)
        med = float(np.median(times))
        results["peers"][f"cloudcompare_curv_mean_{target}"] = dict(
            seconds=med, all_seconds=times, seconds_minus_load=med - load, radius=r,
            peak_rss_mb=max(rss),
            note="whole process (xvfb + load + -CURV MEAN, no save); seconds_minus_load is "
                 "the curvature step")
        print(f"  CloudCompare -CURV MEAN r={r:.3f}: {med:.2f} s (minus load {med - load:.2f} s)")


def build_cgal(tmp):
    cxx = shutil.which("g++")
    if cxx is None:
        return None, "g++ not installed"
    if not Path("/usr/include/CGAL/Monge_via_jet_fitting.h").exists():
        return None, "CGAL headers missing (apt-get install -y libcgal-dev libeigen3-dev)"
    exe = Path(tmp) / "cgal_monge"
    cmd = [cxx, "-O3", "-DNDEBUG", "-fopenmp", "-std=c++17", "-I/usr/include/eigen3",
           str(HERE / "cgal_monge.cpp"), "-o", str(exe)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode:
        return None, "compile failed: " + p.stderr[-800:]
    return exe, None


# --------------------------------------------------------------------------- main

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="results.json")
    ap.add_argument("--skip-peers", action="store_true")
    ap.add_argument("--skip-300", action="store_true", help="only the ~50-neighbour radius")
    ap.add_argument("--tmp", default=None, help="work directory (default: a new temp dir)")
    ap.add_argument("--whole", action="store_true",
                    help="whole-process comparison with CloudCompare and the profile")
    ap.add_argument("--auto", type=int, default=1,
                    help="with --whole: runs of the automatic scale (0: none) [1]")
    ap.add_argument("--skip-fixed", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--targets", type=int, nargs="+", default=list(TARGETS),
                    help="with --whole: median neighbour counts to compare at [50 300]")
    ap.add_argument("--shared", action="store_true",
                    help="record that other work ran on the machine meanwhile")
    ap.add_argument("--before", default=None, metavar="SRC",
                    help="with --whole: also run and profile the package found at SRC (a "
                    "PYTHONPATH, e.g. the src folder of an earlier checkout) in the same run, "
                    "alternately with this one, and compare the two outputs byte by byte")
    ap.add_argument("--key", default=None,
                    help="with --whole: store the run under this key of --out, keeping the "
                    "file's other keys")
    ap.add_argument("--numba-cache", default=None, metavar="DIR",
                    help="with --whole: Numba cache folder (default: one in the work folder)")
    ap.add_argument("--input", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--output", default=None, help=argparse.SUPPRESS)
    # child-mode options
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--data", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--radius", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--k", type=int, default=50, help=argparse.SUPPRESS)
    ap.add_argument("--workers", type=int, default=-1, help=argparse.SUPPRESS)
    ap.add_argument("--save-knn", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--knn", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--xyzbin", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--outbin", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--cgal-exe", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.child:
        res = CHILDREN[args.child](args)
        res["vmhwm_mb"] = _vmhwm_mb()
        Path(args.child_out).write_text(json.dumps(res))
        return
    if args.whole:
        return main_whole(args)

    tmp = Path(args.tmp or tempfile.mkdtemp(prefix="lidarstat_bench_"))
    tmp.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba_cache"))
    import numba
    import scipy

    import lidarstat

    results = dict(
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        machine=dict(platform=platform.platform(), cpu=_cpu_name(), cores=os.cpu_count(),
                     python=platform.python_version(), numpy=np.__version__,
                     scipy=scipy.__version__, numba=numba.__version__,
                     numba_threads=numba.config.NUMBA_NUM_THREADS,
                     lidarstat=getattr(lidarstat, "__version__", "?"), git=_git_rev()),
        points=None, lidarstat={}, peers={}, skipped={})

    print(f"work dir {tmp}")
    t0 = time.perf_counter()
    xyz, nbuild = make_cloud(args.points)
    results["points"] = int(xyz.shape[0])
    results["cloud"] = dict(density_per_m2=DENSITY, noise_sigma=NOISE, buildings=nbuild,
                            generate_seconds=time.perf_counter() - t0)
    data = tmp / "cloud.npy"
    np.save(data, xyz)
    from lidarstat.io import PointCloud, write

    las = tmp / "cloud.las"
    t0 = time.perf_counter()
    write(las, PointCloud(xyz=xyz))
    results["cloud"]["las_write_seconds"] = time.perf_counter() - t0
    targets = TARGETS[:1] if args.skip_300 else TARGETS
    radii = {}
    for tgt in targets:
        r, med = calibrate_radius(xyz, tgt)
        radii[tgt] = r
        results["cloud"][f"radius_{tgt}"] = r
        results["cloud"][f"median_neighbors_sample_{tgt}"] = med
        print(f"target {tgt} neighbours: radius {r:.4f} m, sample median {med:.0f}")

    # --- lidarstat: cold (compile into the private cache), then warm repeats
    r50 = radii[50]
    print("lidarstat cold run (numba compile) ...", flush=True)
    cold = run_child("lidarstat", env, data=data, radius=r50)
    results["lidarstat"]["cold_50"] = cold
    print(f"  cold: {cold['seconds']:.2f} s (process {cold['process_wall']:.2f} s)")
    for tgt, r in radii.items():
        res = run_repeats("lidarstat", args.repeats, env, data=data, radius=r)
        res["radius"] = r
        res["points_per_second"] = results["points"] / res["seconds"]
        results["lidarstat"][f"curvature_{tgt}"] = res
        print(f"  curvature ~{tgt} nbrs (r={r:.3f}): {res['seconds']:.2f} s, "
              f"{res['points_per_second']:.0f} pts/s, median nbrs {res['median_neighbors']:.0f}, "
              f"peak RSS {res['peak_rss_mb']:.0f} MB", flush=True)
        pc = run_repeats("pieces", args.repeats, env, data=data, radius=r)
        results["lidarstat"][f"pieces_{tgt}"] = pc
        print("  pieces: " + ", ".join(f"{k} {v:.2f} s" for k, v in pc["pieces"].items()),
              flush=True)
    # baseline RSS: python + imports + the cloud, no work
    results["lidarstat"]["baseline_rss_note"] = "peak RSS includes the interpreter, NumPy/SciPy/Numba imports and the input array (48 MB at 2M points)"

    if not args.skip_peers:
        run_peers(results, tmp, env, data, las, xyz, radii, args.repeats)

    ref = results["lidarstat"]["curvature_50"]["seconds"]
    ref300 = results["lidarstat"].get("curvature_300", {}).get("seconds")
    for name, m in list(results["lidarstat"].items()) + list(results["peers"].items()):
        if not isinstance(m, dict) or "seconds" not in m:
            continue
        m["points_per_second"] = results["points"] / m["seconds"]
        use = ref300 if ("300" in name and ref300) else ref
        m["ratio_to_lidarstat"] = m["seconds"] / use
    Path(args.out).write_text(json.dumps(results, indent=1, default=str))
    print_table(results)
    print(f"wrote {args.out}")


def run_peers(results, tmp, env, data, las, xyz, radii, repeats):
    sk = results["skipped"]
    # (b) scipy anchors
    for tgt, r in radii.items():
        try:
            res = run_repeats("scipy_pairs", repeats, env, data=data, radius=r)
            results["peers"][f"scipy_query_pairs_{tgt}"] = res
            print(f"  scipy query_pairs r={r:.3f}: {res['seconds']:.2f} s", flush=True)
        except Exception as e:  # noqa: BLE001
            sk[f"scipy_query_pairs_{tgt}"] = str(e)
            print(f"[skip] scipy query_pairs: {e}")
    knn = tmp / "knn50.npy"
    for w in (1, -1):
        res = run_repeats("scipy_knn", repeats, env, data=data, k=50, workers=w,
                          save_knn=knn)
        results["peers"][f"scipy_knn50_workers{w}"] = res
        print(f"  scipy query k=50 workers={w}: {res['seconds']:.2f} s", flush=True)
    # (c) pgeof, jakteristics
    for name, kw in (("pgeof", dict(knn=knn)), ("jakteristics", dict(radius=radii[50]))):
        try:
            __import__(name)
        except ImportError as e:
            sk[name] = f"not installed ({e}); pip install {name}"
            print(f"[skip] {name}: not installed")
            continue
        try:
            res = run_repeats(name, repeats, env, data=data, **kw)
            results["peers"][f"{name}_50"] = res
            print(f"  {name}: {res['seconds']:.2f} s", flush=True)
        except Exception as e:  # noqa: BLE001
            sk[name] = str(e)
            print(f"[skip] {name}: {e}")
    # (d) CGAL jet fitting, neighbours from cKDTree k=50
    exe, why = build_cgal(tmp)
    if exe is None:
        sk["cgal"] = why
        print(f"[skip] CGAL: {why}")
    else:
        xyzbin = tmp / "xyz.bin"
        np.ascontiguousarray(xyz - xyz.min(0), dtype="<f8").tofile(xyzbin)
        k = np.load(knn)
        knnbin = tmp / "knn50.bin"
        k.astype("<i4").tofile(knnbin)
        try:
            res = run_repeats("cgal", repeats, env, cgal_exe=exe, xyzbin=xyzbin, knn=knnbin,
                              outbin=tmp / "cgal_out.bin")
            results["peers"]["cgal_jet_deg2_knn50"] = res
            print(f"  CGAL jet fitting: {res['seconds']:.2f} s", flush=True)
        except Exception as e:  # noqa: BLE001
            sk["cgal"] = str(e)
            print(f"[skip] CGAL: {e}")
    # (a) CloudCompare
    try:
        peer_cloudcompare(results, tmp, las, xyz, radii, repeats)
    except Exception as e:  # noqa: BLE001
        sk["cloudcompare"] = str(e)
        print(f"[skip] CloudCompare: {e}")


def print_table(results):
    n = results["points"]
    print(f"\n{n} points, {results['machine']['cores']} cores, {results['date']}")
    print(f"{'measurement':<36s} {'seconds':>9s} {'points/s':>11s} {'ratio':>7s} {'peak RSS MB':>11s}")
    rows = [(f"lidarstat {k}", v) for k, v in results["lidarstat"].items() if isinstance(v, dict)]
    rows += list(results["peers"].items())
    for name, m in rows:
        if "seconds" not in m:
            continue
        rss = m.get("peak_rss_mb")
        print(f"{name:<36s} {m['seconds']:9.2f} {n / m['seconds']:11.0f} "
              f"{m.get('ratio_to_lidarstat', float('nan')):7.2f} "
              f"{'' if rss is None else f'{rss:11.0f}'}")
        if "pieces" in m:
            for k, v in m["pieces"].items():
                print(f"    {k:<32s} {v:9.2f}")
    for k, v in results["skipped"].items():
        print(f"skipped {k}: {v}")


def _vmhwm_mb():
    """Peak resident set of this process (VmHWM, Linux), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _cpu_name():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _git_rev():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True,
                              text=True).stdout.strip()
    except OSError:
        return "?"


if __name__ == "__main__":
    main()
