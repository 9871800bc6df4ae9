"""Segmentation and Polylines containers: validation and round trips of their files."""

import csv
import json

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError, UnknownFormatError
from lidarstat.io import read
from lidarstat.segment import Polylines, Segmentation, segment_table


@pytest.fixture
def seg(rng):
    xyz = rng.normal(size=(100, 3)) + 4.5e6  # UTM-sized: centroids must stay exact
    labels = np.repeat([1, 2, 0], [60, 30, 10])
    table = segment_table(labels, xyz)
    lines = Polylines.from_segments([[0, 0, 0]], [[1, 2, 2]], {"rms": [0.01]})
    return Segmentation(labels, table, lines=lines, fields={"score": rng.random(100)},
                        method="test", params={"a": 1}), xyz


def test_segment_table_centroids(seg):
    s, xyz = seg
    assert s.n_segments == 2
    assert s.table["n_points"].tolist() == [60, 30]
    np.testing.assert_allclose(s.table["centroid_x"][0], xyz[:60, 0].mean(), rtol=0, atol=1e-8)
    fields = s.to_fields()
    assert fields["segment_id"].dtype == np.uint32 and list(fields) == ["segment_id", "score"]
    assert "2 segments" in s.summary() and "1 lines" in s.summary()


def test_table_files(seg, tmp_path):
    s, _ = seg
    s.write_table(tmp_path / "t.csv")
    rows = list(csv.DictReader((tmp_path / "t.csv").read_text().splitlines()))
    assert [int(r["segment_id"]) for r in rows] == [1, 2]
    assert float(rows[1]["centroid_z"]) == pytest.approx(s.table["centroid_z"][1], abs=1e-9)
    s.write_table(tmp_path / "t.json")
    recs = json.loads((tmp_path / "t.json").read_text())
    assert recs[0]["n_points"] == 60
    with pytest.raises(UnknownFormatError, match="t.xlsx"):
        s.write_table(tmp_path / "t.xlsx")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "t.json"]  # no temp left


def test_validation():
    with pytest.raises(InvalidParameterError, match="segment_id"):
        Segmentation(np.array([1, 1]), {"n": [2]})
    with pytest.raises(InvalidParameterError, match="2 segments"):
        Segmentation(np.array([1, 2]), {"segment_id": [1]})
    with pytest.raises(InvalidParameterError, match="score"):
        Segmentation(np.array([1]), {"segment_id": [1]}, fields={"score": [1, 2]})


def test_polylines_files(tmp_path):
    pl = Polylines([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[5, 5, 5], [5, 5, 7]]],
                   {"strength": np.array([0.5, 2.0]), "pair": np.array([12, 13])})
    np.testing.assert_allclose(pl.lengths(), [2.0, 2.0])
    pl.write(tmp_path / "l.geojson")
    doc = json.loads((tmp_path / "l.geojson").read_text())
    assert doc["features"][1]["geometry"]["coordinates"] == [[5, 5, 5], [5, 5, 7]]
    assert doc["features"][0]["properties"] == {"line_id": 1, "strength": 0.5, "pair": 12}
    pl.write(tmp_path / "l.csv")
    rows = list(csv.DictReader((tmp_path / "l.csv").read_text().splitlines()))
    assert len(rows) == 5 and rows[4]["line_id"] == "2" and float(rows[4]["z"]) == 7
    pl.write(tmp_path / "l.las", spacing=0.25)
    pc = read(tmp_path / "l.las")
    ids = pc.attributes["line_id"]
    assert np.count_nonzero(ids == 1) == 9 and np.count_nonzero(ids == 2) == 9
    np.testing.assert_allclose(pc.attributes["strength"][ids == 2], 2.0)
    # Sampled points lie on the lines.
    on_first = pc.xyz[ids == 1]
    assert np.all((np.abs(on_first[:, 1]) < 1e-4) | (np.abs(on_first[:, 0] - 1) < 1e-4))
