"""The terrain step of `moments` against exact synthetic truth (lidarstat.synth terrain
scenes), with a seed sweep; small scenes (about 8,000 points, a second or two each)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.classify import filter_errors, moments
from lidarstat.classify._terrain import (TERRAIN_DEFAULTS, drop_opened, grow_ground,
                                         noise_fence, refine_terrain, reject_plateaus,
                                         reject_walled)
from lidarstat.synth import TERRAIN_SCENES, make_terrain_scene

SEEDS = (0, 1)


def _scene(name, seed):
    return make_terrain_scene(name, extent=(100.0, 80.0), density=1.0, rng=seed)


def _errors(scene, **kw):
    res = moments(scene.xyz, scene.intensity, **kw)
    return filter_errors(res.ground, scene.ground), res


@pytest.mark.parametrize("seed", SEEDS)
def test_embankment_is_ground(seed):
    """An embankment 5 m high with a 12 m top is narrower than the envelope's opening, so
    the window cut leaves it out (about 20 % total error); the terrain step climbs it."""
    s = _scene("embankment", seed)
    with_t, res = _errors(s)
    without, _ = _errors(s, terrain=False)
    assert without.total > 0.1  # the hard case is hard without the step
    assert with_t.total < 0.01
    assert np.all(res.tolerance[res.ground] >= res.height[res.ground])


@pytest.mark.parametrize("seed", SEEDS)
def test_ramp_and_wall(seed):
    """Two levels split by a retaining wall and joined by a ramp: all terrain."""
    e, _ = _errors(_scene("ramp", seed))
    assert e.total < 0.02


@pytest.mark.parametrize("seed", SEEDS)
def test_bridge_deck_is_not_ground(seed):
    """The deck joins the embankments smoothly at both ends but stands on walls along
    its sides: the growth reaches it and the wall test takes it back. Where the growth
    joined an embankment to the deck in one region, the embankment goes back with it, so
    the step only guarantees not to lose ground the cut kept."""
    s = _scene("bridge", seed)
    e, _ = _errors(s)
    without, _ = _errors(s, terrain=False)
    assert e.type_ii < 0.01  # the deck stays an object
    assert e.total <= without.total + 1e-9


@pytest.mark.parametrize("seed", SEEDS)
def test_quarry_benches_are_ground(seed):
    e, _ = _errors(_scene("quarry", seed))
    assert e.total < 0.03


@pytest.mark.parametrize("seed", SEEDS)
def test_large_flat_roof_is_not_ground(seed):
    """A 60 x 40 m roof, wider than the opening: walls on every side."""
    e, _ = _errors(_scene("flat_roof", seed))
    assert e.type_ii < 0.01 and e.total < 0.01


@pytest.mark.parametrize("seed", SEEDS)
def test_low_platform_is_ground_garage_and_cars_are_not(seed):
    """A plinth 0.8 m high on a vertical rim: the smooth growth cannot climb the rim, the
    platform growth (steps up to 1 m, regions of at least 16 cells, walls higher than
    1 m on at most a fifth of the border) can; the garage roof (2.5 m) and the cars
    (1.5 m, too small) stay objects."""
    s = _scene("platform", seed)
    e, res = _errors(s)
    plinth = np.hypot(s.xyz[:, 0] - 35, s.xyz[:, 1] - 40) < 10.0
    assert res.ground[plinth].mean() > 0.98
    assert e.type_ii < 0.01 and e.total < 0.01


@pytest.mark.parametrize("seed", SEEDS)
def test_low_objects_above_the_noise_are_not_ground(seed):
    """Low walls and planters 0.25-0.45 m high on terrain scanned with 0.02 m noise: all
    within the fixed 0.5 m tolerance, but 12-22 noise standard deviations up, so the
    noise fence (median + 7 robust SDs of the ground around them, about 0.2 m) takes
    them out; no ground point is lost. With 0.05 m noise the same objects are within
    the fence (the test has no power there, as it should not)."""
    s = make_terrain_scene("low_objects", extent=(100.0, 80.0), density=1.0, sigma=0.02,
                           rng=seed)
    e, res = _errors(s)
    assert e.type_i < 0.001 and e.type_ii < 0.25
    assert np.median(res.tolerance[s.ground]) < 0.3
    t = refine_terrain(s.xyz[:, :2], s.xyz[:, 2], s.ground, cell=2.0, tolerance=0.5,
                       slope_tolerance=1.25, step=0.3, max_rise=1.0, below=1.0)
    assert t.ground[~s.ground].mean() > 0.9  # without the fence: objects kept as ground


@pytest.mark.parametrize("seed", range(4))
def test_noise_fence_follows_the_local_noise(seed):
    """Heights of ground points, 0.02 m noise on one half and 0.08 m on the other, with
    a quarter of them surface vertices (height exactly 0, left out of the spread): the
    bound is the median + 7 robust SDs of each half's heights (within 15 %), and a point
    0.3 m up is above it on the smooth half only."""
    g = np.random.default_rng(seed)
    xy = g.uniform(0, 80, (20000, 2))
    sd = np.where(xy[:, 0] < 40, 0.02, 0.08)
    h = np.abs(g.normal(0, 1, 20000)) * sd
    h[g.random(20000) < 0.25] = 0.0
    probe = np.array([[20.0, 40.0], [60.0, 40.0]])
    xy, h = np.r_[xy, probe], np.r_[h, 0.3, 0.3]
    bound = noise_fence(xy, h, np.r_[np.ones(20000, bool), False, False], cell=2.0,
                        fence=7.0, min_points=64, max_radius=8)
    half = 0.6745  # median of |N(0, 1)|
    mad = 1.4826 * 0.3991  # MAD of |N(0, 1)|, scaled as the fence scales it
    for sel, s in ((xy[:, 0] < 38, 0.02), (xy[:, 0] > 42, 0.08)):
        assert np.median(bound[sel]) == pytest.approx(s * (half + 7 * mad), rel=0.15)
    assert h[-2] > bound[-2] and h[-1] < bound[-1]
    assert TERRAIN_DEFAULTS["fence"] == 7.0


def test_scenes_exported():
    assert set(TERRAIN_SCENES) == {"ramp", "embankment", "bridge", "quarry", "flat_roof",
                                   "platform", "low_objects"}
    with pytest.raises(ValueError):
        make_terrain_scene("volcano")


def test_growth_climbs_a_slope_and_stops_at_a_wall():
    """Raster growth: a 30 % ramp is continued cell by cell; a 3 m wall is not."""
    x = np.arange(30, dtype=float)
    lowest = np.tile(np.where(x < 20, 0.3 * x, 0.3 * 19 + 3.0), (5, 1)).T  # ramp, then wall
    seeds = np.full_like(lowest, np.inf)
    seeds[:3] = lowest[:3]
    grown = grow_ground(lowest, seeds, cell=1.0, step=0.3, max_rise=1.0)
    assert np.isfinite(grown[:20]).all() and not np.isfinite(grown[20:]).any()


def test_walled_region_is_taken_back():
    """A plateau reached over one smooth cell and walled elsewhere is rejected."""
    lowest = np.zeros((20, 20))
    lowest[5:15, 5:15] = 4.0
    ground = np.where(lowest == 0, 0.0, np.inf)
    grown = ground.copy()
    grown[5:15, 5:15] = 4.0
    out, rejected = reject_walled(grown, ground, lowest, cell=1.0, step=0.3, max_rise=1.0,
                                  wall_fraction=0.2)
    assert rejected == 100 and not np.isfinite(out[5:15, 5:15]).any()


def test_slope_dependent_tolerance():
    """On a 40 % slope the tolerance is 0.5 + 1.25 * 0.4 = 1.0 m, on flat ground 0.5 m.
    The surface of 2 m cells' lowest points lies up to 0.4 * 1 m under the slope, so a
    point 0.55 m above the slope (at most 0.95 m above the surface) is ground there, and
    one 0.7 m above flat ground is not."""
    g = np.random.default_rng(3)
    xy = g.uniform(0, 40, (6000, 2))
    steep = xy[:, 0] >= 20
    z = np.where(steep, 0.4 * (xy[:, 0] - 20), 0.0)
    probe = np.array([[10.0, 20.0], [30.0, 20.0]])
    pz = np.array([0.7, 0.4 * 10 + 0.55])
    t = refine_terrain(np.r_[xy, probe], np.r_[z, pz], np.r_[np.ones(6000, bool), False, False],
                       cell=2.0, tolerance=0.5, slope_tolerance=1.25, step=0.3, max_rise=1.0,
                       below=1.0)
    assert not t.ground[-2] and t.ground[-1]
    assert t.tolerance[-2] == pytest.approx(0.5, abs=0.02)
    assert t.tolerance[-1] == pytest.approx(1.0, abs=0.05)
    assert 0.55 <= t.height[-1] <= 0.95 + 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_fill_matches_linear_interpolation(seed):
    """The rasterised triangles give the linear interpolation on the holes of the rim
    cells' Delaunay triangulation (matplotlib's interpolator on the same triangles),
    nearest cell outside the hull."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation
    from scipy import ndimage as ndi

    from lidarstat.classify._terrain import _fill
    from lidarstat.neighbors import delaunay_triangles

    g = np.random.default_rng(seed)
    a = (np.add.outer(np.linspace(0, 5, 40), np.sin(np.linspace(0, 3, 30)))
         + g.normal(0, 0.1, (40, 30)))
    holes = (g.random(a.shape) < 0.3) | ndi.binary_dilation(g.random(a.shape) < 0.01,
                                                           iterations=3)
    a[holes] = np.inf
    rim = ~holes & ndi.binary_dilation(holes, structure=np.ones((3, 3), bool))
    full = np.argwhere(rim).astype(float)
    tri = Triangulation(full[:, 0], full[:, 1], delaunay_triangles(full))
    q = np.argwhere(holes).astype(float)
    expect = LinearTriInterpolator(tri, a[rim])(q[:, 0], q[:, 1]).filled(np.nan)
    got = _fill(a)[holes]
    inside = np.isfinite(expect)
    assert inside.mean() > 0.9
    assert np.abs(got[inside] - expect[inside]).max() < 1e-9
    assert np.isfinite(got).all()


