"""Local plane regression (seed 002, eq. 6-7): kernel against a naive loop, exactness,
calibrated standard errors and planarity test, PRESS, bandwidth selection, Geary."""

import numpy as np
import pytest
from scipy import stats

from lidarstat.errors import InvalidParameterError, InvalidPointsError
from lidarstat.features import (geary_bandwidths, local_planes, select_plane_bandwidth)
from lidarstat.neighbors import radius_neighbors


def _naive(points, i, b):
    d = np.hypot(*(points[:, :2] - points[i, :2]).T)
    use = d < b
    w = (1 - (d[use] / b) ** 3) ** 3
    A = np.c_[np.ones(use.sum()), points[use, :2] - points[i, :2]]
    z = points[use, 2]
    N = A.T @ (w[:, None] * A)
    Ni = np.linalg.inv(N)
    beta = Ni @ A.T @ (w * z)
    C = Ni @ A.T @ ((w * w)[:, None] * A) @ Ni
    r = z - A @ beta
    q = np.sum(w * r * r)
    B = np.diag(w) - (w[:, None] * A) @ Ni @ (A.T * w)
    return beta, C, q, np.trace(B), np.trace(B @ B), Ni[0, 0]


def test_kernel_matches_naive_loop(rng):
    pts = np.c_[rng.uniform(0, 10, (600, 2)), rng.normal(0, 1, 600)]
    fit = local_planes(pts, 1.3, sigma=1.0)
    for i in rng.choice(600, 25, replace=False):
        if not fit.ok[i]:
            continue
        beta, C, q, tb, tb2, h = _naive(pts, i, 1.3)
        np.testing.assert_allclose(fit.beta[i], beta, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(fit.cofactor[i], C, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(fit.leverage[i], h, rtol=1e-9)
        np.testing.assert_allclose(fit.local_sigma2[i], q / tb, rtol=1e-8)
        np.testing.assert_allclose(fit.planarity.df[i], tb * tb / tb2, rtol=1e-8)


def test_exact_on_a_plane_and_utm_coordinates(rng):
    xy = rng.uniform(0, 30, (2000, 2)) + [512000.0, 5400000.0]
    z = 120.0 + 0.3 * (xy[:, 0] - 512000) - 0.7 * (xy[:, 1] - 5400000)
    fit = local_planes(np.c_[xy, z], 1.5, sigma=0.01)
    ok = fit.ok
    assert ok.mean() > 0.99
    np.testing.assert_allclose(fit.beta[ok, 1], 0.3, atol=1e-8)
    np.testing.assert_allclose(fit.beta[ok, 2], -0.7, atol=1e-8)
    np.testing.assert_allclose(fit.z0[ok], z[ok], atol=1e-6)


def _independent_planes(rng, n_patches=400, sigma=0.05, b=1.5):
    """Patches 4b apart: neighbourhoods of the patch centres do not overlap."""
    centres = np.stack(np.meshgrid(np.arange(20), np.arange(20)), -1).reshape(-1, 2) * 4 * b
    pts, idx = [], []
    for k, c in enumerate(centres[:n_patches]):
        p = c + rng.uniform(-b, b, (40, 2))
        p[0] = c
        idx.append(len(pts) * 40)
        pts.append(p)
    xy = np.concatenate(pts)
    z = 3.0 + 0.4 * xy[:, 0] + 0.1 * xy[:, 1] + rng.normal(0, sigma, len(xy))
    return np.c_[xy, z], np.array(idx)


def test_standard_errors_and_planarity_test_are_calibrated(rng):
    pts, centre = _independent_planes(rng)
    fit = local_planes(pts, 1.5, sigma=0.05, alpha=0.05)
    zs = (fit.beta[centre, 1] - 0.4) / fit.se[centre, 1]
    assert 0.85 < zs.std() < 1.15
    zn = (fit.beta[centre, 2] - 0.1) / fit.se[centre, 2]
    assert 0.85 < zn.std() < 1.15
    rate = fit.planarity.reject[centre].mean()
    lo, hi = stats.binom.ppf([0.001, 0.999], centre.size, 0.05) / centre.size
    assert lo <= rate <= hi


def test_estimated_sigma_and_planarity_rejects_a_ridge(rng):
    xy = rng.uniform(0, 20, (6000, 2))
    z = np.where(xy[:, 0] < 10, 0.6 * xy[:, 0], 12 - 0.6 * xy[:, 0]) + rng.normal(0, 0.03, 6000)
    fit = local_planes(np.c_[xy, z], 1.2)
    assert abs(np.sqrt(fit.sigma2) - 0.03) < 0.004
    ridge = np.abs(xy[:, 0] - 10) < 0.3
    far = np.abs(xy[:, 0] - 10) > 1.5
    assert fit.planarity.reject[ridge].mean() > 0.9
    assert fit.planarity.reject[far].mean() < 0.1


def test_press_equals_brute_force_leave_one_out(rng):
    pts = np.c_[rng.uniform(0, 6, (300, 2)), rng.normal(0, 0.1, 300)]
    pts[:, 2] += np.sin(pts[:, 0])
    fit = local_planes(pts, 1.2, sigma=0.1)
    for i in rng.choice(300, 10, replace=False):
        keep = np.arange(300) != i
        d = np.hypot(*(pts[keep, :2] - pts[i, :2]).T)
        use = d < 1.2
        w = (1 - (d[use] / 1.2) ** 3) ** 3
        A = np.c_[np.ones(use.sum()), pts[keep][use, :2] - pts[i, :2]]
        beta = np.linalg.solve(A.T @ (w[:, None] * A), A.T @ (w * pts[keep][use, 2]))
        loo = pts[i, 2] - beta[0]
        assert fit.resid[i] / (1 - fit.leverage[i]) == pytest.approx(loo, rel=1e-8)


def test_bandwidth_selection_balances_bias_and_variance(rng):
    xy = rng.uniform(0, 20, (3000, 2))
    cand = [0.6, 1.0, 1.6, 2.5, 4.0]
    plane = np.c_[xy, 0.2 * xy[:, 0] + rng.normal(0, 0.05, 3000)]
    assert select_plane_bandwidth(plane, cand).bandwidth == 4.0
    wavy = np.c_[xy, np.sin(xy[:, 0] * 1.5) + rng.normal(0, 0.02, 3000)]
    for crit in ("rice", "gcv", "press"):
        sel = select_plane_bandwidth(wavy, cand, criterion=crit)
        assert sel.bandwidth <= 1.0 and np.argmin(sel.scores) == cand.index(sel.bandwidth)
    # the penalty grows as the bandwidth shrinks towards ~2 points per window
    sel = select_plane_bandwidth(plane, [0.12, 4.0], criterion="rice")
    assert sel.scores[0] > sel.scores[1]


def test_geary_adaptive_bandwidth_shrinks_at_a_step(rng):
    xy = rng.uniform(0, 20, (5000, 2))
    z = np.where(xy[:, 0] < 10, 0.0, 3.0) + rng.normal(0, 0.02, 5000)
    pts = np.c_[xy, z]
    b = geary_bandwidths(pts, 1.5)
    near = np.abs(xy[:, 0] - 10) < 0.3
    far = np.abs(xy[:, 0] - 10) > 3
    # at the step the indicator exceeds its neighbours' -> smaller windows; on the flat,
    # noise alone drives gamma (it is a ratio of noisy sums), so windows spread about b
    assert np.median(b[near]) < 1.5 < np.median(b[far])
    assert np.median(b[near]) < 0.6 * np.median(b[far])
    assert b.min() >= 0.75 - 1e-12 and b.max() <= 3.0 + 1e-12
    fit = local_planes(pts, 1.5, adaptive=True)
    np.testing.assert_allclose(fit.bandwidth, b)


def test_given_neighborhoods_give_the_same_fit(rng):
    pts = np.c_[rng.uniform(0, 8, (800, 2)), rng.normal(0, 0.1, 800)]
    nbh = radius_neighbors(pts, 1.5, dim=2)
    a = local_planes(pts, 1.2, sigma=0.1)
    b = local_planes(pts, 1.2, sigma=0.1, neighborhoods=nbh)
    np.testing.assert_allclose(a.beta, b.beta, equal_nan=True)
    with pytest.raises(InvalidParameterError, match="radius"):
        local_planes(pts, 2.0, neighborhoods=nbh)


def test_bad_input():
    with pytest.raises(InvalidParameterError, match="'bandwidth'"):
        local_planes(np.zeros((5, 3)), -1.0)
    with pytest.raises(InvalidPointsError, match="NaN"):
        local_planes(np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), 1.0)
    pts = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]  # collinear
    fit = local_planes(pts, 5.0, sigma=0.1)
    assert (fit.status[3:7] == 2).all() and np.isin(fit.status, [1, 2]).all()
    assert np.isnan(fit.beta).all() and not fit.ok.any()


