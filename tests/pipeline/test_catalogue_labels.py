"""Label fields joined across the tile files of a catalogue: the join of one file's
``--tile`` run (same records, same rule), whatever the scheduler; outputs only when the
join is done; a stopped run resumed from the tiles' records."""

import numpy as np
import pytest

from lidarstat.errors import PointCloudWriteError
from lidarstat.io import PointCloud, read, write
from lidarstat.pipeline import process_catalogue, process_file

STRIP = 2.0  # width (y) of each strip: the "surfaces" the tile functions label
X0, Y0 = 3.0e5, 6.1e6


def _cloud(tmp_path, seed=7, n=6000):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, [12.0, 10.0], (n, 2))
    path = write(tmp_path / "whole.laz",
                 PointCloud(np.c_[xy + [X0, Y0], rng.normal(0, 0.01, n)]))
    return path, read(path).xyz


def _cut(xyz, folder, size):
    """Tiles of `size` on the grid of ``process_file`` (from the points' lower-left)."""
    lo = xyz[:, :2].min(axis=0)
    key = np.floor((xyz[:, :2] - lo) / size).astype(np.int64)
    folder.mkdir()
    for k in np.unique(key, axis=0):
        keep = np.all(key == k, axis=1)
        write(folder / f"t_{k[0]:02d}_{k[1]:02d}.laz", PointCloud(xyz[keep]))
    return lo


def _strips(xyz, key, seed, jitter, phase):
    """Each strip of y labelled, numbered at random per tile `key`, its borders moved by
    up to `jitter` per tile, the points of a hole labelled 0."""
    g = np.random.default_rng([seed, *key])
    y = xyz[:, 1] - Y0 - phase + g.uniform(-jitter, jitter)
    strip = np.clip(np.floor(y / STRIP), -1, 5).astype(np.int64) + 1
    lab = (g.permutation(7) + 1 + g.integers(0, 3))[strip]
    lab[np.hypot(xyz[:, 0] - X0 - 6.0, xyz[:, 1] - Y0 - 5.0) < 0.7] = 0
    return lab.astype(np.uint32)


def _tile_functions(seed, jitter, phase, lo, size):
    def in_file(xyz, tile):
        return {"seg": _strips(xyz, tile.key, seed, jitter, phase)}

    def in_catalogue(tile):  # the same tile's key: the grid square of its points
        key = tuple(np.floor((np.median(tile.core.xyz[:, :2], axis=0) - lo) / size)
                    .astype(int).tolist())
        return {"seg": _strips(tile.xyz, key, seed, jitter, phase)}

    return in_file, in_catalogue


def _by_point(folder, field="seg"):
    xyz, lab = [], []
    for p in sorted(folder.glob("*.laz")):
        c = read(p)
        xyz.append(c.xyz)
        lab.append(np.asarray(c.attributes[field]).astype(np.int64))
    xyz, lab = np.concatenate(xyz), np.concatenate(lab)
    key = np.round(xyz * 1000).astype(np.int64)
    order = np.lexsort(key.T[::-1])
    return key[order], lab[order]


