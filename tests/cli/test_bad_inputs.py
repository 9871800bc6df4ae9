"""A corpus of bad and degenerate inputs and bad option values, run through every command.

Every file is generated here (nothing binary is committed). For each case the contract is:
no traceback; a non-zero exit on nonsense (or exit 0 with a valid output where the input is
valid but degenerate); on an error, stderr is one line naming the input file or the option
as typed; the input is unchanged; a failed run leaves no output, partial or temporary.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import subprocess
import sys
import warnings
from pathlib import Path

import laspy
import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write

# --------------------------------------------------------------------------- inputs
#: Kinds of input. "unreadable": every command must refuse it, ``info`` included;
#: "invalid": readable but unusable (no points, NaN, overflowing values), every command
#: but ``info`` must refuse it; "degenerate": valid data (too few points, duplicates,
#: collinear or coplanar), a command may refuse it or succeed with a valid output.
UNREADABLE, INVALID, DEGENERATE = "unreadable", "invalid", "degenerate"


def _las(path, xyz, **kw):
    write(path, PointCloud(xyz=np.asarray(xyz, float), **kw))
    return path


def _zero_point_las(path):
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    laspy.LasData(hdr).write(path)
    return path


def _ply_ascii(path, rows, n=None):
    n = len(rows) if n is None else n
    head = (f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nend_header\n")
    path.write_text(head + "".join(" ".join(map(str, r)) + "\n" for r in rows))
    return path


def _csv(path, rows, header="x,y,z"):
    path.write_text(header + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def _grid(n=12, spacing=0.1):
    g = np.arange(n) * spacing
    x, y = np.meshgrid(g, g)
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]


def build_inputs(folder: Path) -> dict[str, tuple[Path, str]]:
    """Write the corpus of inputs into `folder`; name -> (path, kind)."""
    f = Path(folder)
    rng = np.random.default_rng(7)
    good = _las(f / "good_src.laz", rng.random((300, 3)))
    good_las = _las(f / "good_src.las", rng.random((300, 3)))
    cases: dict[str, tuple[Path, str]] = {}

    def add(name, path, kind):
        cases[name] = (path, kind)

    for suffix in (".las", ".laz", ".ply", ".csv", ".npz", ".txt"):
        p = f / f"empty_file{suffix}"
        p.write_bytes(b"")
        add(f"0-byte{suffix}", p, UNREADABLE)
    add("0-point.las", _zero_point_las(f / "zero_points.las"), INVALID)
    add("0-point.laz", _zero_point_las(f / "zero_points.laz"), INVALID)
    p = f / "text.las"
    p.write_text("this is not a point cloud\n")
    add("text.las", p, UNREADABLE)
    p = f / "text.laz"
    p.write_text("x,y,z\n0,0,0\n")
    add("text.laz", p, UNREADABLE)
    data = good.read_bytes()
    (f / "trunc_half.laz").write_bytes(data[: len(data) // 2])
    add("truncated.laz", f / "trunc_half.laz", UNREADABLE)
    data = good_las.read_bytes()
    (f / "trunc_half.las").write_bytes(data[: len(data) // 2])
    add("truncated.las", f / "trunc_half.las", UNREADABLE)
    (f / "trunc_header.las").write_bytes(data[:100])
    add("truncated-header.las", f / "trunc_header.las", UNREADABLE)
    p = f / "cloud.xyz"
    p.write_text("0 0 0\n1 1 1\n")
    add("suffix.xyz", p, UNREADABLE)
    p = f / "cloud_no_suffix"
    p.write_bytes(good_las.read_bytes())
    add("no-suffix", p, UNREADABLE)
    (f / "folder.las").mkdir()
    add("directory", f / "folder.las", UNREADABLE)
    add("missing", f / "no_such_file.las", UNREADABLE)
    p = f / "garbage.ply"
    p.write_bytes(b"ply\n" + rng.bytes(300))
    add("garbage.ply", p, UNREADABLE)
    add("ply-no-data", _ply_ascii(f / "ply_short.ply", [], n=5), UNREADABLE)
    p = f / "garbage.csv"
    p.write_bytes(rng.bytes(400))
    add("garbage.csv", p, UNREADABLE)
    add("csv-words", _csv(f / "words.csv", [("a", "b", "c"), ("foo", "bar", "baz")]),
        UNREADABLE)
    add("csv-2-columns", _csv(f / "two_cols.csv", [(0, 1), (2, 3)], header="x,y"), UNREADABLE)
    p = f / "garbage.npz"
    p.write_bytes(rng.bytes(400))
    add("garbage.npz", p, UNREADABLE)
    np.savez(f / "npz_no_xyz.npz", foo=np.zeros(3))
    add("npz-no-xyz", f / "npz_no_xyz.npz", UNREADABLE)
    np.savez(f / "npz_strings.npz", xyz=np.array([["a", "b", "c"]] * 4))
    add("npz-strings", f / "npz_strings.npz", UNREADABLE)
    np.savez(f / "npz_2cols.npz", xyz=np.zeros((4, 2)))
    add("npz-2-columns", f / "npz_2cols.npz", UNREADABLE)
    bad = rng.random((40, 3))
    for label, value in (("nan", "nan"), ("inf", "inf"), ("huge", 1.5e308)):
        rows = bad.tolist()
        rows[5][2] = value
        add(f"{label}.csv", _csv(f / f"{label}.csv", rows), INVALID)
        arr = bad.copy()
        arr[5, 2] = float(value)
        np.savez(f / f"{label}.npz", xyz=arr)
        add(f"{label}.npz", f / f"{label}.npz", INVALID)
    rows = bad.tolist()
    rows[5][2] = rows[9][0] = 1.5e308  # their sum overflows
    add("overflow.csv", _csv(f / "overflow.csv", rows), INVALID)
    add("nan.ply", _ply_ascii(f / "nan.ply", [(0, 0, 0), (1, "nan", 0), (0, 1, 0)]), INVALID)
    add("1-point.las", _las(f / "one.las", [[1.0, 2.0, 3.0]]), DEGENERATE)
    add("2-points.las", _las(f / "two.las", [[1.0, 2.0, 3.0], [1.1, 2.0, 3.0]]), DEGENERATE)
    add("3-points.las", _las(f / "three.las", [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0.01]]),
        DEGENERATE)
    add("1-point.csv", _csv(f / "one.csv", [(1, 2, 3)]), DEGENERATE)
    add("duplicates.las", _las(f / "dups.las", np.tile([[5.0, 5.0, 1.0]], (60, 1))),
        DEGENERATE)
    line = np.c_[np.linspace(0, 3, 80), np.zeros(80), np.zeros(80)]
    add("collinear.las", _las(f / "line.las", line), DEGENERATE)
    add("coplanar-grid.las", _las(f / "grid.las", _grid()), DEGENERATE)
    tilted = _grid()
    tilted[:, 2] = 0.3 * tilted[:, 0] + 0.1 * tilted[:, 1]
    add("coplanar-tilted.csv", _csv(f / "tilted.csv", tilted.tolist()), DEGENERATE)
    for name in ("good_src.laz", "good_src.las"):
        (f / name).unlink()
    return cases


# --------------------------------------------------------------------------- commands
#: command label -> argv builder (input, output folder) -> (argv, main output or None).
COMMANDS = {
    "info": lambda i, o: (["info", i], None),
    "curvature": lambda i, o: (["curvature", i, o / "c.las", "--radius", "0.5"], o / "c.las"),
    "curvature-tile": lambda i, o: (["curvature", i, o / "t.las", "--radius", "0.5",
                                     "--tile", "5", "--sigma", "0.01"], o / "t.las"),
    "covariance": lambda i, o: (["covariance", i, o / "v.las", "--k", "8"], o / "v.las"),
    "moments": lambda i, o: (["moments", i, o / "m.las", "--no-report"], o / "m.las"),
    "ridges": lambda i, o: (["ridges", i, o / "r.las", "--radius", "0.5"], o / "r.las"),
    "segment-curvature": lambda i, o: (["segment", i, o / "s.las", "--method", "curvature",
                                        "--radius", "0.5"], o / "s.las"),
    "segment-sar": lambda i, o: (["segment", i, o / "s.las", "--method", "sar",
                                  "--radius", "0.5"], o / "s.las"),
    "segment-covariance": lambda i, o: (["segment", i, o / "s.las", "--method", "covariance",
                                         "--k", "8"], o / "s.las"),
    "segment-ridges": lambda i, o: (["segment", i, o / "s.las", "--method", "ridges",
                                     "--radius", "0.5"], o / "s.las"),
    "evaluate": lambda i, o: (["evaluate", i, "--reference", i], None),
}


def run_cli(argv) -> tuple[int, str, str, BaseException | None]:
    """Run ``lidarstat`` in-process: (exit status, stdout, stderr, escaped exception).

    Warnings are recorded apart: the error message, not the warnings before it, must be
    one line.
    """
    out, err = io.StringIO(), io.StringIO()
    exc = None
    with warnings.catch_warnings(record=True) as caught, \
            contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        try:
            code = main([str(a) for a in argv])
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException as e:  # noqa: BLE001 - any escape is the defect counted
            code, exc = 1, e
    del caught
    return code, out.getvalue(), err.getvalue(), exc


def _digest(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def check_outcome(kind, command, code, stderr, exc, names, out_path, out_dir, before) -> list:
    """Every broken promise of one run, as short labels (empty when the run is clean)."""
    problems = []
    lines = stderr.strip().splitlines()
    if exc is not None or "Traceback" in stderr:
        problems.append("traceback")
    must_fail = kind == UNREADABLE or (kind == INVALID and command != "info")
    if code == 0 and must_fail:
        problems.append("exit-0-on-nonsense")
    if code != 0 and exc is None:
        if len(lines) != 1:
            problems.append("not-one-line")
        if not any(n and n in stderr for n in names):
            problems.append("names-neither-file-nor-option")
    if code != 0 and _listing(out_dir) - before:
        problems.append("partial-output")
    if code == 0 and out_path is not None:
        try:
            ok = out_path.is_file() and len(read(out_path)) >= 0
        except Exception:  # noqa: BLE001
            ok = False
        if not ok:
            problems.append("invalid-output")
    if code == 0 and [p for p in _listing(out_dir) if Path(p).name.startswith(".")]:
        problems.append("temporary-left")
    return problems


def run_input_case(inputs, name, command, out_dir: Path) -> tuple[int, str, list]:
    """Run one corpus input through one command; (exit status, stderr, problems)."""
    path, kind = inputs[name]
    argv, out_path = COMMANDS[command](path, out_dir)
    digest = _digest(path)
    before = _listing(out_dir)
    code, _, err, exc = run_cli(argv)
    problems = check_outcome(kind, command, code, err, exc, [str(path)], out_path, out_dir,
                             before)
    if _digest(path) != digest:
        problems.append("input-modified")
    return code, err, problems


# --------------------------------------------------------------------------- options
#: (argv with IN/OUT placeholders, option named in the message). Each value is nonsense.
_B = ["bandwidth", "--K0", "0", "--H0", "-0.45", "--sigma", "0.015", "--density", "3000"]


def _bw(opt, value):
    argv = list(_B)
    if opt in argv:
        argv[argv.index(opt) + 1] = value
    else:
        argv += [opt, value]
    return argv


_CURV = ["curvature", "IN", "OUT", "--radius", "0.5"]
_COV = ["covariance", "IN", "OUT"]
_MOM = ["moments", "IN", "OUT", "--no-report"]
_RID = ["ridges", "IN", "OUT", "--radius", "0.5"]
_SEG = {m: ["segment", "IN", "OUT", "--method", m] for m in ("sar", "curvature",
                                                              "covariance", "ridges")}
_SEG["curvature"] += ["--radius", "0.5"]
_SEG["ridges"] += ["--radius", "0.5"]

OPTION_CASES = [
    (["moments", "IN", "OUT", "--iterations", "-1"], "--iterations"),
    (_MOM + ["--workers", "0"], "--workers"),
    (_MOM + ["--workers", "-3"], "--workers"),
    (_CURV + ["--tile", "20", "--workers", "-1"], "--workers"),
    (_CURV + ["--tile", "20", "--workers", "0"], "--workers"),
    (["evaluate", "IN", "--reference", "IN", "--ground-codes", "abc"], "--ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--ground-codes", ""], "--ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--ground-codes", ",,"], "--ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--ground-codes", "2,256"], "--ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--ground-codes", "-2"], "--ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--reference-ground-codes", "x"],
     "--reference-ground-codes"),
    (["evaluate", "IN", "--reference", "IN", "--reference-ground-codes", ""],
     "--reference-ground-codes"),
    (_bw("--density", "inf"), "--density"),
    (_bw("--density", "nan"), "--density"),
    (_bw("--density", "0"), "--density"),
    (_bw("--sigma", "-1"), "--sigma"),
    (_bw("--sigma", "nan"), "--sigma"),
    (_bw("--K0", "nan"), "--K0"),
    (_bw("--H0", "inf"), "--H0"),
    (_bw("--alpha", "0"), "--alpha"),
    (_bw("--alpha", "1"), "--alpha"),
    (_bw("--power", "0.2"), "--power"),
    (_bw("--power", "nan"), "--power"),
    (_SEG["covariance"] + ["--k", "0"], "--k"),
    (_SEG["covariance"] + ["--k", "-5"], "--k"),
    (_SEG["covariance"] + ["--min-size", "-1"], "--min-size"),
    (_SEG["covariance"] + ["--min-size", "0"], "--min-size"),
    (_SEG["covariance"] + ["--grow-k", "0"], "--grow-k"),
    (_SEG["covariance"] + ["--min-angle", "nan"], "--min-angle"),
    (_SEG["covariance"] + ["--min-angle", "-5"], "--min-angle"),
    (_SEG["covariance"] + ["--min-angle", "120"], "--min-angle"),
    (_SEG["covariance"] + ["--boundary-alpha", "2"], "--boundary-alpha"),
    (_SEG["covariance"] + ["--border-band", "0"], "--border-band"),
    (_SEG["covariance"] + ["--jump-alpha", "1"], "--jump-alpha"),
    (_SEG["covariance"] + ["--seeds", "random"], "--seeds"),
    (_SEG["covariance"] + ["--curved", "sphere"], "--curved"),
    (_SEG["covariance"] + ["--boundary", "visible"], "--boundary"),
    (_SEG["curvature"] + ["--max-angle", "nan"], "--max-angle"),
    (_SEG["curvature"] + ["--max-angle", "-1"], "--max-angle"),
    (_SEG["curvature"] + ["--max-angle", "720"], "--max-angle"),
    (_SEG["curvature"] + ["--normal-angle", "720"], "--normal-angle"),
    (_SEG["curvature"] + ["--min-size", "-1"], "--min-size"),
    (_SEG["curvature"] + ["--radius", "nan"], "--radius"),
    (_SEG["sar"] + ["--sar-degree", "0"], "--sar-degree"),
    (_SEG["sar"] + ["--sar-degree", "7"], "--sar-degree"),
    (_SEG["sar"] + ["--sar-degree", "two"], "--sar-degree"),
    (_SEG["sar"] + ["--fs-block", "0"], "--fs-block"),
    (_SEG["sar"] + ["--fs-block", "-1"], "--fs-block"),
    (_SEG["sar"] + ["--fs-alpha", "1.5"], "--fs-alpha"),
    (_SEG["sar"] + ["--fs-envelope", "nan"], "--fs-envelope"),
    (_SEG["sar"] + ["--envelope-alpha", "nan"], "--envelope-alpha"),
    (_SEG["sar"] + ["--fs-stop", "never"], "--fs-stop"),
    (_SEG["sar"] + ["--criterion", "aic"], "--criterion"),
    (_SEG["sar"] + ["--adaptive", "sometimes"], "--adaptive"),
    (_SEG["sar"] + ["--k", "8"], "--k"),
    (_SEG["sar"] + ["--sensor", "0", "0", "9"], "--sensor"),
    (_SEG["sar"] + ["--edge-alpha", "0"], "--edge-alpha"),
    (_SEG["sar"] + ["--outlier-alpha", "-0.1"], "--outlier-alpha"),
    (_SEG["sar"] + ["--gof-alpha", "1"], "--gof-alpha"),
    (_SEG["sar"] + ["--search", "-1"], "--search"),
    (_SEG["sar"] + ["--w-radius", "0"], "--w-radius"),
    (_SEG["sar"] + ["--radius", "inf"], "--radius"),
    (_SEG["sar"] + ["--sigma", "-0.1"], "--sigma"),
    (_SEG["sar"] + ["--alpha", "nan"], "--alpha"),
    (_SEG["ridges"] + ["--jet-radius", "0"], "--jet-radius"),
    (_SEG["ridges"] + ["--ridges-only"], "--ridges-only"),
    (_CURV + ["--noise", "sideways"], "--noise"),
    (_CURV + ["--test", "exact"], "--test"),
    (_SEG["ridges"] + ["--ridge-grow-k", "0"], "--ridge-grow-k"),
    (_SEG["ridges"] + ["--band", "-1"], "--band"),
    (_SEG["ridges"] + ["--extend", "nan"], "--extend"),
    (_CURV[:3] + ["--radius", "nan"], "--radius"),
    (_CURV[:3] + ["--radius", "inf"], "--radius"),
    (_CURV[:3] + ["--radius", "0.5", "-1"], "--radius"),
    (_CURV + ["--sigma", "-1"], "--sigma"),
    (_CURV + ["--sigma", "nan"], "--sigma"),
    (_CURV + ["--alpha", "0"], "--alpha"),
    (_CURV + ["--alpha", "1.5"], "--alpha"),
    (_CURV + ["--min-neighbors", "0"], "--min-neighbors"),
    (_CURV + ["--min-neighbors", "3"], "--min-neighbors"),
    (_CURV + ["--sensor", "nan", "0", "0"], "--sensor"),
    (_CURV + ["--sensor", "0", "inf", "0"], "--sensor"),
    (_CURV + ["--tile", "0"], "--tile"),
    (_CURV + ["--tile", "-5"], "--tile"),
    (_CURV + ["--tile", "nan"], "--tile"),
    (_CURV + ["--tile", "0.25"], "--tile"),
    (_CURV + ["--tile", "5", "--chunk-points", "0"], "--chunk-points"),
    (_COV + ["--k", "0"], "--k"),
    (_COV + ["--k", "2"], "--k"),
    (_COV + ["--k", "abc"], "--k"),
    (_COV + ["--radius", "nan"], "--radius"),
    (_COV + ["--radius", "-1"], "--radius"),
    (_COV + ["--sigma", "inf"], "--sigma"),
    (_COV + ["--alpha", "1"], "--alpha"),
    (_COV + ["--border-band", "nan"], "--border-band"),
    (_COV + ["--border-band", "-1"], "--border-band"),
    (_COV + ["--jump-alpha", "0"], "--jump-alpha"),
    (_COV + ["--curved-alpha", "1"], "--curved-alpha"),
    (_COV + ["--curvature-threshold", "nan"], "--curvature-threshold"),
    (_COV + ["--variance-threshold", "-1"], "--variance-threshold"),
    (_MOM + ["--window", "0"], "--window"),
    (_MOM + ["--window", "inf"], "--window"),
    (_MOM + ["--tile-size", "0"], "--tile-size"),
    (_MOM + ["--min-window", "-1"], "--min-window"),
    (_MOM + ["--alpha", "1"], "--alpha"),
    (_MOM + ["--min-points", "0"], "--min-points"),
    (_MOM + ["--min-cluster", "0"], "--min-cluster"),
    (_MOM + ["--seed", "-1"], "--seed"),
    (_MOM + ["--method", "nope"], "--method"),
    (_MOM + ["--cycle", "-1"], "--cycle"),
    (_MOM + ["--bandwidth", "-1"], "--bandwidth"),
    (_MOM + ["--bandwidth", "nan"], "--bandwidth"),
    (_MOM + ["--bandwidth", "wide"], "--bandwidth"),
    (_MOM + ["--surface-cell", "0"], "--surface-cell"),
    (_MOM + ["--opening-window", "nan"], "--opening-window"),
    (_MOM + ["--scale", "0"], "--scale"),
    (_MOM + ["--scale", "nan"], "--scale"),
    (_MOM + ["--ground-spread", "-1"], "--ground-spread"),
    (_RID[:3] + ["--radius", "0"], "--radius"),
    (_RID[:3] + ["--k", "1"], "--k"),
    (_RID + ["--ratio", "0.5"], "--ratio"),
    (_RID + ["--ratio", "nan"], "--ratio"),
    (_RID + ["--min-length", "-1"], "--min-length"),
    (_RID + ["--alpha", "0"], "--alpha"),
    (_RID + ["--sigma", "nan"], "--sigma"),
    (["synth", "plane", "OUT", "--sigma", "-1"], "--sigma"),
    (["synth", "plane", "OUT", "--sigma", "nan"], "--sigma"),
    (["synth", "plane", "OUT", "--seed", "-1"], "--seed"),
    (["demo", "OUTDIR", "--sigma", "nan"], "--sigma"),
    (["demo", "OUTDIR", "--radius", "0"], "--radius"),
    (["demo", "OUTDIR", "--seed", "-2"], "--seed"),
]


def _option_id(case):
    argv, opt = case
    rest = argv[len(argv) - argv[::-1].index(opt):]
    value = rest[:next((i for i, a in enumerate(rest) if a.startswith("--")), len(rest))]
    return f"{argv[0]}{' ' + argv[4] if argv[0] == 'segment' else ''} {opt} {' '.join(value)!r}"


def option_cloud(folder: Path) -> Path:
    """A small valid cloud (a noisy curved patch with a classification) for option cases."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 4, (400, 2))
    z = 0.1 * (xy ** 2).sum(1) + rng.normal(0, 0.005, 400)
    path = Path(folder) / "valid.las"
    cls = np.where(z < 0.8, 2, 6).astype(np.uint8)
    return _las(path, np.c_[xy, z], attributes={"classification": cls})


