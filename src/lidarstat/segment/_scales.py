"""Scale-adaptive planar neighbourhoods for region growing (seed 003, segmentation).

A face narrower than the k = 50 neighbourhood (a fascia, a soffit, a gable strip seen at
grazing incidence) has no point whose 50 nearest neighbours lie on it alone, so every
one of its points is an edge at that scale and region growing on k = 50 surface points
cannot find it. Here every point gets the *largest* prefix of its distance-sorted
neighbour row, among ``m = 8, 12, 16, 20, 30, 40, 50`` (up to the row length), that
passes the plane test of the classification at that size:

    T_m = (m - 1) lambda0(m) / sigma_i^2  ~  chi2(m - 3)

with sigma_i the noise across the plane of that prefix (``sigma_r(r_i) |cos theta_m|``
with a sensor, theta_m between the ray and the prefix's own normal; else sigma). The
selected size ``scale_k`` (0 when even the 8 nearest are not a plane) and the p-value of
its test, ``scale_plane_p``, are written beside the segment ids. Region growing then
joins a point to the points of its selected prefix: a link is always backed by a plane
test that accepted the neighbourhood containing both points. Choosing the largest
accepted size is a scale selection by testing (the neighbourhood grows while it stays a
plane), the statistical counterpart of Weinmann et al.'s (2015) minimum-eigenentropy
choice of k, which has no noise model and so no notion of "still a plane".
"""

from __future__ import annotations

import numba
import numpy as np

from .._shared._jit import kernel_array, njit_parallel
from .._shared._kernels import eigh3 as _eigh3
from ..stats import chi2_critical, chi2_test

_CHUNK = 256  # points per parallel task (scratch arrays allocated once per task)

#: Candidate neighbourhood sizes (the smallest has 5 degrees of freedom).
SCALES = (8, 12, 16, 20, 30, 40, 50)


@njit_parallel
def _prefix_planes(visit, pts, indptr, idx, sizes, crit, sig, sensor, has_sensor, kstar,
                   stat, normal):
    """Rows visited in the order `visit` (a permutation; each row is independent)."""
    n = indptr.size - 1
    ns = sizes.size
    nch = (n + _CHUNK - 1) // _CHUNK
    for ch in numba.prange(nch):
        a = np.empty((3, 3))
        ev = np.empty(3)
        evec = np.empty((3, 3))
        mom = np.empty((ns, 9))
        for ii in range(ch * _CHUNK, min(n, (ch + 1) * _CHUNK)):
            i = visit[ii]
            s = indptr[i]
            cnt = indptr[i + 1] - s
            kstar[i] = 0
            stat[i] = np.nan
            normal[i, 0] = np.nan
            normal[i, 1] = np.nan
            normal[i, 2] = np.nan
            sx = 0.0
            sy = 0.0
            sz = 0.0
            sxx = 0.0
            sxy = 0.0
            sxz = 0.0
            syy = 0.0
            syz = 0.0
            szz = 0.0
            ox, oy, oz = pts[i, 0], pts[i, 1], pts[i, 2]
            c = 0
            rx, ry, rz = 0.0, 0.0, 1.0
            if has_sensor:
                rx, ry, rz = ox - sensor[0], oy - sensor[1], oz - sensor[2]
                rn = np.sqrt(rx * rx + ry * ry + rz * rz)
                if rn > 0:
                    rx, ry, rz = rx / rn, ry / rn, rz / rn
            # moment sums of every prefix size first (same order of additions as one pass),
            # then the tests from the largest size down: the first that passes is the answer
            # (most points are planes at the largest size: one eigen-decomposition, not seven)
            top = 0
            for q in range(ns):
                m = sizes[q]
                if m > cnt:
                    break
                while c < m:
                    j = idx[s + c]
                    x, y, z = pts[j, 0] - ox, pts[j, 1] - oy, pts[j, 2] - oz
                    sx += x
                    sy += y
                    sz += z
                    sxx += x * x
                    sxy += x * y
                    sxz += x * z
                    syy += y * y
                    syz += y * z
                    szz += z * z
                    c += 1
                mom[q, 0] = sx
                mom[q, 1] = sy
                mom[q, 2] = sz
                mom[q, 3] = sxx
                mom[q, 4] = sxy
                mom[q, 5] = sxz
                mom[q, 6] = syy
                mom[q, 7] = syz
                mom[q, 8] = szz
                top = q + 1
            for q in range(top - 1, -1, -1):
                m = sizes[q]
                sx, sy, sz = mom[q, 0], mom[q, 1], mom[q, 2]
                sxx, sxy, sxz = mom[q, 3], mom[q, 4], mom[q, 5]
                syy, syz, szz = mom[q, 6], mom[q, 7], mom[q, 8]
                mx, my, mz = sx / m, sy / m, sz / m
                a[0, 0] = (sxx - m * mx * mx) / (m - 1)
                a[0, 1] = (sxy - m * mx * my) / (m - 1)
                a[0, 2] = (sxz - m * mx * mz) / (m - 1)
                a[1, 1] = (syy - m * my * my) / (m - 1)
                a[1, 2] = (syz - m * my * mz) / (m - 1)
                a[2, 2] = (szz - m * mz * mz) / (m - 1)
                a[1, 0] = a[0, 1]
                a[2, 0] = a[0, 2]
                a[2, 1] = a[1, 2]
                _eigh3(a, ev, evec)
                across = sig[i]
                if has_sensor:
                    across *= abs(rx * evec[0, 0] + ry * evec[1, 0] + rz * evec[2, 0])
                if not across > 0:
                    continue
                t = (m - 1) * max(ev[0], 0.0) / (across * across)
                if t <= crit[q]:
                    kstar[i] = m
                    stat[i] = t
                    normal[i, 0] = evec[0, 0]
                    normal[i, 1] = evec[1, 0]
                    normal[i, 2] = evec[2, 0]
                    break


