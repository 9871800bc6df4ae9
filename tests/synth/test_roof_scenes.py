"""Roof scenes: the houses, dormers, steep planes and trees the scenes promise, checked
against their geometry (plane equations, tree roles, overhangs) over a seed sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.synth import ROOF_SCENE_KINDS, make_roof_scene


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("kind", ROOF_SCENE_KINDS)
def test_scene_truth_is_consistent(kind, seed):
    c = make_roof_scene(kind, density=4.0, rng=seed, layout_seed=seed)
    cls = c.attributes["classification"]
    assert np.array_equal(cls, c.fields["true_class"])
    pid = c.fields["roof_plane"]
    on = pid > 0
    rp = c.meta["roof_planes"]
    res = np.einsum("ij,ij->i", c.meta["xyz_true"][on], rp["normal"][pid[on] - 1])
    assert np.abs(res - rp["offset"][pid[on] - 1]).max() < 1e-8
    assert np.all(cls[on] == 6)
    assert np.all(c.fields["building_id"][cls != 6] == 0)
    bids = {b["id"] for b in c.meta["buildings"]}
    assert set(np.unique(c.fields["building_id"][cls == 6]).tolist()) == bids
    assert {2, 6, 11} <= set(np.unique(cls).tolist())
    assert np.any(np.isin(cls, (4, 5)))
    assert c.meta["kind"] == kind


def test_mixed_scene_holds_the_hard_cases():
    c = make_roof_scene("mixed", density=6.0, rng=0)
    b = c.meta["buildings"]
    assert [x["roof"] for x in b] == ["gable", "hip", "flat", "gable", "gable", "L", "hip"]
    assert b[3]["n_dormers"] == 2
    rp = c.meta["roof_planes"]
    slopes = np.degrees(np.arccos(rp["normal"][:, 2]))
    assert slopes.max() > 49.0                          # steep planes
    dormer = np.array(["dormer" in n for n in rp["name"]])
    assert dormer.sum() == 4 and np.all(rp["n_points"][dormer] > 0)
    # the large flat roof is low and big
    flat = b[2]
    fp = flat["footprint"]
    area = 0.5 * abs(np.dot(fp[:, 0], np.roll(fp[:, 1], 1))
                     - np.dot(fp[:, 1], np.roll(fp[:, 0], 1)))
    assert area > 300 and flat["ridge_z"] - flat["base_z"] < 4.6
    roles = [t["role"] for t in c.meta["trees"]]
    assert roles.count("over") >= 3 and roles.count("next") >= 3
    over = [t for t in c.meta["trees"] if t["role"] == "over"]
    assert all(t["house"] in t["overhangs"] for t in over)
    # vegetation echoes above roofs of the houses the crowns overhang
    veg = np.isin(c.attributes["classification"], (3, 4, 5))
    assert veg.sum() > 500
    # the crowns next to a house touch its wall (centre within radius + 0.4 m of it)
    for t in c.meta["trees"]:
        if t["role"] != "next":
            continue
        fp = c.meta["buildings"][t["house"] - 1]["footprint"]
        p = np.asarray(t["center"][:2])
        d = min(_seg_dist(p, fp[i - 1], fp[i]) for i in range(len(fp)))
        assert d < t["radius"] + 0.4


def _seg_dist(p, a, b):
    u = b - a
    s = np.clip(np.dot(p - a, u) / np.dot(u, u), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + s * u)))


def test_layout_is_fixed_by_layout_seed():
    a = make_roof_scene("steep", density=2.0, rng=0, layout_seed=5)
    b = make_roof_scene("steep", density=2.0, rng=1, layout_seed=5)
    assert [x["ridge_z"] for x in a.meta["buildings"]] == \
        [x["ridge_z"] for x in b.meta["buildings"]]
    assert a.xyz.shape != b.xyz.shape or not np.allclose(a.xyz, b.xyz)
    steep = np.degrees(np.arccos(a.meta["roof_planes"]["normal"][:, 2]))
    assert np.sum(steep > 45.0) >= 6 and math.isfinite(steep.sum())


def test_bad_parameters_are_refused():
    with pytest.raises(InvalidParameterError, match="kind"):
        make_roof_scene("castle")
    with pytest.raises(InvalidParameterError, match="density"):
        make_roof_scene(density=0.0)
