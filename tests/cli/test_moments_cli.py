"""`lidarstat moments` and `lidarstat evaluate` end to end (in-process)."""

import json

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write


@pytest.fixture
def scene_file(tmp_path, rng):
    n = 4000
    xy = rng.uniform(0, 60, (n, 2))
    z = 300 + 0.05 * xy[:, 0] + rng.normal(0, 0.05, n)
    cls = np.full(n, 2, np.uint8)
    roof = (np.abs(xy - 30) < 8).all(axis=1)
    z[roof] += 6
    cls[roof] = 6
    inten = rng.normal(150, 10, n).clip(0, 65535).astype(np.uint16)
    path = tmp_path / "scene.las"
    write(path, PointCloud(np.c_[xy, z], {"intensity": inten, "classification": cls}))
    return path


def test_moments_then_evaluate(scene_file, tmp_path, capsys):
    out = tmp_path / "out.las"
    before = scene_file.read_bytes()
    assert main(["moments", str(scene_file), str(out), "--window", "60", "-q"]) == 0
    assert scene_file.read_bytes() == before
    c = read(out)
    assert "cluster_id" in c
    roof = read(scene_file)["classification"] == 6
    assert (c["classification"][roof] == 6).mean() > 0.9
    rep = tmp_path / "out_report"
    assert (rep / "index.html").is_file() and (rep / "report.json").is_file()
    assert list(rep.glob("step_*.png"))
    js = tmp_path / "e.json"
    assert main(["evaluate", str(out), "--reference", str(scene_file), "--classes",
                 "--json", str(js)]) == 0
    e = json.loads(js.read_text())
    # measured: total 0, kappa 1.0
    assert e["ground_object"]["total"] < 0.01 and e["ground_object"]["kappa"] > 0.95
    assert "Type I" in capsys.readouterr().out


def test_moments_errors(tmp_path, scene_file, capsys):
    empty = tmp_path / "empty.las"
    write(empty, PointCloud(np.zeros((0, 3)), {}))
    assert main(["moments", str(empty), str(tmp_path / "o.las")]) == 2
    assert "0 points" in capsys.readouterr().err
    assert main(["moments", str(scene_file), str(scene_file)]) == 2
    small = tmp_path / "s.las"
    write(small, PointCloud(np.zeros((5, 3)), {}))
    assert main(["evaluate", str(small), "--reference", str(scene_file)]) == 2


def test_moments_units_options(scene_file, tmp_path):
    """A feet copy of the scene with --scale 0.3048 (or --units ft) gets the metre labels."""
    c = read(scene_file)
    feet = tmp_path / "feet.las"
    write(feet, PointCloud(c.xyz / 0.3048, {"intensity": c["intensity"]}))
    ref, out_s, out_u = tmp_path / "m.las", tmp_path / "s.las", tmp_path / "u.las"
    common = ["--window", "60", "--no-report", "-q"]
    assert main(["moments", str(scene_file), str(ref), *common]) == 0
    js = tmp_path / "s.json"
    assert main(["moments", str(feet), str(out_s), "--scale", "0.3048", "--summary-json",
                 str(js), *common]) == 0
    assert main(["moments", str(feet), str(out_u), "--units", "ft", *common]) == 0
    a = read(ref)["classification"]
    assert (read(out_s)["classification"] == a).mean() > 0.998
    assert (read(out_u)["classification"] == a).mean() > 0.998
    assert json.loads(js.read_text())["units"]["horizontal_m"] == 0.3048
    assert main(["moments", str(feet), str(tmp_path / "x.las"), "--scale", "-1"]) == 2


def test_moments_summary_json_has_the_parameters_used(scene_file, tmp_path):
    js = tmp_path / "s.json"
    assert main(["moments", str(scene_file), str(tmp_path / "o.las"), "--window", "60",
                 "--min-points", "12", "--seed", "3", "--no-report", "-q",
                 "--summary-json", str(js)]) == 0
    params = json.loads(js.read_text())["params"]
    assert params["window"] == 60 and params["min_window"] == 16
    assert params["min_points"] == 12 and params["rng"] == 3
    assert params["method"] == "moments" and params["road_rule"] == "antimode"
    assert not {"tile_size", "min_tile_size", "min_cluster", "cut_interpolation"} & set(params)


def test_deprecated_spellings_work_and_say_so(scene_file, tmp_path, capsys):
    """--tile-size, --min-tile-size and --min-cluster run as --window, --min-window and
    --min-points (the same labels) and warn after the run."""
    new, old = tmp_path / "new.las", tmp_path / "old.las"
    assert main(["moments", str(scene_file), str(new), "--window", "60", "--min-window",
                 "20", "--min-points", "12", "--no-report", "-q"]) == 0
    capsys.readouterr()
    assert main(["moments", str(scene_file), str(old), "--tile-size", "60",
                 "--min-tile-size", "20", "--min-cluster", "12", "--no-report", "-q"]) == 0
    err = capsys.readouterr().err
    for o, n in (("--tile-size", "--window"), ("--min-tile-size", "--min-window"),
                 ("--min-cluster", "--min-points")):
        assert f"lidarstat: warning: {o} is deprecated; use {n}" in err
    assert np.array_equal(read(new)["classification"], read(old)["classification"])


def test_removed_step_cuts_is_refused(scene_file, tmp_path, capsys):
    out = tmp_path / "o.las"
    assert main(["moments", str(scene_file), str(out), "--step-cuts", "--no-report"]) == 2
    assert "--step-cuts" in capsys.readouterr().err and not out.exists()


def test_choices_are_the_library_enums():
    from lidarstat.classify import ElevationRule, MomentsMethod, RoadRule
    from lidarstat.cli import moments as cli

    assert cli.METHODS == tuple(m.value for m in MomentsMethod)
    assert cli.ELEVATION_RULES == tuple(r.value for r in ElevationRule)
    assert cli.ROAD_RULES == tuple(r.value for r in RoadRule)


def test_moments_las_output_is_the_input_record_plus_the_fields(scene_file, tmp_path):
    """LAS in and out: the records are copied chunk by chunk from the input (only the
    attributes the classification reads are held); the file equals the one the generic
    writer makes of the whole input cloud and the same fields."""
    src = tmp_path / "rich.las"
    c = read(scene_file)
    g = np.random.default_rng(3)
    n = len(c)
    c.attributes.update(gps_time=g.uniform(0, 1e5, n), point_source_id=np.full(n, 7, np.uint16),
                        user_data=g.integers(0, 255, n).astype(np.uint8))
    write(src, c)
    out = tmp_path / "out.las"
    assert main(["moments", str(src), str(out), "--window", "60", "-q", "--no-report"]) == 0
    got = read(out)
    names = ("classification", "cluster_id", "building_plane_p", "building_residual",
             "building_patch", "building_patch_p", "building_evidence")
    again = tmp_path / "again.las"
    write(again, read(src), fields={k: got[k] for k in names})
    assert out.read_bytes() == again.read_bytes()
    for k in ("gps_time", "point_source_id", "user_data"):
        np.testing.assert_array_equal(got[k], read(src)[k])
    csv = tmp_path / "out.csv"  # another format: the whole cloud is written
    assert main(["moments", str(src), str(csv), "--window", "60", "-q", "--no-report"]) == 0
    assert "gps_time" in read(csv)
