"""Surface / edge / boundary classes: test sizes under true nulls, detection on known scenes."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarstat.classify import PointClass, classify_covariance, covariance
from lidarstat.classify._covariance_noise import (estimate_range_noise,
                                                  estimate_smooth_range_noise)
from lidarstat.classify._covariance_tests import curved_surface_test
from lidarstat.errors import InvalidParameterError
from lidarstat.features import covariance_features
from lidarstat.synth import make_tls_building, make_tls_plant


def _plane(rng, n=40000, size=20.0, sigma=0.01):
    return np.c_[rng.uniform(0, size, (n, 2)), rng.normal(0, sigma, n)]


def _separated(pts, spacing, margin, rng):
    """A random point of every other cell of a coarse grid: neighbourhoods that do not overlap.

    Random within its cell, so unbiased (the point nearest to a grid node would favour
    isolated points, whose neighbourhoods are atypical).
    """
    lo = pts[:, :2].min(axis=0)
    ij = np.floor((pts[:, :2] - lo) / spacing).astype(np.int64)
    inside = (pts[:, :2] - lo >= margin).all(axis=1) & \
        (pts[:, :2].max(axis=0) - pts[:, :2] >= margin).all(axis=1)
    even = inside & (ij % 2 == 0).all(axis=1)
    cand = rng.permutation(np.flatnonzero(even))
    key = ij[cand, 0] * 1_000_003 + ij[cand, 1]
    _, first = np.unique(key, return_index=True)
    return cand[first]


def _binomial_ok(rejected, alpha):
    n = rejected.size
    rate = rejected.mean()
    half = 3.3 * np.sqrt(alpha * (1 - alpha) / n)  # two-sided 99.9 %
    return abs(rate - alpha) <= half, rate, n


@pytest.mark.parametrize("k", [20, 50])
def test_test_sizes_under_true_nulls(rng, k):
    """Plane (known sigma), boundary and consistent-curvature tests on interior plane points."""
    alpha = 0.05
    plane_rej, bnd_rej, var_rej = [], [], []
    for _ in range(3):
        pts = _plane(rng)
        feats = covariance_features(pts, k=k)
        cls = classify_covariance(feats, sigma=0.01, alpha=alpha)
        flat = pts.copy()
        flat[:, 2] = 0.0  # the boundary test's null: a symmetric neighbourhood
        cls0 = classify_covariance(covariance_features(flat, k=k), sigma=0.01)
        sel = _separated(pts, 2.2 * np.sqrt(k / (np.pi * 100.0)), 1.0, rng)
        plane_rej.append(cls["plane_p"][sel] < alpha)
        bnd_rej.append(cls0["boundary_p"][sel] < alpha)
        var_rej.append(cls["variation_p"][sel] < alpha)
    for name, rej in (("plane", plane_rej), ("boundary", bnd_rej), ("variation", var_rej)):
        ok, rate, n = _binomial_ok(np.concatenate(rej), alpha)
        assert ok, f"{name} test rejects {rate:.3f} of {n} true nulls at alpha {alpha}"


def _gable(rng, n=40000, sigma=0.005):
    xy = rng.uniform(0, 10, (n, 2))
    z = 5 - np.tan(np.radians(30)) * np.abs(xy[:, 0] - 5) + rng.normal(0, sigma, n)
    pts = np.c_[xy, z]
    ridge = np.abs(xy[:, 0] - 5) * np.cos(np.radians(30))  # distance to the ridge line
    border = np.minimum.reduce([xy[:, 0], 10 - xy[:, 0], xy[:, 1], 10 - xy[:, 1]])
    return pts, ridge, border


def _f1(pred, truth):
    tp = np.count_nonzero(pred & truth)
    return 2 * tp / max(np.count_nonzero(pred) + np.count_nonzero(truth), 1)


def test_gable_roof_edges_and_boundaries(rng):
    """A ridge (crease) and the outer border of a noisy gable roof, k = 50.

    Truth: edge points lie within 0.6 r_k of the ridge, boundary points within 0.5 r_k of
    the border (r_k the median distance of the 50th neighbour): the bands whose
    neighbourhoods the tests can tell from a plane (docs/methods/covariance.md gives F1
    for other bands).
    """
    pts, ridge, border = _gable(rng)
    res = covariance(pts, k=50)
    d, _ = cKDTree(pts).query(pts[::50], k=50)
    rk = np.median(d[:, -1])
    pc = res.point_class
    assert _f1(pc == PointClass.EDGE, (ridge < 0.6 * rk) & (border > ridge)) >= 0.88
    assert _f1(pc == PointClass.BOUNDARY, (border < 0.5 * rk) & (ridge > border)) >= 0.85
    band = 0.6 * rk
    far = (ridge > 2 * band) & (border > 2 * band)
    assert (pc[far] == PointClass.SURFACE).mean() > 0.99


def test_pipe_is_a_consistently_curved_surface_not_an_edge(rng):
    """The paper's point: high curvature but consistent -> surface (Fig. 1)."""
    n = 30000
    t = rng.uniform(0, 2 * np.pi, n)
    h = rng.uniform(0, 6, n)
    r = 0.3 + rng.normal(0, 0.002, n)
    pts = np.c_[r * np.cos(t), r * np.sin(t), h]
    # the noise is radial, across the surface: noise='normal' (the default 'z' would
    # give this vertical pipe no noise across it)
    res = covariance(pts, k=50, sigma=0.002, noise="normal")
    inner = (h > 1) & (h < 5)
    assert (res["plane_p"][inner] < 0.05).mean() > 0.9  # not planes
    assert (res.point_class[inner] == PointClass.SURFACE).mean() > 0.9


