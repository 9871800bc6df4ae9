"""Terrain models: the TIN of the ground points against analytic terrain, GeoTIFF and
VRT output, and tiles of a catalogue that mosaic into the whole area's model."""

import numpy as np
import pytest

from lidarstat.errors import InvalidPointsError
from lidarstat.io import PointCloud, Raster, read_geotiff, write, write_geotiff, write_vrt
from lidarstat.pipeline import process_catalogue, terrain_model

EPSG_RD = "EPSG:28992"


def _terrain(x, y):
    return 0.02 * x + 1.5 * np.sin(y / 9.0) + 0.5 * np.cos(x / 6.0)


def _curvature_bound():
    """Largest |second derivative| of _terrain along any direction."""
    return 1.5 / 81 + 0.5 / 36


def _scene(seed, n=20000, extent=80.0, with_buildings=True):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, extent, (n, 2))
    z = _terrain(xy[:, 0], xy[:, 1])
    cls = np.full(n, 2, dtype=np.uint8)
    if with_buildings:  # box buildings: their points are above the ground, class 6
        for cx, cy in rng.uniform(10, extent - 10, (4, 2)):
            inside = (np.abs(xy[:, 0] - cx) < 4) & (np.abs(xy[:, 1] - cy) < 3)
            z[inside] += 7.0
            cls[inside] = 6
    return np.c_[xy + [120000.0, 480000.0], z], cls


@pytest.mark.parametrize("seed", range(4))
def test_tin_follows_the_analytic_ground(seed):
    xyz, cls = _scene(seed)
    dtm = terrain_model(xyz, cls, resolution=1.0)
    cx, cy = dtm.centres()
    gx, gy = np.meshgrid(cx - 120000.0, cy - 480000.0)
    truth = _terrain(gx, gy)
    err = np.abs(dtm.values - truth)
    inside = np.isfinite(dtm.values)
    assert inside.mean() > 0.95  # only cells outside the hull of the ground have no value
    # linear interpolation on triangles of edge h errs by at most M h^2 / 2; under a
    # building the triangles span its footprint (8 m x 6 m), elsewhere about 1 m
    ground_h = 1.5
    assert np.nanmax(err[inside]) < _curvature_bound() * 10.0 ** 2 / 2
    assert np.nanpercentile(err[inside], 95) < _curvature_bound() * ground_h ** 2 / 2


@pytest.mark.parametrize("seed", range(3))
def test_blocked_tin_equals_the_whole_triangulation(seed):
    """Built block by block (a margin of ground around each block, grown where a
    triangle may not be the whole triangulation's), the TIN is the whole one's: holes
    larger than the first margin (a lake, a missing corner) included."""
    xyz, cls = _scene(seed, n=5000)
    xy = xyz[:, :2] - [120000.0, 480000.0]
    cls[np.hypot(xy[:, 0] - 40, xy[:, 1] - 40) < 15] = 9  # a lake wider than the margin
    cls[(xy[:, 0] > 65) & (xy[:, 1] > 60)] = 6  # the hull of the ground misses a corner
    whole = terrain_model(xyz, cls, resolution=1.0)
    blocked = terrain_model(xyz, cls, resolution=1.0, block_points=1200)
    np.testing.assert_array_equal(np.isnan(blocked.values), np.isnan(whole.values))
    np.testing.assert_allclose(blocked.values, whole.values, rtol=0, atol=1e-9,
                               equal_nan=True)


def test_objects_do_not_raise_the_terrain():
    xyz, cls = _scene(7)
    with_objects = terrain_model(xyz, cls, resolution=2.0)
    as_ground = terrain_model(xyz, np.full(len(cls), 2), resolution=2.0)
    assert np.nanmax(with_objects.values - _terrain(*np.meshgrid(
        with_objects.centres()[0] - 120000.0, with_objects.centres()[1] - 480000.0))) < 0.5
    assert np.nanmax(as_ground.values - with_objects.values) > 5.0  # the test can fail


def test_geotiff_and_vrt_round_trip(tmp_path):
    xyz, cls = _scene(3, n=4000, extent=40.0)
    dtm = terrain_model(xyz, cls, resolution=0.5, crs=EPSG_RD)
    path = write_geotiff(tmp_path / "dtm.tif", dtm)
    back = read_geotiff(path)
    np.testing.assert_allclose(back.values, dtm.values.astype(np.float32), equal_nan=True)
    assert (back.left, back.top, back.resolution) == (dtm.left, dtm.top, dtm.resolution)
    assert "Amersfoort" in back.crs
    # two halves as tiles of one grid: the VRT mosaic is the whole
    rows = dtm.values.shape[0] // 2
    north = Raster(dtm.values[:rows], dtm.left, dtm.top, dtm.resolution, EPSG_RD)
    south = Raster(dtm.values[rows:], dtm.left, dtm.top - rows * dtm.resolution,
                   dtm.resolution, EPSG_RD)
    tiles = [write_geotiff(tmp_path / "n.tif", north), write_geotiff(tmp_path / "s.tif", south)]
    mosaic = read_geotiff(write_vrt(tmp_path / "dtm.vrt", tiles))
    np.testing.assert_allclose(mosaic.values, dtm.values.astype(np.float32), equal_nan=True)


def test_catalogue_tiles_mosaic_into_the_whole_area_model(tmp_path):
    xyz, cls = _scene(11, n=16000, extent=60.0)
    whole = terrain_model(xyz, cls, resolution=1.0)
    (tmp_path / "tiles").mkdir()
    edges = np.linspace(120000.0, 120060.0, 4)
    ix = np.clip(np.searchsorted(edges, xyz[:, 0], side="right") - 1, 0, 2)
    for i in range(3):
        keep = ix == i
        write(tmp_path / "tiles" / f"t{i}.laz",
              PointCloud(xyz[keep], {"classification": cls[keep]}))
    (tmp_path / "dtm").mkdir()

    def dtm_of_tile(tile):
        e = tile.extent
        bounds = (e.xmin, e.ymin, e.xmax, e.ymax)
        r = terrain_model(tile.xyz, tile.attribute("classification"), resolution=1.0,
                          bounds=bounds)
        write_geotiff(tmp_path / "dtm" / f"{e.path.stem}.tif", r)
        return {}

    process_catalogue(dtm_of_tile, tmp_path / "tiles", tmp_path / "out", buffer=10.0,
                      scheduler="sync")
    mosaic = read_geotiff(write_vrt(tmp_path / "dtm.vrt",
                                    sorted((tmp_path / "dtm").glob("*.tif"))))
    # the mosaic's grid is the whole model's (cells are multiples of the resolution)
    dx = round((mosaic.left - whole.left) / whole.resolution)
    dy = round((whole.top - mosaic.top) / whole.resolution)
    part = whole.values[dy:dy + mosaic.shape[0], dx:dx + mosaic.shape[1]]
    both = np.isfinite(part) & np.isfinite(mosaic.values)
    assert both.mean() > 0.9
    np.testing.assert_allclose(mosaic.values[both], part[both].astype(np.float32),
                               rtol=0, atol=1e-4)  # float32 of heights of a few metres


def test_too_few_ground_points_are_refused():
    xyz = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 5]])
    with pytest.raises(InvalidPointsError, match="2 ground points"):
        terrain_model(xyz, np.array([2, 2, 6, 6]), resolution=0.5)
    with pytest.raises(InvalidPointsError, match="one line"):
        terrain_model(np.c_[np.arange(5.0), np.arange(5.0), np.zeros(5)], np.full(5, 2),
                      resolution=0.5)
