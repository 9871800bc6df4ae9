import numpy as np
import pytest

from _reference import quadric_fit_reference
from lidarstat.features import (FitStatus, curvature_jacobian, curvatures, fit_quadrics,
                                principal_jacobian)
from lidarstat.neighbors import knn_neighbors, radius_neighbors


def test_kernel_matches_dense_reference(rng):
    pts = rng.random((600, 3)) * [4, 4, 0.3]
    b = 0.8
    nb = radius_neighbors(pts, b)
    for cov in ("paper", "sandwich"):
        fit = fit_quadrics(pts, nb, covariance=cov)
        for i in range(0, 600, 53):
            idx, dist = nb.row(i)
            ref = quadric_fit_reference(pts, i, idx, dist, b)
            np.testing.assert_allclose(fit.beta[i], ref["beta"], rtol=1e-7, atol=1e-9)
            np.testing.assert_allclose(fit.q[i], ref["q"], rtol=1e-7)
            np.testing.assert_allclose(fit.trace_b[i], ref["trB"], rtol=1e-8)
            np.testing.assert_allclose(fit.trace_b2[i], ref["trB2"], rtol=1e-8)
            want = ref["Ninv"] if cov == "paper" else ref["sandwich"]
            np.testing.assert_allclose(fit.cofactor[i], want, rtol=1e-6, atol=1e-12)
            assert fit.neighbors[i] == ref["p"]


def test_exact_on_quadric_in_utm_coordinates():
    g = np.linspace(-1, 1, 31)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    z = 0.1 + 0.2 * x - 0.3 * y + 0.5 * (0.4 * x**2 + 2 * 0.1 * x * y - 0.2 * y**2)
    pts = np.c_[x + 6.5e5, y + 5.1e6, z + 300.0]
    fit = fit_quadrics(pts, radius_neighbors(pts, 0.45))
    c = 15 * 31 + 15
    np.testing.assert_allclose(fit.beta[c, 1:], [0.2, -0.3, 0.4, 0.1, -0.2], atol=1e-6)
    assert fit.q[c] < 1e-12


def test_degenerate_neighbourhoods_are_statuses_not_errors():
    line = np.c_[np.linspace(0, 1, 30), np.zeros(30), np.zeros(30)]
    dup = np.zeros((20, 3))
    lonely = np.array([[100.0, 100, 100]])
    pts = np.vstack([line, dup + [50, 50, 0], lonely])
    fit = fit_quadrics(pts, radius_neighbors(pts, 0.5))
    assert (fit.status[:30] == FitStatus.DEGENERATE).all()
    assert (fit.status[30:50] == FitStatus.DEGENERATE).all()
    assert fit.status[50] == FitStatus.TOO_FEW_NEIGHBORS
    assert np.isnan(fit.beta[50]).all()


def test_knn_bandwidth_is_farthest_neighbour(rng):
    pts = rng.random((400, 3)) * [2, 2, 0.01]
    fit = fit_quadrics(pts, knn_neighbors(pts, 30))
    assert (fit.neighbors == 29).all()  # the farthest gets weight 0 (LOESS convention)


def _fd_jacobian(a, h=1e-7):
    J = np.empty((a.shape[0], 2, 5))
    for k in range(5):
        ap, am = a.copy(), a.copy()
        ap[:, k] += h
        am[:, k] -= h
        Kp, Hp, _, _ = curvatures(ap)
        Km, Hm, _, _ = curvatures(am)
        J[:, 0, k] = (Kp - Km) / (2 * h)
        J[:, 1, k] = (Hp - Hm) / (2 * h)
    return J


