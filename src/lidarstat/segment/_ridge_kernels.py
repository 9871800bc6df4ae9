"""Numba kernels of ridge detection (zero crossings of the extremalities) and tracing.

Per point the Monge form gives, for each principal curvature k_a with direction d_a, the
extremality e_a (b0 for k1 along d1, b3 for k2 along d2: the derivative of k_a along its
own line) and the second derivative of k_a along that line (Cazals and Pouget 2005):

    k1'' = c0 - 3 k1^3 + 3 b1^2 / (k1 - k2)      (P1 / (k1 - k2))
    k2'' = c4 - 3 k2^3 - 3 b2^2 / (k1 - k2)      (P2 / (k2 - k1))

A crest (``ridge`` 1) is a ridge of the convex curvature k2 < 0 where |k2| is maximal
across the line (k2 minimal: e2 crosses zero from - to + along d2, k2'' > 0); a ravine
(2) a ridge of the concave k1 > 0 where k1 is maximal (e1 from + to -, k1'' < 0). The
normal points up or to the sensor, so convex means negative curvature.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

CREST = 1
RAVINE = 2

# per-point candidate columns: k, e (extremality), kpp (k''), kpp_sd, dir (3), tan (3), e_sd
# candidate = the dominant curvature is significant, dominant and of the right sign


@njit_parallel
def candidates(monge, sd, frames, ok, ratio, z, ctype, cval):
    """Which ridge each point may lie on, and the quantities the crossing test needs.

    ctype[i]: 0 none, CREST, RAVINE. cval[i]: k, e, k'', sd(k''), direction (3),
    tangent of the ridge (3) (the other principal direction), sd(e), sd(k).
    """
    n = monge.shape[0]
    for i in prange(n):
        ctype[i] = 0
        for t in range(cval.shape[1]):
            cval[i, t] = np.nan
        if not ok[i]:
            continue
        k1 = monge[i, 0]
        k2 = monge[i, 1]
        gap = k1 - k2
        if not gap > 0.0:
            continue
        if -k2 > ratio * abs(k1) and -k2 > z * sd[i, 1]:
            ctype[i] = CREST  # k2 dominant: b2, b3, c4 (Monge columns 4, 5, 10)
            _store_candidate(cval, i, monge, sd, frames, gap, 1, 5, 10, 4, -1.0, 1, 0)
        elif k1 > ratio * abs(k2) and k1 > z * sd[i, 0]:
            ctype[i] = RAVINE  # k1 dominant: b1, b0, c0 (Monge columns 3, 2, 6)
            _store_candidate(cval, i, monge, sd, frames, gap, 0, 2, 6, 3, 1.0, 0, 1)


@njit
def _store_candidate(cval, i, monge, sd, frames, gap, kc, ec, kppc, bc, sgn, dr, tr):
    """Row i of `cval` for a candidate of the dominant curvature ``k = monge[i, kc]``: its
    extremality (column `ec`), ``k'' = monge[i, kppc] - 3 k^3 + sgn 3 monge[i, bc]^2 /
    gap``, their standard deviations, the direction (frame row `dr`) and the ridge's
    tangent (frame row `tr`)."""
    k = monge[i, kc]
    cval[i, 0] = k
    cval[i, 1] = monge[i, ec]
    cval[i, 2] = monge[i, kppc] - 3.0 * k * k * k + sgn * (3.0 * monge[i, bc] ** 2 / gap)
    cval[i, 3] = sd[i, kppc]
    cval[i, 10] = sd[i, ec]
    cval[i, 11] = sd[i, kc]
    for c in range(3):
        cval[i, 4 + c] = frames[i, dr, c]
        cval[i, 7 + c] = frames[i, tr, c]


@njit_parallel
def crossings(pts, indptr, idx, ctype, cval, z4, cos_max, ridge, where, count):
    """Zero crossings of the extremality between neighbours, along the principal direction.

    For each candidate i and candidate neighbour q of the same type: orient q's direction
    like i's (the extremality flips with it), require the offset to run mostly along the
    direction (|cos| >= cos_max), opposite signs in the sense of an extremum of the right
    kind (crest: e goes from - to + along the direction; ravine: + to -), and the mean
    k'' of the two of the right sign and significant (one-sided z4). Point i is marked
    when it is the nearer end of a crossing; ``where`` accumulates the interpolated
    crossing positions (their mean is the ridge vertex), ``count`` their number.
    """
    n = ctype.size
    for i in prange(n):
        ridge[i] = 0
        count[i] = 0
        for c in range(3):
            where[i, c] = 0.0
        t = ctype[i]
        if t == 0:
            continue
        ei = cval[i, 1]
        for s in range(indptr[i], indptr[i + 1]):
            q = idx[s]
            if q == i or ctype[q] != t:
                continue
            dot = 0.0
            for c in range(3):
                dot += cval[i, 4 + c] * cval[q, 4 + c]
            sgn = 1.0 if dot >= 0.0 else -1.0
            eq = sgn * cval[q, 1]
            # offset along the direction of i
            dx = pts[q, 0] - pts[i, 0]
            dy = pts[q, 1] - pts[i, 1]
            dz = pts[q, 2] - pts[i, 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if not dist > 0.0:
                continue
            along = dx * cval[i, 4] + dy * cval[i, 5] + dz * cval[i, 6]
            if abs(along) < cos_max * dist:
                continue
            # values at the back (b) and front (f) end along the direction
            if along > 0:
                eb = ei
                ef = eq
            else:
                eb = eq
                ef = ei
            if t == CREST:
                if not (eb < 0.0 and ef > 0.0):
                    continue
            else:
                if not (eb > 0.0 and ef < 0.0):
                    continue
            kpp = 0.5 * (cval[i, 2] + cval[q, 2])
            sdk = 0.5 * (cval[i, 3] + cval[q, 3])
            if t == CREST:
                if not kpp > z4 * sdk:
                    continue
            else:
                if not -kpp > z4 * sdk:
                    continue
            if abs(ei) > abs(eq):
                continue  # the other end is nearer to the crossing
            f = ei / (ei - eq)
            ridge[i] = t
            where[i, 0] += pts[i, 0] + f * dx
            where[i, 1] += pts[i, 1] + f * dy
            where[i, 2] += pts[i, 2] + f * dz
            count[i] += 1
        if count[i] > 0:
            for c in range(3):
                where[i, c] /= count[i]


@njit
def trace(indptr, idx, ridge, vert, tangent, step, cos_min, order, line_of,
          out_pts, out_start):
    """Chain ridge points into polylines (sequential, deterministic).

    From each unvisited ridge point in `order`, walk both ways along the ridge tangent:
    the next vertex is the unvisited neighbour of the same type whose offset from the
    current vertex runs forward within the cone cos_min and is the farthest forward
    within `step`; every same-type neighbour within `step` of the current vertex and not
    behind it is absorbed into the line (the band of the ridge). Returns the number of lines; vertex
    point ids in ``out_pts[out_start[l]:out_start[l + 1]]``; ``line_of`` per point (0 none).
    """
    n = ridge.size
    nv = 0
    nl = 0
    back = np.empty(n, dtype=np.int64)
    for oi in range(order.size):
        seed = order[oi]
        if ridge[seed] == 0 or line_of[seed] != 0:
            continue
        nl += 1
        line_of[seed] = nl
        t = ridge[seed]
        nb = 0
        nf_start = -1
        for direction in range(2):
            cur = seed
            sg = 1.0 if direction == 0 else -1.0
            tx = sg * tangent[seed, 0]
            ty = sg * tangent[seed, 1]
            tz = sg * tangent[seed, 2]
            if direction == 0:
                out_start[nl - 1] = nv
                # forward vertices are written after the backward ones: store later
                nf_start = nv
            while True:
                best = -1
                best_p = 0.0
                for s in range(indptr[cur], indptr[cur + 1]):
                    q = idx[s]
                    if ridge[q] != t or (line_of[q] != 0 and line_of[q] != nl) or q == cur:
                        continue
                    dx = vert[q, 0] - vert[cur, 0]
                    dy = vert[q, 1] - vert[cur, 1]
                    dz = vert[q, 2] - vert[cur, 2]
                    d = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if d > step or not d > 0.0:
                        continue
                    p = dx * tx + dy * ty + dz * tz
                    if line_of[q] == 0 and p >= cos_min * d and p > best_p:
                        best_p = p
                        best = q
                # absorb the band around the current vertex
                for s in range(indptr[cur], indptr[cur + 1]):
                    q = idx[s]
                    if ridge[q] == t and line_of[q] == 0 and q != best:
                        dx = vert[q, 0] - vert[cur, 0]
                        dy = vert[q, 1] - vert[cur, 1]
                        dz = vert[q, 2] - vert[cur, 2]
                        if (dx * dx + dy * dy + dz * dz <= step * step
                                and dx * tx + dy * ty + dz * tz >= 0.0):
                            line_of[q] = nl
                if best < 0:
                    break
                line_of[best] = nl
                # orient the next tangent like the current walking direction
                ux = tangent[best, 0]
                uy = tangent[best, 1]
                uz = tangent[best, 2]
                if ux * tx + uy * ty + uz * tz < 0.0:
                    ux = -ux
                    uy = -uy
                    uz = -uz
                tx = ux
                ty = uy
                tz = uz
                cur = best
                if direction == 0:
                    out_pts[nv] = best
                    nv += 1
                else:
                    back[nb] = best
                    nb += 1
        # assemble: reversed backward walk, seed, forward walk
        nfw = nv - nf_start
        for a in range(nfw - 1, -1, -1):
            out_pts[nf_start + nb + 1 + a] = out_pts[nf_start + a]
        for a in range(nb):
            out_pts[nf_start + a] = back[nb - 1 - a]
        out_pts[nf_start + nb] = seed
        nv = nf_start + nb + 1 + nfw
        out_start[nl] = nv
    return nl


@njit_parallel
def band_edges(indptr, idx, band, ok):
    """Edges usable by region growing: both ends outside the ridge band."""
    n = indptr.size - 1
    for i in prange(n):
        for s in range(indptr[i], indptr[i + 1]):
            ok[s] = not band[i] and not band[idx[s]]


@njit
def monge_height(monge, X, Y):
    """Height Z(X, Y) of the degree-4 Monge form ``monge`` (k1, k2, b0..b3, c0..c4).

    ``Z = (k1 X^2 + k2 Y^2)/2 + (b0 X^3 + 3 b1 X^2 Y + 3 b2 X Y^2 + b3 Y^3)/6
    + (c0 X^4 + 4 c1 X^3 Y + 6 c2 X^2 Y^2 + 4 c3 X Y^3 + c4 Y^4)/24``; NaN coefficients
    (a lower Monge degree) count as zero.
    """
    z = 0.5 * (monge[0] * X * X + monge[1] * Y * Y)
    if not math.isnan(monge[2]):
        z += (monge[2] * X * X * X + 3.0 * monge[3] * X * X * Y + 3.0 * monge[4] * X * Y * Y
              + monge[5] * Y * Y * Y) / 6.0
    if not math.isnan(monge[6]):
        x2 = X * X
        y2 = Y * Y
        z += (monge[6] * x2 * x2 + 4.0 * monge[7] * x2 * X * Y + 6.0 * monge[8] * x2 * y2
              + 4.0 * monge[9] * X * y2 * Y + monge[10] * y2 * y2) / 24.0
    return z


@njit_parallel
def assign_by_jets(pts, query, cand, labels, monge, frames, offset, per_unit, out):
    """Label each query point with the unit whose jets explain it best.

    For query point p = pts[query[r]] and each candidate i = cand[r, t] (labelled points
    sorted by distance, -1 = none), the residual is the height of p above the Monge surface
    of i, in i's Monge frame (rows d1, d2, n of ``frames[i]``, origin the fitted point
    ``pts[i] + offset[i] n``): ``Z - Z_i(X, Y)``. Each unit among the candidates scores the
    median |residual| of its `per_unit` nearest candidates (one jet that happens to pass
    near p does not decide); out[r] = the unit of the smallest score (0 without a
    candidate).
    """
    K = cand.shape[1]
    for r in prange(query.size):
        p = query[r]
        res = np.empty(K)
        lab = np.empty(K, dtype=np.int64)
        m = 0
        for t in range(K):
            i = cand[r, t]
            if i < 0:
                continue
            e = abs(_jet_residual(pts, p, i, monge, frames, offset))
            if math.isnan(e):
                continue
            res[m] = e
            lab[m] = labels[i]
            m += 1
        best = np.inf
        unit = 0
        tmp = np.empty(per_unit)
        for a in range(m):
            u = lab[a]
            first = True  # score each unit once, at its nearest candidate
            for b in range(a):
                if lab[b] == u:
                    first = False
                    break
            if not first:
                continue
            c = 0
            for b in range(a, m):
                if lab[b] == u and c < per_unit:
                    tmp[c] = res[b]
                    c += 1
            score = np.median(tmp[:c])
            if score < best:
                best = score
                unit = u
        out[r] = unit


@njit_parallel
def unit_boundaries(pts, indptr, idx, dist, labels, normals, max_dist, out):
    """Points with a neighbour of another unit within `max_dist`: 1 convex, 2 concave.

    The crease between the units of i and j is convex when the normals open away from
    each other across it, ``(n_i - n_j) . (x_i - x_j) > 0`` (normals up or to the
    sensor); the sign is summed over i's neighbours of other units.
    """
    n = indptr.size - 1
    for i in prange(n):
        out[i] = 0
        if labels[i] <= 0:
            continue
        s = 0.0
        hit = False
        for t in range(indptr[i], indptr[i + 1]):
            j = idx[t]
            if labels[j] <= 0 or labels[j] == labels[i] or dist[t] > max_dist:
                continue
            hit = True
            acc = 0.0
            for c in range(3):
                acc += (normals[i, c] - normals[j, c]) * (pts[i, c] - pts[j, c])
            if not math.isnan(acc):
                s += acc
        if hit:
            out[i] = CREST if s > 0.0 else RAVINE


@njit
def _jet_residual(pts, p, i, monge, frames, offset):
    """Height of pts[p] above the degree-4 Monge surface fitted at point i."""
    w0 = pts[p, 0] - pts[i, 0] - offset[i] * frames[i, 2, 0]
    w1 = pts[p, 1] - pts[i, 1] - offset[i] * frames[i, 2, 1]
    w2 = pts[p, 2] - pts[i, 2] - offset[i] * frames[i, 2, 2]
    X = w0 * frames[i, 0, 0] + w1 * frames[i, 0, 1] + w2 * frames[i, 0, 2]
    Y = w0 * frames[i, 1, 0] + w1 * frames[i, 1, 1] + w2 * frames[i, 1, 2]
    Z = w0 * frames[i, 2, 0] + w1 * frames[i, 2, 1] + w2 * frames[i, 2, 2]
    return Z - monge_height(monge[i], X, Y)


@njit_parallel
def jet_consistent_edges(pts, indptr, idx, monge, frames, offset, tol, ok):
    """Edges (i, j) along which each end lies on the other's fitted jet: |residual| <= tol.

    A neighbour across a crease that the chi-square test missed (a one-sided neighbourhood
    at a face corner, a weak fold) lies off the point's jet and the edge is cut. Points
    without a jet (NaN) are judged by the other end's jet only.
    """
    n = indptr.size - 1
    for i in prange(n):
        for t in range(indptr[i], indptr[i + 1]):
            j = idx[t]
            if j == i:
                ok[t] = True
                continue
            a = abs(_jet_residual(pts, j, i, monge, frames, offset))
            b = abs(_jet_residual(pts, i, j, monge, frames, offset))
            # a point without a jet (too few neighbours) gives no evidence: the other
            # end's jet decides, and an edge between two such points is kept
            if math.isnan(a):
                a = 0.0 if math.isnan(b) else b
            if math.isnan(b):
                b = a
            ok[t] = a <= tol and b <= tol
