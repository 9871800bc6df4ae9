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