@pytest.mark.parametrize("seed", range(4))
def test_opening_drops_roof_seeds_and_keeps_slopes(seed):
    """A 16 m roof 6 m high among seeds on a 40 % slope: the progressive opening (slope
    0.5, radius 18 m) drops the roof's cells and keeps every slope cell (the opening of
    a plane is the plane)."""
    g = np.random.default_rng(seed)
    x = np.arange(40)[:, None] * 2.0 + np.zeros((40, 30))
    ground_z = 0.4 * x + g.normal(0, 0.05, x.shape)
    roof = np.zeros(x.shape, bool)
    i, j = g.integers(10, 22), g.integers(8, 14)
    roof[i:i + 8, j:j + 8] = True
    ground_z[roof] += 6.0
    out = drop_opened(ground_z, cell=2.0, slope=0.5, max_radius=18.0)
    assert not np.isfinite(out[roof]).any()
    assert np.isfinite(out[~roof]).all()


@pytest.mark.parametrize("seed", range(4))
def test_walled_part_is_taken_back_terrace_is_not(seed):
    """A roof on the data's edge (walls on its three inner sides) leaves the surface; a
    terrace under a retaining wall (walled downhill, higher ground uphill, smooth at its
    ends) stays."""
    g = np.random.default_rng(seed)
    z = np.zeros((60, 40)) + g.normal(0, 0.03, (60, 40))
    # terrace: rows 20-29 raised by 3 m over columns 5-34, ramps at both ends, the
    # ground uphill of it (rows >= 30) higher still
    z[30:] += 6.0
    z[20:30, 10:30] += 3.0
    z[20:30, 5:10] += np.linspace(0.0, 3.0, 5)[None, :]
    z[20:30, 30:35] += np.linspace(3.0, 0.0, 5)[None, :]
    # roof on the data's edge (column 0): 5 m above the terrain around it
    z[2:12, 0:8] += 5.0
    surface, rejected = reject_plateaus(z.copy(), z.copy(), cell=2.0, step=0.3,
                                        max_rise=1.0, fraction=0.5)
    assert not np.isfinite(surface[2:12, 0:8]).any()
    assert np.isfinite(surface[20:30]).all() and rejected == 80