def _same_partition(a, b):
    pairs = np.unique(np.c_[a, b], axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


@pytest.mark.parametrize("seed", range(6))
def test_catalogue_join_equals_the_tiled_file(tmp_path, seed):
    """Tile files cut on the grid of ``process_file``: the catalogue's joined labels are
    the tiled file's (as a partition of the points), every strip one id, over a sweep
    of tile sizes, buffers and strip offsets."""
    g = np.random.default_rng(seed)
    size, halo, phase = g.uniform(1.7, 4.5), g.uniform(0.3, 0.8), g.uniform(0, STRIP)
    path, xyz = _cloud(tmp_path)
    lo = _cut(xyz, tmp_path / "tiles", size)
    in_file, in_catalogue = _tile_functions(seed, 0.05, phase, lo, size)
    process_file(in_file, path, tmp_path / "file.laz", size=size, halo=halo, with_tile=True,
                 labels={"seg": True})
    runs = process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / "out",
                             buffer=halo, labels={"seg": True}, scheduler="sync")
    assert {r.status for r in runs} == {"done"}
    key, cat = _by_point(tmp_path / "out")
    c = read(tmp_path / "file.laz")
    fkey = np.round(c.xyz * 1000).astype(np.int64)
    order = np.lexsort(fkey.T[::-1])
    np.testing.assert_array_equal(fkey[order], key)
    tiled = np.asarray(c.attributes["seg"]).astype(np.int64)[order]
    assert _same_partition(cat, tiled)
    np.testing.assert_array_equal(cat == 0, tiled == 0)
    y = key[:, 1] / 1000 - Y0 - phase
    clear = (np.abs(y - STRIP * np.round(y / STRIP)) > 0.05) & (cat > 0)
    truth = np.floor(y / STRIP).astype(np.int64)
    whole = range(int((10.0 - phase) // STRIP))  # the strips of full width
    ids = [np.unique(cat[clear & (truth == s)]) for s in whole]
    assert all(len(i) == 1 for i in ids), ids  # each strip one id over the area
    assert len({int(i[0]) for i in ids}) == len(ids) >= 4
    n = len(np.unique(cat[cat > 0]))
    assert sorted(np.unique(cat[cat > 0]).tolist()) == list(range(1, n + 1))
    assert not (tmp_path / "out" / ".lidarstat-pending").exists()


def test_touching_labels_are_not_joined(tmp_path):
    """Tiles disagreeing on a wide band of border points (a tenth of a strip) keep the
    strips apart, as in one file: a join needs most of the overlap."""
    _, xyz = _cloud(tmp_path)
    lo = _cut(xyz, tmp_path / "tiles", 3.0)
    _, in_catalogue = _tile_functions(11, 0.2, 0.0, lo, 3.0)
    process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / "out", buffer=0.5,
                      labels={"seg": True})
    key, cat = _by_point(tmp_path / "out")
    y = key[:, 1] / 1000 - Y0
    clear = (np.abs(y - STRIP * np.round(y / STRIP)) > 0.2) & (cat > 0)
    truth = np.floor(y / STRIP).astype(np.int64)
    pairs = np.unique(np.c_[cat[clear], truth[clear]], axis=0)
    assert len(np.unique(pairs[:, 0])) == len(pairs)  # no id over two strips
    assert len(np.unique(pairs[:, 1])) == 5 == len(pairs)  # each strip one id


def test_schedulers_give_the_same_ids(tmp_path):
    _, xyz = _cloud(tmp_path, seed=3)
    lo = _cut(xyz, tmp_path / "tiles", 2.5)
    _, in_catalogue = _tile_functions(5, 0.05, 0.7, lo, 2.5)
    schedulers = ["sync", "threads"]
    try:
        import dask  # noqa: F401

        schedulers.append("dask")
    except ImportError:  # pragma: no cover - dask is optional
        pass
    results = []
    for s in schedulers:
        process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / s, buffer=0.6,
                          labels={"seg": True}, scheduler=s, workers=3)
        results.append({p.name: np.asarray(read(p).attributes["seg"])
                        for p in sorted((tmp_path / s).glob("*.laz"))})
    for other in results[1:]:
        assert other.keys() == results[0].keys()
        for name in other:
            np.testing.assert_array_equal(other[name], results[0][name])


