"""Numba kernels shared by several subpackages (features, classify, segment).

:func:`eigh3` is the one 3x3 symmetric eigen-solver of the local models (covariance
normals, PCA frames of the quadric and jet fits, the visible-boundary and scale kernels);
:func:`cholesky_lower` and :func:`lower_inverse` are the one Cholesky factorisation and
triangular inverse of the small normal matrices (quadric and jet fits, the Taubin quadric of
a merge).
"""

from __future__ import annotations

import numpy as np

from ._jit import njit

__all__ = ["cholesky_lower", "eigh3", "lower_inverse", "mirror3", "uf_find"]


@njit
def eigh3(a, evals, evecs):
    """Cyclic Jacobi eigen-decomposition of a symmetric 3x3 matrix (ascending order).

    `a` is overwritten. Columns of `evecs` are the eigenvectors.
    """
    for i in range(3):
        for j in range(3):
            evecs[i, j] = 1.0 if i == j else 0.0
    for _sweep in range(50):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= 1e-30 * diag or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(3):
                    akp = a[k, p]
                    akq = a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(3):
                    apk = a[p, k]
                    aqk = a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(3):
                    vkp = evecs[k, p]
                    vkq = evecs[k, q]
                    evecs[k, p] = c * vkp - s * vkq
                    evecs[k, q] = s * vkp + c * vkq
    for i in range(3):
        evals[i] = a[i, i]
    # sort ascending (insertion sort on 3 items, columns follow)
    for i in range(1, 3):
        j = i
        while j > 0 and evals[j - 1] > evals[j]:
            tmp = evals[j - 1]
            evals[j - 1] = evals[j]
            evals[j] = tmp
            for k in range(3):
                tv = evecs[k, j - 1]
                evecs[k, j - 1] = evecs[k, j]
                evecs[k, j] = tv
            j -= 1


@njit
def mirror3(cov):  # pragma: no cover - compiled
    """Copy the upper triangle of the 3 x 3 `cov` to its lower triangle."""
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]


@njit
def uf_find(parent, i):  # pragma: no cover - compiled
    """Root of `i` in the union-find forest `parent`, with path halving (every visited
    node is pointed at its grandparent)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit
def cholesky_lower(a, m, tol, L):  # pragma: no cover - compiled
    """Cholesky factor of the SPD leading m x m block of `a` into the lower triangle of `L`
    (``a = L L'``; the upper triangle of `L` is not touched); False as soon as a pivot is not
    above `tol`."""
    for j in range(m):
        sjj = a[j, j]
        for k in range(j):
            sjj -= L[j, k] * L[j, k]
        if not sjj > tol:
            return False
        L[j, j] = np.sqrt(sjj)
        for r in range(j + 1, m):
            s = a[r, j]
            for k in range(j):
                s -= L[r, k] * L[j, k]
            L[r, j] = s / L[j, j]
    return True


@njit
def lower_inverse(L, m, inv):  # pragma: no cover - compiled
    """Inverse of the lower-triangular leading m x m block of `L` into `inv` (forward
    substitution, column by column; the upper triangle of `inv` is zeroed)."""
    for j in range(m):
        for r in range(m):
            inv[r, j] = 0.0
    for j in range(m):
        inv[j, j] = 1.0 / L[j, j]
        for r in range(j + 1, m):
            acc = 0.0
            for k in range(j, r):
                acc -= L[r, k] * inv[k, j]
            inv[r, j] = acc / L[r, r]