@pytest.mark.parametrize("seed", SEEDS)
def test_surface_passes_through_ground_on_a_slope(seed):
    """On a 50 % slope the surface is the TIN of the cells' lowest points at their own
    positions: ground heights stay within the noise, std 0.02 m (a grid of cell centres
    would lie 0.5 m under the slope, a median height near 0.5 m)."""
    g = np.random.default_rng(seed)
    xy = g.uniform(0, 60, (6000, 2))
    z = 0.5 * xy[:, 0] + g.normal(0, 0.02, 6000)
    t = refine_terrain(xy, z, np.ones(6000, bool), cell=2.0, tolerance=0.5,
                       slope_tolerance=1.25, step=0.3, max_rise=1.0, below=1.0)
    assert abs(np.median(t.height)) < 0.05 and t.height.min() > -6 * 0.02
    assert t.ground.all()


@pytest.mark.parametrize("seed", range(4))
def test_point_test_and_fence_equal_their_definition(seed):
    """The compiled point test and noise fence of :func:`refine_terrain` give, bit for
    bit, the heights, bounds and ground of their definition written out with the
    model's public pieces: ``height = round(z - surface, 6)``, ``upper = tolerance + s
    slope``, ground within ``[-(below + s slope), upper]``, then ``upper = min(upper,
    fence bound + s slope)`` and ground only under it."""
    scene = _scene(TERRAIN_SCENES[seed % len(TERRAIN_SCENES)], seed)
    xy = scene.xyz[:, :2] - scene.xyz[:, :2].min(axis=0)
    z = scene.xyz[:, 2]
    kw = {"cell": 2.0, "tolerance": 0.5, "slope_tolerance": 1.25, "step": 0.3,
          "max_rise": 1.0, "below": 1.0}
    t = refine_terrain(xy, z, scene.ground, fence=7.0, fence_points=64, fence_radius=8, **kw)
    model = t.surface
    height = np.round(z - model(xy), 6)
    extra = 1.25 * model.slope_at(xy)
    upper = 0.5 + extra
    keep = (height <= upper) & (height >= -(1.0 + extra))
    bound = noise_fence(xy, height, keep, cell=2.0, fence=7.0, min_points=64, max_radius=8)
    upper = np.minimum(upper, bound + extra)
    keep &= height <= upper
    assert np.array_equal(t.height, height)
    assert np.array_equal(t.tolerance, upper)
    assert np.array_equal(t.ground, keep)
    assert np.isfinite(bound[keep]).mean() > 0.9  # the fence bounds most of the ground
    plain = refine_terrain(xy, z, scene.ground, **kw)  # no fence
    assert np.array_equal(plain.ground, (height <= 0.5 + extra) & (height >= -(1.0 + extra)))


