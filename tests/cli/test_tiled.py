"""``--tile SIZE`` on one file for ridges, segment and covariance: the tiled run gives the
untiled answer where the buffer covers the method's reach (field by field, tile sizes and
grid offsets swept), segments keep one id across tile borders, the output appears only
when complete, and what a tiled run cannot honour is refused in one line."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import PointCloud, read, write

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from test_catalogue import _assert_same_fields, _synthetic
from test_catalogue_methods import _agreement, _assert_same_jets

SIGMA = 0.02


def _gable(path, seed=0, n=12000, shift=(0.0, 0.0)):
    """Two roof planes meeting at a ridge (x = 31) over 60 x 60 m, noise SIGMA; file order
    random. `shift` moves the points (and so the tile grid's offset from the ridge)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 60, (n, 2))
    z = 8 - 0.5 * np.abs(xy[:, 0] - 31) + rng.normal(0, SIGMA, n)
    write(path, PointCloud(np.c_[xy + [1000.0 + shift[0], 2000.0 + shift[1]], z]))
    return path


def _run(args, capsys):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return out.out


def _fields(path, names=None):
    c = read(path)
    names = names or [k for k in c.attributes if k not in ("intensity",)]
    return c.xyz, {k: np.asarray(c.attributes[k]) for k in names if k in c.attributes}


@pytest.mark.parametrize("tile, shift", [(17.0, (0.0, 0.0)), (23.0, (3.7, 11.2))])
def test_ridges_tiled_equals_untiled(tmp_path, capsys, tile, shift):
    """The jets (every Monge coefficient, its sd and test) are the untiled run's; the ridge
    points agree where the lines are traced the same (the crest of the gable)."""
    src = _gable(tmp_path / "in.laz", seed=1, shift=shift)
    _run(["ridges", src, tmp_path / "w.laz", "--radius", "3", "--sigma", SIGMA, "-q"],
         capsys)
    _run(["ridges", src, tmp_path / "t.laz", "--radius", "3", "--sigma", SIGMA, "-q",
          "--tile", tile, "--chunk-points", 2500, "--summary-json", tmp_path / "s.json"],
         capsys)
    xa, a = _fields(tmp_path / "t.laz")
    xb, b = _fields(tmp_path / "w.laz")
    np.testing.assert_array_equal(xa, xb)  # the input's order and coordinates
    ridge_names = {"ridge", "ridge_line", "umbilic", "extremality"}
    _assert_same_jets(a, b, set(b) - ridge_names)
    np.testing.assert_array_equal(a["umbilic"], b["umbilic"])
    assert (b["ridge"] == 3).sum() > 100  # the crease of the gable is found ...
    assert np.mean(a["ridge"] == b["ridge"]) > 0.99  # ... and the same points tiled
    meta = json.loads((tmp_path / "s.json").read_text())
    assert meta["buffer"] == 9.0 and meta["tile"] == tile
    assert meta["crest_points"] == int((a["ridge"] == 1).sum())
    # the lines: every tile's lines in one file, ids unique over the file
    lines = json.loads((tmp_path / "t.ridges.geojson").read_text())["features"]
    assert len(lines) == meta["n_lines"] > 0
    ids = [f["properties"]["line_id"] for f in lines if "line_id" in f["properties"]]
    assert len(ids) == len(set(ids))


@pytest.mark.parametrize("method, tile, shift, options", [
    ("covariance", 13.0, (0.0, 0.0), ["--radius", "1.5"]),
    ("covariance", 17.0, (5.3, 2.9), ["--radius", "1.5"]),
    ("covariance", 29.0, (8.1, 0.4), ["--k", "20"]),
    ("sar", 19.0, (1.1, 6.6), ["--radius", "1.5"]),
    ("curvature", 21.0, (2.2, 4.5), ["--radius", "1.5"]),
])
def test_segment_tiled_keeps_one_id_across_tile_borders(tmp_path, capsys, method, tile,
                                                        shift, options):
    """Each roof plane crosses several tile borders and is one segment tiled, as untiled."""
    src = _gable(tmp_path / "in.laz", seed=2, shift=shift)
    common = ["--method", method, *options, "--sigma", SIGMA, "-q"]
    _run(["segment", src, tmp_path / "w.laz", *common], capsys)
    _run(["segment", src, tmp_path / "t.laz", *common, "--tile", tile,
          "--summary-json", tmp_path / "s.json"], capsys)
    xyz, a = _fields(tmp_path / "t.laz", ["segment_id"])
    _, b = _fields(tmp_path / "w.laz", ["segment_id"])
    a, b = a["segment_id"].astype(np.int64), b["segment_id"].astype(np.int64)
    x = xyz[:, 0] - 1000.0 - shift[0]
    for side in (x < 30, x > 32):  # each plane, away from the ridge, is one id
        ids, counts = np.unique(a[side & (a > 0)], return_counts=True)
        assert counts.max() > 0.99 * (side & (a > 0)).sum(), (ids, counts)
    big = np.unique(a[a > 0], return_counts=True)[1]
    assert (big > 1000).sum() == 2  # two planes, over every tile
    assert _agreement(a, b) > 0.99 and _agreement(b, a) > 0.99
    meta = json.loads((tmp_path / "s.json").read_text())
    table = (tmp_path / "t.segments.csv").read_text().splitlines()
    head = table[0].split(",")
    rows = {int(r.split(",")[0]): int(r.split(",")[head.index("n_points")])
            for r in table[1:]}
    assert len(rows) == meta["n_segments"]
    found = dict(zip(*np.unique(a[a > 0], return_counts=True)))
    assert rows == {int(k): int(v) for k, v in found.items()}  # ids 1.., their sizes
    assert sorted(rows) == list(range(1, len(rows) + 1))


@pytest.mark.parametrize("seed, neighbourhood", [(0, ["--radius", "1.5"]),
                                                 (2, ["--k", "20"])])
def test_covariance_tiled_equals_untiled(tmp_path, capsys, seed, neighbourhood):
    write(tmp_path / "in.laz", _synthetic(seed, n=9000))
    src = tmp_path / "in.laz"
    _run(["covariance", src, tmp_path / "w.laz", *neighbourhood, "--sigma", "0.05", "-q"],
         capsys)
    _run(["covariance", src, tmp_path / "t.laz", *neighbourhood, "--sigma", "0.05", "-q",
          "--tile", "25", "--workers", "2"], capsys)
    _assert_same_fields(_fields(tmp_path / "t.laz"), _fields(tmp_path / "w.laz"))


def test_tiled_decisions_are_made_once_and_printed(tmp_path, capsys):
    src = _gable(tmp_path / "in.laz", seed=3, n=6000)
    out = _run(["ridges", src, tmp_path / "t.laz", "--radius", "3", "--tile", "20"], capsys)
    assert "sigma" in out and "used for every tile" in out and "buffer 9" in out


def test_a_failing_tile_leaves_no_output(tmp_path, capsys, monkeypatch):
    """The output appears when complete: a run stopped by a tile's error leaves neither
    the output nor a scratch file, and an existing output is untouched."""
    import lidarstat.segment

    src = _gable(tmp_path / "in.laz", seed=4, n=6000)
    calls = []

    def broken(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise MemoryError("tile too large")
        return real(*a, **k)

    real = lidarstat.segment.ridges
    monkeypatch.setattr(lidarstat.segment, "ridges", broken)
    rc = main(["ridges", str(src), str(tmp_path / "t.laz"), "--radius", "3", "--sigma",
               "0.02", "--tile", "20", "--scheduler", "sync", "-q"])
    assert rc != 0 and len(calls) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.laz"]
    (tmp_path / "t.laz").write_bytes(b"kept")  # an existing output: replaced only whole
    calls.clear()
    rc = main(["ridges", str(src), str(tmp_path / "t.laz"), "--radius", "3", "--sigma",
               "0.02", "--tile", "20", "--scheduler", "sync", "-q"])
    assert rc != 0 and len(calls) == 2 and (tmp_path / "t.laz").read_bytes() == b"kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.laz", "t.laz"]


@pytest.mark.parametrize("argv, words", [
    (["ridges", "--radius", "3", "--tile", "8"],
     "--tile: invalid value '8': must be larger than the buffer 9"),
    (["segment", "--method", "covariance", "--radius", "1.5", "--tile", "5"],
     "--tile: invalid value '5': must be larger than the buffer 6"),
    (["covariance", "--radius", "2", "--tile", "4"],
     "--tile: invalid value '4': must be larger than the buffer 4"),
    (["segment", "--method", "sar", "--radius", "1.5", "--tile", "20", "--diagnostics",
      "d"], "--diagnostics: not with --tile"),
    (["ridges", "--radius", "3", "--tile", "20", "--report", "r"], "--report: not with --tile"),
])
def test_what_a_tiled_run_cannot_honour_is_refused(tmp_path, capsys, argv, words):
    src = _gable(tmp_path / "in.laz", seed=5, n=3000)
    rc = main([argv[0], str(src), str(tmp_path / "t.laz"), *argv[1:], "--sigma", "0.02"])
    err = capsys.readouterr().err
    assert rc == 2 and words in err, err
    assert len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.laz"]


def test_tile_is_refused_with_a_catalogue(tmp_path, capsys):
    (tmp_path / "tiles").mkdir()
    _gable(tmp_path / "tiles" / "a.laz", n=2000)
    _gable(tmp_path / "tiles" / "b.laz", n=2000, shift=(60.0, 0.0))
    rc = main(["ridges", str(tmp_path / "tiles"), str(tmp_path / "out"), "--tile", "20"])
    assert rc == 2 and "--tile: not with a catalogue" in capsys.readouterr().err
