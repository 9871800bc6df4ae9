"""`covariance` and `segment --method covariance` with their defaults on independent scenes.

The scenes (``indep_parts.py``: flanged and bored machined parts at random tilts, range
images with noise along z and terrestrial scans with range noise) are built without
``lidarstat.synth``; no scale is given (the automatic scale) and no noise model (the
default: along the rays with a sensor, else along z). Pooled over a seed sweep:

* edges: precision and recall >= 0.9 (``indep_parts.edge_scores``);
* Hoover correct detection (T = 0.8) of >= 90 % of the surfaces of at least 300 points;
* the plane test's size at alpha within its binomial interval on steep and flat faces
  of a z-noise range image alike, and the estimated sigma on steep faces.
"""

from __future__ import annotations

import numpy as np
import pytest

import indep_parts as ip
from lidarstat.classify import classify_covariance, covariance
from lidarstat.features import covariance_features
from lidarstat.segment import segment_covariance

SEEDS = range(4)


@pytest.fixture(scope="module")
def runs():
    out = []
    for seed in SEEDS:
        rng = np.random.default_rng(1000 + seed)
        for gen in (ip.range_image, ip.tls_scan):
            for kind in ("flange", "block"):
                scan = gen(rng, kind)
                res = covariance(scan.points, sensor=scan.sensor, keep_neighbors=True)
                seg = segment_covariance(scan.points, res)
                out.append((scan, res, seg))
    return out


@pytest.mark.slow
def test_edges_precision_recall(runs):
    hits_p = flagged = hits_r = near = 0
    for scan, res, _ in runs:
        edge = res.point_class == 2
        other = ip.other_face_distance(scan)
        reach = res.features["OptimalRadius"]
        sel = (scan.crease_distance < scan.spacing) & (other < 2 * scan.spacing)
        hits_r += int(edge[sel].sum())
        near += int(sel.sum())
        hits_p += int((other[edge] <= reach[edge]).sum())
        flagged += int(edge.sum())
    precision, recall = hits_p / flagged, hits_r / near
    assert precision >= 0.9, precision
    assert recall >= 0.9, recall


@pytest.mark.slow
def test_hoover_every_surface(runs):
    correct = total = 0
    for scan, _, seg in runs:
        c, n = ip.hoover_counts(scan, seg.labels)
        correct += c
        total += n
    assert correct / total >= 0.9, (correct, total)


@pytest.mark.slow
def test_automatic_scale_is_reported(runs):
    for _, res, _ in runs[:2]:
        k = res.features["OptimalKNN"]
        assert k.min() >= 20 and k.max() <= 50
        assert np.array_equal(k, res.features["neighbors"])
        assert res.params["scale"] == "optimal"
        assert "automatic" in res.summary()


def _plane_image(rng, slope_deg, sigma, spacing=1.0, size=120):
    """A range image of a plane of the given slope, noise along z."""
    g = np.arange(0, size, spacing)
    x, y = np.meshgrid(g, g, indexing="ij")
    x, y = x.ravel(), y.ravel()
    az = rng.uniform(0, 2 * np.pi)
    t = np.tan(np.radians(slope_deg))
    z = t * (np.cos(az) * x + np.sin(az) * y) + rng.normal(0, sigma, x.size)
    return np.c_[x, y, z], np.c_[x, y]


def _spread_queries(xy, k_radius, size):
    """Points on a lattice far enough apart that their neighbourhoods do not overlap."""
    step = 2.5 * k_radius
    lattice = np.arange(step, size - step, step)
    gx, gy = np.meshgrid(lattice, lattice, indexing="ij")
    from scipy.spatial import cKDTree

    return cKDTree(xy).query(np.c_[gx.ravel(), gy.ravel()])[1]


@pytest.mark.parametrize("slope", [0.0, 60.0])
def test_plane_test_size_z_noise(slope):
    """Size of the plane test (alpha 0.05, k = 30, the true sigma) on flat and steep
    faces of a z-noise range image: within the 99.9 % binomial interval."""
    def plane_p(pts):
        feats = covariance_features(pts, k=30)
        return classify_covariance(feats, sigma=0.05, noise="z", points=pts)["plane_p"]

    _assert_plane_test_size(slope, plane_p)