@pytest.mark.parametrize("k", [20, 50])
def test_cylinder_test_size_under_true_nulls(rng, k):
    """The consistent-curvature (cylinder) test on a noisy pipe and a noisy plane, axes
    estimated from the normals: on the pipe the rejection rate is within the 99.9 %
    interval of alpha; on the plane (where the test only runs after the plane test
    rejected) the axis is chosen by the noise itself, the direction along which the
    neighbourhood is straightest, and the test is conservative (measured 2.4-4.2 %:
    docs/methods/covariance.md), never above alpha."""
    alpha, sigma, n = 0.05, 0.002, 40000
    rej = {"pipe": [], "plane": []}
    for _ in range(3):
        t = rng.uniform(0, 2 * np.pi, n)
        h = rng.uniform(0, 8, n)
        r = 0.3 + rng.normal(0, sigma, n)
        pipe = np.c_[r * np.cos(t), r * np.sin(t), h]
        plane = _plane(rng, n=n, sigma=sigma)
        for name, pts, flat in (("pipe", pipe, np.c_[0.3 * t, h]), ("plane", plane, plane)):
            feats = covariance_features(pts, k=k)
            rk = np.sqrt(k / (np.pi * n / np.ptp(flat[:, 0]) / np.ptp(flat[:, 1])))
            sel = _separated(np.c_[flat[:, :2], np.zeros(n)], 2.2 * rk, 0.3, rng)
            p, radius = curved_surface_test(pts, feats, sel, sigma)
            rej[name].append(p < alpha)
            if name == "pipe":
                assert abs(np.median(radius) - 0.3) < 0.01
    ok, rate, m = _binomial_ok(np.concatenate(rej["pipe"]), alpha)
    assert ok and m > 200, f"cylinder test rejects {rate:.3f} of {m} points of a pipe"
    ok, rate, m = _binomial_ok(np.concatenate(rej["plane"]), alpha)
    assert m > 200 and alpha / 3 < rate <= alpha + 3.3 * np.sqrt(alpha * (1 - alpha) / m), \
        f"cylinder test rejects {rate:.3f} of {m} points of a plane"


def _support_f1(make, step):
    from lidarstat.synth import neighborhood_class_truth

    sc = make(step=step, rng=0)
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True)
    truth = neighborhood_class_truth(sc, res.features.neighborhoods)
    return sc, res, truth


def test_tls_plant_pipes_and_tanks_are_surfaces_not_edges():
    """Consistently curved surfaces come out as surface (the cylinder test): on the
    sides of the pipes and tanks whose neighbourhoods hold no other face, < 3 % edges
    (the variation-of-curvature test gives 22 %); edges found with F1 >= 0.6 against the
    neighbourhood truth (0.43 with the variation test; docs/methods/covariance.md)."""
    sc, res, truth = _support_f1(make_tls_plant, 0.004)
    pc = res.point_class
    names = np.array(sc.meta["face_names"])[sc.face]
    curved = np.char.endswith(names.astype(str), "_side") & (truth == 1)
    assert curved.sum() > 3000
    assert (pc[curved] == PointClass.EDGE).mean() < 0.03
    assert _f1(pc == PointClass.EDGE, truth == 2) >= 0.6
    assert res.classes.meta["curved"] == "cylinder"


