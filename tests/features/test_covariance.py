"""Covariance features: exact kNN, brute-force reference, peers (jakteristics, pgeof), input checks."""

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError, InvalidPointsError
from lidarstat.features import covariance_features, covariance_frames, eigen_features
from lidarstat.neighbors import Neighborhoods, radius_neighbors


def _cloud(rng, n=3000):
    """Two planes at different densities, a dense cluster and exact duplicates."""
    a = np.c_[rng.uniform(0, 10, (n, 2)), rng.normal(0, 0.01, n)]
    b = np.c_[rng.uniform(0, 2, (n // 3, 1)), np.full((n // 3, 1), 5.0),
              rng.uniform(0, 3, (n // 3, 1))]
    c = rng.normal([8, 8, 2], 0.05, (200, 3))
    pts = np.vstack([a, b, c, a[:20]])
    return pts + [512_000.0, 5_430_000.0, 120.0]


def _reference(pts, rows):
    """Brute force: np.cov of each neighbourhood, eigh, surface variation, eq. 5."""
    ev = np.empty((len(rows), 3))
    nz = np.empty(len(rows))
    for i, r in enumerate(rows):
        w, v = np.linalg.eigh(np.cov(pts[r].T))
        ev[i] = w
        nz[i] = abs(v[2, 0])
    sv = ev[:, 0] / ev.sum(axis=1)
    cv = np.array([sv[r].var() for r in rows])
    return ev, nz, sv, cv


def test_knn_is_exact_and_sorted(rng):
    from scipy.spatial import cKDTree

    pts = _cloud(rng)
    k = 30
    res = covariance_features(pts, k=k, keep_neighbors=True)
    d, _ = cKDTree(pts - pts.min(axis=0)).query(pts - pts.min(axis=0), k=k)
    nb = res.neighborhoods
    got = nb.distances.reshape(-1, k)
    assert np.all(np.diff(got, axis=1) >= 0)  # rows sorted by distance
    np.testing.assert_allclose(got, d, rtol=0, atol=1e-9)  # same k-th distances everywhere
    assert np.all(nb.indices.reshape(-1, k)[:, 0] == np.arange(len(pts))) or \
        np.all(got[:, 0] == 0)
    assert nb.indices.dtype == np.int32  # kept rows: 4 bytes per neighbour, not 8


def _no_ties(rng, n=4000):
    """Planes and a noisy ball without duplicates (distance ties have probability 0)."""
    a = np.c_[rng.uniform(0, 10, (n, 2)), rng.normal(0, 0.01, n)]
    b = np.c_[rng.uniform(0, 2, (n // 4, 1)), rng.normal(5.0, 0.01, (n // 4, 1)),
              rng.uniform(0, 3, (n // 4, 1))]
    c = rng.normal([8, 8, 2], 0.05, (300, 3))
    return np.vstack([a, b, c]) + [512_000.0, 5_430_000.0, 120.0]


@pytest.mark.parametrize("k", [20, 50])
def test_fused_knn_equals_kdtree_neighbourhoods_bit_for_bit(rng, k):
    """The grid kNN finds cKDTree's neighbours in cKDTree's order, and the covariance fused
    into the search equals the generic per-row kernel on those neighbourhoods exactly."""
    from scipy.spatial import cKDTree

    from lidarstat.features import _covariance as cov
    from lidarstat.features import _covariance_kernels as ck

    pts = _no_ties(rng)
    index, table, nbh, raw = cov._knn_table(pts, k, block_size=700, sort=True)
    local = index.sorted_points
    d, j = cKDTree(local).query(local, k=k)
    assert np.array_equal(table, j)
    # the input-order neighbourhoods written beside the table are the same rows
    assert np.array_equal(nbh.indices.reshape(-1, k)[index.order], index.order[j])
    np.testing.assert_allclose(nbh.distances.reshape(-1, k)[index.order], d, rtol=1e-15,
                               atol=0)
    ref = np.empty_like(raw)
    n = len(pts)
    # int32 neighbour indices, as every producer of lidarstat.neighbors gives them
    ck.covariance_rows(local, np.arange(n), np.arange(n + 1) * k, j.ravel().astype(np.int32),
                       np.zeros(3), False, ref)
    assert np.array_equal(raw, ref)
    # without sorting only the summation order changes
    _, table_u, _, raw_u = cov._knn_table(pts, k, block_size=700, sort=False)
    assert np.array_equal(np.sort(table_u, axis=1), np.sort(j, axis=1))
    np.testing.assert_allclose(raw_u, raw, rtol=1e-9, atol=1e-13)


def test_knn_with_many_exact_duplicates(rng):
    """40 copies of every point: distance ties everywhere (the selection's sorting fallback)."""
    from scipy.spatial import cKDTree

    base = np.c_[rng.uniform(0, 5, (150, 2)), rng.normal(0, 0.02, 150)]
    pts = np.repeat(base, 40, axis=0)
    k = 50
    res = covariance_features(pts, k=k, keep_neighbors=True)
    got = res.neighborhoods.distances.reshape(-1, k)
    d, _ = cKDTree(pts).query(pts, k=k)
    np.testing.assert_allclose(got, d, rtol=0, atol=1e-12)
    unsorted = covariance_features(pts, k=k)
    np.testing.assert_allclose(unsorted["Eigenvalue2"], res["Eigenvalue2"], rtol=1e-9)


@pytest.mark.parametrize("mode", ["raw", "sqrt", "normalized"])
def test_fields_equal_eigen_features(rng, mode):
    """The fused output kernel computes eigen_features' formulas.

    The two paths evaluate the same expressions in the same order, but transcendental calls
    (``cbrt``, ``log``) come from Numba's libm in one and NumPy's in the other, which may
    differ in the last bit on some CPUs: the comparison allows 4 ulps.
    """
    pts = _cloud(rng, 1500)
    res = covariance_features(pts, k=20, eigen_mode=mode)
    ref = eigen_features(res.eigenvalues, res.normals, res.major, mode=mode)
    for name, v in ref.items():
        got = np.asarray(res[name], dtype=np.float64)
        want = np.asarray(v, dtype=np.float64)
        assert np.array_equal(np.isnan(got), np.isnan(want)), name
        ok = ~np.isnan(want)
        ulp = np.spacing(np.maximum(np.abs(got[ok]), np.abs(want[ok])))
        assert np.all(np.abs(got[ok] - want[ok]) <= 4 * ulp), name


def test_features_match_brute_force(rng):
    pts = _cloud(rng)
    k = 25
    res = covariance_features(pts, k=k, keep_neighbors=True)
    rows = res.neighborhoods.indices.reshape(-1, k)
    ev, nz, sv, cv = _reference(pts, rows)
    np.testing.assert_allclose(res.eigenvalues, ev, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(np.abs(res["NormalZ"]), nz, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res["SurfaceVariation"], sv, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(res["CurvatureVariance"], cv, rtol=1e-6, atol=1e-14)
    assert np.all(res["NormalZ"] >= 0)  # oriented up without a sensor


def test_radius_path_equals_given_neighbourhoods(rng):
    pts = _cloud(rng, 1500)
    a = covariance_features(pts, radius=0.6)
    b = covariance_features(pts, neighborhoods=radius_neighbors(pts, 0.6))
    for name in ("Eigenvalue0", "Eigenvalue2", "SurfaceVariation", "CurvatureVariance",
                 "Linearity", "NormalX"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-9, atol=1e-12, equal_nan=True)
    assert np.array_equal(a["neighbors"], b["neighbors"])


@pytest.mark.parametrize("sensor", [None, [3.0, -20.0, 15.0]])
@pytest.mark.parametrize("block_size", [262144, 37])
def test_frames_equal_the_features_bit_for_bit(rng, sensor, block_size):
    """Normals, centroids and normal-spread directions of :func:`covariance_frames` are
    those of :func:`covariance_features` on the same rows, bit for bit, in one block or
    many; kNN rows and radius rows (with rows of fewer than 3 points: NaN in both)."""
    pts = _cloud(rng, 1500)
    for nbh in (covariance_features(pts, k=25, keep_neighbors=True).neighborhoods,
                radius_neighbors(pts, 0.25)):
        ref = covariance_features(pts, neighborhoods=nbh, sensor=sensor)
        normals, centroids, dirs = covariance_frames(pts, nbh, sensor=sensor,
                                                     block_size=block_size)
        np.testing.assert_array_equal(normals, ref.normals)
        np.testing.assert_array_equal(centroids, ref.centroid)
        np.testing.assert_array_equal(
            dirs, np.c_[ref["PrincipalDirX"], ref["PrincipalDirY"], ref["PrincipalDirZ"]])
    assert (ref["neighbors"] < 3).any() and np.isnan(normals[ref["neighbors"] < 3]).all()
    with pytest.raises(InvalidParameterError, match="one row per point"):
        covariance_frames(pts[:-1], nbh)


def test_utm_offset_does_not_change_features(rng):
    pts = _cloud(rng, 1500)
    local = pts - pts.min(axis=0)
    a = covariance_features(pts, k=20)
    b = covariance_features(local, k=20)
    for name in ("Eigenvalue0", "Eigenvalue1", "SurfaceVariation", "Planarity"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(a.centroid - pts.min(axis=0), b.centroid, atol=1e-6)


def test_normals_point_to_the_sensor(rng):
    xy = rng.uniform(-5, 5, (2000, 2))
    wall = np.c_[xy[:, 0], np.zeros(2000), xy[:, 1]]  # the plane y = 0
    res = covariance_features(wall, k=15, sensor=[0.0, -10.0, 0.0])
    assert np.all(res["NormalY"] < -0.999)
    res = covariance_features(wall, k=15, sensor=[0.0, 10.0, 0.0])
    assert np.all(res["NormalY"] > 0.999)


def test_eigen_features_definitions():
    ev = np.array([[1.0, 2.0, 4.0]])
    n = np.array([[0.0, 0.0, 1.0]])
    a = np.array([[1.0, 0.0, 0.0]])
    f = eigen_features(ev, n, a)
    assert f["Linearity"][0] == pytest.approx(0.5)
    assert f["Planarity"][0] == pytest.approx(0.25)
    assert f["Scattering"][0] == pytest.approx(0.25)
    assert f["Omnivariance"][0] == pytest.approx(2.0)
    assert f["SurfaceVariation"][0] == pytest.approx(1 / 7)
    assert f["DemantkeVerticality"][0] == pytest.approx(0.0)
    # unary vector (4, 2, 1) / |.|: z = 1 / sqrt(21)
    assert f["Verticality"][0] == pytest.approx(1 / np.sqrt(21))
    s = eigen_features(ev, n, a, mode="sqrt")
    assert s["Linearity"][0] == pytest.approx((2 - np.sqrt(2)) / 2)
    assert s["SurfaceVariation"][0] == pytest.approx(1 / 7)  # always raw (eq. 4)


def test_equal_to_jakteristics(rng):
    jak = pytest.importorskip("jakteristics", reason="jakteristics not installed")
    pts = _cloud(rng, 2000) - [512_000.0, 5_430_000.0, 120.0]
    r = 0.7
    names = ["eigenvalue1", "eigenvalue2", "eigenvalue3", "linearity", "planarity",
             "sphericity", "omnivariance", "anisotropy", "eigenentropy", "surface_variation",
             "verticality", "eigenvalue_sum", "number_of_neighbors"]
    ref = jak.compute_features(pts, r, feature_names=names, num_threads=1).astype(np.float64)
    res = covariance_features(pts, radius=r)
    ours = {
        "eigenvalue1": res["Eigenvalue2"], "eigenvalue2": res["Eigenvalue1"],
        "eigenvalue3": res["Eigenvalue0"], "linearity": res["Linearity"],
        "planarity": res["Planarity"], "sphericity": res["Scattering"],
        "omnivariance": res["Omnivariance"], "anisotropy": res["Anisotropy"],
        "eigenentropy": res["Eigenentropy"], "surface_variation": res["SurfaceVariation"],
        "verticality": res["DemantkeVerticality"], "eigenvalue_sum": res["EigenvalueSum"],
        "number_of_neighbors": res["neighbors"],
    }
    # well-conditioned neighbourhoods (jakteristics works in float32 and matches eigenvectors
    # to eigenvalues with a 1e-5 absolute tolerance, so near-degenerate ones are unreliable)
    ev = res.eigenvalues
    ok = (res["neighbors"] >= 10) & (ev[:, 0] > 1e-3 * ev[:, 2]) & \
        (np.diff(ev, axis=1).min(axis=1) > 1e-2 * ev[:, 2])
    assert ok.sum() > 500
    # jakteristics forms the ratios from float32 eigenvalues: differences of close eigenvalues
    # (linearity, planarity, anisotropy) carry its float32 cancellation, about 1e-7 absolute
    ratio = {"linearity", "planarity", "anisotropy"}
    for j, name in enumerate(names):
        atol = 2 * np.finfo(np.float32).eps if name in ratio else 0.0
        np.testing.assert_allclose(ours[name][ok], ref[ok, j], rtol=1e-6, atol=atol,
                                   err_msg=name)


def test_sqrt_mode_matches_pgeof(rng):
    pgeof = pytest.importorskip("pgeof", reason="pgeof not installed")
    pts = rng.normal(size=(3000, 3)) * [1.0, 0.5, 0.2]
    k = 20
    res = covariance_features(pts, k=k, eigen_mode="sqrt", keep_neighbors=True)
    nb = res.neighborhoods
    ref = pgeof.compute_features(pts.astype(np.float32), nb.indices.astype(np.uint32),
                                 nb.indptr.astype(np.uint32), k_min=1)
    # pgeof divides by sqrt(l2) plus a small regulariser, so its L + P + S is slightly below
    # 1; renormalised, its values are ours to float32 precision
    lps = ref[:, :3].astype(np.float64)
    lps /= lps.sum(axis=1, keepdims=True)
    ours = np.c_[res["Linearity"], res["Planarity"], res["Scattering"]]
    np.testing.assert_allclose(ours, lps, rtol=0, atol=2e-6)


@pytest.mark.parametrize("kwargs, match", [
    (dict(points=np.empty((0, 3))), "empty"),
    (dict(points=np.array([[0.0, 0, 0], [np.nan, 0, 0], [1, 1, 1]])), "NaN"),
    (dict(points=np.zeros((10, 3)), k=11), "'k' parameter"),
    (dict(points=np.zeros((10, 3)), k=5, sensor=[0, 0]), "'sensor' parameter"),
    (dict(points=np.zeros((10, 3)), radius=-1.0), "'radius' parameter"),
    (dict(points=np.zeros((10, 3)), eigen_mode="log"), "'eigen_mode' parameter"),
])
def test_bad_input(kwargs, match):
    points = kwargs.pop("points")
    with pytest.raises((InvalidParameterError, InvalidPointsError), match=match):
        covariance_features(points, **kwargs)


def test_neighbourhood_mismatch_and_input_untouched(rng):
    pts = rng.normal(size=(50, 3))
    before = pts.copy()
    nb = Neighborhoods(np.array([0, 1]), np.array([0]), np.array([0.0]), 50)
    with pytest.raises(InvalidParameterError, match="one row per point"):
        covariance_features(pts, neighborhoods=nb)
    covariance_features(pts, k=10)
    assert np.array_equal(pts, before)


def test_duplicates_and_tiny_neighbourhoods_are_nan_not_errors():
    pts = np.zeros((20, 3))
    res = covariance_features(pts, k=5)
    assert np.isnan(res["SurfaceVariation"]).all()  # 0 / 0: no geometry
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [5, 5, 5], [9, 9, 9]])
    res = covariance_features(pts, radius=1.5)
    assert np.isnan(res["Eigenvalue0"]).all() and res["neighbors"].tolist() == [2, 2, 1, 1]


@pytest.mark.parametrize("how", ["knn", "radius"])
def test_principal_direction_across_a_cylinder(rng, how):
    """Section 5: the normal turns fastest across a pipe; n x direction is its axis."""
    n = 12000
    t = rng.uniform(0, 2 * np.pi, n)
    h = rng.uniform(0, 6, n)
    pts = np.c_[0.5 * np.cos(t), 0.5 * np.sin(t), h] + rng.normal(0, 0.001, (n, 3))
    res = covariance_features(pts, **({"k": 30} if how == "knn" else {"radius": 0.2}))
    d = np.c_[res["PrincipalDirX"], res["PrincipalDirY"], res["PrincipalDirZ"]]
    inner = (h > 0.5) & (h < 5.5)
    axis = np.cross(res.normals, d)
    assert np.median(np.abs(axis[inner, 2])) > 0.999
    assert np.percentile(np.abs(d[inner, 2]), 90) < 0.1
    # a plane: no preferred direction, no normal variation beyond noise
    flat = covariance_features(np.c_[rng.uniform(0, 5, (3000, 2)), np.zeros(3000)], k=20)
    assert np.nanmax(flat["NormalVariation"]) < 1e-20
