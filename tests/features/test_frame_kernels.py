"""The closed-form eigenpairs of the quadric's PCA frame against LAPACK and the Jacobi solver."""

import numpy as np
import pytest

from lidarstat._shared._kernels import eigh3
from lidarstat.features._frame_kernels import CLOSED_FORM_GAP, eigh3_closed


def _spd(rng, lam):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return np.ascontiguousarray((q * lam) @ q.T)


@pytest.mark.parametrize("spectrum", [(0.0, 0.15, 0.25), (4e-4, 0.15, 0.2), (1e-6, 0.005, 0.02),
                                      (0.1, 0.2, 0.3), (2e-3, 0.01, 0.5)])
def test_closed_form_matches_lapack(rng, spectrum):
    ev, vec = np.empty(3), np.empty((3, 3))
    for _ in range(200):
        lam = np.array(spectrum) * rng.uniform(0.9, 1.1, 3) * 10.0 ** rng.uniform(-3, 3)
        lam.sort()
        a = _spd(rng, lam)
        kept = a.copy()
        assert eigh3_closed(a, ev, vec)
        np.testing.assert_array_equal(a, kept)  # the input is left alone
        want_val, want_vec = np.linalg.eigh(a)
        np.testing.assert_allclose(ev, want_val, rtol=0, atol=1e-12 * want_val[2])
        for col in (0, 2):  # the normal and e1, up to sign
            cos = abs(vec[:, col] @ want_vec[:, col])
            assert 1.0 - cos < 1e-12
        np.testing.assert_allclose(vec.T @ vec, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(np.cross(vec[:, 0], vec[:, 1]), vec[:, 2], atol=1e-14)


def test_same_frame_as_jacobi(rng):
    """Where it answers, the closed form gives Jacobi's normal and e1 (up to sign)."""
    ev, vec, ev_j, vec_j = np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    for _ in range(300):
        lam = np.sort(rng.uniform(0, 1, 3))
        a = _spd(rng, lam)
        if not eigh3_closed(a, ev, vec):
            continue
        eigh3(a.copy(), ev_j, vec_j)
        np.testing.assert_allclose(ev, ev_j, rtol=0, atol=1e-11 * lam[2])
        for col in (0, 2):
            assert 1.0 - abs(vec[:, col] @ vec_j[:, col]) < 1e-10


@pytest.mark.parametrize("lam", [(1.0, 1.0, 1.0), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.1, 0.5, 0.5),
                                 (0.1, 0.1, 0.5), (0.0, 0.3, 0.3 * (1 + 0.5 * CLOSED_FORM_GAP))])
def test_close_eigenvalues_go_to_jacobi(rng, lam):
    """Collinear, isotropic and circular neighbourhoods (any two eigenvalues within the
    gap) are refused, so the Jacobi solver decides them as before."""
    ev, vec = np.empty(3), np.empty((3, 3))
    assert not eigh3_closed(_spd(rng, np.array(lam)), ev, vec)


def test_spd_inverse6_matches_lapack(rng):
    from lidarstat.features._quadric_kernels import _spd_inverse6

    L, LI, inv = np.zeros((6, 6)), np.zeros((6, 6)), np.empty((6, 6))
    for _ in range(100):
        x = rng.normal(size=(int(rng.integers(7, 60)), 6)) * 10.0 ** rng.uniform(-2, 2, 6)
        a = np.ascontiguousarray(x.T @ x)
        assert _spd_inverse6(a, 1e-12, L, LI, inv)
        want = np.linalg.inv(a)
        cond = np.linalg.cond(a)
        np.testing.assert_allclose(inv, want, rtol=0, atol=1e-13 * cond * np.abs(want).max())
        np.testing.assert_array_equal(inv, inv.T)
        upper = a.copy()  # only the lower triangle is read
        upper[np.triu_indices(6, 1)] = np.nan
        got = np.empty((6, 6))
        assert _spd_inverse6(upper, 1e-12, L, LI, got)
        np.testing.assert_array_equal(got, inv)
    singular = np.ones((6, 6))
    assert not _spd_inverse6(singular, 1e-12, L, LI, inv)
    assert not _spd_inverse6(np.zeros((6, 6)), 1e-12, L, LI, inv)


