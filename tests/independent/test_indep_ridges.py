"""Ridges with their defaults (automatic scale) on independent scenes (issue 17, part 3).

A seed sweep of small randomised scenes from ``indep_ridges`` (plain NumPy, exact truth):
Gaussian and cylindrical crest and trench profiles of several widths, heights and noise
levels, along straight and circular axes at random azimuths; planes, spheres and
cylinders for "no ridge there". Every true ridge line (and every crease line of a
cylindrical profile) must be found within one point spacing on at least 90 % of its
length (beyond 0.1 m of the scene's ends), with at least 90 % of the ridge and crease
points within 2.5 spacings of a true line.
"""

import functools

import numpy as np
import pytest
from indep_ridges import CREASE, line_recall, make_null_scene, make_ridge_scene, ridge_precision

from lidarstat.segment import ridges

MARGIN = 0.1  # metres of each line's ends left out (one-sided neighbourhoods)


def _scene(seed, kind, sign, curved):
    rng = np.random.default_rng(seed)
    spacing = float(rng.uniform(0.018, 0.024))
    length = float(rng.uniform(0.8, 1.0))
    return make_ridge_scene(rng, kind=kind, sign=sign, curved=curved, spacing=spacing,
                            length=length)


@functools.cache
def _scored(seed, kind, sign, curved):
    """Scene, result, recall per line and precision (each scene run once per session)."""
    with np.errstate(divide="ignore"):
        scene = _scene(seed, kind, sign, curved)
    return (scene, *_score(scene))


def _score(scene):
    res = ridges(scene.xyz, creases=True)
    rec = line_recall(scene, res["ridge"], scene.xyz, margin=MARGIN)
    return res, rec, ridge_precision(scene, res["ridge"])


GAUSS = [(seed, sign, curved) for seed, (sign, curved) in
         enumerate([(1.0, False), (-1.0, False), (1.0, True), (-1.0, True),
                    (1.0, False), (-1.0, True)])]


@pytest.mark.parametrize("seed,sign,curved", GAUSS)
def test_gaussian_ridges_found_at_the_automatic_scale(seed, sign, curved):
    """Axis line and both flank lines of a Gaussian crest or trench: each within a spacing
    on >= 90 % of its length."""
    scene, res, rec, _ = _scored(100 + seed, "gauss", sign, curved)
    assert all(r >= 0.9 for _, r in rec), (rec, scene.params)
    assert res.params["scale"] == "auto"
    assert np.all(np.isin(res["radius"], res.params["radii"]))


def test_gaussian_ridge_points_lie_on_true_lines():
    """>= 90 % of the ridge points within 2.5 spacings of a true line, on every scene."""
    worst = 1.0
    for seed, sign, curved in GAUSS:
        prec = _scored(100 + seed, "gauss", sign, curved)[3]
        worst = min(worst, prec)
    assert worst >= 0.9, worst


def test_cylindrical_profile_ridges_found_at_the_automatic_scale():
    """A circular arc on flat ground: its feet are creases (the curvature jumps from 0 to
    1/r), no smooth ridge. Each foot line found by crease points (code 3) within a
    spacing on >= 90 % of its length; >= 90 % of the crest, ravine and crease points
    within 2.5 spacings of a foot line (the arc, of constant curvature, has no ridge)."""
    worst_rec, worst_prec = 1.0, 1.0
    for seed, (sign, curved) in enumerate([(1.0, False), (-1.0, True)]):
        scene, res, rec, prec = _scored(200 + seed, "cyl", sign, curved)
        assert all(t == CREASE for t, _ in rec)
        worst_rec = min([worst_rec] + [r for _, r in rec])
        worst_prec = min(worst_prec, prec)
    assert worst_rec >= 0.9 and worst_prec >= 0.9, (worst_rec, worst_prec)


@functools.cache
def _null(kind, seed):
    xyz, info = make_null_scene(300 + seed, kind, half=0.3)
    return xyz, info, ridges(xyz, creases=True)


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder"])
def test_no_ridge_on_planes_spheres_cylinders(kind):
    """No ridge and no crease point at all (``ridge`` 0 everywhere, no line); a plane is
    not umbilic (k1 = k2 = 0 is not a significant curvature): the umbilic share stays at
    the level of chance."""
    for seed in range(2):
        _, _, res = _null(kind, seed)
        assert int((res["ridge"] > 0).sum()) == 0 and len(res.lines) == 0, (kind, seed)
        if kind == "plane":
            assert res["umbilic"].mean() < 0.05


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder"])
def test_nothing_to_detect_keeps_the_smallest_radius(kind):
    """Where no ridge's k'' exists (planes; spheres and cylinders, whose curvature is
    constant along its lines) the rung selection (level alpha per seed, a simulated null)
    leaves >= 95 % of the points at the smallest radius."""
    for seed in range(2):
        _, _, res = _null(kind, seed)
        assert np.mean(res["radius"] == res.params["radii"][0]) >= 0.95, (kind, seed)


def test_sigma_estimate_is_median_unbiased():
    """The noise estimated at the smallest rung (a median over jets whose variance
    estimates are skewed chi-squares of about 16 degrees of freedom) is within 3 % of
    the true sigma on average over spheres and cylinders (noise along z, normal near z)."""
    ratios = []
    for kind in ("sphere", "cylinder"):
        for seed in range(2):
            _, info, res = _null(kind, seed)
            ratios.append(res.jets.sigma / info["sigma"])
    assert 0.97 <= np.mean(ratios) <= 1.03, ratios
    assert all(0.9 <= r <= 1.1 for r in ratios), ratios


