"""Slow, obviously correct reference implementations the kernels are checked against."""

from __future__ import annotations

import numpy as np


def tricube(d, b):
    t = np.clip(d / b, 0, 1)
    return np.where(d < b, (1 - t**3) ** 3, 0.0)


def quadric_fit_reference(pts, i, nbr, dist, b):
    """WLS quadric in the z frame at point i with dense matrices (eq. 2-6)."""
    d = pts[nbr] - pts[i]
    w = tricube(dist, b)
    keep = w > 0
    d, w = d[keep], w[keep]
    u, v, h = d[:, 0], d[:, 1], d[:, 2]
    X = np.c_[np.ones_like(u), u, v, 0.5 * u * u, u * v, 0.5 * v * v]
    W = np.diag(w)
    N = X.T @ W @ X
    Ninv = np.linalg.inv(N)
    beta = Ninv @ X.T @ W @ h
    e = h - X @ beta
    B = W - W @ X @ Ninv @ X.T @ W
    sandwich = Ninv @ X.T @ W @ W @ X @ Ninv
    return dict(beta=beta, q=e @ W @ e, trB=np.trace(B), trB2=np.trace(B @ B), Ninv=Ninv,
                sandwich=sandwich, p=int(keep.sum()))


# The vectorised NumPy formulation of the curvature tests (the first implementation),
# kept as the reference the Numba statistics kernel is checked against.
from scipy import stats as _st  # noqa: E402

from lidarstat.classify import hk_surface_types  # noqa: E402
from lidarstat.features import FitStatus  # noqa: E402
from lidarstat.features import _quadric_kernels as _k  # noqa: E402
from lidarstat.features._curvature_formulas import (curvature_jacobian, curvatures,  # noqa: E402
                                                    principal_jacobian)
from lidarstat.stats import (f_test_paper, variance_test_paper,  # noqa: E402
                             variance_test_satterthwaite, wald_test, z_test)


def curvature_tests_reference(out, *, sigma2, alpha, test, minimal_detectable=False):
    """Turn raw kernel outputs of one block into curvature, tests and types.

    Parameters
    ----------
    out : dict
        Kernel outputs (``status``, ``npts``, ``beta``, ``cof``, ``frames``, ``stats``).
    sigma2 : float or (M,) ndarray
        Variance of the heights (see :func:`height_variance`).
    alpha : float
        Significance level.
    test : {'calibrated', 'paper'}
        Which family of tests (see docs/methods/curvature.md).

    Returns
    -------
    dict of per-point arrays named as in ``FIELDS``.
    """
    beta, cof, st = out["beta"], out["cof"], out["stats"]
    sigma2 = np.broadcast_to(np.asarray(sigma2, dtype=np.float64), out["status"].shape)
    q, trb, trb2 = st[:, 0], st[:, 2], st[:, 3]
    p = out["npts"].astype(np.float64)
    fitted = out["status"] == _k.OK
    a = beta[:, 1:]
    K, H, kmin, kmax = curvatures(a)
    J = curvature_jacobian(a)
    if test == "paper":
        with np.errstate(invalid="ignore", divide="ignore"):
            s0 = q / (p - 6.0)
        chi2 = variance_test_paper(q, p, sigma2, alpha)
        Qww = J @ cof[:, 1:, 1:] @ np.swapaxes(J, 1, 2)
        ftest = f_test_paper(np.stack([K, H], 1), Qww, s0, alpha)
        planar = ~ftest.reject
        planar_p = ftest.pvalue
        with np.errstate(invalid="ignore"):
            sdK = np.sqrt(s0 * Qww[:, 0, 0])
            sdH = np.sqrt(s0 * Qww[:, 1, 1])
        ktest = z_test(K, sdK, alpha / 2)
        K_sig, K_p = ktest.reject, ktest.pvalue
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            s0 = q / trb
        chi2 = variance_test_satterthwaite(q, trb, trb2, sigma2, alpha)
        cov_a = sigma2[:, None, None] * cof[:, 1:, 1:]
        plan = wald_test(a[:, 2:], cov_a[:, 2:, 2:], alpha)
        planar = ~plan.reject
        planar_p = plan.pvalue
        Cw = J @ cov_a @ np.swapaxes(J, 1, 2)
        with np.errstate(invalid="ignore"):
            sdK = np.sqrt(Cw[:, 0, 0])
            sdH = np.sqrt(Cw[:, 1, 1])
        # K = kmin*kmax differs from 0 iff both principal curvatures do (intersection-union
        # test: each at level alpha/2 gives a level-alpha/2 test of K = 0).
        Jp = principal_jacobian(K, H, J)
        Cp = Jp @ cov_a @ np.swapaxes(Jp, 1, 2)
        with np.errstate(invalid="ignore"):
            t_min = z_test(kmin, np.sqrt(Cp[:, 0, 0]), alpha / 2)
            t_max = z_test(kmax, np.sqrt(Cp[:, 1, 1]), alpha / 2)
        K_sig = t_min.reject & t_max.reject
        K_p = np.fmax(t_min.pvalue, t_max.pvalue)
    htest = z_test(H, sdH, alpha / 2)
    chi2_pass = fitted & np.isfinite(chi2.pvalue) & ~chi2.reject
    status = out["status"].copy()
    status[fitted & ~chi2_pass] = FitStatus.MODEL_REJECTED
    surface_type = hk_surface_types(K, H, tested=chi2_pass, planar=planar, K_sig=K_sig,
                                    H_sig=htest.reject)
    frames = out["frames"]
    nl = np.stack([-a[:, 0], -a[:, 1], np.ones_like(K)], axis=1)
    nl /= np.linalg.norm(nl, axis=1, keepdims=True)
    normal = np.einsum("nij,ni->nj", frames, nl)
    res = {
        "neighbors": out["npts"],
        "z0": beta[:, 0] * frames[:, 2, 2],  # z offset of the fitted point; caller adds z
        "sigma0_sq": s0,
        "chi2_pass": chi2_pass.astype(np.uint8),
        "K": K, "H": H, "kmin": kmin, "kmax": kmax,
        "K_sig": (chi2_pass & K_sig).astype(np.uint8),
        "H_sig": (chi2_pass & htest.reject).astype(np.uint8),
        "surface_type": surface_type,
        "status": status,
        "dz0": beta[:, 0],
        "chi2_p": chi2.pvalue, "planar_p": planar_p, "K_p": K_p, "H_p": htest.pvalue,
        "NormalX": normal[:, 0], "NormalY": normal[:, 1], "NormalZ": normal[:, 2],
    }
    if minimal_detectable:
        zc = _st.norm.isf(alpha / 4)  # two-sided at alpha/2 (Bonferroni), eq. 19
        res["K_min"] = zc * sdK
        res["H_min"] = zc * sdH
    return res


