"""Numba kernel of the planar Delaunay triangulation: the sweep-hull insertion.

The points are inserted in the order of their distance from the circumcentre of a seed
triangle near the middle of the set (Sinclair's sweep-hull, as in the delaunator
library): each point then lies outside the hull of the points before it, so it is joined
to the hull edges it sees and the new triangles are made Delaunay by edge flips. The hull
is a doubly linked list of vertices in counter-clockwise order, found from a point through
a hash of its pseudo-angle about the centre.

Triangles are stored counter-clockwise as three vertex indices, with their half-edges:
half-edge ``3 t + k`` runs from vertex ``k`` to vertex ``k + 1`` (mod 3) of triangle
``t``, ``twin[h]`` is the opposite half-edge of the neighbouring triangle (-1 on the hull).
"""

from __future__ import annotations

import math

import numpy as np

from .._shared._jit import njit


@njit
def _cross(ax, ay, bx, by, cx, cy):  # pragma: no cover - compiled
    """Twice the signed area of (a, b, c): positive when counter-clockwise."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit
def _in_circle(ax, ay, bx, by, cx, cy, px, py):  # pragma: no cover - compiled
    """Positive when p lies inside the circumcircle of the counter-clockwise (a, b, c)."""
    adx, ady = ax - px, ay - py
    bdx, bdy = bx - px, by - py
    cdx, cdy = cx - px, cy - py
    ad = adx * adx + ady * ady
    bd = bdx * bdx + bdy * bdy
    cd = cdx * cdx + cdy * cdy
    return (ad * (bdx * cdy - cdx * bdy) - bd * (adx * cdy - cdx * ady)
            + cd * (adx * bdy - bdx * ady))


@njit
def _circum_radius2(ax, ay, bx, by, cx, cy):  # pragma: no cover - compiled
    """Squared circumradius of (a, b, c); inf when they are collinear."""
    dx, dy = bx - ax, by - ay
    ex, ey = cx - ax, cy - ay
    bl, cl = dx * dx + dy * dy, ex * ex + ey * ey
    d = dx * ey - dy * ex
    if d == 0.0:
        return np.inf
    x = (ey * bl - dy * cl) * 0.5 / d
    y = (dx * cl - ex * bl) * 0.5 / d
    return x * x + y * y


@njit
def _hash_key(x, y, cx, cy, size):  # pragma: no cover - compiled
    """Bucket of the pseudo-angle of (x, y) about (cx, cy): monotone in the angle."""
    dx, dy = x - cx, y - cy
    s = abs(dx) + abs(dy)
    p = dx / s if s > 0.0 else 0.0
    a = (3.0 - p) if dy > 0.0 else (1.0 + p)  # in [0, 4)
    return int(math.floor(a / 4.0 * size)) % size


@njit
def _link(twin, a, b):  # pragma: no cover - compiled
    twin[a] = b
    if b >= 0:
        twin[b] = a


@njit
def _add(tri, twin, n_half, i0, i1, i2, a, b, c):  # pragma: no cover - compiled
    t = n_half
    tri[t], tri[t + 1], tri[t + 2] = i0, i1, i2
    _link(twin, t, a)
    _link(twin, t + 1, b)
    _link(twin, t + 2, c)
    return t


@njit
def _legalize(x, y, tri, twin, hull_tri, stack, a):  # pragma: no cover - compiled
    """Flip the edges opposite the new point while they fail the empty-circle test,
    starting with half-edge `a`; keeps ``hull_tri`` on the hull edges that move.
    Returns the stack (grown when full)."""
    depth = 0
    while True:
        b = twin[a]
        a0 = a - a % 3
        ar = a0 + (a + 2) % 3
        flip = False
        if b >= 0:
            al = a0 + (a + 1) % 3
            b0 = b - b % 3
            bl = b0 + (b + 2) % 3
            p0, pr, pl, p1 = tri[ar], tri[a], tri[al], tri[bl]
            # p1 inside the circle of (pr, pl, p0), and the quad convex: the two new
            # triangles stay counter-clockwise whatever the rounding
            if (_in_circle(x[pr], y[pr], x[pl], y[pl], x[p0], y[p0], x[p1], y[p1]) > 0.0
                    and _cross(x[p1], y[p1], x[pl], y[pl], x[p0], y[p0]) > 0.0
                    and _cross(x[p0], y[p0], x[pr], y[pr], x[p1], y[p1]) > 0.0):
                flip = True
                tri[a] = p1
                tri[b] = p0
                hbl, har = twin[bl], twin[ar]
                _link(twin, a, hbl)  # p1 -> pl moves from bl to a
                _link(twin, b, har)  # p0 -> pr moves from ar to b
                _link(twin, ar, bl)  # the new diagonal
                if hbl < 0:
                    hull_tri[p1] = a
                if har < 0:
                    hull_tri[p0] = b
                if depth == stack.size:
                    grown = np.empty(2 * stack.size, np.int64)
                    grown[:depth] = stack
                    stack = grown
                stack[depth] = b0 + (b + 1) % 3
                depth += 1
        if not flip:
            if depth == 0:
                return stack
            depth -= 1
            a = stack[depth]


@njit
def delaunay_kernel(x, y):  # pragma: no cover - compiled
    """Delaunay triangles of the points (x, y) as an (M, 3) int64 array of
    counter-clockwise vertex indices; (0, 3) when they are collinear or fewer than
    three. Of points sharing a location, the first in the sweep's order is used."""
    n = x.size
    empty = np.empty((0, 3), np.int64)
    if n < 3:
        return empty
    xmin, ymin, xmax, ymax = x[0], y[0], x[0], y[0]
    for i in range(n):
        xmin, xmax = min(xmin, x[i]), max(xmax, x[i])
        ymin, ymax = min(ymin, y[i]), max(ymax, y[i])
    mx, my = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    # seed: the point nearest the middle, its nearest point, and the third point that
    # makes the smallest circumcircle with them
    i0, best = 0, np.inf
    for i in range(n):
        d = (x[i] - mx) ** 2 + (y[i] - my) ** 2
        if d < best:
            i0, best = i, d
    i1, best = -1, np.inf
    for i in range(n):
        d = (x[i] - x[i0]) ** 2 + (y[i] - y[i0]) ** 2
        if i != i0 and 0.0 < d < best:
            i1, best = i, d
    if i1 < 0:
        return empty
    i2, best = -1, np.inf
    for i in range(n):
        if i == i0 or i == i1:
            continue
        r = _circum_radius2(x[i0], y[i0], x[i1], y[i1], x[i], y[i])
        if r < best:
            i2, best = i, r
    if i2 < 0:
        return empty
    if _cross(x[i0], y[i0], x[i1], y[i1], x[i2], y[i2]) < 0.0:
        i1, i2 = i2, i1
    # the sweep's centre: the seed triangle's circumcentre
    dx, dy = x[i1] - x[i0], y[i1] - y[i0]
    ex, ey = x[i2] - x[i0], y[i2] - y[i0]
    bl, cl = dx * dx + dy * dy, ex * ex + ey * ey
    d = dx * ey - dy * ex
    cx = x[i0] + (ey * bl - dy * cl) * 0.5 / d
    cy = y[i0] + (dx * cl - ex * bl) * 0.5 / d
    dist = np.empty(n)
    for i in range(n):
        dist[i] = (x[i] - cx) ** 2 + (y[i] - cy) ** 2
    order = np.argsort(dist)
    # the sweep reads the points in its order: their coordinates copied in that order
    # keep the reads of hull neighbours close in memory
    xs, ys = np.empty(n), np.empty(n)
    rank = np.empty(n, np.int64)
    for k in range(n):
        xs[k], ys[k] = x[order[k]], y[order[k]]
        rank[order[k]] = k
    tri = _sweep(xs, ys, rank[i0], rank[i1], rank[i2], cx, cy)
    for h in range(tri.size):
        tri[h] = order[tri[h]]
    return tri.reshape(tri.size // 3, 3)


@njit
def _sweep(x, y, i0, i1, i2, cx, cy):  # pragma: no cover - compiled
    """The half-edges' vertices (3 per triangle) of the points inserted in index order,
    the seed triangle (i0, i1, i2) counter-clockwise about (cx, cy)."""
    n = x.size

    max_half = 3 * max(2 * n - 5, 1)
    tri = np.empty(max_half, np.int64)
    twin = np.empty(max_half, np.int64)
    hull_prev = np.empty(n, np.int64)
    hull_next = np.empty(n, np.int64)
    hull_tri = np.empty(n, np.int64)
    size = max(int(math.ceil(math.sqrt(n))), 1)
    hull_hash = np.full(size, -1, np.int64)
    stack = np.empty(1024, np.int64)

    hull_next[i0], hull_prev[i1] = i1, i0
    hull_next[i1], hull_prev[i2] = i2, i1
    hull_next[i2], hull_prev[i0] = i0, i2
    hull_tri[i0], hull_tri[i1], hull_tri[i2] = 0, 1, 2
    hull_hash[_hash_key(x[i0], y[i0], cx, cy, size)] = i0
    hull_hash[_hash_key(x[i1], y[i1], cx, cy, size)] = i1
    hull_hash[_hash_key(x[i2], y[i2], cx, cy, size)] = i2
    n_half = 3 + _add(tri, twin, 0, i0, i1, i2, -1, -1, -1)

    for i in range(n):
        if i == i0 or i == i1 or i == i2:
            continue
        px, py = x[i], y[i]
        # a hull vertex near p's angle, then the first hull edge p sees from there
        key = _hash_key(px, py, cx, cy, size)
        start = -1
        for j in range(size):
            s = hull_hash[(key + j) % size]
            if s >= 0 and hull_next[s] != s:
                start = s
                break
        start = hull_prev[start]
        e = start
        while _cross(x[e], y[e], x[hull_next[e]], y[hull_next[e]], px, py) >= 0.0:
            e = hull_next[e]
            if e == start:
                e = -1
                break
        if e < 0:  # sees no edge: a copy of a hull vertex
            continue
        q = hull_next[e]
        t = _add(tri, twin, n_half, e, i, q, -1, -1, hull_tri[e])
        n_half += 3
        hull_tri[e], hull_tri[i] = t, t + 1
        stack = _legalize(x, y, tri, twin, hull_tri, stack, t + 2)
        # the edges p sees after e, then before it
        nxt = q
        while True:
            q = hull_next[nxt]
            if _cross(x[nxt], y[nxt], x[q], y[q], px, py) >= 0.0:
                break
            t = _add(tri, twin, n_half, nxt, i, q, hull_tri[i], -1, hull_tri[nxt])
            n_half += 3
            hull_tri[i] = t + 1
            stack = _legalize(x, y, tri, twin, hull_tri, stack, t + 2)
            hull_next[nxt] = nxt  # off the hull
            nxt = q
        while True:
            q = hull_prev[e]
            if _cross(x[q], y[q], x[e], y[e], px, py) >= 0.0:
                break
            t = _add(tri, twin, n_half, q, i, e, -1, hull_tri[e], hull_tri[q])
            n_half += 3
            hull_tri[q] = t
            stack = _legalize(x, y, tri, twin, hull_tri, stack, t + 2)
            hull_next[e] = e
            e = q
        hull_prev[i], hull_next[i] = e, nxt
        hull_next[e], hull_prev[nxt] = i, i
        hull_hash[key] = i
        hull_hash[_hash_key(x[e], y[e], cx, cy, size)] = e
    return tri[:n_half]
