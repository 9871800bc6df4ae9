"""``segment`` on a catalogue: a surface crossing tile borders keeps one id over the area,
two surfaces meeting at a border stay two, the result is one file's ``--tile`` run with
the same tiling, and every tile's table and lines name the final ids."""

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from lidarstat.io import PointCloud, read, write

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_catalogue_methods import _agreement
from test_tiled import SIGMA, _gable, _run

COMMON = ["--method", "covariance", "--radius", "1.5", "--sigma", str(SIGMA), "-q"]


def _plane(path, seed=0, n=9000):
    """One tilted plane over 60 x 60 m, noise SIGMA; file order random."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 60, (n, 2))
    z = 5 + 0.1 * xy[:, 0] + 0.05 * xy[:, 1] + rng.normal(0, SIGMA, n)
    return write(path, PointCloud(np.c_[xy + [1000.0, 2000.0], z]))


def _cut(src, folder, xs=(), ys=(), origin=(1000.0, 2000.0)):
    """Tile files of `src` cut at the borders x = origin + xs, y = origin + ys."""
    xyz = read(src).xyz
    col = np.searchsorted(np.asarray(xs, float) + origin[0], xyz[:, 0])
    row = np.searchsorted(np.asarray(ys, float) + origin[1], xyz[:, 1])
    folder.mkdir()
    for c in np.unique(col):
        for r in np.unique(row):
            keep = (col == c) & (row == r)
            if keep.any():
                write(folder / f"t_{c}_{r}.laz", PointCloud(xyz[keep]))
    return folder


def _gather(folder):
    xyz, ids = [], []
    for p in sorted(folder.glob("*.laz")):
        c = read(p)
        xyz.append(c.xyz)
        ids.append(np.asarray(c.attributes["segment_id"]).astype(np.int64))
    xyz, ids = np.concatenate(xyz), np.concatenate(ids)
    order = np.lexsort(np.round(xyz * 1000).T[::-1])
    return xyz[order], ids[order]


def _tables(folder):
    rows = {}
    for p in sorted(folder.glob("*.segments.csv")):
        with open(p, newline="") as fh:
            rows[p.name] = {int(r["segment_id"]): r for r in csv.DictReader(fh)}
    return rows


@pytest.mark.parametrize("xs, ys", [((30.0,), ()), ((20.0, 40.0), ()), ((30.0,), (30.0,))],
                         ids=["one border", "two borders", "corner"])
def test_a_plane_crossing_tile_borders_keeps_one_id(tmp_path, capsys, xs, ys):
    tiles = _cut(_plane(tmp_path / "in.laz"), tmp_path / "tiles", xs, ys)
    _run(["segment", tiles, tmp_path / "out", *COMMON], capsys)
    _, ids = _gather(tmp_path / "out")
    found, counts = np.unique(ids[ids > 0], return_counts=True)
    assert counts.max() > 0.99 * (ids > 0).sum() and (ids > 0).mean() > 0.95
    big = int(found[np.argmax(counts)])
    # every tile's table lists the plane under its id with its points over the area
    tables = _tables(tmp_path / "out")
    assert len(tables) == len(list(tiles.glob("*.laz")))
    for rows in tables.values():
        assert int(rows[big]["n_points"]) == counts.max()
        for sid, row in rows.items():  # each row is the segment's, whatever the tile
            assert row == next(iter(tables.values())).get(sid, row)


def test_two_planes_meeting_at_a_tile_border_stay_two(tmp_path, capsys):
    """The ridge of the gable (x = 31) is a tile border: the two roof planes share only
    their boundary points there and keep two ids; each keeps one over its tiles."""
    tiles = _cut(_gable(tmp_path / "in.laz", seed=2), tmp_path / "tiles", (31.0,), (30.0,))
    _run(["segment", tiles, tmp_path / "out", *COMMON], capsys)
    xyz, ids = _gather(tmp_path / "out")
    x = xyz[:, 0] - 1000.0
    planes = []
    for side in (x < 30, x > 32):
        found, counts = np.unique(ids[side & (ids > 0)], return_counts=True)
        assert counts.max() > 0.99 * (side & (ids > 0)).sum(), (found, counts)
        planes.append(int(found[np.argmax(counts)]))
    assert planes[0] != planes[1]
    lines = [f["properties"] for p in sorted((tmp_path / "out").glob("*.lines.geojson"))
             for f in json.loads(p.read_text())["features"]]
    assert {(d["segment_a"], d["segment_b"]) for d in lines} <= {tuple(planes),
                                                                  tuple(planes[::-1])}
    assert lines  # the ridge line between the two planes, named by their final ids


@pytest.mark.parametrize("tile, shift", [(20.0, (0.0, 0.0)), (23.0, (3.7, 11.2))])
def test_a_catalogue_gives_the_tiled_file_result(tmp_path, capsys, tile, shift):
    """The tiles of ``--tile`` as files of a catalogue: the same segments."""
    src = _gable(tmp_path / "in.laz", seed=3, shift=shift)
    lo = read(src).xyz[:, :2].min(axis=0)
    borders = np.arange(tile, 60.0, tile)
    tiles = _cut(src, tmp_path / "tiles", borders, borders, origin=lo)
    _run(["segment", src, tmp_path / "t.laz", *COMMON, "--tile", tile], capsys)
    _run(["segment", tiles, tmp_path / "out", *COMMON], capsys)
    _, a = _gather(tmp_path / "out")
    c = read(tmp_path / "t.laz")
    order = np.lexsort(np.round(c.xyz * 1000).T[::-1])
    b = np.asarray(c.attributes["segment_id"]).astype(np.int64)[order]
    assert _agreement(a, b) > 0.995 and _agreement(b, a) > 0.995
    big = [np.sort(np.unique(v[v > 0], return_counts=True)[1])[-2:] for v in (a, b)]
    np.testing.assert_allclose(big[0], big[1], rtol=0.01)  # the two planes, whole


def test_schedulers_give_the_same_ids(tmp_path, capsys):
    tiles = _cut(_gable(tmp_path / "in.laz", seed=4, n=6000), tmp_path / "tiles",
                 (20.0, 40.0), (30.0,))
    _run(["segment", tiles, tmp_path / "a", *COMMON, "--scheduler", "sync"], capsys)
    _run(["segment", tiles, tmp_path / "b", *COMMON, "--scheduler", "threads",
          "--workers", "2"], capsys)
    for p in sorted((tmp_path / "a").iterdir()):
        if p.suffix == ".laz":
            np.testing.assert_array_equal(read(tmp_path / "b" / p.name)["segment_id"],
                                          read(p)["segment_id"])
        else:
            assert (tmp_path / "b" / p.name).read_text() == p.read_text()


def test_a_pending_record_is_resumed_only_with_the_same_options():
    """The key of a catalogue run (``_run_key``) changes with an option that shapes the
    segments or with what the run chose from the data, not with how it runs."""
    from lidarstat.cli._app import build_parser
    from lidarstat.cli._catalogue import _run_key

    def key(*extra, chosen=None):
        args = build_parser().parse_args(["segment", "tiles", "out", *COMMON, *extra])
        return _run_key("segment", args, chosen or {})

    base = key()
    assert key("--workers", "1", "--scheduler", "sync") == base
    assert key("--radius", "1.6") != base
    assert key("--alpha", "0.01") != base
    assert key(chosen={"scales": np.array([1.0, 2.0])}) != key(
        chosen={"scales": np.array([1.0, 2.5])})
