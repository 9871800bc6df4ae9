"""Ground truth for the two accuracy targets of SAR-FS segmentation (issue 5):

* plane normals: the reported surface comes from the raw cluster (not from the points the
  search selected by their residuals), so its error is sampling error only, and the
  propagated standard errors are right: the 95 % confidence cones of the normals cover the
  true normals at 95 % (binomial interval) and every face whose angular standard error is
  below 0.5/3 degrees is within 0.5 degrees;
* clutter: the final outlier test removes points off the plane at its nominal level
  under the null and removes planted off-plane points.
"""

import numpy as np
import pytest
from scipy import stats

from lidarstat.segment import hoover, segment_sar
from lidarstat.segment._sar_outliers import OUTLIER_MAX, outlier_test
from lidarstat.segment._sar_refine import refit_unit


def _gable_village(rng, rows=5, cols=7, density=8.0, sigma=0.03):
    """rows x cols gable houses (8 x 6 m, random slope 20-40 degrees, rotation and
    height) on flat ground, every face about 200 points; a tree crown's leaves over every
    third roof. Returns points, the face label (0 ground, -1 leaves) and the true unit
    normal of each face (1..F)."""
    ext = np.array([cols * 12.0, rows * 11.0])
    n = rng.poisson(density * ext.prod())
    xy = rng.uniform(0, ext, (n, 2))
    z = np.zeros(n)
    face = np.zeros(n, int)
    normals, offsets = [np.zeros(3)], [0.0]
    for k in range(rows * cols):
        cx, cy = 6.0 + 12.0 * (k % cols), 5.5 + 11.0 * (k // cols)
        th = rng.uniform(0, np.pi)
        slope = np.radians(rng.uniform(20, 40))
        h = rng.uniform(5, 8)
        c, s = np.cos(th), np.sin(th)
        u = (xy[:, 0] - cx) * c + (xy[:, 1] - cy) * s
        v = -(xy[:, 0] - cx) * s + (xy[:, 1] - cy) * c
        inside = (np.abs(u) < 4.0) & (np.abs(v) < 3.0)
        z[inside] = h - np.tan(slope) * np.abs(v[inside])
        face[inside] = 2 * k + 1 + (v[inside] > 0)
        for sign in (-1, 1):  # face v < 0 rises towards +v: normal along (0, -tan, 1)
            nl = np.array([0.0, sign * np.sin(slope), np.cos(slope)])
            normals.append(np.array([-s * nl[1], c * nl[1], nl[2]]))
            offsets.append(normals[-1] @ [cx, cy, h])  # the ridge lies on both faces
    z += rng.normal(0, sigma, n)
    # leaves of a small crown over every third house: 25 points 0.1-2 m over its roof
    leaves = []
    for k in range(0, rows * cols, 3):
        on = np.flatnonzero((face == 2 * k + 1) | (face == 2 * k + 2))
        centre = xy[rng.choice(on)]
        r, a = 0.7 * np.sqrt(rng.uniform(0, 1, 25)), rng.uniform(0, 2 * np.pi, 25)
        lxy = centre + np.c_[r * np.cos(a), r * np.sin(a)]
        below = np.argmin(np.sum((xy[on] - lxy[:, None]) ** 2, axis=2), axis=1)
        leaves.append(np.c_[lxy, z[on][below] + rng.uniform(0.1, 2.0, 25)])
    leaves = np.concatenate(leaves)
    return (np.r_[np.c_[xy, z], leaves], np.r_[face, np.full(len(leaves), -1)],
            np.array(normals), np.array(offsets))


@pytest.fixture(scope="module")
def village():
    pts, face, normals, offsets = _gable_village(np.random.default_rng(11))
    return pts, face, normals, offsets, segment_sar(pts, radius=0.8)


def _face_errors(pts, face, normals, seg):
    score = hoover(seg.labels, np.maximum(face, 0), 0.8)
    se, ang, t2 = [], [], []
    for f, s in score.correct_pairs:
        unit = seg.units[s - 1]
        cen = pts[seg.labels == s].mean(axis=0)
        e, a, t = unit.normal_error(cen, normals[f])
        se.append(e[0]), ang.append(a[0]), t2.append(t[0])
        assert np.isclose(seg.table["normal_se_deg"][s - 1], e[0])
    return score, np.array(se), np.array(ang), np.array(t2)


def test_normal_confidence_cones_cover_the_truth_at_95_percent(village):
    pts, face, normals, _, seg = village
    score, se, ang, t2 = _face_errors(pts, face, normals, seg)
    n_faces = len(normals) - 1
    assert score.correct >= 0.95 * n_faces
    covered = int(np.count_nonzero(t2 <= stats.chi2.ppf(0.95, 2)))
    lo, hi = stats.binom.interval(0.99, t2.size, 0.95)
    assert lo <= covered <= hi, (covered, t2.size)
    # the whole law, not only its 95 % point: t2 ~ chi2(2)
    assert stats.kstest(t2, "chi2", args=(2,)).pvalue > 0.01
    # where 0.5 degrees is 3 standard errors or more, every face is within it
    ok = se < 0.5 / 3
    assert ok.sum() >= 0.5 * se.size
    assert np.all(ang[ok] < 0.5), np.round(ang[ok].max(), 3)


def test_leaves_off_the_roof_planes_are_not_in_roof_segments(village):
    """Leaves 0.1-2 m over a roof: none farther than 3 sigma from the plane of the roof
    segment (of min_points or more) it is in (the search refuses most, the final outlier test the rest). Leaves
    closer than that lie *on* that plane within its noise - above the neighbouring face
    near a ridge, where they are where the plane continues - and no test can tell them
    from roof points."""
    pts, face, normals, offsets, seg = village
    sigma = 0.03
    major = np.array([np.bincount(np.maximum(face[seg.labels == s], 0)).argmax()
                      for s in range(1, seg.n_segments + 1)])
    # the second stage's planes of 12 to 29 points (kept by their own tests) have too
    # little power to refuse a leaf a few decimetres over them, which tilts them: at
    # most 1 % of the 300 leaves lie in one
    small = seg.table["n_points"] < seg.params["min_points"]
    in_small = (face < 0) & (seg.labels > 0)
    in_small[in_small] = small[seg.labels[in_small] - 1]
    assert np.count_nonzero(in_small) <= 0.01 * np.count_nonzero(face < 0)
    inside = np.flatnonzero((face < 0) & (seg.labels > 0) & ~in_small)
    f = major[seg.labels[inside] - 1]
    assert np.all(f > 0)  # only roof segments here (the ground is one segment)
    n = normals[f]
    dz = (np.einsum("ij,ij->i", pts[inside], n) - offsets[f]) / n[:, 2]
    assert np.all(np.abs(dz) <= 3 * sigma), np.round(dz / sigma, 1)
    # and the test does not eat the roofs: at most 2 % of the faces' points are removed
    removed = seg.fields["surface_outlier"] > 0
    assert np.count_nonzero(removed & (face > 0)) < 0.02 * np.count_nonzero(face > 0)


@pytest.mark.parametrize("alpha", [0.01, 0.02])
def test_outlier_test_rejects_at_its_level_under_the_null_and_finds_planted_points(rng, alpha):
    """The rate of the iterated test on true surface points is its level: the scale is
    fixed (robust) before the iterations, so removals do not shrink it (with the
    leave-one-out scale of the kept points the removals cascaded: 1.73 % at 0.01 on the
    158k town). The count stays below the per-segment cap, which would hide a cascade."""
    n_raw, n_extra = 400, 3000
    xy = rng.uniform(0, 30, (n_raw + n_extra, 2))
    xy[:n_raw] = rng.uniform(12, 18, (n_raw, 2))  # the raw cluster: a central patch
    z = 2.0 + 0.4 * xy[:, 0] - 0.2 * xy[:, 1] + rng.normal(0, 0.03, xy.shape[0])
    planted = rng.choice(np.arange(n_raw, n_raw + n_extra), 30, replace=False)
    z[planted] += rng.choice([-1, 1], 30) * rng.uniform(0.2, 0.5, 30)  # 7-17 sigma
    pts = np.c_[xy, z]
    unit = refit_unit(pts, np.arange(n_raw), np.arange(n_raw, n_raw + n_extra),
                      w_radius=0.5)
    labels = np.ones(pts.shape[0], dtype=np.int64)
    new, units, removed = outlier_test(pts, labels, [unit], alpha)
    assert np.all(removed[planted] == 1) and np.all(new[planted] == 0)
    assert not removed[:n_raw].any()  # raw-cluster points are not tested
    null = np.setdiff1d(np.arange(n_raw, n_raw + n_extra), planted)
    k = int(np.count_nonzero(removed[null]))
    lo, hi = stats.binom.interval(0.998, null.size, alpha)
    assert lo <= k <= hi, k
    assert np.count_nonzero(removed) < OUTLIER_MAX
    assert units[0].accepted.size == pts.shape[0] - np.count_nonzero(removed)
