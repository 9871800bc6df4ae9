"""COPC input: read whole like any LAZ, written back as plain LAS/LAZ (no octree records)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import file_extent, read

pytest.importorskip("copclib", reason="copclib (writes the COPC test files) is missing")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from _copc import write_copc  # noqa: E402


@pytest.mark.parametrize("seed", [0, 1])
def test_copc_in_plain_laz_out(tmp_path, seed):
    rng = np.random.default_rng(seed)
    xyz = np.c_[rng.uniform(0, 40, (3000, 2)) + [85000.0, 440000.0],
                rng.normal(2.0, 0.01, 3000)]
    src = write_copc(tmp_path / "in.copc.laz", xyz, rng.integers(0, 900, 3000))
    assert file_extent(src).copc
    out = tmp_path / "out.laz"
    assert main(["curvature", str(src), str(out), "--radius", "2", "-q"]) == 0
    res = read(out)
    assert not file_extent(out).copc
    grid = np.round(xyz, 3)  # the COPC file's 1 mm grid
    order_in, order_out = np.lexsort(grid.T[::-1]), np.lexsort(res.xyz.T[::-1])
    np.testing.assert_allclose(res.xyz[order_out], grid[order_in], atol=1e-6)
    copc = read(src)
    np.testing.assert_array_equal(res.attributes["intensity"][order_out],
                                  copc.attributes["intensity"][np.lexsort(copc.xyz.T[::-1])])
    assert (res.attributes["surface_type"] == 1).mean() > 0.9  # a noisy plane is planar
