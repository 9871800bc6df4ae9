"""The terrain step's memory follows the points, not their bounding box
(:mod:`lidarstat.classify._terrain_frame`): a large hole, two clumps far apart and a
thinned copy of the synthetic terrain scenes, with a seed sweep; the peak memory of
clumps 20 km apart measured in a subprocess."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from unittest import mock

import numpy as np
import pytest

from lidarstat.classify import _terrain, moments
from lidarstat.classify._terrain import terrain_step
from lidarstat.classify._terrain_frame import BAND_HALO, BandFrame, near_points, terrain_cell
from lidarstat.synth import make_terrain_scene

SEEDS = (0, 1, 2)


def _seeds(scene):
    """The moments ground of a scene: the terrain step's seeds."""
    return moments(scene.xyz, scene.intensity).ground


def _step(xyz, seeds):
    return terrain_step(xyz[:, :2] - xyz[:, :2].min(axis=0), xyz[:, 2], seeds)


@pytest.mark.parametrize("seed", SEEDS)
def test_hole_far_filled_cells_are_no_vertices(seed):
    """A 210 x 210 m hole (no point, a lake) in a 260 x 260 m scene: the filled cells
    more than 3 cells from a point outnumber the cells holding points and are no
    vertices of the TIN; every ground decision is that of the TIN with all of them. The
    heights of at most 2 % of the points (0.5 % of the ground points) differ, by less
    than 0.25 m (measured 0.3-0.6 %, 0.02-0.09 %, 0.02-0.12 m): the triangles under the
    points are those of the whole TIN but in squares of four co-circular filled centres,
    whose diagonal Qhull takes by its order of processing, so by the other vertices."""
    s = make_terrain_scene("embankment", extent=(260.0, 260.0), density=0.4, rng=seed)
    xy = s.xyz[:, :2]
    hole = (np.abs(xy[:, 0] - 130) < 105) & (np.abs(xy[:, 1] - 130) < 105)
    xyz, seeds = s.xyz[~hole], _seeds(s)[~hole]
    ring = _step(xyz, seeds)
    with mock.patch.object(_terrain, "near_points", lambda low: np.ones(low.shape, bool)):
        every = _step(xyz, seeds)
    assert np.array_equal(ring[0], every[0])
    differ = ring[1] != every[1]
    assert differ.mean() < 0.02 and differ[ring[0]].mean() < 0.005
    assert np.abs(ring[1] - every[1]).max() < 0.25
    # the hole's inner cells are not vertices: about 105 x 105 cells less 3 rings
    assert ring[2].tin.P.shape[0] < every[2].tin.P.shape[0] - 95 * 95


def test_near_points_ring():
    low = np.full((20, 20), np.inf)
    low[2, 2] = low[17, 17] = 1.0  # 184 far cells in their 16 x 16 box
    near = near_points(low, ring=3)
    assert near.sum() == 72 and near[5, 0] and not near[6, 2] and not near[9, 9]
    low = np.zeros((20, 20))
    low[:, 12:] = np.inf  # 8 empty columns outside the box of the others: all kept
    assert near_points(low, ring=3).all()
    low = np.zeros((20, 20))
    low[:, 12:] = np.inf  # 8 empty columns, 1 beyond the ring: every cell stays
    assert near_points(low, ring=3).all()


@pytest.mark.parametrize("seed", SEEDS)
def test_two_clumps_far_apart(seed):
    """Two scenes 560 m apart on the diagonal (gaps of 230-240 cells: the full grid, and
    no step reads across) and 20 km apart (a 7,000 x 7,000-cell box): the far pair's
    grid has the empty bands taken out (about 350 x 350 cells). The classes are those of
    the near pair but for at most 0.2 % of the points (measured 0-0.03 %), and heights
    differ on at most 15 % (measured 5.4-8.9 %): the filled cells and the TIN are
    Delaunay triangulations of lattice points, whose co-circular squares take the
    diagonal Qhull's order of processing gives, so they depend on every vertex. The full
    grid differs as much between gaps of 560 and 900 m (classes 0.01-0.08 %, heights
    7.3-8.9 %, seeds 0-2)."""
    a = make_terrain_scene("bridge", density=1.0, rng=seed)
    b = make_terrain_scene("ramp", density=1.0, rng=seed + 10)
    seeds = np.r_[_seeds(a), _seeds(b)]
    out = {}
    for d in (560.0, 20_000.0):
        xyz = np.r_[a.xyz, b.xyz + [d, d, 0.0]]
        out[d] = _step(xyz, seeds)
    near, far = out[560.0], out[20_000.0]
    assert near[2].frame is None and far[2].frame is not None
    assert far[2].grid.size < 400 ** 2
    assert (near[0] != far[0]).mean() < 0.002
    assert (near[1] != far[1]).mean() < 0.15


