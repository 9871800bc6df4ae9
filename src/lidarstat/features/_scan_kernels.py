"""Centroid statistic of a terrestrial scan's neighbourhoods on its angular grid.

A terrestrial scanner samples the directions of a regular (azimuth, elevation) grid, and
its range noise moves a point along its own ray only: the *directions* of the points are
the grid's nodes, exactly. Seen in Euclidean coordinates the same neighbourhood is far
from a uniform disc - on grazing ground the scan lines are arcs tens of centimetres apart
while the points on a line are a few centimetres apart, and the density falls with the
range across the neighbourhood - which moves the neighbourhood centroid off the index
point where there is no border (the paper's eq. 6-8 test then finds false boundaries).

Per point i, with sensor ``s``, unit ray ``d_i`` and range ``R_i``, each neighbour j is
mapped to *linearised scan coordinates* on the plane of the index point (normal ``n_i``):

    x_j = R_i (dd_j - d_i (n_i . dd_j) / (n_i . d_i)),
    dd_j = (az_j - az_i) dd/daz + (el_j - el_i) dd/del      (at the index point's ray)

(the first-order image of the angular offset on the tangent plane; ``|n_i . d_i|`` is
floored at 0.05). The angular offsets are differences of each point's azimuth and
elevation, not of its unit vector: the second-order terms of ``d_j - d_i`` are even in
the offset and would bend the scan lines into the arcs they are on the ground (a grazing
row bows toward the scanner by ``x^2 / 2r`` across a neighbourhood, which alone moves the
centroid off the index point). In these coordinates the scan lines are straight and
equally spaced and
the mirror image ``-x_j`` of a grid node is a grid node, at exactly the same distance.
Distances ``L_j = |x_j|`` differ from the 3-D distances ``D_j`` by the local density
gradient; with ``g = max_j D_j / L_j`` (over ``D_j > 0.2 r``, r the farthest neighbour)
every surface point with ``L < rho = r / g`` has ``D < r`` and therefore *is* in the
neighbourhood. The points with ``L < rho`` (the *complete disc*) are thus, for a point
away from every border, a centrally symmetric set of nodes - their centroid is the index
point - whatever the scan pattern; where the visible surface ends inside the disc the
nodes beyond it are missing and the centroid moves away from the border.

Output per point: Hotelling's ``T2 = m c' S^-1 c`` of the complete disc's centroid c
(m points, S their covariance) against the index point, m, ``rho / r`` and the reach r
(the farthest neighbour, the scale of the ``'grid'`` boundary test of
:mod:`lidarstat.classify._grid_boundary`).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._geometry import scan_angles  # noqa: F401 (used by features._covariance)
from .._shared._jit import njit_parallel

#: Columns of :func:`scan_centroid_rows`'s output.
S_T2 = 0
S_M = 1
S_RHO = 2
S_REACH = 3
NSCAN = 4
_MIN_COS = 0.05


@njit_parallel
def scan_centroid_rows(pts, angles, rowpoint, indptr, idx, normals, major, sensor, out):
    """Complete-disc centroid statistic of every CSR row (module doc).

    Row r lists the neighbours (indices into `pts`, the point itself allowed) of point
    ``rowpoint[r]``; ``angles[j]`` is (azimuth, elevation) of point j seen from `sensor`;
    ``normals[r]``, ``major[r]`` are that point's normal and largest
    eigenvector. `pts` and `sensor` share one (local) origin. ``out`` is (M, NSCAN):
    T2, m, rho / r and r; T2 is NaN where m < 4 or the disc is degenerate.
    """
    nrow = indptr.size - 1
    for r in prange(nrow):
        i = rowpoint[r]
        s, e = indptr[r], indptr[r + 1]
        out[r, S_T2] = np.nan
        out[r, S_M] = 0.0
        out[r, S_RHO] = np.nan
        out[r, S_REACH] = np.nan
        px = pts[i, 0] - sensor[0]
        py = pts[i, 1] - sensor[1]
        pz = pts[i, 2] - sensor[2]
        ri = np.sqrt(px * px + py * py + pz * pz)
        if not (ri > 0) or e - s < 5:
            continue
        d0, d1, d2 = px / ri, py / ri, pz / ri
        azi = angles[i, 0]
        eli = angles[i, 1]
        ce, se = np.cos(eli), np.sin(eli)
        ca, sa = np.cos(azi), np.sin(azi)
        # derivatives of the unit ray with respect to azimuth and elevation
        za0, za1 = -ce * sa, ce * ca
        ze0, ze1, ze2 = -se * ca, -se * sa, ce
        n0, n1, n2 = normals[r, 0], normals[r, 1], normals[r, 2]
        a0, a1, a2 = major[r, 0], major[r, 1], major[r, 2]
        b0, b1, b2 = n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0
        nd = n0 * d0 + n1 * d1 + n2 * d2
        if abs(nd) < _MIN_COS:
            nd = _MIN_COS if nd >= 0 else -_MIN_COS
        m = e - s
        u = np.empty(m)
        v = np.empty(m)
        ll = np.empty(m)
        dd = np.empty(m)
        reach = 0.0
        for t in range(m):
            j = idx[s + t]
            da = angles[j, 0] - azi
            if da > np.pi:
                da -= 2.0 * np.pi
            elif da < -np.pi:
                da += 2.0 * np.pi
            de = angles[j, 1] - eli
            e0 = da * za0 + de * ze0
            e1 = da * za1 + de * ze1
            e2 = de * ze2
            k = (n0 * e0 + n1 * e1 + n2 * e2) / nd
            x0 = ri * (e0 - d0 * k)
            x1 = ri * (e1 - d1 * k)
            x2 = ri * (e2 - d2 * k)
            u[t] = x0 * a0 + x1 * a1 + x2 * a2
            v[t] = x0 * b0 + x1 * b1 + x2 * b2
            ll[t] = np.sqrt(u[t] * u[t] + v[t] * v[t])
            f0 = pts[j, 0] - pts[i, 0]
            f1 = pts[j, 1] - pts[i, 1]
            f2 = pts[j, 2] - pts[i, 2]
            dd[t] = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            if j == i:
                dd[t] = 0.0
                ll[t] = 0.0
            reach = max(reach, dd[t])
        out[r, S_REACH] = reach
        if not reach > 0:
            continue
        g = 1.0
        for t in range(m):
            if dd[t] > 0.2 * reach and ll[t] > 0:
                g = max(g, dd[t] / ll[t])
        rho = reach / g * (1.0 - 1e-7)  # mirror nodes tie in L: keep the pair together
        cu = 0.0
        cv = 0.0
        mi = 0
        for t in range(m):
            if ll[t] > 0 and ll[t] < rho:
                cu += u[t]
                cv += v[t]
                mi += 1
        out[r, S_M] = mi
        out[r, S_RHO] = rho / reach
        if mi < 4:
            continue
        cu /= mi
        cv /= mi
        suu = 0.0
        suv = 0.0
        svv = 0.0
        for t in range(m):
            if ll[t] > 0 and ll[t] < rho:
                x = u[t] - cu
                y = v[t] - cv
                suu += x * x
                suv += x * y
                svv += y * y
        det = suu * svv - suv * suv
        if not det > 1e-12 * (suu + svv) * (suu + svv):
            continue
        # T2 = m c' S^-1 c with S = sums / (m - 1)
        out[r, S_T2] = mi * (mi - 1) * (cu * cu * svv - 2.0 * cu * cv * suv
                                        + cv * cv * suu) / det