@pytest.mark.parametrize("rung", [1, 3])
def test_scale_null_quantile_holds_on_fresh_planes(rung):
    """The k'' selection statistic on fresh simulated planes (other noise, other pattern,
    at a rung inside and one outside the simulated ones) exceeds the calibrated
    quantile at 1 % and 0.2 % within the exact binomial intervals of those rates."""
    from lidarstat.features._jet_scale import _null_sample, null_quantile
    from lidarstat.segment._ridges import RIDGE_SCALE
    from lidarstat.stats import binomial_test

    kw = dict(degree=4, weight="tricube", min_neighbors=16)
    fresh = _null_sample(RIDGE_SCALE, rung, 4, "tricube", 16, samples=2000, seed=7)
    for prob in (0.01, 0.002):
        hits = int(np.sum(fresh > null_quantile(RIDGE_SCALE, rung, prob, kw)))
        # two-sided at 0.002: neither too many nor too few exceedances
        assert not binomial_test(hits, fresh.size, prob, alpha=0.001).reject, (prob, hits)
        assert not binomial_test(fresh.size - hits, fresh.size, 1 - prob,
                                 alpha=0.001).reject, (prob, hits)


def _tilted_plane_selection(tilt_deg, rung, samples=2000, seed=1, alpha=0.01):
    """Seeds of a plane tilted by `tilt_deg` (noise along z, a jittered unit grid in plan:
    stretched along the slope) at which the automatic scale would take rung `rung` by
    the k'' test alone (the statistic above its quantile at ``alpha / J``, no power term),
    and the number of fitted seeds."""
    import math

    from scipy.spatial import cKDTree

    from lidarstat.features import height_variance, jet_tests
    from lidarstat.features._jet_fit import _fit_cells, _to_fit
    from lidarstat.features._jet_scale import SCALE_RUNGS, null_quantile, radius_ladder
    from lidarstat.neighbors import CellIndex
    from lidarstat.segment._ridges import RIDGE_SCALE, _ridge_statistic

    rng = np.random.default_rng(seed)
    m = int(math.ceil(math.sqrt(samples)))
    r_max = 4.0 * math.sqrt(2.0) ** rung  # about the rung's radius on a unit grid
    step = 1.25 * r_max
    side = int(m * step + 4 * r_max) + 2
    g = np.arange(side, dtype=np.float64)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    x = x + rng.uniform(-0.5, 0.5, x.size)
    y = y + rng.uniform(-0.5, 0.5, y.size)
    sigma = 0.01
    pts = np.c_[x, y, math.tan(math.radians(tilt_deg)) * x + rng.normal(0, sigma, x.size)]
    r = float(radius_ladder(pts, sample=20000)[rung])
    grid = 2 * r_max + 1 + step * np.arange(m)
    gx, gy = (a.ravel()[:samples] for a in np.meshgrid(grid, grid))
    q = np.unique(cKDTree(pts[:, :2]).query(np.c_[gx, gy])[1])
    mask = np.zeros(len(pts), bool)
    mask[q] = True
    kw = dict(degree=4, monge_degree=4, weight="tricube", sensor=None, min_neighbors=16,
              standard_errors=True)
    out = _fit_cells(CellIndex(pts, r), active=mask, block_size=131072, progress=None, **kw)
    fit = _to_fit({k: v[q] for k, v in out.items()}, 4, 4, "tricube")
    fields = jet_tests(fit, height_variance(fit.frame, sigma, noise="z"), alpha)
    ok = fit.status == 0
    above = (_ridge_statistic(fit, fields) > null_quantile(
        RIDGE_SCALE, rung, alpha / SCALE_RUNGS, kw)) & ok
    return int(above.sum()), int(ok.sum()), alpha / SCALE_RUNGS


@pytest.mark.parametrize("rung", [0, pytest.param(2, marks=pytest.mark.xfail(
    strict=True, reason="measured 10 of 2,000 seeds above the quantile at rung 2 (rate "
    "0.005 against alpha / J = 0.0014, binomial p = 0.0008): the null is simulated on an "
    "isotropic jittered grid, and a 60-degree plane sampled on a grid in plan is stretched "
    "twice along its slope; the statistic's law depends on that pattern. To come: "
    "simulate the null on the data's own neighbourhood patterns (the seeds' offsets with "
    "noise heights)"))])
def test_scale_selection_size_on_a_steep_plane(rung):
    """Nothing to detect on a plane tilted by 60 degrees with z noise (a pattern stretched
    along the slope, not the simulated one; k1 = k2 = 0, where the linearised sd of k''
    does not describe its spread): the share of seeds the k'' test (without the power
    term) would move to a rung is not above alpha / J (one-sided exact binomial test at
    0.001): the simulated null, not a normal one, carries the test's size there."""
    from lidarstat.stats import binomial_test

    above, n, p0 = _tilted_plane_selection(60.0, rung)
    assert n >= 1900
    assert not binomial_test(above, n, p0, alpha=0.001).reject, (above, n, p0)