def test_outputs_appear_after_the_join_and_a_failure_leaves_none(tmp_path):
    """Nothing is in OUT while the join is pending; a failing tile leaves no output, and
    the rerun runs only the tiles without a record, giving a clean run's result."""
    _, xyz = _cloud(tmp_path, seed=4)
    lo = _cut(xyz, tmp_path / "tiles", 3.0)
    _, in_catalogue = _tile_functions(2, 0.05, 0.3, lo, 3.0)
    n_tiles = len(list((tmp_path / "tiles").glob("*.laz")))
    seen, calls = [], []

    def collect(index, info, bases):
        seen.append(index)

    def finish(maps):
        assert not list((tmp_path / "ref").glob("*.laz"))  # the join before any output
        assert maps["seg"].final.max() == 6

    process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / "ref", buffer=0.5,
                      labels={"seg": True}, collect=collect, finish=finish)
    assert seen == list(range(n_tiles))  # catalogue order, whatever finished first

    def failing(tile):
        calls.append(tile.n_core)
        if len(calls) == 5 and not seen[n_tiles:]:
            raise RuntimeError("stopped")
        return in_catalogue(tile)

    with pytest.raises(RuntimeError):
        process_catalogue(failing, tmp_path / "tiles", tmp_path / "out", buffer=0.5,
                          labels={"seg": True}, scheduler="sync")
    # no output: only the tiles' records, in the hidden pending folder
    assert [p.name for p in (tmp_path / "out").iterdir()] == [".lidarstat-pending"]
    assert len(list((tmp_path / "out" / ".lidarstat-pending").glob("*.join"))) == 4
    calls.clear()
    seen.append("rerun")
    runs = process_catalogue(failing, tmp_path / "tiles", tmp_path / "out", buffer=0.5,
                             labels={"seg": True}, scheduler="sync")
    assert len(calls) == n_tiles - 4
    assert [r.status for r in runs].count("resumed") == 4
    assert not (tmp_path / "out" / ".lidarstat-pending").exists()
    for p in sorted((tmp_path / "ref").glob("*.laz")):
        np.testing.assert_array_equal(read(tmp_path / "out" / p.name).attributes["seg"],
                                      read(p).attributes["seg"])


def test_a_run_stopped_while_writing_is_finished_by_the_rerun(tmp_path, monkeypatch):
    """Stopped after some outputs are written: the rerun joins the same records again and
    writes the missing outputs, leaving the written ones untouched."""
    from lidarstat.pipeline import _catalogue_join

    _, xyz = _cloud(tmp_path, seed=5)
    lo = _cut(xyz, tmp_path / "tiles", 3.0)
    _, in_catalogue = _tile_functions(3, 0.05, 1.1, lo, 3.0)
    process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / "ref", buffer=0.5,
                      labels={"seg": True})
    real, written = _catalogue_join.rewrite, []

    def stopping(*args, **kwargs):
        if len(written) == 3:
            raise KeyboardInterrupt
        written.append(real(*args, **kwargs))

    monkeypatch.setattr(_catalogue_join, "rewrite", stopping)
    with pytest.raises(KeyboardInterrupt):
        process_catalogue(in_catalogue, tmp_path / "tiles", tmp_path / "out", buffer=0.5,
                          labels={"seg": True})
    monkeypatch.setattr(_catalogue_join, "rewrite", real)
    assert len(list((tmp_path / "out").glob("*.laz"))) == 3
    mtimes = {p: p.stat().st_mtime_ns for p in written}
    calls = []
    runs = process_catalogue(lambda t: calls.append(1) or in_catalogue(t), tmp_path / "tiles",
                             tmp_path / "out", buffer=0.5, labels={"seg": True})
    assert not calls and {r.status for r in runs} == {"resumed"}
    assert all(p.stat().st_mtime_ns == t for p, t in mtimes.items())
    for p in sorted((tmp_path / "ref").glob("*.laz")):
        np.testing.assert_array_equal(read(tmp_path / "out" / p.name).attributes["seg"],
                                      read(p).attributes["seg"])


