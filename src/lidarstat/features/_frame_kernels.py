"""Numba kernels every local fit shares: tricube weights, the local frame of a
neighbourhood (z, auto or PCA; the normal toward the sensor or up) and the Cholesky
inverse of a small SPD normal matrix."""

from __future__ import annotations

import math

from .._shared._jit import njit
from .._shared._kernels import cholesky_lower, lower_inverse, mirror3
from .._shared._kernels import eigh3 as _eigh3

FRAME_Z = 0
FRAME_AUTO = 1
FRAME_PCA = 2

#: Closed-form eigenpairs of a neighbourhood's covariance (:func:`eigh3_closed`) are used
#: only where the eigenvalues are apart by at least this share of the largest (then the
#: eigenvectors of the smallest and largest have errors of about 1e-16 times its inverse);
#: elsewhere the Jacobi solver decides
CLOSED_FORM_GAP = 1e-4
_TWO_THIRDS_PI = 2.0 * math.pi / 3.0


@njit
def _tricube(d, b):
    if d >= b:
        return 0.0
    t = d / b
    t = 1.0 - t * t * t
    return t * t * t


@njit
def _local_frame(buf, nk, px, py, pz, frame, sensor, has_sensor, R, cov, evals, evecs,
                 closed_form):
    """Fill R (3x3, rows e1, e2, n) for the point at (px, py, pz) from the offsets
    ``buf[:nk, :3]`` of its neighbours and their weights ``buf[:nk, 3]`` (all positive).
    Returns False if the frame is degenerate. With `closed_form` the eigenpairs come from
    :func:`eigh3_closed` where its eigenvalues are well apart (a fit whose result does
    not depend on the direction of e1 within the tangent plane), else from ``eigh3``."""
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
    # the weighted covariance sums in registers (each term as add_outer3 forms it)
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(nk):
        w = buf[t, 3]
        d0 = buf[t, 0] - m0
        d1 = buf[t, 1] - m1
        d2 = buf[t, 2] - m2
        c00 += w * d0 * d0
        c01 += w * d0 * d1
        c02 += w * d0 * d2
        c11 += w * d1 * d1
        c12 += w * d1 * d2
        c22 += w * d2 * d2
    cov[0, 0] = c00
    cov[0, 1] = c01
    cov[0, 2] = c02
    cov[1, 1] = c11
    cov[1, 2] = c12
    cov[2, 2] = c22
    mirror3(cov)
    return frame_from_covariance(cov, px, py, pz, frame, sensor, has_sensor, R, evals, evecs,
                                 closed_form)


@njit
def frame_from_covariance(cov, px, py, pz, frame, sensor, has_sensor, R, evals, evecs,
                          closed_form):
    """R (rows e1, e2, n) of the `auto` or `pca` frame of the point at (px, py, pz) from
    the weighted covariance `cov` (3 x 3, symmetric, both triangles) of its neighbours:
    the second half of :func:`_local_frame`, for kernels that form the covariance in
    their own pass over the neighbours. Returns False if the frame is degenerate."""
    if not (closed_form and eigh3_closed(cov, evals, evecs)):
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
def _null_direction(b00, b01, b02, b11, b12, b22, out, col):
    """Unit vector spanning the null space of the symmetric rank-2 matrix b (the largest
    cross product of two of its rows) into ``out[:, col]``; its squared norm before
    normalising is returned (0: none found)."""
    x0 = b01 * b12 - b02 * b11
    x1 = b02 * b01 - b00 * b12
    x2 = b00 * b11 - b01 * b01
    y0 = b01 * b22 - b02 * b12
    y1 = b02 * b02 - b00 * b22
    y2 = b00 * b12 - b01 * b02
    z0 = b11 * b22 - b12 * b12
    z1 = b12 * b02 - b01 * b22
    z2 = b01 * b12 - b11 * b02
    nx = x0 * x0 + x1 * x1 + x2 * x2
    ny = y0 * y0 + y1 * y1 + y2 * y2
    nz = z0 * z0 + z1 * z1 + z2 * z2
    if ny > nx and ny >= nz:
        x0, x1, x2, nx = y0, y1, y2, ny
    elif nz > nx:
        x0, x1, x2, nx = z0, z1, z2, nz
    if not nx > 0.0:
        return 0.0
    inv = 1.0 / math.sqrt(nx)
    out[0, col] = x0 * inv
    out[1, col] = x1 * inv
    out[2, col] = x2 * inv
    return nx


@njit
def eigh3_closed(a, evals, evecs):
    """Eigenpairs of the symmetric 3 x 3 `a` in closed form where they are well conditioned.

    The eigenvalues from the trigonometric solution of the characteristic cubic (ascending
    into `evals`); the eigenvectors of the smallest and the largest (columns 0 and 2 of
    `evecs`) from cross products of the rows of ``a - lambda I``, the largest one made
    orthogonal to the smallest, column 1 their cross product. Returns False, and leaves
    the work to the Jacobi solver, unless every eigenvalue gap exceeds
    :data:`CLOSED_FORM_GAP` times the largest eigenvalue (positive): collinear and
    isotropic neighbourhoods, and those whose tangent spread is nearly circular, go to
    ``eigh3``. `a` is not modified.
    """
    a00 = a[0, 0]
    a01 = a[0, 1]
    a02 = a[0, 2]
    a11 = a[1, 1]
    a12 = a[1, 2]
    a22 = a[2, 2]
    m = (a00 + a11 + a22) / 3.0
    k00 = a00 - m
    k11 = a11 - m
    k22 = a22 - m
    p2 = (k00 * k00 + k11 * k11 + k22 * k22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
    if not p2 > 0.0:
        return False
    p = math.sqrt(p2)
    det = (k00 * (k11 * k22 - a12 * a12) - a01 * (a01 * k22 - a12 * a02)
           + a02 * (a01 * a12 - k11 * a02))
    r = min(max(det / (2.0 * p2 * p), -1.0), 1.0)
    phi = math.acos(r) / 3.0
    l2 = m + 2.0 * p * math.cos(phi)
    l0 = m + 2.0 * p * math.cos(phi + _TWO_THIRDS_PI)
    l1 = 3.0 * m - l0 - l2
    gap = CLOSED_FORM_GAP * l2
    if not (gap > 0.0 and l1 - l0 > gap and l2 - l1 > gap):
        return False
    evals[0] = l0
    evals[1] = l1
    evals[2] = l2
    if _null_direction(a00 - l0, a01, a02, a11 - l0, a12, a22 - l0, evecs, 0) == 0.0:
        return False
    if _null_direction(a00 - l2, a01, a02, a11 - l2, a12, a22 - l2, evecs, 2) == 0.0:
        return False
    n0 = evecs[0, 0]
    n1 = evecs[1, 0]
    n2 = evecs[2, 0]
    d = evecs[0, 2] * n0 + evecs[1, 2] * n1 + evecs[2, 2] * n2
    e0 = evecs[0, 2] - d * n0
    e1 = evecs[1, 2] - d * n1
    e2 = evecs[2, 2] - d * n2
    inv = 1.0 / math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    e0 *= inv
    e1 *= inv
    e2 *= inv
    evecs[0, 2] = e0
    evecs[1, 2] = e1
    evecs[2, 2] = e2
    evecs[0, 1] = e1 * n2 - e2 * n1
    evecs[1, 1] = e2 * n0 - e0 * n2
    evecs[2, 1] = e0 * n1 - e1 * n0
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
