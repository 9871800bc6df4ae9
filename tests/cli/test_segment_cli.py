"""The ``segment`` command's shared machinery, driven by a minimal method defined here."""

import csv
import json

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.cli import segment as segment_cli
from lidarstat.io import PointCloud, read, write


#: The shared options of ``segment`` this test method uses.
USES = frozenset({"min_points"})


def add_arguments(group):
    group.add_argument("--gap", type=float, default=1.0, help="test option")


def run(args, cloud):
    """Connected components at distance `gap` (a method as a registered module gives it)."""
    from lidarstat.neighbors import radius_neighbors
    from lidarstat.segment import Polylines, Segmentation, components, segment_table

    lab = components(radius_neighbors(cloud.xyz, args.gap), min_points=args.min_points or 1)
    lines = Polylines.from_segments([[0, 0, 0]], [[1, 0, 0]])
    return Segmentation(lab, segment_table(lab, cloud.xyz), lines=lines, method="fake",
                        params={"gap": args.gap})


@pytest.fixture
def fake_method(monkeypatch):
    monkeypatch.setitem(segment_cli.SEGMENT_METHODS, "fake", __name__)


@pytest.fixture
def two_blobs(tmp_path, rng):
    xyz = np.r_[rng.uniform(0, 1, (200, 3)), rng.uniform(5, 6, (100, 3))]
    path = tmp_path / "in.las"
    write(path, PointCloud(xyz=xyz, attributes={"intensity": np.arange(300) % 7}))
    return path


def test_segment_writes_points_table_and_lines(fake_method, two_blobs, tmp_path, capsys):
    out = tmp_path / "out.laz"
    before = two_blobs.read_bytes()
    rc = main(["segment", str(two_blobs), str(out), "--method", "fake", "--gap", "0.5",
               "--summary-json", str(tmp_path / "s.json")])
    assert rc == 0
    assert two_blobs.read_bytes() == before
    pc = read(out)
    assert np.bincount(pc.attributes["segment_id"]).tolist() == [0, 200, 100]
    assert np.array_equal(pc.attributes["intensity"], np.arange(300) % 7)
    rows = list(csv.DictReader((tmp_path / "out.segments.csv").read_text().splitlines()))
    assert [r["n_points"] for r in rows] == ["200", "100"]
    assert json.loads((tmp_path / "out.lines.geojson").read_text())["features"]
    meta = json.loads((tmp_path / "s.json").read_text())
    assert meta["n_segments"] == 2 and meta["params"] == {"gap": 0.5}
    assert "2 segments" in capsys.readouterr().out


def test_segment_custom_table_and_errors(fake_method, two_blobs, tmp_path, capsys):
    out = tmp_path / "o.ply"
    assert main(["segment", str(two_blobs), str(out), "--method", "fake", "--gap", "0.5",
                 "--table", str(tmp_path / "tab.json"), "--lines", str(tmp_path / "l.csv"),
                 "-q"]) == 0
    assert json.loads((tmp_path / "tab.json").read_text())[1]["n_points"] == 100
    assert (tmp_path / "l.csv").is_file()
    assert main(["segment", str(tmp_path / "missing.las"), str(out), "--method", "fake"]) == 2
    assert "missing.las" in capsys.readouterr().err
    assert main(["segment", str(two_blobs), str(two_blobs), "--method", "fake"]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err


def test_option_of_another_method_is_refused(fake_method, two_blobs, tmp_path, capsys):
    out = tmp_path / "out.laz"
    rc = main(["segment", str(two_blobs), str(out), "--method", "fake", "--fs-alpha", "0.01"])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert "argument --fs-alpha: an option of --method sar, not of --method fake" in err


@pytest.mark.parametrize("option", [["--k", "10"], ["--radius", "1"], ["--sensor", "0", "0", "9"],
                                    ["--sigma", "0.1"], ["--noise", "z"]])
def test_shared_option_the_method_does_not_use_is_refused(fake_method, two_blobs, tmp_path,
                                                          capsys, option):
    out = tmp_path / "out.laz"
    rc = main(["segment", str(two_blobs), str(out), "--method", "fake", *option])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert f"argument {option[0]}: --method fake does not use it" in err


def test_deprecated_spelling_works_and_says_so(fake_method, two_blobs, tmp_path, capsys):
    out = tmp_path / "out.laz"
    rc = main(["segment", str(two_blobs), str(out), "--method", "fake", "--min-size", "150",
               "-q"])
    err = capsys.readouterr().err
    assert rc == 0
    assert "lidarstat: warning: --min-size is deprecated; use --min-points" in err
    labels = read(out).attributes["segment_id"]
    assert set(np.unique(labels)) == {0, 1}  # the 100-point blob is below 150 points