@pytest.mark.parametrize("slope", [0.0, 60.0])
def test_plane_test_size_z_noise_automatic_scale(slope):
    """The same at the automatic scale (each point's prefix chosen by its plane test):
    within the 99.9 % binomial interval on flat and steep faces (4.1 % of 864 and 6.8 %
    of 384 neighbourhoods)."""
    _assert_plane_test_size(slope, lambda pts: covariance(pts, sigma=0.05)["plane_p"])


def _assert_plane_test_size(slope, plane_p):
    """Rejections at level 0.05 of `plane_p(points)` on 120 spread queries of six z-noise
    range images of a face of `slope` degrees: within the 99.9 % binomial interval."""
    from scipy.stats import binom

    alpha, rejected, tested = 0.05, 0, 0
    for seed in range(6):
        rng = np.random.default_rng(seed)
        pts, xy = _plane_image(rng, slope, 0.05)
        q = _spread_queries(xy, 3.5 / np.cos(np.radians(slope)) ** 0.5, 120)
        rejected += int((plane_p(pts)[q] < alpha).sum())
        tested += q.size
    lo, hi = binom.interval(0.999, tested, alpha)
    assert lo <= rejected <= hi, (rejected, tested)


@pytest.mark.parametrize("slope", [0.0, 60.0])
def test_sigma_estimate_on_steep_faces(slope):
    """The estimated z-noise sigma on a flat and a steep face (automatic scale)."""
    rng = np.random.default_rng(7)
    pts, _ = _plane_image(rng, slope, 0.05, size=80)
    res = covariance(pts)
    assert res.classes.sigma_estimated
    assert abs(res.classes.sigma / 0.05 - 1) < 0.1, res.classes.sigma


def test_normal_noise_calls_steep_z_noise_faces_rough_or_smooth():
    """With noise along z the default model (z) accepts a steep face as often as a flat
    one; the isotropic model calibrated on the flat face accepts the steep one more
    often (its noise across is sigma |n_z|, half of sigma at 60 degrees)."""
    rng = np.random.default_rng(3)
    flat, _ = _plane_image(rng, 0.0, 0.05, size=60)
    steep, _ = _plane_image(rng, 60.0, 0.05, size=60)
    steep = steep + [200.0, 0.0, 0.0]
    pts = np.r_[flat, steep]
    on_steep = np.arange(pts.shape[0]) >= flat.shape[0]
    z = covariance(pts, k=30, sigma=0.05)
    normal = covariance(pts, k=30, sigma=0.05, noise="normal")
    assert z.params["noise"] == "z"
    rate_z = (z["plane_p"][on_steep] < 0.05).mean()
    rate_normal = (normal["plane_p"][on_steep] < 0.05).mean()
    assert 0.02 < rate_z < 0.09
    assert rate_normal < 0.005


def test_tested_scale_stops_at_the_crease_only():
    """The tested scale (``tested_scale``): on a z-noise range image of two planes
    meeting at a 30-degree crease, the points far from the crease keep all 50 neighbours
    (a stop by chance has probability 4e-4 per size) and those beside it stop below 50,
    with a neighbourhood that reaches across the crease."""
    from lidarstat.features import tested_scale

    rng = np.random.default_rng(5)
    g = np.arange(0, 60, 1.0)
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    z = np.tan(np.radians(30)) * np.maximum(x - 30, 0) + rng.normal(0, 0.05, x.size)
    pts = np.c_[x, y, z]
    feats = covariance_features(pts, k=50, keep_neighbors=True)
    k = tested_scale(pts, feats.neighborhoods, sigma=0.05, noise="z")
    inner = (y > 5) & (y < 55) & (x > 5) & (x < 55)
    far = inner & (np.abs(x - 30) > 6)
    near = inner & (np.abs(x - 30) < 1.5)
    assert (k[far] == 50).mean() > 0.99
    assert (k[near] < 50).all()
    side = x > 30
    rows = side[feats.neighborhoods.indices.reshape(-1, 50)]
    prefix = np.arange(50)[None, :] < k[:, None]
    across = (rows & prefix).any(axis=1) & (~rows & prefix).any(axis=1)
    assert across[near].all()
