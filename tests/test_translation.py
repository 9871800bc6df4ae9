"""UTM-sized coordinates give the results of the same cloud near the origin.

Every method subtracts a local origin before its arithmetic, so translating a cloud by a
projected-coordinate offset changes its results only by the rounding of the coordinates
themselves. The clouds are snapped to a dyadic grid of 2**-14 units (finer than a LAS file's
1e-4 scale, and exact in binary) so that the translation itself is exact in float64; what
remains is the rounding inside the kernels, a few ulps of the offset (about 1e-9 here).
"""

import numpy as np
import pytest

from lidarstat.classify import covariance, moments
from lidarstat.features import curvature
from lidarstat.io import PointCloud
from lidarstat.synth import SCENES

OFFSET = np.array([512_000.0, 5_430_000.0, 120.0])


def _snapped(xyz):
    return np.round(xyz * 2.0**14) / 2.0**14


def _pair(scene, seed, **kwargs):
    sc = SCENES[scene](rng=seed, **kwargs)
    cloud = PointCloud(xyz=sc.xyz, attributes=dict(sc.attributes))
    near = _snapped(cloud.xyz)
    near -= np.floor(near.min(axis=0))
    far = near + OFFSET
    assert np.array_equal(far - OFFSET, near)  # the translation is exact
    return near, far, cloud.attributes


def _agree(a, b, name, *, rtol, atol, share=0.999):
    """Equal within tolerance on at least `share` of the points, NaN where the other is."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    both = np.isnan(a) & np.isnan(b)
    close = both | np.isclose(a, b, rtol=rtol, atol=atol)
    assert close.mean() >= share, f"{name}: {close.mean():.5f} of the points agree"


@pytest.mark.parametrize("seed", [0, 1])
def test_curvature_is_translation_invariant(seed):
    near, far, _ = _pair("agpart", seed, sigma=0.015)
    a = curvature(near, radius=0.2, sigma=0.015)
    b = curvature(far, radius=0.2, sigma=0.015)
    # K and H come from second derivatives over a 0.2 dm sphere: a 1e-9 dm change of the
    # coordinates moves them by about 1e-9 / 0.2^2 relative to their scale
    for name in ("K", "H", "kmin", "kmax"):
        _agree(a[name], b[name], name, rtol=1e-6, atol=1e-6)
    _agree(a["chi2_p"], b["chi2_p"], "chi2_p", rtol=1e-6, atol=1e-9)
    # a type flips only where a p-value sits on alpha within that rounding
    assert np.mean(a["surface_type"] == b["surface_type"]) >= 0.999
    assert np.array_equal(a["neighbors"], b["neighbors"])


@pytest.mark.parametrize("seed", [0, 1])
def test_covariance_is_translation_invariant(seed):
    near, far, _ = _pair("agpart", seed, sigma=0.015)
    a = covariance(near, k=30)
    b = covariance(far, k=30)
    fa, fb = a.to_fields(), b.to_fields()
    for name in ("Eigenvalue0", "Eigenvalue1", "Eigenvalue2", "SurfaceVariation",
                 "Planarity", "Linearity"):
        _agree(fa[name], fb[name], name, rtol=1e-6, atol=1e-12)
    assert np.mean(fa["point_class"] == fb["point_class"]) >= 0.999


def test_moments_is_translation_invariant():
    near, far, attrs = _pair("hip_roof", 0)
    kw = {k: attrs[k] for k in ("number_of_returns", "return_number")}
    a = moments(near, attrs["intensity"], **kw)
    b = moments(far, attrs["intensity"], **kw)
    assert np.mean(a.classification == b.classification) >= 0.999
