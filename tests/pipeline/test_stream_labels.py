"""Label fields of a streamed, tiled run: ids unique over the file, and joined across tiles
where two tiles label the same points of their overlap (a surface crossing a tile border
keeps one id; surfaces that only touch stay apart)."""

import numpy as np
import pytest

from lidarstat.io import PointCloud, read, write
from lidarstat.pipeline import process_file, sample_file

STRIP = 2.0  # width (y) of each strip: the "surfaces" the tile function labels


@pytest.fixture
def strips(tmp_path):
    """Points over 12 x 10 in five strips of y; file order unrelated to space."""
    rng = np.random.default_rng(7)
    n = 6000
    xy = rng.uniform(0, [12.0, 10.0], (n, 2))
    xyz = np.c_[xy + [3.0e5, 6.1e6], rng.normal(0, 0.01, n)]
    path = tmp_path / "strips.laz"
    write(path, PointCloud(xyz))
    return path, read(path).xyz


def _labeller(jitter: float, seed: int):
    """A tile function labelling each strip, numbered at random within each tile (the
    numbers mean nothing across tiles), its borders moved by up to `jitter` per tile (so
    neighbouring tiles disagree on the points near a strip border) and the points of a
    hole labelled 0."""

    def label(xyz, tile):
        g = np.random.default_rng([seed, *tile.key])
        y = xyz[:, 1] - 6.1e6 + g.uniform(-jitter, jitter)
        strip = np.clip(np.floor(y / STRIP), 0, 4).astype(np.int64)
        numbers = g.permutation(5) + 1 + g.integers(0, 3)
        lab = numbers[strip]
        hole = np.hypot(xyz[:, 0] - 3.0e5 - 6.0, y - 5.0) < 0.7
        lab[hole] = 0
        return {"seg": lab.astype(np.uint32), "local": lab.astype(np.int32)}

    return label


@pytest.mark.parametrize("seed", range(6))
def test_joined_labels_are_the_strips_whatever_the_tiling(strips, tmp_path, seed):
    path, xyz = strips
    g = np.random.default_rng(seed)
    size = g.uniform(1.7, 4.5)  # tile sizes and grid offsets of the sweep
    halo = g.uniform(0.3, 0.8)
    jitter = 0.05
    out = tmp_path / "out.laz"
    maps = {}
    process_file(_labeller(jitter, seed), path, out, size=size, halo=halo,
                 points_per_chunk=int(g.integers(700, 2500)), with_tile=True,
                 labels={"seg": True, "local": False}, finish=maps.update)
    res = read(out)
    seg = np.asarray(res.attributes["seg"]).astype(np.int64)
    assert res.attributes["seg"].dtype == np.uint32
    y = xyz[:, 1] - 6.1e6
    truth = np.floor(y / STRIP).astype(np.int64)
    hole = np.hypot(xyz[:, 0] - 3.0e5 - 6.0, y - 5.0) < 0.7 + jitter
    clear = ~hole & (np.abs(y - STRIP * np.round(y / STRIP)) > jitter)
    # every strip is one id over the whole file, and distinct strips have distinct ids
    ids = [np.unique(seg[clear & (truth == s)]) for s in range(5)]
    assert all(len(i) == 1 and i[0] > 0 for i in ids), ids
    assert len({int(i[0]) for i in ids}) == 5
    assert set(np.unique(seg).tolist()) <= {0, 1, 2, 3, 4, 5}  # numbered 1.. over the file
    assert np.all(seg[np.hypot(xyz[:, 0] - 3.0e5 - 6.0, y - 5.0) < 0.7 - jitter] == 0)
    # the map handed to `finish`: the core points of each id are the points written
    m = maps["seg"]
    totals = np.bincount(m.final, weights=m.core_points, minlength=6)
    np.testing.assert_array_equal(totals[1:], np.bincount(seg, minlength=6)[1:])
    # a field that is not joined keeps one id per tile and label, unique over the file
    local = np.asarray(res.attributes["local"]).astype(np.int64)
    assert res.attributes["local"].dtype == np.int32
    pairs = np.unique(np.c_[local[local > 0], seg[local > 0]], axis=0)
    assert len(np.unique(pairs[:, 0])) == len(pairs)  # each local id in one strip
    assert len(np.unique(local[local > 0])) > 5  # strips cut at the tile borders


def test_touching_labels_are_not_joined(strips, tmp_path):
    """Two tiles that disagree on a wide band of border points (a tenth of a strip) still
    keep the strips apart: a join needs most of the overlap, not a few points."""
    path, _ = strips
    out = tmp_path / "out.laz"
    process_file(_labeller(0.2, 11), path, out, size=3.0, halo=0.5, with_tile=True,
                 labels={"seg": True})
    seg = np.asarray(read(out).attributes["seg"])
    assert len(np.unique(seg[seg > 0])) == 5


def test_sample_file_takes_tiles_spread_over_the_file(strips):
    path, xyz = strips
    sample = sample_file(path, 3.0, count=4, points_per_chunk=1000)
    assert len(sample) == 4 and sample.n_points == len(xyz)
    for i, f in enumerate(sample.files):
        pts = sample.tile_xyz(i)
        x0, y0, x1, y1 = f.bounds
        assert len(pts) == f.n_points > 0
        assert np.all((pts[:, 0] >= x0) & (pts[:, 0] < x1) & (pts[:, 1] >= y0)
                      & (pts[:, 1] < y1))
        inside = ((xyz[:, 0] >= x0) & (xyz[:, 0] < x1) & (xyz[:, 1] >= y0)
                  & (xyz[:, 1] < y1))
        assert inside.sum() == len(pts)
    assert len({f.bounds for f in sample.files}) == 4