def planar_scales(points, nbh, sigma, *, sensor=None, alpha=0.05, scales=SCALES):
    """Largest distance-sorted prefix of each row that passes the plane test.

    Parameters
    ----------
    points : (N, 3) ndarray
    nbh : Neighborhoods
        kNN rows sorted by distance (the point itself first).
    sigma : float or (N,) array_like
        Noise std per point: along the rays with a `sensor`, else across the surface.
    sensor : (3,) array_like, optional
    alpha : float
        Level of each plane test.
    scales : sequence of int
        Candidate prefix sizes (increasing, >= 4).

    Returns
    -------
    scale_k : (N,) ndarray of int32
        Selected size (0: no prefix is a plane).
    scale_plane_p : (N,) ndarray
        p-value of the plane test at that size (NaN where 0).
    normal : (N, 3) ndarray
        Unit normal of the selected prefix (NaN where 0; sign arbitrary).
    """
    pts = np.asarray(points, dtype=np.float64)
    origin = pts.mean(axis=0)
    local = np.ascontiguousarray(pts - origin)
    sizes = np.asarray(sorted(int(m) for m in scales), dtype=np.int64)
    crit = np.asarray(chi2_critical(alpha, sizes - 3.0), dtype=np.float64)  # chi2(m - 3)
    n = pts.shape[0]
    sig = kernel_array(np.broadcast_to(np.asarray(sigma, dtype=np.float64), (n,)))
    sens = (np.asarray(sensor, dtype=np.float64) - origin) if sensor is not None \
        else np.zeros(3)
    kstar = np.empty(n, dtype=np.int32)
    stat = np.empty(n)
    normal = np.empty((n, 3))
    _prefix_planes(nbh.visit_order(), local, np.ascontiguousarray(nbh.indptr, dtype=np.int64),
                   np.ascontiguousarray(nbh.indices), sizes, crit, sig, sens,
                   sensor is not None, kstar, stat, normal)
    with np.errstate(invalid="ignore"):
        p = np.where(kstar > 0, chi2_test(stat, np.maximum(kstar - 3.0, 1.0), alpha=alpha).pvalue,
                     np.nan)
    return kstar, p, normal


def prefix_edges(nbh, kstar):
    """CSR entries within the first ``kstar[i]`` neighbours of each row i."""
    from ._edge_kernels import prefix_lengths

    out = np.empty(nbh.nnz, dtype=bool)
    prefix_lengths(nbh.indptr, np.ascontiguousarray(kstar, dtype=np.int64), out)
    return out
