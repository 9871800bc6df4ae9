"""The command line, tested in-process: outputs, one-line errors, no partial output."""

import hashlib
import os
import re

import laspy
import numpy as np
import pytest

from conftest import shared_file
from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write
from lidarstat.synth import make_surface


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def sample_las(tmp_path):
    cloud = make_surface("peak", sigma=0.001, rng=0, spacing=0.04)
    path = tmp_path / "peak.las"
    write(path, PointCloud(xyz=cloud.xyz, attributes={"intensity": np.arange(len(cloud.xyz)) % 4096}))
    return path


CONTRACT = ["neighbors", "z0", "sigma0_sq", "chi2_pass", "K", "H", "kmin", "kmax", "K_sig",
            "H_sig", "surface_type"]


@pytest.mark.parametrize("suffix", [".laz", ".ply", ".npz", ".csv"])
def test_curvature_writes_contract_fields(sample_las, tmp_path, capsys, suffix):
    out = tmp_path / f"out{suffix}"
    code, stdout, _ = _run(["curvature", sample_las, out, "--radius", "0.3", "--sigma", "0.001"],
                           capsys)
    assert code == 0
    assert "elliptic_peak" in stdout and "model_rejected" in stdout
    res = read(out)
    for f in CONTRACT:
        assert f in res.field_names, f
    src = read(sample_las)
    np.testing.assert_allclose(res.xyz, src.xyz, atol=1e-3 if suffix == ".laz" else 1e-9)
    assert np.array_equal(np.asarray(res["intensity"], dtype=np.int64),
                          np.asarray(src["intensity"], dtype=np.int64))
    assert np.mean(np.asarray(res["surface_type"]) == 4) > 0.8


def test_info_and_synth(tmp_path, capsys):
    out = tmp_path / "agpart.laz"
    code, stdout, _ = _run(["synth", "agpart", out, "--sigma", "0.01"], capsys)
    assert code == 0 and out.exists()
    code, stdout, _ = _run(["info", out], capsys)
    assert code == 0 and "34492" in stdout.replace(",", "")


def test_bandwidth_command(capsys):
    code, stdout, _ = _run(["bandwidth", "--K0", "0", "--H0", "-0.4545", "--sigma", "0.015",
                            "--density", "2976"], capsys)
    assert code == 0 and "smallest radius" in stdout


def test_demo_writes_las_and_pngs(tmp_path, capsys):
    code, stdout, _ = _run(["demo", tmp_path / "demo"], capsys)
    assert code == 0
    for name in ("agpart_curvature.las", "K.png", "H.png", "chi2.png", "surface_type.png"):
        assert (tmp_path / "demo" / name).stat().st_size > 1000
    assert "shaft_side" in stdout and "automatic radius" in stdout
    agree = float(re.search(r"surface type equals the truth on ([0-9.]+)% of interior points",
                            stdout).group(1))
    assert agree >= 90.0


def _bad_inputs(tmp_path):
    empty = tmp_path / "empty.las"
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    laspy.LasData(hdr).write(empty)
    nan = tmp_path / "nan.csv"
    nan.write_text("x,y,z\n0,0,0\n1,nan,0\n")
    good = tmp_path / "good.laz"
    write(good, PointCloud(xyz=np.random.default_rng(0).random((2000, 3))))
    trunc = tmp_path / "trunc.laz"
    trunc.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    return {"empty": (empty, "empty"), "nan": (nan, "NaN"), "trunc": (trunc, "unreadable"),
            "missing": (tmp_path / "nope.las", "no such file"),
            "suffix": (tmp_path / "cloud.xyz", "unknown point-cloud format")}


@pytest.mark.parametrize("case", ["empty", "nan", "trunc", "missing", "suffix"])
def test_bad_input_one_line_error_no_output(tmp_path, capsys, case):
    path, words = _bad_inputs(tmp_path)[case]
    if case == "suffix":
        path.write_text("0 0 0\n")
    out = tmp_path / "out.laz"
    code, stdout, err = _run(["curvature", path, out, "--radius", "0.1"], capsys)
    assert code != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and path.name in lines[0] and words in lines[0], err
    assert not out.exists()
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".out.laz")]


@pytest.mark.parametrize("argv,words", [
    (["--radius", "0"], "argument --radius: invalid value '0': must be a number > 0"),
    (["--radius", "-1"], "argument --radius: invalid value '-1': must be a number > 0"),
])
def test_bad_radius_cli(sample_las, tmp_path, capsys, argv, words):
    out = tmp_path / "o.las"
    code, _, err = _run(["curvature", sample_las, out, *argv], capsys)
    assert code != 0 and words in err and not out.exists()


def test_unknown_output_suffix_fails_before_work(sample_las, tmp_path, capsys):
    code, _, err = _run(["curvature", sample_las, tmp_path / "o.xyz", "--radius", "0.3"], capsys)
    assert code != 0 and "o.xyz" in err and "unknown point-cloud format" in err


def test_real_file_end_to_end_input_untouched(tmp_path, capsys):
    src = shared_file("pdal_testdata/sample_c.las")
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    out = tmp_path / "sample_c_curv.laz"
    code, stdout, _ = _run(["curvature", src, out, "--radius", "1.5", "--sigma", "0.05"], capsys)
    assert code == 0
    assert hashlib.sha256(src.read_bytes()).hexdigest() == digest
    a, b = laspy.read(src), laspy.read(out)
    assert len(a.points) == len(b.points)
    assert a.header.point_format.id == b.header.point_format.id
    np.testing.assert_array_equal(a.classification, b.classification)
    np.testing.assert_array_equal(a.X, b.X)
    assert "surface_type" in b.point_format.extra_dimension_names


def test_curvature_tiled_equals_whole(sample_las, tmp_path, capsys):
    whole, tiled = tmp_path / "whole.laz", tmp_path / "tiled.laz"
    # Radius 0.29, not 0.3: on this 0.04 grid some neighbours lie exactly at 0.3, where the
    # rounding of tile-local coordinates may flip the "inside" decision (weight 0 anyway).
    args = ["curvature", sample_las, None, "--radius", "0.29", "--sigma", "0.001"]
    assert _run(args[:2] + [whole] + args[3:], capsys)[0] == 0
    code, stdout, _ = _run(args[:2] + [tiled] + args[3:] + ["--tile", "1.0", "--chunk-points",
                                                             "500"], capsys)
    assert code == 0 and "elliptic_peak" in stdout
    a, b = read(whole), read(tiled)
    for f in CONTRACT:
        np.testing.assert_allclose(np.asarray(b[f], float), np.asarray(a[f], float),
                                   rtol=1e-9, atol=1e-12, err_msg=f)
    # Without --sigma the noise comes from the first chunk, and the summary says so.
    code, stdout, _ = _run(args[:2] + [tiled] + ["--radius", "0.29", "--tile", "1.0"], capsys)
    assert code == 0 and "estimated from the data" in stdout
