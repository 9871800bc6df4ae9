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
