"""Tiles with halos: exact cover, complete halos, and tiled results equal to untiled ones."""

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.features import curvature
from lidarstat.pipeline import map_tiles, tile_grid


def test_every_point_is_core_once_and_halos_are_complete(rng):
    xyz = rng.uniform(0, 10, (4000, 3)) + [4.5e5, 5.7e6, 0]
    size, halo = 2.5, 0.7
    tiles = tile_grid(xyz, size, halo)
    core_count = np.zeros(len(xyz), int)
    for t in tiles:
        core_count[t.points[t.core]] += 1
        x0, y0, x1, y1 = t.bounds
        inside = ((xyz[:, 0] >= x0) & (xyz[:, 0] < x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] < y1))
        near = ((xyz[:, 0] >= x0 - halo + 1e-9) & (xyz[:, 0] < x1 + halo - 1e-9)
                & (xyz[:, 1] >= y0 - halo + 1e-9) & (xyz[:, 1] < y1 + halo - 1e-9))
        members = np.zeros(len(xyz), bool)
        members[t.points] = True
        # Core points are the points of the square (up to rounding at the borders) ...
        assert np.count_nonzero(inside ^ np.isin(np.arange(len(xyz)), t.points[t.core])) <= 2
        # ... and every point within the halo band is in the tile.
        assert not np.any(near & ~members)
        assert np.all(np.diff(t.points) > 0)
    assert np.all(core_count == 1)
    assert len(tiles) == 16


@pytest.mark.parametrize("scheduler", ["sync", "threads", "dask"])
def test_tiled_curvature_equals_untiled(rng, scheduler):
    if scheduler == "dask":
        pytest.importorskip("dask", reason="dask is not installed")
    g = np.arange(0, 6, 0.05)
    x, y = np.meshgrid(g, g)
    z = 0.2 * np.sin(x) * np.cos(0.7 * y) + rng.normal(0, 0.002, x.shape)
    xyz = np.c_[x.ravel(), y.ravel(), z.ravel()]
    radius = 0.18

    def run(p):
        return curvature(p, radius=radius, sigma=0.002)

    whole = run(xyz).to_fields()
    tiled = map_tiles(run, xyz, size=1.5, halo=radius, scheduler=scheduler, workers=2)
    assert set(tiled) == set(whole)
    for name, ref in whole.items():
        if ref.dtype.kind == "f":
            np.testing.assert_allclose(tiled[name], ref, rtol=1e-9, atol=1e-12, err_msg=name)
        else:
            assert np.array_equal(tiled[name], ref), name
    # A halo narrower than the radius truncates neighbourhoods at tile borders.
    short = map_tiles(run, xyz, size=1.5, halo=radius / 3)
    assert not np.array_equal(short["neighbors"], whole["neighbors"])


def test_progress_and_bad_results(rng):
    xyz = rng.uniform(0, 4, (500, 3))
    seen = []
    out = map_tiles(lambda p: {"z": p[:, 2]}, xyz, size=1.0, halo=0.1,
                    progress=lambda d, n: seen.append((d, n)))
    assert np.array_equal(out["z"], xyz[:, 2])
    assert seen[-1] == (500, 500) and len(seen) == 16
    with pytest.raises(InvalidParameterError, match="rows"):
        map_tiles(lambda p: {"z": p[:1, 2]}, xyz, size=1.0, halo=0.1)
    with pytest.raises(InvalidParameterError, match="dict"):
        map_tiles(lambda p: 3, xyz, size=1.0, halo=0.1)
    with pytest.raises(InvalidParameterError, match="halo"):
        tile_grid(xyz, 1.0, 2.0)
    with pytest.raises(InvalidParameterError, match="scheduler"):
        map_tiles(lambda p: {}, xyz, size=1.0, halo=0.1, scheduler="mpi")


@pytest.mark.parametrize("seed", range(3))
def test_views_give_the_copies_result_and_keep_the_inputs(seed):
    # a cloud sorted tile by tile: every tile of the no-halo grid is a block of rows,
    # handed to func as a read-only view; a halo grid's tiles are not blocks (copies)
    g = np.random.default_rng(seed)
    xyz = g.uniform(0, 40, (3000, 3))
    order = np.concatenate([t.points for t in tile_grid(xyz, 10.0)])
    xyz = xyz[order]
    w = g.normal(size=len(xyz))
    before = xyz.copy(), w.copy()

    def f(p, a):
        return {"s": p[:, 2] * a["w"] + p[:, 0], "n": np.full(len(p), p.flags.writeable)}

    for halo in (0.0, 2.0):
        tiles = tile_grid(xyz, 10.0, halo)
        ref = map_tiles(f, xyz, tiles=tiles, attributes={"w": w})
        got = map_tiles(f, xyz, tiles=tiles, attributes={"w": w}, views=True)
        assert np.array_equal(ref["s"], got["s"])
        assert ref["n"].all() and got["n"].any() != (halo == 0)
    with pytest.raises(ValueError, match="read-only"):
        map_tiles(lambda p: p.__setitem__((slice(None), 2), 0.0) or {"z": p[:, 2]}, xyz,
                  tiles=tile_grid(xyz, 10.0), views=True)
    assert np.array_equal(xyz, before[0]) and np.array_equal(w, before[1])


@pytest.mark.parametrize("scheduler", ["sync", "threads"])
def test_points_given_as_attributes_alone(scheduler):
    # without `xyz` the tiles' points are their attributes (columns held apart): the
    # same fields as the (N, 3) array whose columns they are, views for block tiles
    g = np.random.default_rng(5)
    xyz = g.uniform(0, 40, (3000, 3))
    xyz = xyz[np.concatenate([t.points for t in tile_grid(xyz, 10.0)])]
    xy, z = np.ascontiguousarray(xyz[:, :2]), xyz[:, 2].copy()
    tiles = tile_grid(xyz, 10.0)
    ref = map_tiles(lambda p: {"s": p[:, 0] * p[:, 2] - p[:, 1], "m": p[:, 2] > p[:, 2].mean()},
                    xyz, tiles=tiles, scheduler=scheduler)
    got = map_tiles(lambda a: {"s": a["xy"][:, 0] * a["z"] - a["xy"][:, 1],
                               "m": a["z"] > a["z"].mean()},
                    None, tiles=tiles, attributes={"xy": xy, "z": z}, scheduler=scheduler,
                    views=True)
    assert np.array_equal(ref["s"], got["s"]) and np.array_equal(ref["m"], got["m"])
    assert not ref["m"].all() and ref["m"].any()
    with pytest.raises(ValueError, match="read-only"):
        map_tiles(lambda a: a["z"].__setitem__(0, 1.0) or {}, None, tiles=tiles,
                  attributes={"xy": xy, "z": z}, views=True)
    with pytest.raises(InvalidParameterError, match="without `xyz`"):
        map_tiles(lambda a: {}, None, size=10.0, attributes={"z": z})
    with pytest.raises(InvalidParameterError, match="rows"):
        map_tiles(lambda a: {}, None, tiles=tiles, attributes={"xy": xy, "z": z[:-1]})
