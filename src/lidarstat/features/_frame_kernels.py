"""Numba kernels every local fit shares: tricube weights, the local frame of a
neighbourhood (z, auto or PCA; the normal toward the sensor or up) and the Cholesky
inverse of a small SPD normal matrix."""

from __future__ import annotations

from .._shared._jit import njit
from .._shared._kernels import add_outer3, cholesky_lower, lower_inverse, mirror3
from .._shared._kernels import eigh3 as _eigh3

FRAME_Z = 0
FRAME_AUTO = 1
FRAME_PCA = 2


@njit
def _tricube(d, b):
    if d >= b:
        return 0.0
    t = d / b
    t = 1.0 - t * t * t
    return t * t * t


@njit
def _local_frame(buf, nk, px, py, pz, frame, sensor, has_sensor, R, cov, evals, evecs):
    """Fill R (3x3, rows e1, e2, n) for the point at (px, py, pz) from the offsets
    ``buf[:nk, :3]`` of its neighbours and their weights ``buf[:nk, 3]`` (all positive).
    Returns False if the frame is degenerate."""
    if frame == FRAME_Z:
        for a in range(3):
            for c in range(3):
                R[a, c] = 1.0 if a == c else 0.0
        return True
    sw = 0.0
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for t in range(nk):
        w = buf[t, 3]
        sw += w
        m0 += w * buf[t, 0]
        m1 += w * buf[t, 1]
        m2 += w * buf[t, 2]
    if sw <= 0.0:
        return False
    m0 /= sw
    m1 /= sw
    m2 /= sw
    for a in range(3):
        for c in range(3):
            cov[a, c] = 0.0
    for t in range(nk):
        d0 = buf[t, 0] - m0
        d1 = buf[t, 1] - m1
        d2 = buf[t, 2] - m2
        add_outer3(cov, buf[t, 3], d0, d1, d2)
    mirror3(cov)
    _eigh3(cov, evals, evecs)
    if evals[1] <= 0.0:
        return False
    n0 = evecs[0, 0]
    n1 = evecs[1, 0]
    n2 = evecs[2, 0]
    if frame == FRAME_AUTO:
        k = 0
        if abs(n1) > abs(n0):
            k = 1
        if abs(n2) > abs(n0) and abs(n2) > abs(n1):
            k = 2
        sign = 1.0
        if has_sensor and sensor[k] - (px, py, pz)[k] < 0.0:
            sign = -1.0
        for a in range(3):
            for c in range(3):
                R[a, c] = 0.0
        k1 = (k + 1) % 3
        k2 = (k + 2) % 3
        if sign > 0:
            R[0, k1] = 1.0
            R[1, k2] = 1.0
            R[2, k] = 1.0
        else:
            R[0, k2] = 1.0
            R[1, k1] = 1.0
            R[2, k] = -1.0
        return True
    # PCA frame: n = smallest eigenvector, oriented to the sensor or up
    pca_rotation(evecs, px, py, pz, sensor, has_sensor, R)
    return True


@njit
def orient_normal(n0, n1, n2, px, py, pz, sensor, has_sensor):
    """The unit normal ``(n0, n1, n2)`` of the point at (px, py, pz), flipped if needed so
    that it points toward the sensor (`has_sensor`) or up (non-negative z)."""
    if has_sensor:
        flip = n0 * (sensor[0] - px) + n1 * (sensor[1] - py) + n2 * (sensor[2] - pz) < 0.0
    else:
        flip = n2 < 0.0
    if flip:
        return -n0, -n1, -n2
    return n0, n1, n2


@njit
def pca_rotation(evecs, px, py, pz, sensor, has_sensor, R):
    """Rows e1, e2, n of `R` from the ascending eigenvectors (columns of `evecs`) of a
    neighbourhood's covariance: n the smallest, oriented by :func:`orient_normal`, e1 the
    largest and ``e2 = n x e1`` (a direct frame)."""
    n0, n1, n2 = orient_normal(evecs[0, 0], evecs[1, 0], evecs[2, 0], px, py, pz, sensor,
                               has_sensor)
    e0 = evecs[0, 2]
    e1 = evecs[1, 2]
    e2 = evecs[2, 2]
    R[0, 0] = e0
    R[0, 1] = e1
    R[0, 2] = e2
    R[1, 0] = n1 * e2 - n2 * e1
    R[1, 1] = n2 * e0 - n0 * e2
    R[1, 2] = n0 * e1 - n1 * e0
    R[2, 0] = n0
    R[2, 1] = n1
    R[2, 2] = n2


@njit
def to_frame(buf, nk, R, inv_b):
    """Offsets ``buf[:nk, :3]`` to local coordinates in place: ``(u, v, h) = R d`` with the
    tangent coordinates u, v scaled by `inv_b` (the fits' conditioning) and the height h
    not; the weights ``buf[:, 3]`` are left alone."""
    r00 = R[0, 0]
    r01 = R[0, 1]
    r02 = R[0, 2]
    r10 = R[1, 0]
    r11 = R[1, 1]
    r12 = R[1, 2]
    r20 = R[2, 0]
    r21 = R[2, 1]
    r22 = R[2, 2]
    for t in range(nk):
        d0 = buf[t, 0]
        d1 = buf[t, 1]
        d2 = buf[t, 2]
        buf[t, 0] = (r00 * d0 + r01 * d1 + r02 * d2) * inv_b
        buf[t, 1] = (r10 * d0 + r11 * d1 + r12 * d2) * inv_b
        buf[t, 2] = r20 * d0 + r21 * d1 + r22 * d2


@njit
def cholesky_inverse_n(a, m, rel_tol, L, inv):
    """Inverse of the SPD leading m x m block of `a` via Cholesky (shared by the quadric
    and jet kernels); False if a pivot is not above `rel_tol` times the largest diagonal.

    `L` (m x m at least) is scratch; the inverse is written to `inv`.
    """
    scale = 0.0
    for k in range(m):
        if a[k, k] > scale:
            scale = a[k, k]
    if not scale > 0.0:
        return False
    if not cholesky_lower(a, m, rel_tol * scale, L):
        return False
    # inv(L) (lower) into `inv`, then N^-1 = inv(L)' inv(L) via L's upper triangle
    lower_inverse(L, m, inv)
    for r in range(m):
        for c in range(r, m):
            acc = 0.0
            for k in range(c, m):
                acc += inv[k, r] * inv[k, c]
            L[r, c] = acc
    for r in range(m):
        for c in range(r, m):
            inv[r, c] = L[r, c]
            inv[c, r] = L[r, c]
    return True
