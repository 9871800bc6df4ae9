"""Hostile-user run: every command on bad, degenerate and hostile inputs, bad option values
and dangerous output paths, each in its own process with a time and memory limit.

Every case is classified by what a user would see:

- ``traceback``: a Python traceback on stderr;
- ``abort``: the process died from a signal (e.g. an allocation abort, exit 134);
- ``timeout``: still running after ``--timeout`` seconds;
- ``exit0_on_nonsense``: a case that must be refused exited 0;
- ``input_modified``: an input file's bytes changed;
- ``partial_output``: a refused run left a file (or a temporary) in the output folder;
- ``unclear``: the error is not one line naming the file or the option as typed;
- ``ok``: none of the above.

Usage::

    python benchmarks/robustness.py [--timeout 120] [--memory-gb 8] [--out results.json]

Writes ``benchmarks/results_robustness.json`` (counts and every case's outcome).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np

HERE = Path(__file__).resolve().parent


# --------------------------------------------------------------------------- corpus
def _las(path, xyz, *, version="1.2", point_format=1, scale=0.001):
    header = laspy.LasHeader(point_format=point_format, version=version)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    header.offsets = np.floor(xyz.min(axis=0)) if len(xyz) else np.zeros(3)
    header.scales = np.full(3, scale)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if len(xyz):
        las.intensity = np.arange(len(xyz)) % 200
    las.write(str(path))
    return path


def _patch(path, offset, fmt, value, out):
    data = bytearray(Path(path).read_bytes())
    struct.pack_into(fmt, data, offset, value)
    Path(out).write_bytes(bytes(data))
    return out


def build_corpus(d: Path, rng) -> dict[str, tuple[Path, str]]:
    """name -> (file, expectation): 'refuse' must fail cleanly, 'either' may also succeed."""
    c = {}
    surf = rng.uniform(0, 10, (6000, 2))
    z = 0.05 * np.sin(surf[:, 0]) + rng.normal(0, 0.002, len(surf))
    valid = _las(d / "valid.las", np.c_[surf, z])
    c["valid"] = (valid, "either")
    _las(d / "valid14.laz", np.c_[surf, z], version="1.4", point_format=6)
    c["valid_laz"] = (d / "valid14.laz", "either")
    (d / "empty.las").write_bytes(b"")
    c["empty_file"] = (d / "empty.las", "refuse")
    c["zero_points"] = (_las(d / "zero.las", np.empty((0, 3))), "refuse")
    for n in (1, 2, 3):
        c[f"{n}_points"] = (_las(d / f"p{n}.las", rng.uniform(0, 1, (n, 3))), "either")
    c["duplicates_100k"] = (_las(d / "dup.las", np.tile([[5.0, 5.0, 1.0]], (100_000, 1))),
                            "either")
    t = np.linspace(0, 10, 2000)
    c["collinear"] = (_las(d / "line.las", np.c_[t, 2 * t, 0.5 * t]), "either")
    g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2) * 0.5
    c["perfect_grid"] = (_las(d / "grid.las", np.c_[g, np.zeros(len(g))]), "either")
    half = np.c_[surf[:3000], z[:3000]]
    c["half_duplicates"] = (_las(d / "half.las", np.vstack([half, half])), "either")
    for name, txt in {"nan_csv": "x,y,z\n1,2,3\nnan,1,1\n4,5,6\n",
                      "inf_csv": "x,y,z\n1,2,3\ninf,1,1\n4,5,6\n",
                      "huge_csv": "x,y,z\n1,2,3\n1.5e308,1,1\n4,5,6\n",
                      "text_csv": "x,y,z\na,b,c\n",
                      "ragged_csv": "x,y,z\n1,2\n3,4,5,6\n"}.items():
        (d / f"{name}.csv").write_text(txt)
        c[name] = (d / f"{name}.csv", "refuse")
    np.savez(d / "huge.npz", xyz=np.array([[1.0, 2, 3], [1.5e308, 1, 1], [4, 5, 6]]))
    c["huge_npz"] = (d / "huge.npz", "refuse")
    np.savez(d / "strings.npz", xyz=np.array([["a", "b", "c"]] * 3))
    c["strings_npz"] = (d / "strings.npz", "refuse")
    (d / "text.las").write_text("this is not a LAS file\n" * 20)
    c["text_as_las"] = (d / "text.las", "refuse")
    raw = valid.read_bytes()
    (d / "trunc.las").write_bytes(raw[: len(raw) // 2])
    c["truncated_las"] = (d / "trunc.las", "refuse")
    lz = (d / "valid14.laz").read_bytes()
    (d / "trunc.laz").write_bytes(lz[: len(lz) // 2])
    c["truncated_laz"] = (d / "trunc.laz", "refuse")
    (d / "folder.las").mkdir()
    c["directory"] = (d / "folder.las", "refuse")
    c["missing"] = (d / "missing.las", "refuse")
    (d / "cloud.xyzq").write_text("1 2 3\n")
    c["unknown_suffix"] = (d / "cloud.xyzq", "refuse")
    # LAS 1.2 header fields (public header block offsets)
    for name, off, fmt, val in [("scale_zero", 131, "<d", 0.0), ("scale_nan", 131, "<d", np.nan),
                                ("scale_1e306", 131, "<d", 1e306), ("offset_inf", 155, "<d", np.inf),
                                ("count_too_large", 107, "<I", 10_000_000),
                                ("vlr_count_huge", 100, "<I", 4_000_000_000),
                                ("data_offset_past_end", 96, "<I", 4_000_000_000),
                                ("record_length_zero", 105, "<H", 0)]:
        c[name] = (_patch(valid, off, fmt, val, d / f"{name}.las"), "refuse")
    # LAZ: the chunk-table pointer is the first 8 bytes of the point data
    off = struct.unpack_from("<I", lz, 96)[0]
    for name, val in [("laz_chunk_table_past_end", 2**40), ("laz_chunk_table_negative", -5),
                      ("laz_chunk_table_inside_header", 10)]:
        c[name] = (_patch(d / "valid14.laz", off, "<q", val, d / f"{name}.laz"), "refuse")
    return c


# --------------------------------------------------------------------------- cases
def command_cases(corpus, d: Path):
    """(name, argv, inputs, expectation, option_or_None) for every command on every input."""
    cmds = {
        "info": lambda i, o: ["info", i],
        "curvature": lambda i, o: ["curvature", i, o, "--radius", "0.5"],
        "curvature_tile": lambda i, o: ["curvature", i, o, "--radius", "0.5", "--tile", "5"],
        "covariance": lambda i, o: ["covariance", i, o, "--k", "20"],
        "moments": lambda i, o: ["moments", i, o, "--no-report"],
        "segment_curvature": lambda i, o: ["segment", i, o, "--method", "curvature",
                                           "--radius", "0.5"],
        "segment_covariance": lambda i, o: ["segment", i, o, "--method", "covariance"],
        "segment_sar": lambda i, o: ["segment", i, o, "--method", "sar"],
        "ridges": lambda i, o: ["ridges", i, o, "--k", "30"],
    }
    for cname, build in cmds.items():
        for iname, (path, expect) in corpus.items():
            out = d / "out" / f"{cname}_{iname}.las"
            if cname == "info" and iname == "zero_points":
                expect = "either"  # describing an empty file is an answer, not nonsense
            yield (f"{cname}/{iname}", build(str(path), str(out)), [path], expect, None)


def option_cases(valid, d: Path):
    out = str(d / "out" / "opt.las")
    v = str(valid)
    bad = [
        (["moments", v, out, "--iterations", "-1"], "--iterations"),
        (["covariance", v, out, "--k", "0"], "--k"),
        (["segment", v, out, "--method", "covariance", "--k", "0"], "--k"),
        (["curvature", v, out, "--radius", "0.5", "--tile", "20", "--workers", "0"], "--workers"),
        (["curvature", v, out, "--radius", "0.5", "--tile", "20", "--workers", "-1"], "--workers"),
        (["curvature", v, out, "--radius", "-1"], "--radius"),
        (["curvature", v, out, "--radius", "nan"], "--radius"),
        (["curvature", v, out, "--radius", "0.5", "--alpha", "1.5"], "--alpha"),
        (["curvature", v, out, "--radius", "0.5", "--sigma", "inf"], "--sigma"),
        (["curvature", v, out, "--radius", "0.5", "--tile", "0"], "--tile"),
        (["evaluate", v, "--reference", v, "--ground-codes", "abc"], "--ground-codes"),
        (["evaluate", v, "--reference", v, "--ground-codes", ""], "--ground-codes"),
        (["bandwidth", "--K0", "0", "--H0", "-0.45", "--sigma", "0.015", "--density", "inf"],
         "--density"),
        (["segment", v, out, "--method", "covariance", "--normal-angle", "nan"], "--normal-angle"),
        (["segment", v, out, "--method", "covariance", "--normal-angle", "-1"], "--normal-angle"),
        (["segment", v, out, "--method", "covariance", "--normal-angle", "720"], "--normal-angle"),
        (["segment", v, out, "--method", "covariance", "--min-size", "-1"], "--min-size"),
        (["segment", v, out, "--method", "sar", "--sar-degree", "0"], "--sar-degree"),
        (["segment", v, out, "--method", "sar", "--sar-degree", "7"], "--sar-degree"),
        (["segment", v, out, "--method", "sar", "--fs-block", "0"], "--fs-block"),
        (["segment", v, out, "--method", "sar", "--fs-block", "-1"], "--fs-block"),
        (["moments", v, out, "--window", "-5"], "--window"),
        (["moments", v, out, "--alpha", "0"], "--alpha"),
        (["ridges", v, out, "--k", "-3"], "--k"),
    ]
    for i, (argv, opt) in enumerate(bad):
        yield (f"option/{argv[0]}{opt}={argv[argv.index(opt) + 1] if opt in argv else ''}#{i}",
               argv, [valid], "refuse", opt)


def output_cases(valid, d: Path):
    """Side outputs aimed at the input, a symlink or a hard link of it, or a missing folder."""
    v = str(valid)
    link = d / "link.las"
    hard = d / "hard.las"
    if not link.exists():
        link.symlink_to(valid)
        os.link(valid, hard)
    out = str(d / "out" / "o.las")
    for target, how in ((v, "same"), (str(link), "symlink"), (str(hard), "hardlink")):
        yield (f"output/covariance --summary-json {how}", ["covariance", v, out, "--k", "20",
               "--summary-json", target], [valid], "refuse", "--summary-json")
        yield (f"output/curvature --summary-json {how}", ["curvature", v, out, "--radius", "0.5",
               "--summary-json", target], [valid], "refuse", "--summary-json")
        yield (f"output/segment --table {how}", ["segment", v, out, "--method", "curvature",
               "--radius", "0.5", "--table", target], [valid], "refuse", "--table")
        yield (f"output/segment --lines {how}", ["segment", v, out, "--method", "curvature",
               "--radius", "0.5", "--lines", target], [valid], "refuse", "--lines")
        yield (f"output/ridges --lines {how}", ["ridges", v, out, "--k", "30", "--lines", target],
               [valid], "refuse", "--lines")
        yield (f"output/evaluate --json {how}", ["evaluate", v, "--reference", v, "--json",
               target], [valid], "refuse", "--json")
        yield (f"output/main {how}", ["covariance", v, target], [valid], "refuse", None)
    # the default table path of `segment scan.segments.csv scan.las` is the input
    seg_in = d / "scan.segments.csv"
    seg_in.write_text("x,y,z\n" + "\n".join(f"{a},{b},{a * b * 0.01}" for a in range(20)
                                              for b in range(20)))
    yield ("output/segment default table is input", ["segment", str(seg_in), str(d / "scan.las"),
           "--method", "curvature", "--radius", "2"], [seg_in], "refuse", None)
    missing = str(d / "no" / "such" / "dir" / "s.json")
    yield ("output/summary in missing folder", ["covariance", v, out, "--k", "20",
           "--summary-json", missing], [valid], "refuse", "--summary-json")
    yield ("output/table with unknown suffix", ["segment", v, out, "--method", "curvature",
           "--radius", "0.5", "--table", str(d / "out" / "t.xyz")], [valid], "refuse", "--table")
    yield ("output/table in missing folder", ["segment", v, out, "--method", "curvature",
           "--radius", "0.5", "--table", missing.replace(".json", ".csv")], [valid], "refuse",
           "--table")
    existing = d / "existing_report.txt"
    existing.write_text("keep me")
    yield ("output/moments --report is an existing file", ["moments", v, out, "--report",
           str(existing)], [valid, existing], "refuse", "--report")


# --------------------------------------------------------------------------- running
def _digest(paths):
    out = {}
    for p in paths:
        p = Path(p)
        out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
    return out


def _limit(memory_bytes):
    def apply():
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    return apply


def run_case(name, argv, inputs, expect, option, *, outdir, timeout, memory_bytes):
    shutil.rmtree(outdir, ignore_errors=True)
    outdir.mkdir(parents=True)
    before = _digest(inputs)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "lidarstat", *argv], capture_output=True,
                              text=True, timeout=timeout, preexec_fn=_limit(memory_bytes),
                              stdin=subprocess.DEVNULL)
        rc, err = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired as exc:
        rc, err = None, (exc.stderr or b"").decode(errors="replace") if exc.stderr else ""
    seconds = time.perf_counter() - t0
    after = _digest(inputs)
    left = sorted(p.name for p in outdir.iterdir())
    lines = [ln for ln in err.splitlines() if ln.strip()]
    problems = []
    if rc is None:
        problems.append("timeout")
    elif rc < 0 or rc == 134:
        problems.append("abort")
    if "Traceback (most recent call last)" in err:
        problems.append("traceback")
    if before != after:
        problems.append("input_modified")
    if rc == 0 and expect == "refuse":
        problems.append("exit0_on_nonsense")
    if rc not in (0, None):
        if left:
            problems.append("partial_output")
        named = [str(p) for p in inputs] + [Path(p).name for p in inputs]
        named += [a for a in argv if "/" in a]
        said = lines[-1] if lines else ""
        if len(lines) != 1 or not (any(s in said for s in named)
                                  or (option and option in said)):
            problems.append("unclear")
    return {"case": name, "argv": argv, "expect": expect, "exit": rc,
            "seconds": round(seconds, 2), "stderr": lines[-3:], "left": left,
            "problems": problems or ["ok"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--memory-gb", type=float, default=8.0)
    ap.add_argument("--only", default=None, help="run the cases whose name contains this")
    ap.add_argument("--out", default=str(HERE / "results_robustness.json"))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    work = Path(tempfile.mkdtemp(prefix="lidarstat-robustness-"))
    try:
        corpus = build_corpus(work, rng)
        valid = corpus["valid"][0]
        cases = [*command_cases(corpus, work), *option_cases(valid, work),
                 *output_cases(valid, work)]
        if args.only:
            cases = [c for c in cases if args.only in c[0]]
        results = []
        for case in cases:
            r = run_case(*case, outdir=work / "out", timeout=args.timeout,
                         memory_bytes=int(args.memory_gb * 2**30))
            results.append(r)
            if r["problems"] != ["ok"]:
                print(f"{r['case']}: {','.join(r['problems'])}  exit {r['exit']}  "
                      f"{r['stderr'][-1] if r['stderr'] else ''}"[:220], flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    counts = {}
    for r in results:
        for p in r["problems"]:
            counts[p] = counts.get(p, 0) + 1
    summary = {"cases": len(results), "counts": counts,
               "timeout_s": args.timeout, "memory_gb": args.memory_gb}
    print(json.dumps(summary, indent=2))
    Path(args.out).write_text(json.dumps({"summary": summary, "cases": results}, indent=1))


if __name__ == "__main__":
    main()
