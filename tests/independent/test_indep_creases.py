"""Crease points and lines of ``ridges`` (code 3 of the ``ridge`` field) on independent
scenes: folded planes (a tangent jump of known angle along a known line) found, steep
narrow Gaussian crests (smooth, where a degree-4 jet's truncation is rejected) left
without a crease; each crease line carries its test. Plain NumPy scenes, seed sweeps."""

import functools

import numpy as np
import pytest
from indep_ridges import CREASE, make_ridge_scene

from lidarstat.segment import ridges
from lidarstat.segment._ridge_creases import MAX_GROWTH, misfit_growth


def _fold(seed):
    """Two planes meeting along a line (slopes of 15 to 35 degrees on either side, a
    convex or concave fold), jittered grid, random azimuth, noise along z. Returns the
    points, the spacing, and each point's distance to the fold line in plan and
    coordinate along it."""
    rng = np.random.default_rng(seed)
    spacing = float(rng.uniform(0.015, 0.022))
    sigma = float(rng.uniform(0.0005, 0.0015))
    g = np.arange(-0.45, 0.45 + spacing / 2, spacing)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    x = x + rng.uniform(-0.3, 0.3, x.size) * spacing
    y = y + rng.uniform(-0.3, 0.3, y.size) * spacing
    left, right = np.tan(np.radians(rng.uniform(15, 35, 2)))
    sign = rng.choice([-1.0, 1.0])
    z = sign * np.where(x < 0, left * x, -right * x) + rng.normal(0, sigma, x.size)
    th = float(rng.uniform(0, 2 * np.pi))
    c, s = np.cos(th), np.sin(th)
    xyz = np.c_[c * x - s * y, s * x + c * y, z] + np.r_[rng.uniform(-500, 500, 2), 3.0]
    return xyz, spacing, np.abs(x), y


@functools.cache
def _fold_result(seed):
    xyz, spacing, dist, along = _fold(seed)
    return xyz, spacing, dist, along, ridges(xyz)


@pytest.mark.parametrize("seed", range(3))
def test_fold_line_is_a_crease(seed):
    """The fold is found by crease points within a spacing of the line on >= 90 % of its
    length (beyond 0.1 m of the scene's border), >= 90 % of the ridge and crease points
    lie within 2.5 spacings of it, and it is one crease line (code 3) with its test:
    misfit above the noise, chi-square p-value below the Bonferroni level, growth at most
    MAX_GROWTH, length at least twice the crease radius."""
    xyz, spacing, dist, along, res = _fold_result(seed)
    r = res["ridge"]
    crease = r == CREASE
    bins = np.arange(-0.35, 0.35, spacing)
    hit = np.histogram(along[crease & (dist <= spacing)], bins)[0] > 0
    assert hit.mean() >= 0.9, hit.mean()
    assert np.mean(dist[r > 0] <= 2.5 * spacing) >= 0.9
    a = res.lines.attributes
    lines = a["ridge"] == CREASE
    assert lines.any() and np.all(np.isin(res["ridge_line"][crease], a["line_id"][lines]))
    assert np.all(a["misfit"][lines] > 1) and np.all(a["misfit_growth"][lines] <= MAX_GROWTH)
    assert np.all(a["length"][lines] >= 2 * res.params["crease_radius"] * 0.999)
    n_eff = len(xyz) / np.median(res.jets["neighbors"])
    assert np.all(a["misfit_p"][lines] < res.params["alpha"] / n_eff)
    assert np.all(np.isnan(a["misfit"][~lines]))


@pytest.mark.parametrize("seed", range(3))
def test_no_crease_on_steep_narrow_gaussian_crests(seed):
    """A Gaussian crest or trench 0.12 m wide and 0.4 m high (flanks steeper than 60
    degrees) is smooth: a degree-4 jet at the crease radius is rejected near its axis
    (truncation), but that misfit grows like r^10 with the radius, not like a kink's
    r^2: no crease point."""
    with np.errstate(divide="ignore"):
        scene = make_ridge_scene(400 + seed, kind="gauss", sign=(-1.0) ** seed, width=0.12,
                                 amp=0.4, spacing=0.02, length=0.8)
    res = ridges(scene.xyz)
    assert int((res["ridge"] == CREASE).sum()) == 0
    assert not (res.lines.attributes["ridge"] == CREASE).any()


def test_creases_false_leaves_them_out():
    """With ``creases=False`` no point gets code 3 and no crease line is traced."""
    xyz = _fold_result(0)[0]
    res = ridges(xyz, creases=False)
    assert not (res["ridge"] == CREASE).any()
    assert not (res.lines.attributes["ridge"] == CREASE).any()
    assert "crease_radius" not in res.params


def test_crease_radius_from_the_noise():
    """The crease rung is the smallest over which a 45-degree kink rises 35 sigma, not
    below the third rung nor above the last but one."""
    from lidarstat.segment._ridge_creases import KINK_RISE, MIN_CREASE_RUNG, crease_rung

    radii = 0.05 * np.sqrt(2.0) ** np.arange(7)
    rise = radii * np.tan(np.radians(22.5))
    for j in range(MIN_CREASE_RUNG, 6):
        sigma = rise[j] / KINK_RISE  # rung j rises exactly 35 sigma
        assert crease_rung(radii, sigma) == j
        assert crease_rung(radii, sigma * 1.01) == min(j + 1, 5)
    assert crease_rung(radii, 1e-6) == MIN_CREASE_RUNG
    assert crease_rung(radii, 1.0) == 5
    assert crease_rung(radii[:1], 1e-3) == 0


def test_misfit_growth():
    """Excess variance factor's growth from one rung to the next; NaN without excess."""
    g = misfit_growth(np.array([3.0, 11.0, 1.0, 0.5]), np.array([5.0, 321.0, 4.0, 9.0]))
    np.testing.assert_allclose(g[:2], [2.0, 32.0])
    assert np.isnan(g[2:]).all()


def test_summary_and_fields_report_creases():
    """The summary counts crease points and lines; the written ``ridge`` field keeps the
    code 3 (uint8)."""
    *_, res = _fold_result(0)
    text = res.summary()
    assert f"crease points {int((res['ridge'] == CREASE).sum()):>9d}" in text
    assert "creases" in text
    assert res.to_fields()["ridge"].dtype == np.uint8
    assert (res.to_fields()["ridge"] == CREASE).any()
    assert res.params["crease_growth_radius"] > res.params["crease_radius"]


@pytest.mark.parametrize("seed", range(3))
def test_crease_points_do_not_depend_on_the_neighbour_blocks(seed, monkeypatch):
    """The crease test searches each point's neighbourhood once, in blocks of rows; in
    blocks of a few rows it marks the same points."""
    from lidarstat.segment import _ridge_creases as rc

    calls = []
    crease_points = rc.crease_points

    def keep(points, fields, **kw):
        calls.append((points, {k: np.array(v) for k, v in fields.items()}, kw))
        return crease_points(points, fields, **kw)

    monkeypatch.setattr(rc, "crease_points", keep)
    ridges(_fold(seed)[0])
    monkeypatch.setattr(rc, "crease_points", crease_points)
    assert calls
    for points, fields, kw in calls:
        whole = rc.crease_points(points, fields, **kw)
        assert whole.any()
        monkeypatch.setattr(rc, "CREASE_BLOCK", 3 * rc.CREASE_K)
        assert np.array_equal(rc.crease_points(points, fields, **kw), whole)
        monkeypatch.undo()
