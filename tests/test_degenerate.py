"""Degenerate clouds through the library entry point behind every command.

Copies of one location, 1-3 points, collinear and coplanar clouds, a perfect grid with
exact distance ties, two clusters far apart and a cloud whose every point is doubled:
each entry point either returns one row per input point (per-point status codes where it
has them) or raises a :class:`~lidarstat.errors.LidarstatError` whose one-line message
says what is wrong. The clouds are small, but 20,000 copies of one location would make a
quadratic path obvious (4e8 pairs); the neighbour-pair ceiling is lowered so refusals do
not depend on the machine's memory.
"""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.classify import covariance, moments
from lidarstat.errors import (
    DuplicatePointsError,
    InsufficientNeighborsError,
    LidarstatError,
    TooManyNeighborsError,
)
from lidarstat.features import FitStatus, curvature, jets
from lidarstat.segment import ridges, segment_covariance, segment_curvature, segment_sar

SIGMA = 0.01


def _surface(n, seed):
    g = np.random.default_rng(seed)
    xy = g.uniform(0, 6, (n, 2))
    z = 0.05 * xy[:, 0] ** 2 + 0.02 * xy[:, 1] + g.normal(0, SIGMA, n)
    return np.c_[xy, z]


def _clouds():
    g = np.random.default_rng(7)
    t = g.uniform(0, 5, 400)
    grid = np.mgrid[0:40, 0:40].reshape(2, -1).T * 0.1
    blob = g.normal(0, 0.3, (600, 3))
    surf = _surface(1500, 3)
    return {
        "copies": np.tile([[512000.25, 5400000.5, 101.0]], (20000, 1)),
        "one": np.array([[1.0, 2.0, 3.0]]),
        "two": np.array([[0.0, 0, 0], [0.1, 0, 0]]),
        "three": np.array([[0.0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]),
        "collinear": np.c_[t, 2 * t, 0.5 * t],
        "coplanar": np.c_[g.uniform(0, 5, (1500, 2)), np.zeros(1500)],
        "grid": np.c_[grid, np.zeros(len(grid))],
        "far_clusters": np.r_[blob, blob[::-1] + [800.0, 0, 0]],
        "doubled": np.r_[surf, surf],
    }


CLOUDS = _clouds()


def _rows(res):
    """Rows of a result: the length of its per-point arrays."""
    if hasattr(res, "labels"):
        return res.labels.size
    fields = res.to_fields()
    sizes = {np.asarray(v).shape[0] for v in fields.values()}
    assert len(sizes) == 1, sizes
    return sizes.pop()


ENTRY_POINTS = {
    "curvature": lambda p: curvature(p, radius=0.4, sigma=SIGMA),
    "curvature_sigma": lambda p: curvature(p, radius=0.4),
    "ridges": lambda p: ridges(p, radius=0.6, sigma=SIGMA),
    "jets_knn": lambda p: jets(p, k=20, sigma=SIGMA),
    "covariance": lambda p: covariance(p, k=20),
    "moments": lambda p: moments(p, None),
    "segment_curvature": lambda p: segment_curvature(p, radius=0.4, sigma=SIGMA),
    "segment_sar": lambda p: segment_sar(p, radius=0.5, sigma=SIGMA),
    "segment_covariance": lambda p: segment_covariance(p, covariance(p, k=20,
                                                                     keep_neighbors=True)),
}


@pytest.fixture(autouse=True)
def _ceiling(monkeypatch):
    monkeypatch.setenv("LIDARSTAT_MAX_PAIRS", str(10**7))


@pytest.mark.filterwarnings("ignore::lidarstat.errors.LidarstatWarning")  # e.g. no intensity
@pytest.mark.parametrize("cloud", sorted(CLOUDS))
@pytest.mark.parametrize("entry", sorted(ENTRY_POINTS))
def test_clean_outcome(entry, cloud):
    pts = CLOUDS[cloud]
    try:
        res = ENTRY_POINTS[entry](pts.copy())
    except LidarstatError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg
        if cloud == "copies":  # the refusal names the copies
            assert "20,000 points share 1 location" in msg, msg
        return
    assert _rows(res) == pts.shape[0]
    if "status" in getattr(res, "fields", {}):
        status = np.asarray(res.fields["status"])
        assert set(np.unique(status)) <= {int(s) for s in FitStatus}
        if cloud == "copies":
            assert (status == FitStatus.DEGENERATE).all()


def test_copies_get_degenerate_status():
    res = curvature(CLOUDS["copies"], radius=0.4, sigma=SIGMA)
    assert res.counts()["status"]["degenerate"] == 20000


def test_ridges_name_the_real_reason():
    with pytest.raises(InsufficientNeighborsError) as info:
        ridges(CLOUDS["copies"], radius=0.6, sigma=SIGMA)
    msg = str(info.value)
    assert "20,000 points share 1 location" in msg and "each location counts once" in msg
    with pytest.raises(InsufficientNeighborsError, match="degenerate neighbourhoods"):
        jets(CLOUDS["collinear"], radius=0.6, sigma=SIGMA)


def test_segmentation_refuses_copies_with_counts():
    """A cloud that is mostly copies: keeping every point's neighbourhood for the region
    growing would search every copy, so it is refused with the counts."""
    plane = CLOUDS["coplanar"]
    pts = np.vstack([plane, np.tile([[100.0, 100.0, 0.0]], (20000, 1))])
    with pytest.raises(DuplicatePointsError,
                       match=r"up to 20,000 at one\) \(93% of them are copies\)"):
        segment_covariance(pts, covariance(pts, k=20, sigma=0.01, keep_neighbors=True))


def _equal_fields(a, b):
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("entry", ["curvature", "ridges", "covariance"])
def test_doubled_cloud_equals_unique_cloud(entry):
    """Every location enters the local model once: copies change nothing."""
    doubled = CLOUDS["doubled"]
    unique = doubled[:1500]
    a = ENTRY_POINTS[entry](doubled).to_fields()
    b = ENTRY_POINTS[entry](unique).to_fields()
    _equal_fields(a, {k: np.r_[v, v] for k, v in b.items()})


def test_radius_query_refused_before_allocating(monkeypatch):
    from lidarstat.neighbors import radius_neighbors

    with pytest.raises(TooManyNeighborsError, match=r"at least 400,000,000 neighbour pairs"):
        radius_neighbors(CLOUDS["copies"], 0.1)
