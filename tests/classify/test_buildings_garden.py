"""The building test of `moments` on the garden scene (exact truth, seed sweep): flat
roofs with walls, crowns on trunks beside and over the roofs, a clipped hedge as high as
a shed beside a low garden wall (`lidarstat.synth.make_garden_scene`)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.classify import moments
from lidarstat.synth import GARDEN_PARTS, make_garden_scene

SEEDS = (0, 1, 2, 3)


def _run(seed):
    s = make_garden_scene(rng=seed)
    a = s.attributes
    res = moments(s.xyz, s.intensity, number_of_returns=a["number_of_returns"],
                  return_number=a["return_number"])
    return s, res


def _share(pred, s, name):
    return float(pred[s.attributes["part"] == GARDEN_PARTS[name][0]].mean())


def test_garden_scene_truth_is_consistent():
    s = make_garden_scene(rng=5)
    a = s.attributes
    assert len(a["part"]) == len(s.xyz) == len(a["classification"])
    assert np.all(a["return_number"] <= a["number_of_returns"])
    assert set(np.unique(a["part"])) == {code for code, _ in GARDEN_PARTS.values()}
    for code, cls in GARDEN_PARTS.values():
        assert np.all(a["classification"][a["part"] == code] == cls)
    assert np.array_equal(s.ground, a["classification"] == 2)
    # half of the crown pulses give a last echo lower down, none of the roofs'
    first = a["return_number"] == 1
    crown = a["part"] == GARDEN_PARTS["crown"][0]
    roof = a["part"] == GARDEN_PARTS["roof"][0]
    assert 0.45 < np.mean(a["number_of_returns"][crown & first] == 2) < 0.55
    assert np.all(a["number_of_returns"][roof] == 1)
    t = make_garden_scene(rng=5)
    assert np.array_equal(s.xyz, t.xyz)


@pytest.mark.parametrize("seed", SEEDS)
def test_roofs_and_walls_are_buildings_crowns_and_trunks_are_not(seed):
    # Bounds: every roof point and every wall point at least min_height (2 m) above the
    # ground surface is found over the sweep; crowns lose at most a fifth of their
    # points to the roof cells beside them (17.5 % at most over seeds 0-7 at this
    # density), trunks and the 1.2 m garden wall stay below min_height or unplanar.
    s, res = _run(seed)
    pred = res.classification == 6
    assert _share(pred, s, "roof") >= 0.99
    wall = s.attributes["part"] == GARDEN_PARTS["wall"][0]
    high = wall & (res.height >= 2.0)
    assert pred[high].mean() >= 0.95
    assert not pred[wall & (res.height < 2.0)].any()
    assert _share(pred, s, "crown") <= 0.2
    assert _share(pred, s, "trunk") <= 0.05
    assert _share(pred, s, "garden_wall") == 0.0
    veg = np.isin(res.classification, (3, 4, 5))
    assert veg[s.attributes["part"] == GARDEN_PARTS["crown"][0]].mean() >= 0.8
    assert np.mean(res.ground != s.ground) < 0.01


@pytest.mark.xfail(strict=True, reason="a clipped hedge as high as a shed holds patches "
                   "of accepted local planes with few second echoes, and its roof cells "
                   "take the rest (docs/methods/moments.md, Limitations)")
@pytest.mark.parametrize("seed", SEEDS[:2])
def test_hedge_is_not_building(seed):
    s, res = _run(seed)
    assert _share(res.classification == 6, s, "hedge") <= 0.1
