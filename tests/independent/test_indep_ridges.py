"""Ridges with their defaults (automatic scale) on independent scenes (issue 17, part 3).

A seed sweep of small randomised scenes from ``indep_ridges`` (plain NumPy, exact truth):
Gaussian and cylindrical crest and trench profiles of several widths, heights and noise
levels, along straight and circular axes at random azimuths; planes, spheres and
cylinders for "no ridge there". Every true ridge line must be found within one point
spacing on at least 90 % of its length (beyond 0.1 m of the scene's ends), with at least
90 % of the ridge points within 2.5 spacings of a true line.
"""

import functools

import numpy as np
import pytest
from indep_ridges import line_recall, make_null_scene, make_ridge_scene, ridge_precision

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
    res = ridges(scene.xyz)
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


@pytest.mark.xfail(strict=True, reason="measured precision 0.59 and 0.82 on the coarsest "
                   "scenes (spacing 0.023, w/spacing 5.4): on the flat ground beside a narrow "
                   "crest the largest rungs detect the k'' of the smoothed crest and trace "
                   "weak crests (|k| 0.2 /m, chi-square rejected) 2 to 4 widths off the axis")
def test_gaussian_ridge_points_lie_on_true_lines():
    """>= 90 % of the ridge points within 2.5 spacings of a true line, on every scene."""
    worst = 1.0
    for seed, sign, curved in GAUSS:
        prec = _scored(100 + seed, "gauss", sign, curved)[3]
        worst = min(worst, prec)
    assert worst >= 0.9, worst


@pytest.mark.xfail(strict=True, reason="cylindrical profiles (crease lines at the feet of a "
                   "circular arc): benchmarks/ridge_family.py measures 4 of "
                   "16 lines at recall >= 0.9 (median 0.81, min 0.46), precision 0.78-1.00; "
                   "the large rungs chosen on the arc see both creases and "
                   "put crests inside the arc")
def test_cylindrical_profile_ridges_found_at_the_automatic_scale():
    worst_rec, worst_prec = 1.0, 1.0
    for seed, (sign, curved) in enumerate([(1.0, False), (-1.0, True)]):
        _, _, rec, prec = _scored(200 + seed, "cyl", sign, curved)
        worst_rec = min([worst_rec] + [r for _, r in rec])
        worst_prec = min(worst_prec, prec)
    assert worst_rec >= 0.9 and worst_prec >= 0.9, (worst_rec, worst_prec)


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder"])
def test_no_ridge_on_planes_spheres_cylinders(kind):
    """No ridge point at all; a plane is not umbilic (k1 = k2 = 0 is not a significant
    curvature): the umbilic share stays at the level of chance."""
    for seed in range(2):
        xyz, _ = make_null_scene(300 + seed, kind, half=0.3)
        res = ridges(xyz)
        assert int((res["ridge"] > 0).sum()) == 0 and len(res.lines) == 0, (kind, seed)
        if kind == "plane":
            assert res["umbilic"].mean() < 0.05


@pytest.mark.xfail(strict=True, reason="measured 0.898 of the points at the smallest radius on "
                   "a tilted plane (seed 300): about 3 % of the seeds pass the k'' selection "
                   "test where its level is 1 %; the linearised sd of k'' (which holds b2^2 / "
                   "(k1 - k2)) is not normal near k1 = k2")
def test_nothing_to_detect_keeps_the_smallest_radius():
    """On a plane the rung selection (Bonferroni over the rungs, level alpha per seed)
    leaves >= 95 % of the points at the smallest radius (a seed's rung spreads over the
    about 3 seeds' worth of points within the smallest radius)."""
    for seed in range(2):
        xyz, _ = make_null_scene(300 + seed, "plane", half=0.3)
        res = ridges(xyz)
        assert np.mean(res["radius"] == res.params["radii"][0]) >= 0.95, seed