def test_multiscale_bandwidth_shrinks_only_near_the_ridge(rng):
    xy = rng.uniform(0, 20, (6000, 2))
    z = np.where(xy[:, 0] < 10, 0.6 * xy[:, 0], 12 - 0.6 * xy[:, 0]) + rng.normal(0, 0.03, 6000)
    pts = np.c_[xy, z]
    one = local_planes(pts, 1.2)
    ms = local_planes(pts, 1.2, adaptive="multiscale")
    np.testing.assert_allclose(np.unique(ms.bandwidth), [0.6, 0.9, 1.2])
    dist = np.abs(xy[:, 0] - 10)
    # windows shrink where the full window crosses the ridge; elsewhere only after a false
    # rejection of the planarity test (level 0.05)
    shrunk = ms.bandwidth < 1.2
    passed = ms.to_fields()["plane_pass"] == 1
    band = (dist > 0.3) & (dist < 0.9)
    assert shrunk[band].mean() > 0.6 and passed[band].mean() > 0.85
    assert shrunk[dist > 1.5].mean() < 0.08
    # at the ridge no window holds one plane: the test still rejects there
    assert passed[dist < 0.15].mean() < 0.2
    # the same noise estimate; points planar at b keep their fit exactly
    assert ms.sigma2 == one.sigma2
    keep = ms.bandwidth == 1.2
    np.testing.assert_array_equal(ms.beta[keep], one.beta[keep])
    # more points with an accepted plane, and the shrunk windows' slopes are the faces'
    assert ms.to_fields()["plane_pass"].mean() > one.to_fields()["plane_pass"].mean() + 0.03
    small = (ms.bandwidth < 1.2) & (ms.to_fields()["plane_pass"] == 1) & (dist > 0.3)
    true_slope = np.where(xy[small, 0] < 10, 0.6, -0.6)
    z_score = (ms.beta[small, 1] - true_slope) / ms.se[small, 1]
    assert small.sum() > 100 and abs(np.median(z_score)) < 0.5
    with pytest.raises(InvalidParameterError, match="scales"):
        local_planes(pts, 1.2, adaptive="multiscale", scales=(0.8, 0.5))
    with pytest.raises(InvalidParameterError, match="adaptive"):
        local_planes(pts, 1.2, adaptive="lepski")
    nb = radius_neighbors(pts, 1.2, dim=2)
    given = local_planes(pts, 1.2, adaptive="multiscale", neighborhoods=nb)
    np.testing.assert_allclose(given.bandwidth, ms.bandwidth)
    np.testing.assert_allclose(given.beta, ms.beta, equal_nan=True)
