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
    assert main(["moments", str(scene_file), str(out), "--tile-size", "60", "-q"]) == 0
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
    # measured: total 0, kappa 1.0 (was 0.81 before the ground surface extrapolated the
    # terrain slope beyond the hull of its vertices)
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