def test_resume_of_a_complete_run_and_of_a_partial_folder(tmp_path):
    """A complete run is skipped whole; an output without its tile's record (an earlier
    run's) cannot be joined with tiles run now: refused until overwritten."""
    _, xyz = _cloud(tmp_path, seed=6, n=3000)
    lo = _cut(xyz, tmp_path / "tiles", 4.0)
    _, in_catalogue = _tile_functions(4, 0.05, 0.0, lo, 4.0)
    args = (in_catalogue, tmp_path / "tiles", tmp_path / "out")
    process_catalogue(*args, buffer=0.5, labels={"seg": True})
    outputs = sorted((tmp_path / "out").glob("*.laz"))
    mtimes = {p: p.stat().st_mtime_ns for p in outputs}
    runs = process_catalogue(*args, buffer=0.5, labels={"seg": True})
    assert {r.status for r in runs} == {"skipped"}
    assert all(p.stat().st_mtime_ns == t for p, t in mtimes.items())
    before = np.asarray(read(outputs[1]).attributes["seg"])
    outputs[0].unlink()
    with pytest.raises(PointCloudWriteError, match="--overwrite"):
        process_catalogue(*args, buffer=0.5, labels={"seg": True})
    assert not outputs[0].exists()
    runs = process_catalogue(*args, buffer=0.5, labels={"seg": True}, resume=False)
    assert {r.status for r in runs} == {"done"} and outputs[0].exists()
    np.testing.assert_array_equal(read(outputs[1]).attributes["seg"], before)


def test_copc_tiles_are_joined_as_their_las_tiles(tmp_path):
    """A COPC tile's buffer points are numbered by their place in the file (streamed, the
    octree does not number them): the join is the LAS tiles' join."""
    pytest.importorskip("copclib", reason="copclib (writes the COPC test files) is missing")
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from _copc import write_copc

    _, xyz = _cloud(tmp_path, seed=8, n=4000)
    lo = _cut(xyz, tmp_path / "tiles", 4.0)
    (tmp_path / "copc").mkdir()
    for p in sorted((tmp_path / "tiles").glob("*.laz")):
        c = read(p)
        write_copc(tmp_path / "copc" / p.name, c.xyz, np.zeros(len(c.xyz), np.uint16),
                   scale=c.las_header.scales.tolist())
    _, in_catalogue = _tile_functions(9, 0.05, 0.4, lo, 4.0)
    for name in ("tiles", "copc"):
        process_catalogue(in_catalogue, tmp_path / name, tmp_path / f"out_{name}",
                          buffer=0.6, labels={"seg": True}, scheduler="sync")
    (ka, a), (kb, b) = _by_point(tmp_path / "out_tiles"), _by_point(tmp_path / "out_copc")
    np.testing.assert_array_equal(ka, kb)
    assert _same_partition(a, b) and len(np.unique(a[a > 0])) >= 5


def test_records_of_other_options_are_run_again_not_joined(tmp_path):
    """A run stopped with one set of options, rerun with another (its ``run_key``): every
    tile runs again and the result is a clean run's of the second options, never a join
    of tiles run with different options."""
    _, xyz = _cloud(tmp_path, seed=8)
    lo = _cut(xyz, tmp_path / "tiles", 3.0)
    _, first = _tile_functions(1, 0.05, 0.3, lo, 3.0)
    _, second = _tile_functions(2, 0.05, 0.9, lo, 3.0)
    n_tiles = len(list((tmp_path / "tiles").glob("*.laz")))
    process_catalogue(second, tmp_path / "tiles", tmp_path / "ref", buffer=0.5,
                      labels={"seg": True}, run_key="b")
    calls = []

    def failing(tile):
        calls.append(1)
        if len(calls) == 4:
            raise RuntimeError("stopped")
        return first(tile)

    with pytest.raises(RuntimeError):
        process_catalogue(failing, tmp_path / "tiles", tmp_path / "out", buffer=0.5,
                          labels={"seg": True}, scheduler="sync", run_key="a")
    assert len(list((tmp_path / "out" / ".lidarstat-pending").glob("*.join"))) == 3
    calls.clear()
    runs = process_catalogue(lambda t: calls.append(1) or second(t), tmp_path / "tiles",
                             tmp_path / "out", buffer=0.5, labels={"seg": True},
                             scheduler="sync", run_key="b")
    assert len(calls) == n_tiles and {r.status for r in runs} == {"done"}
    for p in sorted((tmp_path / "ref").glob("*.laz")):
        np.testing.assert_array_equal(read(tmp_path / "out" / p.name).attributes["seg"],
                                      read(p).attributes["seg"])