def run_option_case(case, cloud: Path, out_dir: Path) -> tuple[int, str, list]:
    """Run one bad option value; (exit status, stderr, problems)."""
    argv, opt = case
    subst = {"IN": str(cloud), "OUT": str(out_dir / "o.las"), "OUTDIR": str(out_dir / "d")}
    argv = [subst.get(a, a) for a in argv]
    digest = _digest(cloud)
    before = _listing(out_dir)
    code, _, err, exc = run_cli(argv)
    problems = check_outcome(UNREADABLE, argv[0], code, err, exc, [opt], None, out_dir, before)
    if _digest(cloud) != digest:
        problems.append("input-modified")
    return code, err, problems


# --------------------------------------------------------------------------- tests
@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("corpus")
    return build_inputs(folder)


@pytest.fixture(scope="module")
def valid_cloud(tmp_path_factory):
    return option_cloud(tmp_path_factory.mktemp("valid"))


def _input_names():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return list(build_inputs(Path(d)))


INPUT_NAMES = _input_names()
def _params():
    for name in INPUT_NAMES:
        for command in COMMANDS:
            yield pytest.param(name, command, id=f"{name}-{command}")


@pytest.mark.parametrize("name,command", list(_params()))
def test_bad_input(corpus, tmp_path, name, command):
    code, err, problems = run_input_case(corpus, name, command, tmp_path)
    assert not problems, f"exit {code}; {problems}; stderr: {err[-600:]}"


