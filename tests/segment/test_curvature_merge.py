"""segment --method curvature: a merge is refused when the union fails the model test that
each part passes (plane test for planar units, quadric test for curved ones), and the
method runs at the automatic scale."""

import numpy as np
import pytest

from lidarstat.features import curvature
from lidarstat.segment import segment_curvature


def _shallow_crease(seed, slope=0.01, n=60, spacing=0.1, sigma=0.01):
    """Two planes meeting at a crease of 2*atan(slope) (1.1 degrees) along x = 0, with
    noise that hides it from the local curvature tests (the crease points are planar)."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n) - (n - 1) / 2) * spacing
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    z = slope * np.abs(x) + rng.normal(0, sigma, x.size)
    return np.c_[x, y, z], x


def _two_units_one_per_side(pts, x, curv, seg):
    """The two large units of `seg` lie each (at least 90 %) on one side of the crease at
    x = 0, and without the merge test (a level no union fails) they are one unit; returns
    the large units' labels."""
    lab = seg.labels
    big = [k for k in range(1, lab.max() + 1) if (lab == k).sum() > 1000]
    assert len(big) == 2
    for k in big:
        assert abs(np.sign(x[lab == k]).mean()) > 0.8
    merged = segment_curvature(pts, sigma=0.01, merge_alpha=1e-300, curv=curv)
    assert merged.params["merges_refused"] == 0
    assert (merged.labels == 1).sum() > 0.9 * sum((lab == k).sum() for k in big)
    return big


@pytest.mark.parametrize("seed", range(3))
def test_merge_across_a_shallow_crease_is_refused(seed):
    pts, x = _shallow_crease(seed)
    curv = curvature(pts, sigma=0.01)
    seg = segment_curvature(pts, sigma=0.01, curv=curv)
    assert seg.params["merges_refused"] >= 1
    _two_units_one_per_side(pts, x, curv, seg)


@pytest.mark.parametrize("seed", range(3))
def test_one_plane_stays_one_unit(seed):
    rng = np.random.default_rng(100 + seed)
    g = (np.arange(60) - 29.5) * 0.1
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    pts = np.c_[x, y, 0.3 * x - 0.2 * y + rng.normal(0, 0.01, x.size)]
    seg = segment_curvature(pts, sigma=0.01)
    assert (seg.labels == 1).sum() > 0.9 * x.size