def test_frame_sums_match_direct_sums(rng):
    """The lane sums of w, w d and w d d' equal the plain sums (columns only read)."""
    from lidarstat.features._quadric_kernels import frame_sums

    for nk in (0, 1, 7, 8, 9, 50, 301):
        cols = np.ascontiguousarray(rng.uniform(-1, 1, (4, nk + 5)))
        cols[3] = rng.uniform(0, 1, nk + 5)
        before = cols.copy()
        got = frame_sums(cols[0], cols[1], cols[2], cols[3], nk)
        d, w = cols[:3, :nk], cols[3, :nk]
        want = [w.sum(), *(d @ w)] + [(w * d[a] * d[c]).sum()
                                      for a, c in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))]
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * nk)
        np.testing.assert_array_equal(cols, before)


def test_moment_sums_match_direct_sums(rng):
    """The lane sums equal the plain sums of w^(p+1) U^i V^j and w h U^i V^j."""
    from lidarstat.features._quadric_kernels import _MONO, _moment_sums

    mom, rhs = np.empty((3, 15)), np.empty(6)
    for nk in (1, 7, 8, 9, 50, 301):
        cols = np.ascontiguousarray(rng.uniform(-1, 1, (4, nk + 5)))
        cols[3] = rng.uniform(0, 1, nk + 5)
        _moment_sums(cols[0], cols[1], cols[2], cols[3], nk, mom, rhs)
        u, v, h, w = (c[:nk] for c in cols)
        powers = [(i - j, j) for i in range(5) for j in range(i + 1)]  # 1 U V U2 UV V2 ...
        mono = np.array([u ** a * v ** b for a, b in powers])
        assert len(powers) == 15 and max(_MONO) == 14
        for p in range(3):
            np.testing.assert_allclose(mom[p], mono @ w ** (p + 1), rtol=1e-13, atol=1e-13 * nk)
        np.testing.assert_allclose(rhs, mono[:6] @ (w * h), rtol=1e-13, atol=1e-13 * nk)


def test_residual_sum_of_squares_matches_direct_sum(rng):
    """The lane sums of w (h - x'beta)^2 equal the plain sum; the columns are only read."""
    from lidarstat.features._quadric_kernels import _residual_ss

    for nk in (1, 7, 8, 9, 50, 301):
        cols = np.ascontiguousarray(rng.uniform(-1, 1, (4, nk + 5)))
        cols[3] = rng.uniform(0, 1, nk + 5)
        beta = rng.normal(size=6)
        u, v, h, w = (c[:nk].copy() for c in cols)
        x = np.stack([np.ones(nk), u, v, 0.5 * u * u, u * v, 0.5 * v * v], axis=1)
        terms = w * (h - x @ beta) ** 2
        before = cols.copy()
        q = _residual_ss(cols[0], cols[1], cols[2], cols[3], nk, beta)
        np.testing.assert_allclose(q, terms.sum(), rtol=1e-13)
        np.testing.assert_array_equal(cols, before)


def test_row_product_sums_in_order(rng):
    """Each entry of a row of A B is sum_k A[a, k] B[k, c] added in k order, bit for bit."""
    from lidarstat.features._quadric_kernels import _row_product

    A, B = rng.normal(size=(6, 6)) * 10.0 ** rng.uniform(-3, 3, (6, 6)), rng.normal(size=(6, 6))
    for a in range(6):
        want = []
        for c in range(6):
            acc = 0.0
            for k in range(6):
                acc += float(A[a, k]) * float(B[k, c])
            want.append(acc)
        assert list(_row_product(A, a, B)) == want