def test_smooth_range_noise_is_not_inflated_by_pipes_and_tanks():
    """The range noise of tls_plant (default step; truth 0.002 + 5e-5 r) from the
    residuals of the best smooth model (cylinder, the plane its limit) is within 10 % of
    the truth at 8, 15 and 22 m; the medians of the plane residuals, where pipes and tanks
    fill a range bin, are more than 1.5 times too large at 15 and 22 m (b = 2.9e-4). (At step 0.004 the k = 50 neighbourhoods of the pipe rack
    straddle two pipes and a support, most of its range bin is edges, and the smooth
    estimate is 1.3-1.7 times too large there: docs/methods/covariance.md.)"""
    sc = make_tls_plant(rng=0)
    f = covariance_features(sc.xyz, k=50, sensor=sc.scanner, keep_neighbors=True)
    r = np.array([8.0, 15.0, 22.0])
    truth = 0.002 + 5e-5 * r
    a, b = estimate_smooth_range_noise(sc.xyz, f)
    assert np.all(np.abs((a + b * r) / truth - 1) < 0.1), (a, b)
    a0, b0 = estimate_range_noise(f.eigenvalues, f.fields["neighbors"], f.ray_range, f.ray_cos)
    assert np.all((a0 + b0 * r)[1:] / truth[1:] > 1.5), (a0, b0)
    cl = classify_covariance(f, points=sc.xyz)
    assert cl.meta["range_noise"] == (a, b) and cl.params["range_noise"] == [a, b]
    with pytest.raises(InvalidParameterError, match="estimated from the `points`"):
        classify_covariance(f, boundary="centroid")


@pytest.mark.parametrize("make", [make_tls_building, make_tls_plant])
def test_tls_edges_and_boundaries_f1_against_neighbourhood_truth(make):
    """The issue's targets on the benchmark's scans (default step 0.0025, k = 50, every
    setting automatic, the default 'grid' boundary test): edge and boundary points with
    F1 >= 0.9 against the truth judged on the neighbourhoods used (measured: building
    0.955 / 0.909, plant 0.948 / 0.93; see docs/methods/covariance.md for the fixed-band
    truths, on which the figures are lower)."""
    _, res, truth = _support_f1(make, 0.0025)
    assert res.classes.meta["boundary"] == "grid"
    assert _f1(res.point_class == PointClass.EDGE, truth == 2) >= 0.9
    assert _f1(res.point_class == PointClass.BOUNDARY, truth == 3) >= 0.9


def test_user_thresholds_override_the_tests(rng):
    pts, ridge, border = _gable(rng, n=10000)
    feats = covariance_features(pts, k=30)
    everything_edge = classify_covariance(feats, curvature_threshold=0.0, variance_threshold=0.0)
    assert (everything_edge.point_class == PointClass.EDGE).mean() > 0.99
    paper = classify_covariance(feats, variance_threshold=1e-4)
    assert paper.variance_threshold == 1e-4 and "user" in paper.summary()


def test_bad_parameters(rng):
    feats = covariance_features(_plane(rng, n=500), k=10)
    with pytest.raises(InvalidParameterError, match="'alpha' parameter"):
        classify_covariance(feats, alpha=1.5)
    with pytest.raises(InvalidParameterError, match="'sigma' parameter"):
        classify_covariance(feats, sigma=np.ones(3))
    with pytest.raises(TypeError, match="noise_estimate"):
        classify_covariance(feats, noise_estimate="median")
    with pytest.raises(InvalidParameterError, match="'curved' parameter"):
        classify_covariance(feats, curved="sphere")
    exact = np.c_[rng.uniform(0, 1, (200, 2)), np.zeros(200)]
    with pytest.raises(InvalidParameterError, match="estimated noise is 0"):
        classify_covariance(covariance_features(exact, k=10))


def test_enums_strings_and_params(rng):
    """The choices take the enums or their strings; ``params`` records what was used; the
    replay options of earlier versions are gone."""
    from lidarstat.classify import BoundaryTest, CurvedTest
    from lidarstat.features import EigenMode

    pts = _plane(rng, n=1500)
    a = covariance(pts, k=20, boundary=BoundaryTest.CENTROID, curved=CurvedTest.VARIATION,
                   eigen_mode=EigenMode.SQRT)
    b = covariance(pts, k=20, boundary="centroid", curved="variation", eigen_mode="sqrt")
    assert np.array_equal(a.point_class, b.point_class)
    assert np.array_equal(a["Linearity"], b["Linearity"], equal_nan=True)
    p = a.params
    assert (p["boundary"], p["curved"], p["eigen_mode"]) == ("centroid", "variation", "sqrt")
    assert p["k"] == 20 and p["sensor"] is None and p["sigma_estimated"]
    assert p["boundary_alpha"] == 0.001 and p["curved_alpha"] == p["alpha"] == 0.05
    assert "centroid test at 0.001" in a.summary()
    for gone in ("noise_estimate", "edge_boundary_alpha"):
        with pytest.raises(TypeError, match=gone):
            covariance(pts, k=20, **{gone: None})
    with pytest.raises(InvalidParameterError, match="'eigen_mode' parameter"):
        covariance(pts, k=20, eigen_mode="log")
