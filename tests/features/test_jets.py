"""Jets and Monge coefficients against exact jets, CGAL, and their own standard errors."""

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from lidarstat.errors import InsufficientNeighborsError, InvalidParameterError, InvalidPointsError
from lidarstat.features import (fit_jets, height_variance, jet_tests, jets,
                                principal_directions)
from lidarstat.neighbors import knn_neighbors, radius_neighbors
from lidarstat.synth import make_cylinder, make_sphere_cap
from lidarstat.synth._replicates import make_replicates

REPO = Path(__file__).resolve().parents[2]
CGAL_SRC = REPO / "benchmarks" / "cgal_monge.cpp"


def _grid(half, spacing, f, rng=None, sigma=0.0):
    g = np.arange(-half, half + spacing / 2, spacing)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    z = f(x, y)
    if sigma:
        z = z + np.random.default_rng(rng).normal(0, sigma, z.size)
    return np.c_[x, y, z]


def _nearest(pts, x, y):
    return int(np.argmin((pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2))


# ------------------------------------------------------------------------ exact surfaces

def test_sphere_monge_coefficients():
    """Sphere of radius R, normal up (outward): k1 = k2 = -1/R, b = 0, c0 = c4 = 3k^3,
    c2 = k^3, c1 = c3 = 0 (Z = -(r^2/2R + r^4/8R^3 + ...)), whatever the directions."""
    R = 2.0
    pts = _grid(0.6, 0.02, lambda x, y: np.sqrt(R * R - x * x - y * y) - R)
    nb = radius_neighbors(pts, 0.25)
    fit = fit_jets(pts, nb, degree=4)
    i = _nearest(pts, 0.15, -0.1)
    k = -1.0 / R
    m = fit.monge[i]
    np.testing.assert_allclose(m[:2], [k, k], atol=2e-5)
    np.testing.assert_allclose(m[2:6], 0.0, atol=1e-4)
    np.testing.assert_allclose(m[6:], [3 * k**3, 0, k**3, 0, 3 * k**3], atol=5e-3)
    assert fit.normal[i] @ (pts[i] - [0, 0, -R]) > 0.99 * R


def _profile(A, s):
    """Gaussian crest z = A exp(-x^2/2s^2): curvature kappa(x) of the profile and its
    first two arc-length derivatives (closed form for kappa, centred differences)."""
    def kappa(x):
        e = np.exp(-x * x / (2 * s * s))
        f1 = -A * x / s**2 * e
        f2 = A * (x * x / s**4 - 1 / s**2) * e
        return f2 / (1 + f1 * f1) ** 1.5, np.sqrt(1 + f1 * f1)

    def derivs(x, h=1e-4):
        k0, g = kappa(x)
        kp, _ = kappa(x + h)
        km, _ = kappa(x - h)
        kx = (kp - km) / (2 * h)
        kxx = (kp - 2 * k0 + km) / (h * h)
        # d/ds = (1/g) d/dx; g' = f1 f2 / g
        e = np.exp(-x * x / (2 * s * s))
        f1 = -A * x / s**2 * e
        f2 = A * (x * x / s**4 - 1 / s**2) * e
        gx = f1 * f2 / g
        ks = kx / g
        kss = kxx / g**2 - kx * gx / g**3
        return k0, ks, kss

    return derivs


@pytest.mark.parametrize("x0", [0.0, 0.15, 0.3, 0.5])
def test_gaussian_crest_profile_jets(x0):
    """An extruded profile: in the Monge frame Z = kappa X^2/2 + kappa_s X^3/6 +
    (kappa_ss + 3 kappa^3) X^4/24 along the profile and nothing else (k = 0 along y)."""
    A, s = 0.4, 0.5
    pts = _grid(1.0, 0.01, lambda x, y: A * np.exp(-x * x / (2 * s * s)))
    i = _nearest(pts, x0, 0.0)
    nb = radius_neighbors(pts, 0.12, query=np.array([i]))
    fit = fit_jets(pts, nb, degree=4)
    kap, ks, kss = _profile(A, s)(pts[i, 0])
    m, fr = fit.monge[0], fit.frame[0]
    # which principal direction is the profile's (the other is y, curvature 0)
    j = 0 if abs(fr[0, 1]) < abs(fr[1, 1]) else 1
    sign = np.sign(fr[j, 0])  # the direction's orientation along +x
    tol_k = 2e-4 + 1e-3 * abs(kap)
    assert abs(m[j] - kap) < tol_k, (m[:2], kap)
    assert abs(m[1 - j]) < tol_k
    b_own = m[2] if j == 0 else m[5]
    c_own = m[6] if j == 0 else m[10]
    assert abs(sign * b_own - ks) < 2e-3 + 1e-2 * abs(ks), (b_own, ks)
    assert abs(c_own - (kss + 3 * kap**3)) < 0.05 + 0.03 * abs(kss), (c_own, kss + 3 * kap**3)
    cross = [m[3], m[4], m[7], m[8], m[9]]  # b1, b2, c1, c2, c3 vanish on an extrusion
    np.testing.assert_allclose(cross, 0.0, atol=0.05)


def test_monkey_saddle_invariants():
    """z = x^3 - 3xy^2 at the origin: k1 = k2 = 0 and the cubic form is
    6 Re(e^{3i theta}(X + iY)^3) for the (arbitrary) direction angle theta:
    b0^2 + b1^2 = 36, b2 = -b0, b3 = -b1; fourth order zero."""
    pts = _grid(0.5, 0.01, lambda x, y: x**3 - 3 * x * y * y)
    i = _nearest(pts, 0.0, 0.0)
    fit = fit_jets(pts, radius_neighbors(pts, 0.1, query=np.array([i])), degree=4)
    m = fit.monge[0]
    np.testing.assert_allclose(m[:2], 0.0, atol=1e-6)
    assert abs(m[2] ** 2 + m[3] ** 2 - 36.0) < 1e-3
    np.testing.assert_allclose([m[4], m[5]], [-m[2], -m[3]], atol=1e-4)
    np.testing.assert_allclose(m[6:], 0.0, atol=1e-2)


def test_cylinder_principal_directions():
    cyl = make_cylinder(0.8, axis=(1.0, 0.0), spacing=0.02, rng=0)
    pdirs = principal_directions(cyl.xyz, radius=0.15, degree=4)
    inner = (cyl.edge_distance > 0.2) & (pdirs.status == 0)
    assert inner.sum() > 100
    # convex (normal up): k1 = 0 along the axis x, k2 = -1/R across
    np.testing.assert_allclose(pdirs.k1[inner], 0.0, atol=2e-4)
    np.testing.assert_allclose(pdirs.k2[inner], -1 / 0.8, rtol=2e-4)
    pd2 = principal_directions(cyl.xyz, radius=0.15)  # the quadric: biased by u^4/8R^3
    np.testing.assert_allclose(pd2.k2[inner], -1 / 0.8, rtol=1e-2)
    assert np.all(np.abs(pdirs.d1[inner, 0]) > 0.999)
    d = np.einsum("ij,ij->i", pdirs.d1, pdirs.d2)
    assert np.all(np.abs(d[inner]) < 1e-9)
    det = np.linalg.det(np.stack([pdirs.d1, pdirs.d2, pdirs.normal], axis=1)[inner])
    np.testing.assert_allclose(det, 1.0, atol=1e-9)


def test_degree_four_removes_the_quadric_bore_bias():
    """A cylinder of radius 0.28 at bandwidth 0.2 (b/R = 0.71, the agpart bore): the
    quadric's |H| is biased by the circle's u^4 term; the degree-4 jet is not."""
    R = 0.28
    cyl = make_cylinder(R, axis=(1.0, 0.0), convex=False, spacing=0.01, max_slope=80, rng=0)
    pd2 = principal_directions(cyl.xyz, radius=0.2, degree=2)
    pd4 = principal_directions(cyl.xyz, radius=0.2, degree=4)
    inner = cyl.edge_distance > 0.21
    assert inner.sum() > 50
    r2 = 1 / np.median(pd2.k1[inner])
    r4 = 1 / np.median(pd4.k1[inner])
    assert abs(r2 / R - 1) > 0.03  # the degree-2 bias
    assert abs(r4 / R - 1) < 0.01 and abs(r4 / R - 1) < abs(r2 / R - 1) / 4


# ----------------------------------------------------------------- standard errors, test

# an exact Monge form at the origin: k1, k2 along x, y, then b0..b3, c0..c4
MONGE_TRUTH = np.array([0.8, -0.4, 0.6, -0.3, 0.2, 0.5, 1.0, -0.5, 0.4, 0.3, -0.8])


def _monge_surface(x, y, m=MONGE_TRUTH):
    k1, k2, b0, b1, b2, b3, c0, c1, c2, c3, c4 = m
    return (0.5 * (k1 * x * x + k2 * y * y)
            + (b0 * x**3 + 3 * b1 * x * x * y + 3 * b2 * x * y * y + b3 * y**3) / 6
            + (c0 * x**4 + 4 * c1 * x**3 * y + 6 * c2 * x * x * y * y + 4 * c3 * x * y**3
               + c4 * y**4) / 24)


def _monge_replicates(n_rep, sigma, rng, half=0.45, spacing=0.03):
    rng = np.random.default_rng(rng)
    base = _grid(half, spacing, _monge_surface)
    centre = _nearest(base, 0.0, 0.0)
    blocks = []
    for r in range(n_rep):
        p = base.copy()
        p[:, 2] += rng.normal(0, sigma, len(p))
        p[:, 0] += 10 * r
        blocks.append(p)
    return np.concatenate(blocks), centre + len(base) * np.arange(n_rep)


def test_exact_monge_form_from_its_taylor_expansion():
    """Noise-free: the surface IS its Monge form at the origin (principal frame = x, y, z)."""
    pts, q = _monge_replicates(1, 0.0, 0)
    fit = fit_jets(pts, radius_neighbors(pts, 0.4, query=q), degree=4)
    sign = np.sign(fit.d1[0, 0])  # d1 = +-x: the odd-degree terms follow its orientation
    m = fit.monge[0] * np.r_[1, 1, sign, sign, sign, sign, 1, 1, 1, 1, 1]
    np.testing.assert_allclose(m[:2], MONGE_TRUTH[:2], atol=2e-3)
    np.testing.assert_allclose(m[2:6], MONGE_TRUTH[2:6], atol=2e-2)
    np.testing.assert_allclose(m[6:], MONGE_TRUTH[6:], atol=0.15)
    assert abs(abs(fit.d1[0, 0]) - 1) < 1e-4 and abs(fit.normal[0, 2] - 1) < 1e-4


@pytest.mark.parametrize("weight", ["tricube", "none"])
def test_standard_errors_are_calibrated(weight):
    """(estimate - truth)/sd over 300 independent noisy copies: mean ~ 0, std ~ 1 for
    every Monge coefficient (first-order propagation, frame held fixed)."""
    sigma = 0.002
    pts, q = _monge_replicates(300, sigma, 5)
    fit = fit_jets(pts, radius_neighbors(pts, 0.4, query=q), degree=4, weight=weight)
    f = jet_tests(fit, height_variance(fit.frame, sigma, noise="z"), 0.05)
    sign = np.sign(fit.d1[:, 0])
    for j, name in enumerate(("k1", "k2", "b0", "b1", "b2", "b3", "c0", "c1", "c2", "c3",
                              "c4")):
        est = f[name] * (sign if 2 <= j < 6 else 1.0)
        z = (est - MONGE_TRUTH[j]) / f[f"{name}_sd"]
        assert 0.85 < np.std(z) < 1.18, (name, np.std(z))
        assert abs(np.mean(z)) < 0.3, (name, np.mean(z))


@pytest.mark.parametrize("weight", ["tricube", "none"])
def test_chi_square_size(weight):
    """Rejection rate of the jet's chi-square test under a true model (a tilted quadric,
    which a degree-4 jet in the PCA frame represents to well below the noise) within the
    99% binomial interval of alpha over 1000 independent neighbourhoods."""
    n_rep, alpha, sigma = 1000, 0.05, 0.01
    pts, centres = make_replicates("quadric", n_replicates=n_rep, sigma=sigma, curvature=0.2,
                                   rng=11)
    fit = fit_jets(pts, radius_neighbors(pts, 1.0, query=centres), degree=4, weight=weight,
                   standard_errors=False)
    f = jet_tests(fit, height_variance(fit.frame, sigma, noise="z"), alpha)
    rate = 1 - f["chi2_pass"].mean()
    lo, hi = stats.binom.ppf([0.005, 0.995], n_rep, alpha) / n_rep
    assert lo <= rate <= hi, rate


def test_chi_square_power_at_a_crease():
    pts, centres = make_replicates("ridge", n_replicates=300, sigma=0.01, curvature=0.2, rng=3)
    fit = fit_jets(pts, radius_neighbors(pts, 1.0, query=centres), degree=4,
                   standard_errors=False)
    f = jet_tests(fit, height_variance(fit.frame, 0.01, noise="z"), 0.05)
    assert 1 - f["chi2_pass"].mean() > 0.9


# ---------------------------------------------------------------------------- driver

def test_jets_driver_radius_equals_csr_fit():
    cap = make_sphere_cap(1.0, spacing=0.03, sigma=0.001, rng=2)
    res = jets(cap.xyz, radius=0.2, sigma=0.001)
    fit = fit_jets(cap.xyz, radius_neighbors(cap.xyz, 0.2))
    ok = fit.status == 0
    np.testing.assert_array_equal(res.fit.status, fit.status)
    np.testing.assert_allclose(res["k1"][ok], fit.k1[ok], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res["c4"][ok], fit.monge[ok, 10], rtol=1e-7, atol=1e-7)
    inner = ok & (cap.edge_distance > 0.2)
    # 1 - chi2_pass rate near alpha on the exact sphere with the true sigma
    assert abs((1 - res["chi2_pass"][inner].mean()) - 0.05) < 0.04
    assert set(res.to_fields()) == set(res.fields)


@pytest.mark.parametrize("seed", range(4))
def test_fit_by_radius_equals_csr_fit(seed):
    """The fused search (``fit_jets(points, radius=r, query=rows)``, no neighbour table)
    fits the same neighbourhoods as ``radius_neighbors``, in the order of `query`
    (repeats and any order): status and counts equal everywhere; every field within
    1e-10 of its row's largest value where the radius lies inside the cap (condition
    number about 15). At the rim (condition up to 1e5) the order of the sums moves the
    degree-4 coefficients by about 1e-7 relative, which the comparison leaves out."""
    g = np.random.default_rng(seed)
    cap = make_sphere_cap(1.0 + g.uniform(0, 1), spacing=0.03, sigma=0.001, rng=seed)
    n = len(cap.xyz)
    rows = g.choice(n, size=n // 3, replace=False)
    rows = np.r_[rows, rows[:7]]  # repeats are fitted once and copied
    r = g.uniform(0.1, 0.2)
    fused = fit_jets(cap.xyz, radius=r, query=rows)
    csr = fit_jets(cap.xyz, radius_neighbors(cap.xyz, r, query=rows))
    np.testing.assert_array_equal(fused.status, csr.status)
    np.testing.assert_array_equal(fused.neighbors, csr.neighbors)
    inner = (csr.status == 0) & (cap.edge_distance[rows] > r)
    assert inner.mean() > 0.5
    for name in ("jet", "monge", "frame", "monge_cofactor", "q", "sum_w", "bandwidth"):
        a, b = getattr(fused, name)[inner], getattr(csr, name)[inner]
        a, b = a.reshape(len(a), -1), b.reshape(len(b), -1)
        scale = np.abs(b).max(axis=1, keepdims=True)
        assert np.all(np.abs(a - b) <= 1e-10 * scale), name
    whole = fit_jets(cap.xyz, radius=r)
    np.testing.assert_array_equal(whole.status[rows], fused.status)


def test_fit_by_radius_refusals():
    pts = _grid(0.2, 0.05, lambda x, y: 0 * x)
    nb = radius_neighbors(pts, 0.06)
    with pytest.raises(InvalidParameterError, match="neighborhoods. or .radius"):
        fit_jets(pts)
    with pytest.raises(InvalidParameterError, match="already hold"):
        fit_jets(pts, nb, radius=0.06)
    with pytest.raises(InvalidParameterError, match="already hold"):
        fit_jets(pts, nb, query=[0])
    with pytest.raises(InvalidParameterError, match="bandwidth"):
        fit_jets(pts, radius=0.06, bandwidth=0.1)
    with pytest.raises(InvalidParameterError, match="query"):
        fit_jets(pts, radius=0.06, query=[len(pts)])


def test_jets_knn_and_estimated_sigma():
    cap = make_sphere_cap(1.0, spacing=0.03, sigma=0.002, rng=4)
    res = jets(cap.xyz, k=40, degree=3)
    assert res.sigma_estimated
    assert 0.9 * 0.002 < res.sigma < 1.1 * 0.002  # along z, the default noise direction
    assert "c0" not in res.fields and "b3_sd" in res.fields


def test_estimated_sigma_follows_the_noise_direction():
    """On a plane tilted by 50 degrees with noise along z, sigma is estimated along the
    resolved noise direction: sigma itself for noise='z' (the default without a sensor),
    sigma cos(50 deg) for noise='normal' (the residuals along the normal); a median over
    normal residuals would be low wherever a z-noise cloud has steep faces."""
    tilt = np.tan(np.radians(50.0))
    pts = _grid(0.5, 0.02, lambda x, y: tilt * x, rng=11, sigma=0.002)
    for noise, expect in (("z", 0.002), ("normal", 0.002 * np.cos(np.radians(50.0)))):
        res = jets(pts, radius=0.1, degree=2, noise=noise)
        assert res.meta["noise"] == noise
        assert abs(res.sigma / expect - 1.0) < 0.05, (noise, res.sigma, expect)


def test_errors():
    pts = _grid(0.2, 0.05, lambda x, y: 0 * x)
    nb = radius_neighbors(pts, 0.06)
    with pytest.raises(InvalidParameterError, match="degree"):
        fit_jets(pts, nb, degree=5)
    with pytest.raises(InvalidParameterError, match="monge_degree"):
        fit_jets(pts, nb, degree=2, monge_degree=3)
    with pytest.raises(InvalidParameterError, match="weight"):
        fit_jets(pts, nb, weight="gauss")
    with pytest.raises(InsufficientNeighborsError, match="neighbours"):
        jets(pts, radius=0.06)
    bad = pts.copy()
    bad[3, 2] = np.nan
    with pytest.raises(InvalidPointsError, match="NaN"):
        jets(bad, radius=0.1)
    with pytest.raises(InvalidParameterError, match="at most one"):
        jets(pts, radius=0.1, k=20)
    fit = fit_jets(pts, nb, degree=2)
    assert np.all(fit.status == 1) and np.isnan(fit.monge).all()


def test_input_not_modified():
    cap = make_sphere_cap(1.0, spacing=0.05, sigma=0.001, rng=2)
    before = cap.xyz.copy()
    jets(cap.xyz, radius=0.3)
    np.testing.assert_array_equal(cap.xyz, before)


# ------------------------------------------------------------------------------ CGAL

_BUILT = {}


def _cgal_binary(request):
    """The CGAL driver, compiled once per session (and kept in pytest's cache when on)."""
    if "exe" in _BUILT:
        return _BUILT["exe"]
    if shutil.which("g++") is None or not Path("/usr/include/CGAL/Monge_via_jet_fitting.h").exists():
        pytest.skip("g++ or the CGAL headers (apt libcgal-dev libeigen3-dev) are not available")
    tag = hashlib.sha1(CGAL_SRC.read_bytes()).hexdigest()[:12]
    cache = getattr(request.config, "cache", None)
    where = (Path(cache.mkdir("cgal_monge")) if cache is not None
             else request.getfixturevalue("tmp_path_factory").mktemp("cgal"))
    out = where / f"cgal_monge_{tag}"
    if not out.exists():
        tmp = out.with_suffix(".tmp")
        r = subprocess.run(["g++", "-O1", "-DNDEBUG", "-fopenmp", "-std=c++17",
                            "-I/usr/include/eigen3", str(CGAL_SRC), "-o", str(tmp)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot build the CGAL driver: {r.stderr[-300:]}")
        os.replace(tmp, out)
    _BUILT["exe"] = out
    return out


def align_cgal(coef, frame, ref_frame):
    """CGAL's Monge form re-expressed with our normal and d1 orientation.

    A flipped normal swaps (d1, d2), (k1, k2), (b0, b3), (b1, b2), (c0, c4), (c1, c3) and
    negates every coefficient (CGAL's ``comply_wrt_given_normal``); flipping d1 and d2
    together negates the odd-degree b's.
    """
    coef, frame = coef.copy(), frame.copy()
    flip = np.einsum("ij,ij->i", frame[:, 2], ref_frame[:, 2]) < 0
    coef[flip] = -coef[flip][:, [1, 0, 5, 4, 3, 2, 10, 9, 8, 7, 6]]
    frame[flip] = np.stack([frame[flip, 1], frame[flip, 0], -frame[flip, 2]], axis=1)
    s = np.einsum("ij,ij->i", frame[:, 0], ref_frame[:, 0]) < 0
    coef[s, 2:6] *= -1
    frame[s, :2] *= -1
    return coef, frame


@pytest.mark.parametrize("d,dp", [(2, 2), (3, 3), (4, 4), (4, 3)])
def test_equals_cgal(request, tmp_path, d, dp):
    exe = _cgal_binary(request)
    rng = np.random.default_rng(1)
    n, k = 2000, 40
    x, y = rng.uniform(-1, 1, (2, n))
    z = (0.3 * x**2 - 0.2 * x * y + 0.1 * y**2 + 0.4 * x**3 - 0.2 * y**3 + 0.3 * x * x * y * y
         + 0.2 * np.sin(3 * x + y))
    pts = np.c_[x, y, z] + rng.normal(0, 0.002, (n, 3))
    nb = knn_neighbors(pts, k)
    fit = fit_jets(pts, nb, degree=d, monge_degree=dp, weight="none", standard_errors=False)
    # The tolerance of 1e-8 below: both solve the same least squares, CGAL by an SVD of
    # the design matrix (rounding error ~ eps kappa), fit_jets by Cholesky of the
    # equilibrated normal equations (~ eps kappa^2). kappa (`cond`) stays below 3,000 on
    # this cloud, so eps kappa^2 < 2e-9. On kNN neighbourhoods with kappa ~ 1e6 (points
    # strung along scan lines) the two differ by up to about 1e-4 of a coefficient
    # (benchmarks/bench_jets.py records the differences against kappa).
    assert np.nanmax(fit.cond[fit.status == 0]) < 3000
    pts.tofile(tmp_path / "x.bin")
    nb.indices.reshape(n, k).astype(np.int32).tofile(tmp_path / "k.bin")
    subprocess.run([str(exe), str(tmp_path / "x.bin"), str(tmp_path / "k.bin"),
                    str(tmp_path / "o.bin"), str(d), str(dp)], check=True, capture_output=True,
                   env={**os.environ, "OMP_NUM_THREADS": "1"})
    o = np.fromfile(tmp_path / "o.bin").reshape(n, 21)
    coef, frame = align_cgal(o[:, :11], o[:, 11:20].reshape(n, 3, 3), fit.frame)
    nm = {2: 2, 3: 6, 4: 11}[dp]
    scale = np.abs(coef[:, :nm]).max(axis=0)
    np.testing.assert_allclose(fit.monge[:, :nm], coef[:, :nm], rtol=0, atol=1e-8 * scale.max())
    np.testing.assert_allclose(fit.frame, frame, atol=1e-8)
    assert np.isnan(fit.monge[:, nm:]).all()


def _rotated_cap(tilt_deg, rng):
    """A sphere cap (R = 1) turned by `tilt_deg` about x: 90 is a vertical face, 150
    overhangs (its normal points down)."""
    cap = make_sphere_cap(1.0, spacing=0.03, sigma=0.0005, rng=rng)
    t = np.radians(tilt_deg)
    rot = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return cap.xyz @ rot.T, cap.edge_distance


@pytest.mark.parametrize("tilt", [0, 90, 150])
def test_automatic_scale_on_steep_and_overhanging_surfaces(tilt):
    """No scale given: per point the smallest radius of the ladder at which a principal
    curvature is significant; the PCA frame of the jets works at any orientation (flat,
    vertical, overhanging): |H| = 1/R within 2 % in the median, convex toward the sensor
    at the centre everywhere, and the chosen radius is one of the ladder's, written per
    point and in the params."""
    pts, edge = _rotated_cap(tilt, 7)
    t = np.radians(tilt)
    sensor = 5.0 * np.array([0.0, -np.sin(t), np.cos(t)])  # outside, on the cap's axis
    res = jets(pts, sigma=0.0005, noise="normal", sensor=sensor)
    r = res["radius"]
    assert res.meta["scale"] == "auto" and np.all(np.isin(r, res.meta["radii"]))
    assert "automatic scale" in res.summary()
    inner = (edge > 2 * r) & (res["status"] == 0)
    assert inner.mean() > 0.3
    H = 0.5 * (res["k1"] + res["k2"])[inner]
    assert abs(np.median(np.abs(H)) - 1.0) < 0.02, np.median(H)
    assert np.all(H < 0)


def test_automatic_scale_is_the_smallest_detecting_radius():
    """A gentler sphere needs a wider jet for its curvature to be significant at the same
    noise: the chosen radius grows with R, and a plane (nothing to detect) stays at the
    smallest radius of the ladder."""
    rng = np.random.default_rng(5)
    med = []
    for radius in (0.5, 2.0):
        cap = make_sphere_cap(radius, spacing=0.03, sigma=0.002, max_slope=30, rng=rng)
        res = jets(cap.xyz, sigma=0.002)
        med.append(np.median(res["radius"][cap.edge_distance > 0.2]))
    assert med[1] > med[0]
    plane = _grid(0.6, 0.03, lambda x, y: 0.2 * x, rng=5, sigma=0.002)
    res = jets(plane, sigma=0.002)
    assert np.mean(res["radius"] == res.meta["radii"][0]) > 0.95