@pytest.mark.parametrize("seed", SEEDS)
def test_thinned_copy(seed):
    """Every 25th point of a scene (0.02 points per m2, 7 m apart; 1,440 points): at the
    kept points the terrain step on the thinned copy agrees with the step on the whole scene
    (the same seeds) on at least 98 % of the classes (measured 98.4-99.2 %: on a tenth
    of the points the growth and the wall tests see fewer neighbours). The grid keeps its
    2 m cell: 6 cells a point, under the 16 that coarsen it."""
    s = make_terrain_scene("embankment", extent=(300.0, 240.0), density=0.5, rng=seed)
    seeds = _seeds(s)
    whole = terrain_step(s.xyz[:, :2], s.xyz[:, 2], seeds)
    keep = np.arange(len(seeds)) % 25 == 0
    thin = terrain_step(s.xyz[keep, :2], s.xyz[keep, 2], seeds[keep])
    assert terrain_cell(s.xyz[keep, :2], 2.0) == 2.0
    assert (thin[0] == whole[0][keep]).mean() >= 0.98


@pytest.mark.parametrize("seed", SEEDS)
def test_coarser_cell_on_very_sparse_points(seed):
    """4,000 points over 3 x 3 km (one a 2,250 m2): a 2 m grid would hold 560 cells a
    point; the cell grows until the grid holds at most 16 a point and 262,144 cells.
    The ground of a plane with boxes is found at that cell as at 2 m: the neighbour
    tests see no neighbours at either cell."""
    g = np.random.default_rng(seed)
    n = 4000
    xy = g.uniform(0, 3000, (n, 2))
    z = 0.02 * xy[:, 0] + g.normal(0, 0.05, n)
    box = g.random(n) < 0.1
    z[box] += 6.0
    cell = terrain_cell(xy, 2.0)
    assert cell > 2.0
    assert np.prod(np.floor(xy.max(axis=0) / cell) + 1) <= max(16 * n, 1 << 18)
    ground, *_ = terrain_step(xy, z, ~box)
    assert np.array_equal(ground, ~box)


def test_band_frame_moves_points_by_whole_cells(rng):
    xy = np.r_[rng.uniform(0, 50, (500, 2)), rng.uniform(0, 50, (500, 2)) + 9000.0]
    f = BandFrame.of(xy, 2.0)
    assert f is not None
    moved = f(xy)
    assert np.allclose((xy - moved) / 2.0, np.round((xy - moved) / 2.0))
    gap = moved[500:].min(axis=0) - moved[:500].max(axis=0)
    assert np.all(gap >= 2 * 2.0 * BAND_HALO - 2 * 2.0) and np.all(gap < 2 * 2.0 * BAND_HALO + 4)
    assert BandFrame.of(rng.uniform(0, 500, (2000, 2)), 2.0) is None


_RSS = textwrap.dedent("""
    import resource, numpy as np
    from lidarstat.classify._terrain import terrain_step
    from lidarstat.synth import make_terrain_scene
    a = make_terrain_scene("bridge", density=1.0, rng=0)
    b = make_terrain_scene("ramp", density=1.0, rng=1)
    seeds = np.r_[a.ground, b.ground]
    peaks = []
    for d in (200.0, 20000.0):
        xyz = np.r_[a.xyz, b.xyz + [d, d, 0.0]]
        terrain_step(xyz[:, :2] - xyz[:, :2].min(axis=0), xyz[:, 2], seeds)
        peaks.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(peaks[0], peaks[1])
""")


def test_peak_memory_does_not_grow_with_the_gap():
    """The step on two clumps 200 m apart, then 20 km apart (a bounding box of 200 km2,
    50 million 2 m cells: gigabytes on a full grid) in one process: the second run
    raises the process's peak resident memory by less than 40 MiB (measured 20 MiB: the
    256 cells of the narrowed gap)."""
    r = subprocess.run([sys.executable, "-c", _RSS], capture_output=True, text=True,
                       timeout=120, check=True)
    near, far = map(float, r.stdout.split())
    assert far - near < 40.0, (near, far)
