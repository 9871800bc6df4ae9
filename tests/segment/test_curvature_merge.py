"""segment --method curvature: a merge is refused when the union fails the plane test that
each part passes, and the method runs at the automatic scale."""

import numpy as np
import pytest

from lidarstat.features import curvature
from lidarstat.segment import segment_curvature


def _shallow_crease(seed, slope=0.01, n=60, spacing=0.1, sigma=0.01):
    """Two planes meeting at a crease of 2*atan(slope) (1.1 degrees) along x = 0, with
    noise that hides it from the local curvature tests (the crease points are planar)."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n) - (n - 1) / 2) * spacing
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    z = slope * np.abs(x) + rng.normal(0, sigma, x.size)
    return np.c_[x, y, z], x


@pytest.mark.parametrize("seed", range(3))
def test_merge_across_a_shallow_crease_is_refused(seed):
    pts, x = _shallow_crease(seed)
    curv = curvature(pts, sigma=0.01)
    seg = segment_curvature(pts, sigma=0.01, curv=curv)
    lab = seg.labels
    assert seg.params["merges_refused"] >= 1
    big = [k for k in range(1, lab.max() + 1) if (lab == k).sum() > 1000]
    assert len(big) == 2
    for k in big:  # each unit (at least 90 %) on one side of the crease
        assert abs(np.sign(x[lab == k]).mean()) > 0.8
    # without the merge test (a level no union fails) the two faces are one unit
    merged = segment_curvature(pts, sigma=0.01, merge_alpha=1e-300, curv=curv)
    assert merged.params["merges_refused"] == 0
    assert (merged.labels == 1).sum() > 0.9 * sum((lab == k).sum() for k in big)


@pytest.mark.parametrize("seed", range(3))
def test_one_plane_stays_one_unit(seed):
    rng = np.random.default_rng(100 + seed)
    g = (np.arange(60) - 29.5) * 0.1
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    pts = np.c_[x, y, 0.3 * x - 0.2 * y + rng.normal(0, 0.01, x.size)]
    seg = segment_curvature(pts, sigma=0.01)
    assert (seg.labels == 1).sum() > 0.9 * x.size