@pytest.mark.parametrize("seed", range(4))
def test_block_spread_is_exact_where_neighbouring_blocks_differ(seed):
    """The median and MAD of each block are selected first near the previous cell's; on
    cells whose values jump from one cell to the next (offsets of +-50, spreads from 0
    to 10), with ties and blocks of one repeated value, that guess misses and the
    result is still ``np.median``'s."""
    from lidarstat.classify._terrain_kernels import block_spread

    g = np.random.default_rng(seed)
    nx, ny = 19, 13
    key = np.repeat(np.arange(nx * ny), g.integers(0, 30, nx * ny))
    shift = g.choice([-50.0, 0.0, 50.0], nx * ny)
    scale = g.choice([0.0, 0.01, 1.0, 10.0], nx * ny)
    v = np.round(shift[key] + scale[key] * g.standard_normal(key.size), 2)
    offsets = np.r_[0, np.cumsum(np.bincount(key, minlength=nx * ny))]
    centre, spread = np.full(nx * ny, -1.0), np.full(nx * ny, -1.0)
    cells = np.flatnonzero(g.uniform(size=nx * ny) < 0.9)
    block_spread(offsets, v, nx, ny, cells, 40, 3, centre, spread)
    for c in cells:
        i, j = divmod(int(c), ny)
        for w in range(1, 4):
            rows = range(max(0, i - w), min(nx, i + w + 1))
            blk = np.concatenate([v[offsets[a * ny + max(0, j - w)]:
                                    offsets[a * ny + min(ny - 1, j + w) + 1]] for a in rows])
            if blk.size >= 40:
                break
        if blk.size < 3:
            assert np.isnan(centre[c]) and np.isnan(spread[c])
            continue
        m = np.median(blk)
        assert centre[c] == m
        assert spread[c] == 1.4826 * np.median(np.abs(blk - m))
    untouched = np.setdiff1d(np.arange(nx * ny), cells)
    assert (centre[untouched] == -1).all() and (spread[untouched] == -1).all()
