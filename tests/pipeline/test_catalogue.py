"""Tile catalogues: buffers from neighbours, results independent of the tiling, resume,
Dask (local threads and a ``distributed`` LocalCluster of several worker processes)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError, PointCloudReadError, PointCloudWriteError
from lidarstat.features import curvature
from lidarstat.io import PointCloud, read, write
from lidarstat.pipeline import Catalogue, process_catalogue

RADIUS, SIGMA = 1.5, 0.05


def _cut(cloud: PointCloud, folder, n=3, suffix=".laz"):
    """Write `cloud` as an n x n grid of tiles (every field kept); the tile paths."""
    x, y = cloud.xyz[:, 0], cloud.xyz[:, 1]
    xs = np.linspace(x.min(), x.max(), n + 1)
    ys = np.linspace(y.min(), y.max(), n + 1)
    ix = np.clip(np.searchsorted(xs, x, side="right") - 1, 0, n - 1)
    iy = np.clip(np.searchsorted(ys, y, side="right") - 1, 0, n - 1)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for a in range(n):
        for b in range(n):
            keep = (ix == a) & (iy == b)
            sub = PointCloud(cloud.xyz[keep], {k: np.asarray(v)[keep]
                                               for k, v in cloud.attributes.items()})
            paths.append(write(folder / f"tile_{a}_{b}{suffix}", sub))
    return paths


def _curvature_fields(tile):
    """A local method: every field depends on the points within RADIUS only."""
    return curvature(tile.xyz, radius=RADIUS, sigma=SIGMA).to_fields()


def _synthetic(seed, n=12000, extent=60.0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, extent, (n, 2))
    z = 0.05 * xy[:, 0] + np.sin(xy[:, 1] / 7.0) + rng.normal(0, SIGMA, n)
    return PointCloud(np.c_[xy + [150000.0, 450000.0], z],
                      {"intensity": rng.integers(0, 4000, n).astype(np.uint16)})


def _by_xyz(cloud_fields):
    """Rows keyed by coordinates (tiles reorder points)."""
    xyz, fields = cloud_fields
    order = np.lexsort(xyz.T[::-1])
    return xyz[order], {k: np.asarray(v)[order] for k, v in fields.items()}


def _assert_same_fields(tiled, whole):
    (xa, fa), (xb, fb) = _by_xyz(tiled), _by_xyz(whole)
    np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-9)  # the file's 1 mm grid, exactly
    assert set(fa) == set(fb)
    np.testing.assert_array_equal(fa["neighbors"], fb["neighbors"])
    # Fits on 7-9 points (1-3 residual degrees of freedom) have residuals that are
    # differences of nearly equal numbers: their floats are compared on the decisions only.
    posed = fb["neighbors"] >= 10
    for name in fb:
        a, b = fa[name], fb[name]
        if np.issubdtype(b.dtype, np.floating):
            # The same neighbourhoods, gathered in another order (the cell grid starts at
            # each tile's corner), so float sums round differently: values agree to 1e-6
            # of the field's scale (its 99th percentile of magnitudes).
            scale = np.nanpercentile(np.abs(b), 99) if np.isfinite(b).any() else 1.0
            # The cylinder fit behind `variation_p` refines its axis until a step tilts it
            # by less than 1e-3 rad: a roundoff-sized difference can end the refinement
            # one step apart, which moves the p-value by that step's effect (at most
            # 2.4e-4 of it on the 9,000-point scenes), never the decision.
            rtol = 1e-3 if name == "variation_p" else 1e-6
            np.testing.assert_allclose(a[posed], b[posed], rtol=rtol, atol=1e-6 * scale,
                                       equal_nan=True, err_msg=name)
        else:  # every decision, on every point, is identical
            np.testing.assert_array_equal(a, b, err_msg=name)


def _tiled_result(outdir, paths, names):
    xyz, fields = [], {n: [] for n in names}
    for p in sorted(outdir.iterdir()):
        c = read(p)
        xyz.append(c.xyz)
        for n in names:
            fields[n].append(np.asarray(c.attributes[n]))
    return np.concatenate(xyz), {n: np.concatenate(v) for n, v in fields.items()}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_local_method_does_not_depend_on_the_tiling(tmp_path, seed):
    cloud = _synthetic(seed)
    tiles = _cut(read(write(tmp_path / "whole.laz", cloud)), tmp_path / "tiles")
    whole = read(tmp_path / "whole.laz")
    expected = curvature(whole.xyz, radius=RADIUS, sigma=SIGMA).to_fields()
    runs = process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "out",
                             buffer=RADIUS, scheduler="sync")
    assert [r.status for r in runs] == ["done"] * 9
    assert sum(r.n_points for r in runs) == len(whole.xyz)
    assert all(r.n_buffer > 0 for r in runs)
    _assert_same_fields(_tiled_result(tmp_path / "out", tiles, expected),
                        (whole.xyz, expected))
    # every original field is kept, the buffer is not written
    out = read(tmp_path / "out" / "tile_1_1.laz")
    src = read(tiles[4])
    np.testing.assert_array_equal(out.attributes["intensity"], src.attributes["intensity"])


def test_without_buffer_the_tile_borders_differ(tmp_path):
    """The buffer is what makes the answer independent of the tiling (the test can fail)."""
    cloud = _synthetic(5)
    _cut(read(write(tmp_path / "whole.laz", cloud)), tmp_path / "tiles")
    whole = read(tmp_path / "whole.laz")
    expected = curvature(whole.xyz, radius=RADIUS, sigma=SIGMA).to_fields()
    process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "out", buffer=0.0,
                      scheduler="sync")
    with pytest.raises(AssertionError):
        _assert_same_fields(_tiled_result(tmp_path / "out", None, expected),
                            (whole.xyz, expected))


def test_real_tiles_ahn3(tmp_path, shared_data):
    src = read(shared_data / "ahn3_amsterdam" / "ahn_2386_9702.laz")
    tiles = _cut(src, tmp_path / "tiles")
    assert len(tiles) == 9
    expected = curvature(src.xyz, radius=RADIUS, sigma=SIGMA).to_fields()
    process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "out",
                      buffer=RADIUS, scheduler="threads", workers=2)
    _assert_same_fields(_tiled_result(tmp_path / "out", tiles, expected), (src.xyz, expected))


def test_resume_skips_finished_tiles_after_a_failure(tmp_path):
    _cut(_synthetic(3), tmp_path / "tiles")
    calls = []

    def failing(tile):
        calls.append(tile.n_core)
        if len(calls) == 5:
            raise RuntimeError("stopped")
        return {"n": np.full(len(tile.xyz), tile.n_core, dtype=np.int32)}

    with pytest.raises(RuntimeError):
        process_catalogue(failing, tmp_path / "tiles", tmp_path / "out", buffer=1.0,
                          scheduler="sync")
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert len(written) == 4  # the finished tiles, complete; nothing of the fifth
    mtimes = {p: p.stat().st_mtime_ns for p in (tmp_path / "out").iterdir()}
    runs = process_catalogue(failing, tmp_path / "tiles", tmp_path / "out", buffer=1.0,
                             scheduler="sync")
    assert [r.status for r in runs].count("skipped") == 4
    assert [r.status for r in runs].count("done") == 5
    assert all(p.stat().st_mtime_ns == t for p, t in mtimes.items())
    assert len(list((tmp_path / "out").iterdir())) == 9
    for p in (tmp_path / "out").iterdir():
        c = read(p)
        assert np.all(c.attributes["n"] == len(c.xyz))


def test_dask_threads_and_local_cluster_give_the_threaded_result(tmp_path):
    distributed = pytest.importorskip("distributed", reason="distributed is not installed")
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers lack tests/
    _cut(_synthetic(4, n=6000), tmp_path / "tiles")
    process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "a", buffer=RADIUS,
                      scheduler="threads")
    process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "b", buffer=RADIUS,
                      scheduler="dask")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        runs = process_catalogue(_curvature_fields, tmp_path / "tiles", tmp_path / "c",
                                 buffer=RADIUS, scheduler="dask",
                                 address=cluster.scheduler_address)
    assert [r.status for r in runs] == ["done"] * 9
    for p in sorted((tmp_path / "a").iterdir()):
        a = read(p)
        for other in ("b", "c"):
            o = read(tmp_path / other / p.name)
            np.testing.assert_array_equal(o.xyz, a.xyz)
            for name in ("K", "H", "surface_type", "chi2_pass"):
                np.testing.assert_array_equal(o.attributes[name], a.attributes[name])


def test_inputs_folder_glob_and_list(tmp_path):
    paths = _cut(_synthetic(6, n=2000), tmp_path / "tiles")
    assert len(Catalogue(tmp_path / "tiles")) == 9
    assert len(Catalogue(str(tmp_path / "tiles" / "tile_0_*.laz"))) == 3
    assert len(Catalogue(paths[:2])) == 2
    cat = Catalogue(tmp_path / "tiles")
    assert cat.n_points == 2000
    assert sorted(cat.neighbours(4, 3.0)) == [0, 1, 2, 3, 5, 6, 7, 8]
    assert sorted(cat.neighbours(0, 3.0)) == [1, 3, 4]


@pytest.mark.parametrize("make, error, words", [
    (lambda d, p: Catalogue(d / "nothing"), PointCloudReadError, "no such file or folder"),
    (lambda d, p: Catalogue(str(d / "*.xyz")), PointCloudReadError, "no file matches"),
    (lambda d, p: Catalogue([p[0], p[0]]), PointCloudReadError, "named twice"),
    (lambda d, p: Catalogue(d / "tiles").outputs(d / "tiles", "{stem}.laz"),
     PointCloudWriteError, "is an input"),
    (lambda d, p: Catalogue(d / "tiles").outputs(d / "o", "same.laz"),
     PointCloudWriteError, "output of both"),
    (lambda d, p: Catalogue(d / "tiles").outputs(d / "o", "{nope}.laz"),
     InvalidParameterError, "template"),
    (lambda d, p: Catalogue(d / "tiles").outputs(p[0], "{stem}.laz"),
     PointCloudWriteError, "not a folder"),
])
def test_bad_catalogues_are_refused_before_any_work(tmp_path, make, error, words):
    paths = _cut(_synthetic(7, n=900), tmp_path / "tiles")
    before = {p: p.read_bytes() for p in paths}
    with pytest.raises(error, match=words):
        make(tmp_path, paths)
    assert all(p.read_bytes() == b for p, b in before.items())


def test_copc_tiles_are_read_by_bounds_queries(tmp_path):
    pytest.importorskip("copclib", reason="copclib (writes the COPC test files) is missing")
    sys.path.insert(0, str(Path(__file__).parent))
    from _copc import write_copc

    from lidarstat.io import file_extent, read_window

    las_tiles = _cut(_synthetic(8, n=6000), tmp_path / "las")
    (tmp_path / "copc").mkdir()
    for p in las_tiles:
        c = read(p)
        write_copc(tmp_path / "copc" / (p.stem + ".copc.laz"), c.xyz,
                   c.attributes["intensity"], scale=c.las_header.scales.tolist())
    extent = file_extent(tmp_path / "copc" / "tile_0_0.copc.laz")
    assert extent.copc and extent.n_points == len(read(las_tiles[0]).xyz)
    window = (extent.xmin, extent.ymin, extent.xmin + 7.0, extent.ymin + 5.0)
    got = read_window(extent.path, window)
    want = read_window(las_tiles[0], window)
    assert len(got.xyz) == len(want.xyz) > 0
    np.testing.assert_allclose(got.xyz[np.lexsort(got.xyz.T[::-1])],
                               want.xyz[np.lexsort(want.xyz.T[::-1])], atol=1e-9)
    runs = process_catalogue(_curvature_fields, tmp_path / "copc", tmp_path / "out",
                             buffer=RADIUS, scheduler="sync",
                             template="{stem}_curvature.laz")
    assert sorted(r.output.name for r in runs)[0] == "tile_0_0_curvature.laz"
    process_catalogue(_curvature_fields, tmp_path / "las", tmp_path / "ref", buffer=RADIUS,
                      scheduler="sync")
    for p in sorted((tmp_path / "ref").iterdir()):
        a = read(p)
        b = read(tmp_path / "out" / (p.stem + "_curvature.laz"))
        ia, ib = np.lexsort(a.xyz.T[::-1]), np.lexsort(b.xyz.T[::-1])
        np.testing.assert_allclose(b.xyz[ib], a.xyz[ia], atol=1e-9)
        np.testing.assert_array_equal(b.attributes["surface_type"][ib],
                                      a.attributes["surface_type"][ia])


@pytest.mark.parametrize("size", [7.0, 20.0, 25.5])
def test_write_tiles_partitions_the_cloud_on_a_fixed_grid(tmp_path, size):
    from lidarstat.pipeline import write_tiles

    cloud = _synthetic(9, n=3000)
    paths = write_tiles(cloud, tmp_path / "t", size=size)
    parts = [read(p) for p in paths]
    assert sum(len(p.xyz) for p in parts) == len(cloud.xyz)
    q = 1e-4  # the files' coordinate step
    for p, part in zip(paths, parts):
        col, row = (int(v) for v in p.stem.split("_")[1:])
        for axis, k in ((0, col), (1, row)):
            assert np.all((part.xyz[:, axis] >= k * size - q)
                          & (part.xyz[:, axis] < (k + 1) * size + q))
    every = np.round(np.concatenate([p.xyz for p in parts]) / q).astype(np.int64)
    truth = np.round(cloud.xyz / q).astype(np.int64)
    np.testing.assert_array_equal(every[np.lexsort(every.T[::-1])],
                                  truth[np.lexsort(truth.T[::-1])])
    got = np.concatenate([np.asarray(p.attributes["intensity"]) for p in parts])
    assert sorted(got.tolist()) == sorted(np.asarray(cloud.attributes["intensity"]).tolist())
