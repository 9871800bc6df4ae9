"""``lidarstat covariance``: fields written, original fields kept, one-line errors."""

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write

FIELDS = ["point_class", "NormalX", "NormalY", "NormalZ", "Eigenvalue0", "Eigenvalue1",
          "Eigenvalue2", "SurfaceVariation", "CurvatureVariance", "Linearity", "Planarity",
          "Scattering", "Verticality", "Omnivariance", "Anisotropy", "Eigenentropy",
          "plane_p", "variation_p", "boundary_T2", "boundary_p"]


@pytest.fixture
def box_las(tmp_path):
    rng = np.random.default_rng(3)
    n = 3000
    xy = rng.uniform(0, 4, (n, 2))
    z = 2 - 0.5 * np.abs(xy[:, 0] - 2) + rng.normal(0, 0.003, n)  # a gable roof
    path = tmp_path / "roof.las"
    write(path, PointCloud(xyz=np.c_[xy, z] + [6e5, 5.2e6, 0],
                           attributes={"intensity": np.arange(n) % 4096}))
    return path


@pytest.mark.parametrize("suffix", [".laz", ".npz"])
def test_covariance_writes_fields(box_las, tmp_path, capsys, suffix):
    out = tmp_path / f"out{suffix}"
    summary = tmp_path / "s.json"
    code = main(["covariance", str(box_las), str(out), "--k", "30", "--summary-json",
                 str(summary)])
    stdout = capsys.readouterr().out
    assert code == 0 and "surface" in stdout and "boundary" in stdout
    res = read(out)
    for f in FIELDS:
        assert f in res.field_names, f
    pc = np.asarray(res["point_class"])
    assert set(np.unique(pc)) <= {0, 1, 2, 3} and (pc == 1).mean() > 0.6 and (pc == 2).any()
    assert np.array_equal(np.asarray(res["intensity"]), np.asarray(read(box_las)["intensity"]))
    import json

    meta = json.loads(summary.read_text())
    assert meta["k"] == 30 and meta["boundary"] == "centroid" and meta["boundary_alpha"] == 0.001
    assert meta["sigma_estimated"] and meta["point_class"]["surface"] == (pc == 1).sum()


def test_covariance_radius_and_paper_thresholds(box_las, tmp_path, capsys):
    out = tmp_path / "out.npz"
    code = main(["covariance", str(box_las), str(out), "--radius", "0.3",
                 "--variance-threshold", "0.0001", "--eigen-mode", "sqrt", "-q"])
    assert code == 0
    assert "CurvatureVariance" in read(out).field_names


@pytest.mark.parametrize("argv, message", [
    (["covariance", "missing.laz", "out.laz"], "missing.laz"),
    (["covariance", "IN", "out.xyz"], "unknown point-cloud format"),
    (["covariance", "IN", "out.laz", "--k", "1"], "argument --k: invalid value '1'"),
])
def test_covariance_errors(box_las, tmp_path, capsys, argv, message):
    argv = [str(box_las) if a == "IN" else (str(tmp_path / a) if a.startswith("out") else a)
            for a in argv]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "out.laz").exists()


def test_segment_method_covariance(box_las, tmp_path, capsys):
    out = tmp_path / "seg.npz"
    lines = tmp_path / "seg.lines.geojson"
    code = main(["segment", str(box_las), str(out), "--method", "covariance", "--k", "30",
                 "--min-points", "100", "--lines", str(lines)])
    stdout = capsys.readouterr().out
    assert code == 0 and "covariance: 2 segments" in stdout
    res = read(out)
    assert {"segment_id", "point_class", "reintegrated"} <= set(res.field_names)
    table = (tmp_path / "seg.segments.csv").read_text().splitlines()
    assert table[0].startswith("segment_id,n_points") and len(table) == 3
    import json

    feats = json.loads(lines.read_text())["features"]
    assert len(feats) == 1 and feats[0]["properties"]["segment_a"] == 1


def test_segment_covariance_min_size_is_a_deprecated_spelling(box_las, tmp_path, capsys):
    out = tmp_path / "seg.npz"
    code = main(["segment", str(box_las), str(out), "--method", "covariance", "--k", "30",
                 "--min-size", "100", "-q"])
    err = capsys.readouterr().err
    assert code == 0 and "--min-size is deprecated; use --min-points" in err


