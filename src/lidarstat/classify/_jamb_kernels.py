"""Numba kernels of the jamb rule of the ``'grid'`` boundary test (:mod:`._grid_boundary`):
a border edge that a visible face narrower than the grid explains is not a border."""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from .._shared._kernels import eigh3 as _eigh3

#: Grid hops of the near surface's plane fit behind a jump (the jamb rule).
JAMB_HOPS = 3

#: A perpendicular connecting face whose image would span at most this many grid steps
#: can lie between two rays without a sample (the jamb rule: 1 = whenever it could).
JAMB_REACH = 1.0


@njit
def _grid_plane(pts, adj, cut, node, stamp, hops, tol, buf, mark):
    """Normal of the plane through the grid nodes within `hops` grid edges of `node` that
    are reached without crossing a cut edge, refitted once without the nodes farther than
    `tol` from the first plane; (0, 0, 0) with fewer than 6 nodes. ``mark`` holds the
    visit `stamp` (unique per call)."""
    buf[0] = node
    mark[node] = stamp
    head = 0
    tail = 1
    level_end = 1
    level = 0
    while head < tail and level < hops:
        while head < level_end:
            a = buf[head]
            head += 1
            for k in range(adj.shape[1]):
                b = adj[a, k]
                if b < 0 or cut[a, k] or mark[b] == stamp or tail >= buf.size:
                    continue
                mark[b] = stamp
                buf[tail] = b
                tail += 1
        level_end = tail
        level += 1
    cov = np.empty((3, 3))
    evals = np.empty(3)
    evecs = np.empty((3, 3))
    nx = 0.0
    ny = 0.0
    nz = 0.0
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for rnd in range(2):
        m = 0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for t in range(tail):
            j = buf[t]
            if rnd == 1 and abs((pts[j, 0] - cx) * nx + (pts[j, 1] - cy) * ny
                                + (pts[j, 2] - cz) * nz) > tol:
                continue
            sx += pts[j, 0]
            sy += pts[j, 1]
            sz += pts[j, 2]
            m += 1
        if m < 6:
            return 0.0, 0.0, 0.0
        cx = sx / m
        cy = sy / m
        cz = sz / m
        for u in range(3):
            for v in range(3):
                cov[u, v] = 0.0
        for t in range(tail):
            j = buf[t]
            dx = pts[j, 0] - cx
            dy = pts[j, 1] - cy
            dz = pts[j, 2] - cz
            if rnd == 1 and abs(dx * nx + dy * ny + dz * nz) > tol:
                continue
            cov[0, 0] += dx * dx
            cov[0, 1] += dx * dy
            cov[0, 2] += dx * dz
            cov[1, 1] += dy * dy
            cov[1, 2] += dy * dz
            cov[2, 2] += dz * dz
        cov[1, 0] = cov[0, 1]
        cov[2, 0] = cov[0, 2]
        cov[2, 1] = cov[1, 2]
        _eigh3(cov, evals, evecs)
        nx = evecs[0, 0]
        ny = evecs[1, 0]
        nz = evecs[2, 0]
    return nx, ny, nz


@njit_parallel
def visible_jambs(pts, sensor, dirs, rng, adj, cut, edges, sig_r, hops, reach, nchunk, out):
    """The jamb rule: which border edges a visible face narrower than the grid explains.

    For a border edge (a, b) let N be the nearer node and F the farther. The near surface's
    plane is fitted to the grid nodes within `hops` uncut grid edges of N (normal n toward
    the sensor; the kNN normal beside a recess is tilted by the recess back). A face
    perpendicular to it that runs from N's edge back to F's depth (a jamb, a sill, a
    lintel) ends at ``q = N - depth n``. It faces the scanner when q's image lies from N
    toward F (``proj > 0``, in grid steps along N -> F) and fits between the two rays
    without a sample when ``proj <= reach``: then the step is two creases around a visible
    face the grid did not sample, not a border, and ``out[a, k]`` is True.
    `rng` is every node's range (the nearer node of an edge is N); `sig_r` the range noise
    per point (the refit's tolerance is three of it).
    """
    n = adj.shape[0]
    for c in prange(nchunk):
        mark = np.full(n, -1, dtype=np.int64)
        buf = np.empty((2 * hops + 1) * (2 * hops + 1) + 8, dtype=np.int64)
        for a in range(c, n, nchunk):
            for k in range(adj.shape[1]):
                out[a, k] = False
                b = adj[a, k]
                if b < 0 or not edges[a, k]:
                    continue
                near = a if rng[a] <= rng[b] else b
                far = b if rng[a] <= rng[b] else a
                nx, ny, nz = _grid_plane(pts, adj, cut, near, a * adj.shape[1] + k, hops,
                                         3.0 * sig_r[near], buf, mark)
                if nx == 0.0 and ny == 0.0 and nz == 0.0:
                    continue
                if (nx * (sensor[0] - pts[near, 0]) + ny * (sensor[1] - pts[near, 1])
                        + nz * (sensor[2] - pts[near, 2])) < 0:
                    nx, ny, nz = -nx, -ny, -nz
                depth = -((pts[far, 0] - pts[near, 0]) * nx + (pts[far, 1] - pts[near, 1]) * ny
                          + (pts[far, 2] - pts[near, 2]) * nz)
                if not depth > 0:
                    continue
                qx = pts[near, 0] - depth * nx - sensor[0]
                qy = pts[near, 1] - depth * ny - sensor[1]
                qz = pts[near, 2] - depth * nz - sensor[2]
                qn = math.sqrt(qx * qx + qy * qy + qz * qz)
                # the image direction across the step: the mean offset of N's grid
                # neighbours beyond it (perpendicular to the step's image for a straight
                # step, whichever grid edge crosses it)
                ex = 0.0
                ey = 0.0
                ez = 0.0
                mc = 0
                for i in range(adj.shape[1]):
                    x = adj[near, i]
                    if x < 0 or not cut[near, i]:
                        continue
                    ex += dirs[x, 0] - dirs[near, 0]
                    ey += dirs[x, 1] - dirs[near, 1]
                    ez += dirs[x, 2] - dirs[near, 2]
                    mc += 1
                if mc == 0:
                    continue
                ex /= mc
                ey /= mc
                ez /= mc
                ee = ex * ex + ey * ey + ez * ez
                if not (qn > 0 and ee > 0):
                    continue
                proj = ((qx / qn - dirs[near, 0]) * ex + (qy / qn - dirs[near, 1]) * ey
                        + (qz / qn - dirs[near, 2]) * ez) / ee
                out[a, k] = 0.0 < proj <= reach
