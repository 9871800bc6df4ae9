"""``lidarstat segment --method sar|curvature`` end to end on a small LAS file."""

import csv

import numpy as np

from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write


def _gable(rng, tmp_path):
    xy = rng.uniform(0, 16, (4000, 2)) + [85000.0, 445000.0]
    y = xy[:, 1] - 445000
    z = 8 - 0.6 * np.abs(y - 8) + rng.normal(0, 0.03, 4000)
    path = tmp_path / "gable.las"
    write(path, PointCloud(xyz=np.c_[xy, z], attributes={"intensity": np.arange(4000) % 9}))
    return path


def test_sar_method_writes_ids_table_lines_and_plots(rng, tmp_path, capsys):
    src = _gable(rng, tmp_path)
    out = tmp_path / "seg.laz"
    diag = tmp_path / "fs"
    assert main(["segment", str(src), str(out), "--method", "sar", "--radius", "1.0",
                 "--diagnostics", str(diag)]) == 0
    pc = read(out)
    assert np.bincount(pc.attributes["segment_id"])[1:].tolist()[:2] == sorted(
        np.bincount(pc.attributes["segment_id"])[1:].tolist(), reverse=True)[:2]
    assert {"raw_cluster", "surface_residual", "z0", "slope_e", "slope_n"} <= set(pc.attributes)
    rows = list(csv.DictReader((tmp_path / "seg.segments.csv").read_text().splitlines()))
    assert len(rows) == 2
    for row in rows:
        assert int(row["n_s"]) < int(row["m"]) <= int(row["n_sa"])
        assert abs(abs(float(row["c_01"])) - 0.6) < 0.01
    assert (tmp_path / "seg.lines.geojson").is_file()
    assert len(list(diag.glob("fs_*.png"))) == 2
    assert "2 segments" in capsys.readouterr().out
    # one bandwidth for the whole cloud, and the bare flag (Geary) still parse
    for extra in (["--adaptive", "none"], ["--adaptive"]):
        assert main(["segment", str(src), str(tmp_path / "b.las"), "--method", "sar",
                     "--radius", "1.0", *extra]) == 0
        assert "2 segments" in capsys.readouterr().out


def test_sar_deprecated_envelope_option_works_and_warns(rng, tmp_path, capsys):
    src = _gable(rng, tmp_path)
    runs = {}
    for opt in ("--envelope-alpha", "--fs-envelope"):
        out = tmp_path / f"{opt.strip('-')}.las"
        assert main(["segment", str(src), str(out), "--method", "sar", "--radius", "1.0",
                     opt, "0.01", "--summary-json", str(tmp_path / "s.json")]) == 0
        err = capsys.readouterr().err
        runs[opt] = (read(out).attributes["segment_id"],
                     __import__("json").loads((tmp_path / "s.json").read_text()))
        deprecated = "--fs-envelope is deprecated; use --envelope-alpha" in err
        assert deprecated == (opt == "--fs-envelope")
    new, old = runs["--envelope-alpha"], runs["--fs-envelope"]
    np.testing.assert_array_equal(new[0], old[0])
    assert json_params(new[1])["envelope_alpha"] == json_params(old[1])["envelope_alpha"] == 0.01


def json_params(summary):
    """The parameters block of a ``--summary-json`` file."""
    return summary.get("params", summary)


def test_sar_refuses_options_it_cannot_use(rng, tmp_path, capsys):
    src = _gable(rng, tmp_path)
    for extra in (["--k", "8"], ["--sensor", "0", "0", "100"], ["--noise", "z"]):
        assert main(["segment", str(src), str(tmp_path / "x.las"), "--method", "sar",
                     *extra]) == 2
        assert "--method sar does not use it" in capsys.readouterr().err


def test_curvature_method_runs_at_the_automatic_scale(rng, tmp_path, capsys):
    src = _gable(rng, tmp_path)
    out = tmp_path / "c.las"
    assert main(["segment", str(src), str(out), "--method", "curvature", "-q"]) == 0
    ids = np.asarray(read(out).attributes["segment_id"])
    y = read(out).xyz[:, 1] - 445000
    # the two largest units are the two roof faces, one each side of the ridge at y = 8
    assert np.all(y[ids == 1] > 7) or np.all(y[ids == 1] < 9)
    assert np.median(y[ids == 1]) * np.median(y[ids == 2]) > 0
    assert (np.median(y[ids == 1]) - 8) * (np.median(y[ids == 2]) - 8) < 0
    assert np.sum(ids == 1) + np.sum(ids == 2) > 0.85 * ids.size
    assert main(["segment", str(src), str(out), "--method", "curvature", "--radius", "1.0",
                 "--sigma", "0.03", "-q"]) == 0
    assert "surface_type" in read(out).attributes


def test_sar_no_planes_keeps_the_sar_units_alone(rng, tmp_path, capsys):
    src = _gable(rng, tmp_path)
    tables = {}
    for extra in ([], ["--no-planes"]):
        out = tmp_path / f"p{len(extra)}.las"
        assert main(["segment", str(src), str(out), "--method", "sar", "--radius", "1.0",
                     "--summary-json", str(tmp_path / "s.json"), *extra]) == 0
        capsys.readouterr()
        tables[len(extra)] = list(csv.DictReader(
            (tmp_path / f"p{len(extra)}.segments.csv").read_text().splitlines()))
        params = json_params(__import__("json").loads((tmp_path / "s.json").read_text()))
        assert params["planes"] is (not extra)
    assert "stage" in tables[0][0] and "stage" not in tables[1][0]
