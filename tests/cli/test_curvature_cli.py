"""The curvature, bandwidth and ridges commands: one vocabulary, deprecated spellings, refusals."""

import json

import numpy as np
import pytest

from lidarstat.cli._app import build_parser, main
from lidarstat.cli._common import NOISE_CHOICES
from lidarstat.features import Frame, Noise, Test, Weight
from lidarstat.io import PointCloud, read, write
from lidarstat.synth import make_surface


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    path = tmp_path_factory.mktemp("curv") / "cyl.npz"
    cloud = make_surface("cylinder", sigma=0.001, rng=0)
    write(path, PointCloud(xyz=cloud.xyz))
    return path


def _choices(argv, dest):
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices[argv]
    return tuple(next(a for a in sub._actions if a.dest == dest).choices)


def test_choices_come_from_the_enums():
    assert NOISE_CHOICES == Noise.values()
    assert _choices("curvature", "noise") == Noise.values()
    assert _choices("curvature", "test") == Test.values()
    assert _choices("curvature", "frame") == Frame.values()
    assert _choices("bandwidth", "test") == Test.values()
    assert _choices("ridges", "weight") == Weight.values()
    assert _choices("segment", "frame") == Frame.values()


def test_curvature_summary_json_has_the_params(cylinder, tmp_path):
    out, js = tmp_path / "c.npz", tmp_path / "c.json"
    assert main(["curvature", str(cylinder), str(out), "--radius", "0.25", "--sigma", "0.001",
                 "--frame", "pca", "--summary-json", str(js), "-q"]) == 0
    meta = json.loads(js.read_text())
    assert meta["params"]["frame"] == "pca" and meta["params"]["sigma"] == 0.001
    assert meta["params"]["noise"] == "z" and meta["sigma"] == 0.001
    assert meta["surface_type"]["parabolic_ridge"] > 0
    assert "surface_type" in read(out).attributes


def test_bandwidth_summary_json(tmp_path):
    js = tmp_path / "b.json"
    assert main(["bandwidth", "--K0", "0", "--H0", "-0.45", "--sigma", "0.015", "--density",
                 "3000", "--summary-json", str(js)]) == 0
    assert json.loads(js.read_text())["params"]["radius"] > 0


def test_segment_curvature_normal_angle_is_deprecated(cylinder, tmp_path, capsys):
    new, old = tmp_path / "new.npz", tmp_path / "old.npz"
    base = ["segment", str(cylinder), "--method", "curvature", "--radius", "0.25", "--sigma",
            "0.001", "--frame", "pca", "-q"]
    assert main(base[:2] + [str(new)] + base[2:] + ["--max-angle", "20"]) == 0
    assert "deprecated" not in capsys.readouterr().err
    assert main(base[:2] + [str(old)] + base[2:] + ["--normal-angle", "20"]) == 0
    err = capsys.readouterr().err
    assert "lidarstat: warning: --normal-angle is deprecated; use --max-angle" in err
    np.testing.assert_array_equal(read(new).attributes["segment_id"],
                                  read(old).attributes["segment_id"])


def test_segment_curvature_refuses_k(cylinder, tmp_path, capsys):
    rc = main(["segment", str(cylinder), str(tmp_path / "o.npz"), "--method", "curvature",
               "--radius", "0.25", "--k", "20"])
    assert rc == 2 and "argument --k: --method curvature does not use it" in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--ridges-only"], ["--criterion", "gcv"]])
def test_segment_ridges_refuses_removed_and_foreign_options(cylinder, tmp_path, capsys, option):
    rc = main(["segment", str(cylinder), str(tmp_path / "o.npz"), "--method", "ridges",
               "--radius", "0.25", *option])
    assert rc == 2 and option[0] in capsys.readouterr().err


def test_segment_ridges_jet_radius_is_deprecated(cylinder, tmp_path, capsys):
    out = tmp_path / "r.npz"
    rc = main(["segment", str(cylinder), str(out), "--method", "ridges", "--jet-radius", "0.25",
               "--sigma", "0.001", "-q"])
    err = capsys.readouterr().err
    assert rc == 0 and "--jet-radius is deprecated; use --radius" in err
    assert "segment_id" in read(out).attributes


def test_curvature_runs_at_the_automatic_scale_and_prints_it(cylinder, tmp_path, capsys):
    out, js = tmp_path / "auto.npz", tmp_path / "auto.json"
    assert main(["curvature", str(cylinder), str(out), "--summary-json", str(js)]) == 0
    stdout = capsys.readouterr().out
    assert "radius automatic" in stdout and "ladder" in stdout
    meta = json.loads(js.read_text())
    assert meta["params"]["radius"] == "auto" and meta["params"]["frame"] == "pca"
    assert len(meta["params"]["scales"]) >= 3 and meta["params"]["sigma_estimated"]
    assert meta["params"]["radius_p10"] <= meta["params"]["radius_median"]
    radius = np.asarray(read(out).attributes["radius"])
    scales = np.asarray(meta["params"]["scales"])
    assert np.abs(radius[:, None] - scales[None, :]).min(axis=1).max() < 1e-9
    assert meta["surface_type"]["parabolic_ridge"] > 0.9 * radius.size


def test_curvature_automatic_scale_tiled_equals_whole(cylinder, tmp_path):
    whole, tiled = tmp_path / "whole.npz", tmp_path / "tiled.npz"
    assert main(["curvature", str(cylinder), str(whole), "--sigma", "0.001", "-q"]) == 0
    # the ladder comes from the first chunk; on this uniform grid it is the whole cloud's
    assert main(["curvature", str(cylinder), str(tiled), "--sigma", "0.001", "-q", "--tile",
                 "1.0", "--chunk-points", "100000"]) == 0
    a, b = read(whole).attributes, read(tiled).attributes
    np.testing.assert_allclose(b["radius"], a["radius"])
    assert np.mean(np.asarray(a["surface_type"]) == np.asarray(b["surface_type"])) > 0.999