@pytest.mark.parametrize("case", OPTION_CASES, ids=[_option_id(c) for c in OPTION_CASES])
def test_bad_option(valid_cloud, tmp_path, case):
    code, err, problems = run_option_case(case, valid_cloud, tmp_path)
    assert not problems, f"exit {code}; {problems}; stderr: {err[-600:]}"
    assert f"argument {case[1]}" in err or case[1] in err


@pytest.mark.parametrize("name,command", [
    ("0-point.las", "curvature-tile"), ("nan.npz", "moments"), ("text.las", "info"),
    ("1-point.las", "covariance"), ("missing", "segment-sar")])
def test_real_process_exit_status(corpus, tmp_path, name, command):
    path, _ = corpus[name]
    argv, _ = COMMANDS[command](path, tmp_path)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2] / "src"))
    proc = subprocess.run([sys.executable, "-m", "lidarstat", *map(str, argv)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lidarstat: error: "), proc.stderr
    assert str(path) in lines[0]
    assert not list(tmp_path.iterdir())


def test_bad_option_real_process(valid_cloud, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2] / "src"))
    proc = subprocess.run([sys.executable, "-m", "lidarstat", "moments", str(valid_cloud),
                           str(tmp_path / "o.las"), "--iterations", "-1"],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "lidarstat moments: error: argument --iterations: invalid value '-1': must be an "
        "integer >= 0"]
    assert not list(tmp_path.iterdir())
