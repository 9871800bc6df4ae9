"""Window cuts interpolated between windows: no class step at a window border (_seams.py)."""

import numpy as np

from lidarstat.classify import moments
from lidarstat.classify._seams import interpolate_cuts


def test_interpolated_cuts_are_continuous_and_exact_inside_tiles(rng):
    """Random cuts on 32 m tiles, interpolated over 16 m cells: across a border the cut
    changes by at most its bilinear slope (probe pairs 2 mm apart), in a tile's inner
    16 m square it is the tile's own cut bit for bit, and a tile without a cut (inf)
    keeps it."""
    cell, tile = 16.0, 32.0
    tcut = np.round(rng.uniform(0.2, 2.0, (3, 3)), 6)
    tcut[2, 2] = np.inf  # a corner tile without a cut
    t = np.linspace(0.5, 63.5, 128)
    probes = np.r_[np.c_[np.full(128, 63.999), t], np.c_[np.full(128, 64.001), t],
                   np.c_[t, np.full(128, 31.999)], np.c_[t, np.full(128, 32.001)]]
    xy = np.r_[probes, rng.uniform(0, [96, 80], (60000, 2))]
    ij = np.floor(xy / tile).astype(int)
    cut = tcut[ij[:, 0], ij[:, 1]]
    got = interpolate_cuts(xy, cut, cell)
    assert np.array_equal(np.isinf(got), np.isinf(cut))
    fin = tcut[:, :2]
    slope = max(np.abs(np.diff(fin, axis=0)).max(), np.abs(np.diff(fin, axis=1)).max()) / cell
    for a in (0, 256):  # left/right, below/above of each pair
        jump = np.abs(got[a:a + 128] - got[a + 128:a + 256])
        step = np.abs(cut[a:a + 128] - cut[a + 128:a + 256])
        assert step.max() > 0.1  # the tiles' own cuts do step there
        assert jump.max() <= 2 * slope * 0.002 + 1e-9
    inner = (np.abs(xy / tile - ij - 0.5) < 0.25).all(axis=1) & np.isfinite(cut)
    assert inner.sum() > 1000 and np.array_equal(got[inner], cut[inner])
    step = interpolate_cuts(xy, np.where(np.isfinite(cut), 1.25, np.inf), cell)
    assert np.all(step[np.isfinite(cut)] == 1.25)  # one value everywhere: no rounding


def test_no_class_step_at_a_window_border():
    """Two 64 m windows get different cuts (smooth terrain: 0.35 m; rough terrain, 0.25 m
    noise: 1.0 m). A 0.45 m hedge crosses their border: under each window's own cut it
    would be object on one side of the border and ground on the other. The interpolated
    cut is continuous at the border and the hedge keeps one class across it, while the
    points beyond the window centres keep their window's own cut."""
    g = np.random.default_rng(0)
    n = 40000
    xy = g.uniform(0, [128, 64], (n, 2))
    rough = xy[:, 0] >= 64
    terrain = 50 + 0.02 * xy[:, 1]
    z = terrain + g.normal(0, np.where(rough, 0.25, 0.05))
    for cx, cy in [(20, 20), (44, 44), (84, 20), (108, 44)]:
        z[(np.abs(xy[:, 0] - cx) < 7) & (np.abs(xy[:, 1] - cy) < 7)] += 6
    hedge = (np.abs(xy[:, 1] - 32) < 0.6) & (np.abs(xy[:, 0] - 64) < 30)
    z[hedge] = terrain[hedge] + 0.45 + g.normal(0, 0.03, hedge.sum())
    left = hedge & (xy[:, 0] >= 62) & (xy[:, 0] < 64)
    right = hedge & (xy[:, 0] >= 64) & (xy[:, 0] < 66)
    # the seams are a property of the window cuts: the terrain step, which re-tests every
    # point against its own surface, is left out
    smooth = moments(np.c_[xy, z], g.normal(100, 10, n), window=64, min_window=64,
                     terrain=False)
    t0, t1 = (t["threshold"] for t in smooth.windows)
    assert t0 < 0.45 < t1 and t1 - t0 > 0.4  # the scene does give two different cuts
    h = smooth.height
    assert (h[left] > t0).mean() > 0.9 and (h[right] <= t1).mean() > 0.9  # each own cut
    near = np.abs(xy[:, 0] - 64) < 0.25
    cl, cr = smooth.cut[near & ~rough], smooth.cut[near & rough]
    cl, cr = cl[np.isfinite(cl)], cr[np.isfinite(cr)]
    assert abs(np.median(cr) - np.median(cl)) < 0.02  # continuous: no jump at x = 64
    assert abs(smooth.ground[left].mean() - smooth.ground[right].mean()) < 0.1
    far0 = (xy[:, 0] < 32) & np.isfinite(smooth.cut)
    far1 = (xy[:, 0] > 96) & np.isfinite(smooth.cut)
    assert np.all(smooth.cut[far0] == t0) and np.all(smooth.cut[far1] == t1)
