"""Out-of-core tiles: a streamed, tiled run writes what the in-memory run writes."""

import numpy as np
import pytest

from lidarstat.errors import InvalidPointsError
from lidarstat.features import curvature
from lidarstat.io import PointCloud, read, rewrite, write
from lidarstat.pipeline import process_file


@pytest.fixture
def surface_las(tmp_path, rng):
    g = np.arange(0, 5, 0.05)
    x, y = np.meshgrid(g, g)
    z = 0.3 * np.sin(x) * np.cos(0.8 * y) + rng.normal(0, 0.002, x.shape)
    xyz = np.c_[x.ravel(), y.ravel(), z.ravel()] + [4.5e5, 5.7e6, 10.0]
    xyz = xyz[rng.permutation(len(xyz))]  # file order unrelated to space
    path = tmp_path / "in.laz"
    attrs = {"intensity": rng.integers(0, 60000, len(xyz)).astype(np.uint16),
             "classification": np.full(len(xyz), 2, np.uint8)}
    write(path, PointCloud(xyz=xyz, attributes=attrs, crs="EPSG:28992"))
    return path


@pytest.mark.parametrize("scheduler", ["sync", "threads", "dask"])
def test_streamed_tiles_equal_whole_run(surface_las, tmp_path, scheduler):
    if scheduler == "dask":
        pytest.importorskip("dask", reason="dask is not installed")
    radius = 0.16

    def run(p):
        return curvature(p, radius=radius, sigma=0.002)

    src = read(surface_las)
    whole = run(src.xyz).to_fields()
    before = surface_las.read_bytes()
    out = tmp_path / "out.laz"
    seen = []
    process_file(run, surface_las, out, size=1.3, halo=radius, scheduler=scheduler,
                 workers=2, points_per_chunk=1700, progress=lambda d, n: seen.append(d))
    assert surface_las.read_bytes() == before
    res = read(out)
    assert len(res) == len(src) and seen[-1] == len(src)
    np.testing.assert_array_equal(res.attributes["intensity"], src.attributes["intensity"])
    np.testing.assert_allclose(res.xyz, src.xyz, atol=1e-4)
    assert res.crs == src.crs and res.crs
    hdr = res.las_header
    np.testing.assert_allclose(hdr.mins, src.xyz.min(axis=0), atol=1e-3)
    np.testing.assert_allclose(hdr.maxs, src.xyz.max(axis=0), atol=1e-3)
    for name in ("K", "H", "sigma0_sq", "neighbors", "surface_type", "chi2_pass"):
        np.testing.assert_allclose(res.attributes[name], whole[name], rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    # No scratch files are left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.laz", "out.laz"]


def test_rewrite_streams_and_other_formats(surface_las, tmp_path):
    src = read(surface_las)
    out = tmp_path / "o.las"
    rewrite(surface_las, out, lambda s, c: {"rank": np.arange(s, s + len(c))},
            points_per_chunk=999)
    assert np.array_equal(read(out).attributes["rank"], np.arange(len(src)))
    ply = tmp_path / "o.ply"
    rewrite(surface_las, ply, lambda s, c: {"rank": np.arange(s, s + len(c))})
    assert np.array_equal(read(ply).attributes["rank"], np.arange(len(src)))


def test_empty_and_nan_inputs(tmp_path):
    empty = tmp_path / "empty.las"
    write(empty, PointCloud(xyz=np.empty((0, 3)), attributes={}))
    with pytest.raises(InvalidPointsError, match="empty.las"):
        process_file(lambda p: {}, empty, tmp_path / "o.las", size=1.0, halo=0.1)
    assert not (tmp_path / "o.las").exists()
