"""The whole ``moments`` classification's memory follows the points, not their bounding
box: the lower envelope's raster, the grid of the interpolated cuts and the ground TINs
leave out the empty bands of cells (:class:`lidarstat.classify._terrain_frame.BandFrame`),
as the terrain step's grid does (``test_terrain_sparse.py``). Two clumps far apart, with a
seed sweep; the peak memory of clumps 20 km apart measured in a subprocess."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from unittest import mock

import numpy as np
import pytest

from lidarstat.classify import _seams, moments
from lidarstat.classify._moments_ground import opening_surface
from lidarstat.classify._seams import interpolate_cuts
from lidarstat.classify._terrain_frame import BandFrame
from lidarstat.synth import make_terrain_scene

SEEDS = (0, 1, 2)


def _pair(seed):
    a = make_terrain_scene("bridge", density=1.0, rng=seed)   # 100 x 80 m each
    b = make_terrain_scene("ramp", density=1.0, rng=seed + 10)
    return a, b


def _cloud(a, b, d):
    return np.r_[a.xyz, b.xyz + [d, d, 0.0]], np.r_[a.intensity, b.intensity]


@pytest.mark.parametrize("seed", SEEDS)
def test_envelope_and_cuts_without_the_empty_bands_equal_the_full_grid(seed):
    """Clumps 700 m apart on the diagonal (a gap of about 600 cells of 1 m, narrowed to
    256), and a point 5 km off for the 16 m cells of the cuts: the lower envelope under
    every point and every interpolated cut equal those of the full grid, exactly."""
    a, b = _pair(seed)
    xyz, _ = _cloud(a, b, 700.0)
    xy = xyz[:, :2] - np.floor(xyz[:, :2].min(axis=0) / 64.0) * 64.0
    frame = BandFrame.of(xy, 1.0)
    assert frame is not None
    full = opening_surface(xy, xyz[:, 2], window=20.0, frame=None)
    assert np.array_equal(opening_surface(xy, xyz[:, 2], window=20.0, frame=frame), full)
    g = np.random.default_rng(seed)
    cut = np.where(g.random(len(xy)) < 0.1, np.inf, g.normal(1.0, 0.3, len(xy)))
    xy, cut = np.r_[xy, xy[:1] + [0.0, 5000.0]], np.r_[cut, 1.0]  # 300 cells of 16 m
    assert BandFrame.of(xy, 16.0) is not None
    ours = interpolate_cuts(xy, cut, 16.0)
    with mock.patch.object(_seams.BandFrame, "of", lambda *args, **kw: None):
        every = interpolate_cuts(xy, cut, 16.0)
    assert np.array_equal(ours, every)


@pytest.mark.parametrize("seed", SEEDS)
def test_two_clumps_far_apart(seed):
    """Two scenes 192 m, 2,048 m and 20,032 m apart on the diagonal (multiples of the
    64 m window, so every window holds the same points). The two far pairs narrow to the
    same gap, so every field is equal (but the building test's plane statistics, fitted
    in the cloud's own coordinates: their rounding, under 1e-11): memory and results do
    not depend on how far apart the clumps are. Against the near pair (full grids, a 92 m gap) the classes
    differ on at most 1 % of the points (measured 0.12-0.46 %): the ground TIN is a
    Delaunay triangulation over both clumps, whose triangles along each clump's hull
    depend on where the other clump lies. The full grids differ as much between gaps
    of 92 m and 1,950 m (0.16-0.70 %, seeds 0-2)."""
    a, b = _pair(seed)
    out = {d: moments(*_cloud(a, b, d)) for d in (192.0, 2048.0, 20_032.0)}
    near, mid, far = out[192.0], out[2048.0], out[20_032.0]
    for k, v in far.to_fields().items():
        v, w = np.asarray(v), np.asarray(mid.to_fields()[k])
        if k in ("building_plane_p", "building_residual"):  # fitted in the coordinates
            assert np.allclose(v, w, rtol=0, atol=1e-9, equal_nan=True), k
        else:
            assert np.array_equal(v, w, equal_nan=True), k
    assert np.array_equal(far.height, mid.height)
    assert (near.classification != far.classification).mean() < 0.01


_RSS = textwrap.dedent("""
    import resource, numpy as np
    from lidarstat.classify import moments
    from lidarstat.synth import make_terrain_scene
    a = make_terrain_scene("bridge", density=0.5, rng=0)
    b = make_terrain_scene("ramp", density=0.5, rng=10)
    peaks = []
    for d in (192.0, 20032.0):
        moments(np.r_[a.xyz, b.xyz + [d, d, 0.0]], np.r_[a.intensity, b.intensity])
        peaks.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(peaks[0], peaks[1])
""")


def test_peak_memory_does_not_grow_with_the_gap():
    """``moments`` on two clumps 192 m apart, then 20 km apart (a bounding box of
    400 million 1 m cells: the lower envelope's raster alone would take 19 GB, refused)
    in one process: the second run raises the process's peak resident memory by less
    than 40 MiB (measured 21 MiB: the cells of the narrowed gaps)."""
    r = subprocess.run([sys.executable, "-c", _RSS], capture_output=True, text=True,
                       timeout=120, check=True)
    near, far = map(float, r.stdout.split())
    assert far - near < 40.0, (near, far)


@pytest.mark.parametrize("seed", SEEDS)
def test_very_sparse_points_coarser_envelope_and_bins(seed):
    """4,000 points over 3 x 3 km (one a 2,250 m2, as PDAL's thinned mvk): the lower
    envelope's 1 m raster would hold 2,250 cells a point; its cell grows as the terrain
    grid's does (at most 16 cells a point and 262,144 cells), and the ground TINs bin
    their triangles into at most as many cells (every vertex in its own triangles' boxes
    of 2 m bins: 6 million bins, hundreds of MiB)."""
    from lidarstat.classify import _moments_ground, _surface

    g = np.random.default_rng(seed)
    n = 4000
    xy = g.uniform(0, 3000, (n, 2))
    z = 0.02 * xy[:, 0] + g.normal(0, 0.05, n)
    z[g.random(n) < 0.1] += 6.0  # boxes
    cells, bins = [], []
    opening, tin = _moments_ground.opening_surface, _surface.TinSurface.__init__

    def spy_opening(*args, **kw):
        cells.append(kw["cell"])
        return opening(*args, **kw)

    def spy_tin(self, *args, **kw):
        tin(self, *args, **kw)
        if self._tri is not None:
            bins.append((self._tri[3] * self._tri[4], len(self.P)))

    with mock.patch.object(_moments_ground, "opening_surface", spy_opening), \
            mock.patch.object(_surface.TinSurface, "__init__", spy_tin):
        moments(np.c_[xy, z], g.uniform(20, 200, n))
    assert len(cells) == 1 and cells[0] > 1.0
    assert (3000 / cells[0]) ** 2 <= max(16 * n, 1 << 18)
    # bins of side g with (span / g)^2 <= the limit: one more a side at most
    assert bins and all(b <= (max(16 * m, 1 << 18) ** 0.5 + 1) ** 2 for b, m in bins), bins