def _curved_crease(seed, slope, q=0.1, n=60, spacing=0.1, sigma=0.01):
    """A valley z = q x^2 + slope |x|: two parabolic cylinders meeting at a crease of
    2 atan(slope) along x = 0 (4.6 degrees at slope 0.04, below `max_angle`); every
    point, the crease's included, is a tested valley."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n) - (n - 1) / 2) * spacing
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    z = q * x ** 2 + slope * np.abs(x) + rng.normal(0, sigma, x.size)
    return np.c_[x, y, z], x


@pytest.mark.parametrize("seed", range(3))
def test_merge_of_two_quadrics_across_a_crease_is_refused(seed):
    pts, x = _curved_crease(seed, 0.04)
    curv = curvature(pts, sigma=0.01)
    seg = segment_curvature(pts, sigma=0.01, curv=curv)
    assert seg.params["merges_refused_curved"] >= 1
    big = _two_units_one_per_side(pts, x, curv, seg)
    assert set(seg.table["surface_type"][np.array(big) - 1].tolist()) == {3}


@pytest.mark.parametrize("seed", range(3))
def test_one_quadric_split_by_the_growth_is_one_unit(seed):
    """The same valley without the crease: the growth's partial units (tested merges of
    curved units of 30 points and more) end as one."""
    pts, _ = _curved_crease(seed, 0.0)
    seg = segment_curvature(pts, sigma=0.01)
    assert seg.params["merges_refused_curved"] == 0
    valley = seg.fields["surface_type"] == 3
    assert (seg.labels[valley] == 1).mean() > 0.95


def _quadric_patch(rng, kind, n, sigma, noise):
    """`n` points of a cylinder, sphere or saddle patch at a random tilt, with noise along
    z or along the rays from a sensor."""
    u = rng.uniform(-1, 1, (n, 2))
    if kind == "cylinder":
        th = u[:, 0] / 2.0
        p = np.c_[3 * np.sin(th), u[:, 1], 3 - 3 * np.cos(th)]
    elif kind == "sphere":
        p = np.c_[u, 4 - np.sqrt(16 - (u ** 2).sum(axis=1))]
    else:
        p = np.c_[u, 0.2 * u[:, 0] ** 2 - 0.3 * u[:, 1] ** 2]
    a = np.radians(rng.uniform(0, 60))
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    p = p @ rot.T + [50.0, -20.0, 10.0]
    if noise == "z":
        d = np.tile([0.0, 0.0, 1.0], (n, 1))
    else:
        d = p - [45.0, -25.0, 15.0]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
    return p + rng.normal(0, sigma, n)[:, None] * d, d


@pytest.mark.parametrize("noise", ["z", "range"])
def test_quadric_merge_test_size(noise):
    """Under the null (the union of two parts of one quadric), the merge test's statistic
    is refused at alpha = 0.05 within the 99.9 % binomial interval, over a seed sweep of
    cylinder, sphere and saddle patches at random tilts."""
    from scipy.stats import binom

    from lidarstat.segment._quadric_merge_kernels import QUADRIC_DOF, quadric_set_statistic
    from lidarstat.stats import chi2_critical

    alpha, n, sigma = 0.05, 120, 0.01
    crit = float(chi2_critical(alpha, n - QUADRIC_DOF))
    refused = tested = 0
    for kind in ("cylinder", "sphere", "saddle"):
        for seed in range(200):
            p, d = _quadric_patch(np.random.default_rng(seed), kind, n, sigma, noise)
            refused += quadric_set_statistic(p - p[0], d, True, sigma ** 2) > crit
            tested += 1
    lo, hi = binom.interval(0.999, tested, alpha)
    assert lo <= refused <= hi, (refused, tested)


@pytest.mark.parametrize("seed", range(4))
def test_quadric_sums_of_merged_units_equal_the_union(seed):
    """The O(1) merge (the sums of one unit moved to the other's anchor) gives the union's
    statistic as a fit over all its points does."""
    from lidarstat.segment import _quadric_merge_kernels as qk

    rng = np.random.default_rng(seed)
    p, d = _quadric_patch(rng, "sphere", 200, 0.01, "range")
    sums = []
    for part in (p[:90], p[90:]):
        M, G, Gd = (np.zeros((qk.NM, qk.NM)) for _ in range(3))
        c = part[0].copy()
        for i in range(part.shape[0]):
            qk.slot_add_point(M, G, Gd, c, part[i], d[0], True, np.empty(qk.NM),
                              np.empty((qk.NM, 3)), np.empty(qk.NM))
        sums.append((M, G, Gd, c))
    (MA, GA, GdA, cA), (MB, GB, GdB, cB) = sums
    T = np.empty((qk.NM, qk.NM))
    qk.slot_merge(MA, GA, GdA, cA, MB, GB, GdB, cB, True, T)
    merged = qk.quadric_statistic(MA, GA, GdA, True, 1e-4, T)
    direct = qk.quadric_set_statistic(p - p[0], np.tile(d[0], (200, 1)), True, 1e-4)
    assert merged == pytest.approx(direct, rel=1e-6)


def test_quadric_statistic_matches_a_direct_taubin_fit():
    """The kernel's statistic from moments against a direct Taubin fit (SciPy's generalised
    symmetric eigensolver on the monomials of the centred points), range noise."""
    import scipy.linalg as sl

    from lidarstat.segment._quadric_merge_kernels import quadric_set_statistic

    qa, qb = [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]
    for seed in range(5):
        for kind in ("cylinder", "sphere", "saddle"):
            p, d = _quadric_patch(np.random.default_rng(seed), kind, 120, 0.01, "range")
            y = p - p.mean(axis=0)
            m = np.c_[y, np.stack([y[:, a] * y[:, b] for a, b in zip(qa, qb)], axis=1)]
            jac = np.zeros((len(y), 9, 3))
            jac[:, 0, 0] = jac[:, 1, 1] = jac[:, 2, 2] = 1.0
            for q, (a, b) in enumerate(zip(qa, qb)):
                jac[:, 3 + q, a] += y[:, b]
                jac[:, 3 + q, b] += y[:, a]
            mc = m - m.mean(axis=0)
            _, vec = sl.eigh(mc.T @ mc, np.einsum("nik,njk->ij", jac, jac))
            f = mc @ vec[:, 0]
            dg = np.einsum("nik,i,nk->n", jac, vec[:, 0], d)
            direct = len(y) * (f @ f) / (1e-4 * (dg @ dg))
            assert quadric_set_statistic(p - p[0], d, True, 1e-4) == pytest.approx(
                direct, rel=1e-8)