def test_jacobians_match_finite_differences(rng):
    a = rng.normal(size=(50, 5))
    np.testing.assert_allclose(curvature_jacobian(a), _fd_jacobian(a), rtol=1e-5, atol=1e-7)
    K, H, kmin, kmax = curvatures(a)
    Jp = principal_jacobian(K, H, curvature_jacobian(a))
    h = 1e-7
    for k in range(5):
        ap, am = a.copy(), a.copy()
        ap[:, k] += h
        am[:, k] -= h
        _, _, n1, x1 = curvatures(ap)
        _, _, n0, x0 = curvatures(am)
        np.testing.assert_allclose(Jp[:, 0, k], (n1 - n0) / (2 * h), rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(Jp[:, 1, k], (x1 - x0) / (2 * h), rtol=1e-4, atol=1e-6)


def test_curvatures_of_known_surfaces():
    # z = -x^2/(2R): a convex ridge of radius R at the origin: H = -1/(2R), K = 0
    a = np.array([[0.0, 0.0, -1 / 0.5, 0.0, 0.0], [0, 0, 1.0, 0, 1.0], [0, 0, 1.0, 0, -1.0]])
    K, H, kmin, kmax = curvatures(a)
    np.testing.assert_allclose(K, [0, 1, -1])
    np.testing.assert_allclose(H, [-1, 1, 0])
    np.testing.assert_allclose(kmin, [-2, 1, -1])
    np.testing.assert_allclose(kmax, [0, 1, 1])


@pytest.mark.parametrize("frame", ["pca", "auto"])
def test_rotated_frames_recover_curvature(frame, rng):
    # sphere cap of radius 2 viewed from the +z side, then rotated by a random rotation
    g = np.linspace(-0.8, 0.8, 41)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    z = np.sqrt(4 - x**2 - y**2)
    pts = np.c_[x, y, z]
    from scipy.spatial.transform import Rotation
    R = Rotation.random(random_state=3).as_matrix()
    rp = pts @ R.T + [100, 200, 300]
    sensor = np.array([0, 0, 10.0]) @ R.T + [100, 200, 300]
    fit = fit_quadrics(rp, radius_neighbors(rp, 0.3), frame=frame, sensor=sensor)
    c = 20 * 41 + 20
    K, H, _, _ = curvatures(fit.beta[[c], 1:])
    # the second-order model absorbs the sphere's fourth-order terms: bias ~ (b/R)^2 / 3
    tol = (0.3 / 2) ** 2 / 3
    if frame == "pca":
        np.testing.assert_allclose([K[0], H[0]], [0.25, -0.5], rtol=tol)
    else:  # the permuted axis is not the normal, but K, H are frame invariant
        np.testing.assert_allclose([K[0], abs(H[0])], [0.25, 0.5], rtol=tol)
    n_true = (rp[c] - (np.zeros(3) @ R.T + [100, 200, 300])) / 2
    assert np.dot(fit.normal[c], n_true) > 0.9999


@pytest.mark.parametrize("test", ["calibrated", "paper"])
def test_statistics_kernel_matches_numpy_reference(test):
    from _reference import curvature_tests_reference
    from lidarstat.features import curvature_tests
    from lidarstat.synth import make_surface

    pts = np.vstack([make_surface(k, sigma=0.002, rng=1, spacing=0.05).xyz + [5 * i, 0, 0]
                     for i, k in enumerate(["plane", "cylinder", "saddle_ridge", "peak"])])
    pts = np.vstack([pts, [[100.0, 100, 100]]])  # one point without neighbours
    fit = fit_quadrics(pts, radius_neighbors(pts, 0.3),
                       covariance="paper" if test == "paper" else "sandwich")
    out = dict(status=fit.status, npts=fit.neighbors, beta=fit.beta, cof=fit.cofactor,
               frames=fit.frame, stats=np.c_[fit.q, fit.sum_w, fit.trace_b, fit.trace_b2])
    got = curvature_tests(out, sigma2=4e-6, alpha=0.05, test=test, minimal_detectable=True)
    want = curvature_tests_reference(out, sigma2=4e-6, alpha=0.05, test=test,
                                     minimal_detectable=True)
    assert set(got) == set(want)
    for k in want:
        np.testing.assert_allclose(np.asarray(got[k], float), np.asarray(want[k], float),
                                   rtol=1e-6, atol=1e-12, equal_nan=True, err_msg=k)


@pytest.mark.parametrize("frame, bandwidth", [("z", 0.5), ("pca", 0.5), ("pca", 0.35)])
def test_fused_cell_kernel_equals_csr_kernel(rng, frame, bandwidth):
    """The fused search and fit over grid cells gives the CSR kernel's fits; with a
    bandwidth below the search radius its neighbours beyond the bandwidth (weight 0 in
    the fused kernel, left out by the CSR one) change nothing."""
    from lidarstat.features._quadric import _run_cells
    from lidarstat.neighbors import CellIndex

    pts = rng.random((3000, 3)) * [6, 6, 0.4] + [3e5, 4e6, 50]
    index = CellIndex(pts, 0.5)
    csr = fit_quadrics(pts, radius_neighbors(pts, 0.5), frame=frame, bandwidth=bandwidth)
    out = _run_cells(index, 0, index.n_cells, bandwidth=bandwidth, frame=frame, sensor=None,
                     min_neighbors=7, covariance="sandwich")
    o = index.order
    np.testing.assert_array_equal(out["status"], csr.status[o])
    np.testing.assert_array_equal(out["npts"], csr.neighbors[o])
    np.testing.assert_allclose(out["beta"], csr.beta[o], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out["stats"][:, 0], csr.q[o], rtol=1e-8, atol=1e-15)


def test_closed_form_chi2_tails_match_scipy():
    from scipy import stats

    from lidarstat.features._curvature_kernels import chi2_sf_small_df, normal_two_sided

    # df as the kernel's caller gives it (float64): an int would compile a second variant
    for df in (1.0, 2.0, 3.0):
        for x in (0.0, 1e-8, 0.5, 3.0, 7.81, 40.0, 700.0):
            assert chi2_sf_small_df(x, df) == pytest.approx(stats.chi2.sf(x, df), rel=1e-12,
                                                            abs=1e-300)
    assert np.isnan(chi2_sf_small_df(np.nan, 3.0)) and np.isnan(chi2_sf_small_df(1.0, 4.0))
    for z in (0.0, 1.0, 1.96, 6.0, 30.0):
        assert normal_two_sided(z, 1.0) == pytest.approx(2 * stats.norm.sf(z), rel=1e-12,
                                                         abs=1e-300)
    assert np.isnan(normal_two_sided(1.0, 0.0))
