"""The automatic scales computed block by block give the same results, bit for bit, as
the whole-cloud computation: for the covariance features
(:mod:`lidarstat.features._covariance_scale_blocks`) the kNN rows of every point at once,
the size rule on them, :func:`lidarstat.features.prefix_features` of the chosen
prefixes; for the jets, a whole-cloud fused fit per rung."""

import numpy as np
import pytest

from lidarstat import features
from lidarstat.features import (OPTIMAL_K_MAX, OPTIMAL_K_MIN, covariance_features,
                                prefix_features)
from lidarstat.features._covariance import OPTIMAL_MIN_SPREAD
from lidarstat.features._covariance_scale_kernels import optimal_k_rows

ARRAYS = ("centroid", "major", "offset_uv", "mean_variation", "ray_range", "ray_cos",
          "scan_boundary")


def _scene(seed, n=1500):
    """A crease (flat, then a 0.4 slope), a box on it, 1 cm noise, far from the origin."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 15, (n, 2))
    z = np.where(xy[:, 0] < 7, 0.0, 0.4 * (xy[:, 0] - 7))
    z = z + np.where((np.abs(xy - 10) < 2).all(axis=1), 3.0, 0.0) + rng.normal(0, 0.01, n)
    sensor = np.array([5e5 + 7, 5e6 - 30, 600.0]) if seed % 2 else None
    return np.c_[xy, z] + [5e5, 5e6, 100.0], sensor


def _same(a, b):
    """Every field and array equal (NaN where the other has NaN), rows kept alike."""
    assert a.fields.keys() == b.fields.keys()
    for name in a.fields:
        np.testing.assert_array_equal(a.fields[name], b.fields[name], err_msg=name)
        assert a.fields[name].dtype == b.fields[name].dtype, name
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.meta == b.meta
    assert (a.neighborhoods is None) == (b.neighborhoods is None)
    if a.neighborhoods is not None:
        np.testing.assert_array_equal(a.neighborhoods.indices, b.neighborhoods.indices)
        np.testing.assert_array_equal(a.neighborhoods.distances, b.neighborhoods.distances)


@pytest.mark.parametrize("seed", range(4))
def test_eigenentropy_scale_by_blocks_is_the_whole_cloud_computation(seed):
    pts, sensor = _scene(seed)
    keep = seed < 2
    full = covariance_features(pts, k=OPTIMAL_K_MAX, keep_neighbors=True).neighborhoods
    kopt = np.empty(len(pts), dtype=np.int64)
    optimal_k_rows(pts - pts.mean(axis=0), full.indptr, full.indices, OPTIMAL_K_MIN,
                   OPTIMAL_K_MAX, OPTIMAL_MIN_SPREAD, kopt, np.empty(len(pts)))
    ref = prefix_features(pts, full, kopt, sensor=sensor, keep_neighbors=keep,
                          rule="eigenentropy", k_min=OPTIMAL_K_MIN)
    # blocks of about 200 points: many blocks, rows crossing every block border
    got = covariance_features(pts, sensor=sensor, keep_neighbors=keep, block_size=200)
    _same(ref, got)
    assert len(np.unique(got["OptimalKNN"])) > 5


@pytest.mark.parametrize("seed", range(4))
def test_tested_scale_by_blocks_is_the_whole_cloud_computation(seed):
    pts, sensor = _scene(seed)
    rng = np.random.default_rng(seed)
    # one sigma, or one per point along the range (the range noise model)
    if sensor is None:
        sigma, noise = 0.01, "z"
    else:
        sigma, noise = rng.uniform(0.008, 0.012, len(pts)), "range"
    keep = seed in (0, 3)
    full = covariance_features(pts, k=OPTIMAL_K_MAX, keep_neighbors=True).neighborhoods
    sizes = features.tested_scale(pts, full, sigma=sigma, noise=noise, sensor=sensor)
    ref = prefix_features(pts, full, sizes, sensor=sensor, keep_neighbors=keep,
                          rule="tested", k_min=OPTIMAL_K_MIN)
    got = features.tested_features(pts, OPTIMAL_K_MAX, sigma=sigma, noise=noise,
                                   sensor=sensor, keep_neighbors=keep, block_size=200)
    _same(ref, got)
    assert (got["OptimalKNN"] < OPTIMAL_K_MAX).any()
    assert (got["OptimalKNN"] == OPTIMAL_K_MAX).any()


@pytest.mark.parametrize("seed", range(2))
def test_jet_rungs_by_blocks_are_the_whole_cloud_fits(seed):
    """The jets' automatic scale writes each block's fits to its points' rows: the same
    arrays as a whole-cloud fused fit per rung merged by rung (the rung -1 rows skipped)."""
    from lidarstat.features._jet_fit import _fit_cells
    from lidarstat.features._jet_kernels import SKIPPED
    from lidarstat.features._jet_scale import fit_rungs, radius_ladder
    from lidarstat.neighbors import CellIndex

    pts, sensor = _scene(seed, n=1200)
    radii = radius_ladder(pts, rungs=3)
    rung = np.random.default_rng(seed).integers(-1, 3, len(pts))
    kw = dict(degree=4, monge_degree=4, weight="tricube", sensor=sensor, min_neighbors=16,
              standard_errors=True)
    got = fit_rungs(pts, radii, rung, kw, block_size=150)
    for j in range(-1, 3):
        mask = rung == j
        ref = _fit_cells(CellIndex(pts, float(radii[max(j, 0)])),
                         active=mask if j >= 0 else np.zeros(len(pts), bool),
                         block_size=131072, progress=None, **kw)
        for key, val in ref.items():
            np.testing.assert_array_equal(got[key][mask], val[mask], err_msg=key)
    assert (got["status"][rung < 0] == SKIPPED).all()
    assert (got["status"][rung >= 0] == 0).mean() > 0.5
