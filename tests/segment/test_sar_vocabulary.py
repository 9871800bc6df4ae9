"""segment_sar and its pieces speak the project's vocabulary: radius, min_points,
envelope_alpha, search, fs_stop, fs_block; the old names still work and warn; the choices
are enums that also accept their plain strings; params records the names used."""

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError, LidarstatDeprecationWarning
from lidarstat.features import AdaptiveBandwidth, BandwidthCriterion, local_planes
from lidarstat.neighbors import radius_neighbors
from lidarstat.segment import (StopRule, forward_search, raw_clusters, refine_raw_clusters,
                               segment_sar)


@pytest.fixture(scope="module")
def gable():
    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 14, (2500, 2))
    z = np.where(xy[:, 0] < 7, 0.5 * xy[:, 0], 7 - 0.5 * xy[:, 0])
    return np.c_[xy, z + rng.normal(0, 0.03, xy.shape[0])]


@pytest.fixture(scope="module")
def reference(gable):
    return segment_sar(gable, radius=1.5, min_points=40, envelope_alpha=0.01, search=4.0,
                       fs_stop=StopRule.F, fs_block=2)


def test_params_record_the_names_used(reference):
    p = reference.params
    assert reference.n_segments == 2
    for key, value in {"radius": 1.5, "min_points": 40, "envelope_alpha": 0.01,
                       "search": 4.0, "fs_stop": "f", "fs_block": 2, "alpha": 0.05,
                       "fs_alpha": 0.001, "edge_alpha": 0.05, "outlier_alpha": 0.01,
                       "gof_alpha": 0.001, "adaptive": "multiscale",
                       "radius_selected_by": None}.items():
        assert p[key] == value, key
    for old in ("bandwidth", "threshold", "alpha_residual", "min_size", "stop", "block"):
        assert old not in p
    assert isinstance(reference.summary(), str) and reference.to_fields()


def test_old_names_still_work_and_warn(gable, reference):
    with pytest.warns(LidarstatDeprecationWarning) as record:
        old = segment_sar(gable, bandwidth=1.5, min_size=40, alpha_residual=0.01,
                          threshold=4.0, stop="f", block=2)
    names = " ".join(str(w.message) for w in record)
    for name in ("bandwidth", "min_size", "alpha_residual", "threshold", "stop", "block"):
        assert f"{name} is deprecated" in names
    np.testing.assert_array_equal(old.labels, reference.labels)


def test_old_and_new_name_together_are_refused(gable):
    with pytest.raises(InvalidParameterError, match="radius"):
        segment_sar(gable, radius=1.5, bandwidth=1.5)


@pytest.mark.parametrize("kw", [{"fs_stop": "never"}, {"adaptive": "sometimes"},
                                {"criterion": "aic"}, {"min_points": 0}, {"fs_alpha": 1.5},
                                {"envelope_alpha": 0.0}, {"gof_alpha": float("nan")},
                                {"fs_block": 0}, {"sigma": -0.1}])
def test_invalid_choices_are_refused(gable, kw):
    with pytest.raises(InvalidParameterError, match=next(iter(kw))):
        segment_sar(gable, radius=1.5, **kw)


def test_enums_are_their_strings():
    assert [m.value for m in StopRule] == ["both", "f", "residual"]
    assert str(StopRule.RESIDUAL) == "residual" and StopRule("f") is StopRule.F
    assert {m.value for m in AdaptiveBandwidth} == {"multiscale", "geary", "none"}
    assert {m.value for m in BandwidthCriterion} == {"rice", "gcv", "press"}


def test_forward_search_envelope_alias():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 10, 200)
    A = np.c_[np.ones(200), x]
    y = 1 + 0.5 * x + rng.normal(0, 0.1, 200)
    init = np.arange(200) < 30
    new = forward_search(A, y, init, envelope_alpha=0.01, stop=StopRule.RESIDUAL)
    with pytest.warns(LidarstatDeprecationWarning, match="alpha_residual"):
        old = forward_search(A, y, init, alpha_residual=0.01, stop="residual")
    np.testing.assert_array_equal(new.accepted, old.accepted)


def test_refine_and_raw_cluster_aliases(gable):
    fit = local_planes(gable, 1.5, alpha=0.05)
    nbh = radius_neighbors(gable, 0.6, dim=2)
    raw = raw_clusters(gable, fit, nbh, min_points=40)
    with pytest.warns(LidarstatDeprecationWarning, match="min_size"):
        raw_old = raw_clusters(gable, fit, nbh, min_size=40)
    np.testing.assert_array_equal(raw.labels, raw_old.labels)
    new = refine_raw_clusters(gable, raw.labels, search=4.0, w_radius=0.5, min_points=40,
                              fs_alpha=0.01)
    with pytest.warns(LidarstatDeprecationWarning):
        old = refine_raw_clusters(gable, raw.labels, threshold=4.0, w_radius=0.5,
                                  min_size=40, alpha=0.01)
    np.testing.assert_array_equal(new.labels, old.labels)
    assert new.params["search"] == 4.0 and new.params["fs_alpha"] == 0.01


def test_search_areas_alias():
    from lidarstat.segment import search_areas

    g = np.mgrid[0:10, 0:3].reshape(2, -1).T.astype(float)
    pts = np.c_[g, np.zeros(30)]
    lab = np.where(g[:, 0] < 3, 1, 0)
    new = search_areas(pts, lab, search=1.5)
    with pytest.warns(LidarstatDeprecationWarning, match="threshold"):
        old = search_areas(pts, lab, threshold=1.5)
    np.testing.assert_array_equal(new.indices, old.indices)
    assert new.search == 1.5
    with pytest.warns(LidarstatDeprecationWarning, match="threshold"):
        assert old.threshold == 1.5
