"""No valid input is refused by the structure checks: every LAS version and point format
with extra bytes, LAZ, PLY, CSV/TXT, NPZ, UTM-sized coordinates, and the real files."""

from __future__ import annotations

import laspy
import numpy as np
import plyfile
import pytest
from conftest import SHARED_DATA

import lidarstat.io as lio
from lidarstat.io._las_checks import check_las

VERSION_FORMATS = [("1.2", pf) for pf in range(4)] + [("1.3", pf) for pf in range(6)] + [
    ("1.4", pf) for pf in range(11)]
N = 257
UTM = np.array([699_512.25, 5_710_020.5, 48.0])  # UTM 31N-sized values


def _utm_xyz(rng, n=N):
    return UTM + rng.uniform(0, 1000, (n, 3)).round(3)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
@pytest.mark.parametrize(("version", "pf"), VERSION_FORMATS)
def test_every_point_format_with_extra_bytes(tmp_path, rng, version, pf, suffix):
    header = laspy.LasHeader(version=version, point_format=pf)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(UTM)
    header.add_extra_dims([laspy.ExtraBytesParams("dev", "f4"),
                           laspy.ExtraBytesParams("normal", "3f8"),
                           laspy.ExtraBytesParams("tag", "u2")])
    las = laspy.LasData(header)
    xyz = _utm_xyz(rng)
    las.x, las.y, las.z = xyz.T
    las.dev = rng.normal(size=N).astype(np.float32)
    las.normal = rng.normal(size=(N, 3))
    las.tag = rng.integers(0, 65535, N)
    path = tmp_path / f"f{pf}{suffix}"
    las.write(path)
    layout = check_las(path, suffix[1:])
    assert (layout.point_format, layout.point_count) == (pf, N)
    assert layout.compressed == (suffix == ".laz")
    cloud = lio.read(path)
    np.testing.assert_allclose(cloud.xyz, xyz, rtol=0, atol=5e-4)
    np.testing.assert_array_equal(cloud["dev"], las.dev)
    np.testing.assert_array_equal(cloud["normal"], las.normal)
    np.testing.assert_array_equal(cloud["tag"], las.tag)
    chunks = list(lio.iter_chunks(path, 100))
    assert [len(c) for c in chunks] == [100, 100, 57]
    np.testing.assert_array_equal(np.vstack([c.xyz for c in chunks]), cloud.xyz)
    assert lio.describe(path)["point_count"] == N


def test_text_ply_and_npz_keep_utm_coordinates(tmp_path, rng):
    xyz = _utm_xyz(rng) + rng.uniform(0, 1e-6, (N, 3))
    for suffix in (".ply", ".csv", ".txt", ".npz"):
        path = tmp_path / f"utm{suffix}"
        lio.write(path, lio.PointCloud(xyz))
        np.testing.assert_array_equal(lio.read(path).xyz, xyz)
    arr = np.empty(N, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    arr["x"], arr["y"], arr["z"] = xyz.T
    for text in (True, False):
        path = tmp_path / f"plain_{text}.ply"
        plyfile.PlyData([plyfile.PlyElement.describe(arr, "vertex")], text=text,
                        byte_order=">").write(str(path))
        np.testing.assert_allclose(lio.read(path).xyz, xyz, rtol=1e-15)


def _real_las_files():
    return sorted(p for p in SHARED_DATA.rglob("*") if p.suffix.lower() in (".las", ".laz"))


def test_real_files_pass_the_checks():
    files = _real_las_files()
    if not files:
        pytest.skip(f"real data folder not found: {SHARED_DATA}")
    for path in files:
        with laspy.open(path) as reader:
            count = reader.header.point_count
        layout = check_las(path, path.suffix[1:])
        assert layout.point_count == count, path
        assert len(lio.read(path, fields=[])) == count, path