@pytest.mark.parametrize("argv, message", [
    # options that replayed earlier defaults are gone
    (["covariance", "IN", "out.laz", "--noise-estimate", "median"], "--noise-estimate"),
    (["covariance", "IN", "out.laz", "--boundary", "visible"], "--boundary"),
    (["covariance", "IN", "out.laz", "--boundary", "scan"], "--boundary"),
    (["segment", "IN", "out.laz", "--method", "covariance", "--no-refine"], "--no-refine"),
    (["segment", "IN", "out.laz", "--method", "covariance", "--no-adaptive-scale"],
     "--no-adaptive-scale"),
    # options the run cannot use are refused, not ignored
    (["segment", "IN", "out.laz", "--method", "covariance", "--eigen-mode", "sqrt"],
     "--eigen-mode"),
    (["segment", "IN", "out.laz", "--method", "covariance", "--noise", "range"],
     "noise='range' needs features computed with a sensor"),
    (["covariance", "IN", "out.laz", "--noise", "along"], "argument --noise: invalid choice"),
    (["covariance", "IN", "out.laz", "--sensor", "0", "0", "10", "--boundary-alpha", "0.01"],
     "argument --boundary-alpha: the 'grid' boundary test"),
    (["covariance", "IN", "out.laz", "--border-band", "0.4"],
     "argument --border-band: only the 'grid' boundary test"),
    (["covariance", "IN", "out.laz", "--boundary", "centroid", "--jump-alpha", "0.01"],
     "argument --jump-alpha: only the 'grid' boundary test"),
])
def test_covariance_refuses_removed_and_unusable_options(box_las, tmp_path, capsys, argv,
                                                          message):
    argv = [str(box_las) if a == "IN" else (str(tmp_path / a) if a.startswith("out") else a)
            for a in argv]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert not (tmp_path / "out.laz").exists()


def test_covariance_grid_test_with_a_sensor(tmp_path, capsys):
    """With a sensor the 'grid' boundary test runs and its fields are written; the
    summary JSON records its band and jump level."""
    import json

    from lidarstat.synth import scan_spherical
    from lidarstat.synth._csg import Box, FaceRegistry

    reg = FaceRegistry()
    wall = Box(reg, "wall", (12.0, 0.0, 3.0), np.eye(3), (0.2, 3.0, 1.5))
    sc = scan_spherical(wall, sensor=(0.0, 0.0, 1.5), azimuth=(-0.2, 0.2),
                        elevation=(0.0, 0.2), step=0.006, range_sigma=(0.002, 5e-5), rng=0)
    src = tmp_path / "wall.npz"
    write(src, PointCloud(xyz=sc.xyz))
    out, summary = tmp_path / "out.npz", tmp_path / "s.json"
    code = main(["covariance", str(src), str(out), "--sensor", *map(str, sc.scanner),
                 "--border-band", "0.4", "--summary-json", str(summary), "-q"])
    assert code == 0, capsys.readouterr().err
    assert {"border_distance", "border_kind", "jump_p"} <= set(read(out).field_names)
    meta = json.loads(summary.read_text())
    assert meta["boundary"] == "grid" and meta["border_band"] == 0.4
    assert meta["boundary_alpha"] is None and len(meta["range_noise"]) == 2


def test_covariance_automatic_scale_and_noise(box_las, tmp_path, capsys):
    """No --k or --radius: the automatic scale, printed and in the summary; --noise."""
    import json

    out, summary = tmp_path / "out.npz", tmp_path / "s.json"
    assert main(["covariance", str(box_las), str(out), "--summary-json", str(summary)]) == 0
    stdout = capsys.readouterr().out
    assert "automatic (plane test with power, k 20 to 50)" in stdout
    res = read(out)
    k = np.asarray(res["OptimalKNN"])
    assert k.min() >= 20 and k.max() <= 50 and "OptimalRadius" in res.field_names
    meta = json.loads(summary.read_text())
    assert meta["scale"] == "optimal" and meta["k"] is None and meta["noise"] == "z"
    assert meta["scale_rule"] == "tested"
    assert 20 <= meta["optimal_k_median"] <= 50
    assert main(["covariance", str(box_las), str(out), "--k", "30", "--noise", "normal",
                 "--summary-json", str(summary), "-q"]) == 0
    meta = json.loads(summary.read_text())
    assert meta["noise"] == "normal" and meta["k"] == 30 and "scale" not in meta


def test_segment_covariance_takes_noise(box_las, tmp_path):
    out = tmp_path / "seg.npz"
    assert main(["segment", str(box_las), str(out), "--method", "covariance", "--noise",
                 "normal", "-q"]) == 0
