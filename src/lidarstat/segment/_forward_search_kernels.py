"""Numba kernel of the Forward Search (Atkinson and Riani 2000) with rank-one updates.

The regression ``y = A theta + e`` is fitted to a growing subset S. Each step computes,
for every point outside S, the deletion residual ``|y_i - a_i theta| / (s sqrt(1 + a_i P
a_i))`` (``P = (A_S'A_S)^-1``, ``s^2 = RSS_S / (m - r)``), adds the `block` points with
the smallest ones and updates P, theta and RSS by Sherman-Morrison (no refit):
``P <- P - P a a' P / (1 + a'Pa)``, ``theta <- theta + P a (y - a'theta)``,
``RSS <- RSS + (y - a'theta)^2 / (1 + a'Pa)``. P and theta are recomputed from the
accumulated normal equations every `refresh` additions to stop rounding drift.
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit


@njit
def _pinv_form(d, m, tol):
    """d' pinv(m) d for a symmetric PSD matrix m, and the numerical rank of m."""
    w, v = np.linalg.eigh(m)
    top = max(w.max(), 0.0)
    val = 0.0
    rank = 0
    for k in range(w.size):
        if w[k] > tol * top and w[k] > 0.0:
            c = 0.0
            for u in range(d.size):
                c += v[u, k] * d[u]
            val += c * c / w[k]
            rank += 1
    return val, rank


@njit
def _solve_subset(A, y, ins, ata, aty):
    """Exact P = (A_S'A_S)^-1, theta and RSS of the subset from its normal equations."""
    P = np.linalg.inv(ata)
    theta = P @ aty
    rss = 0.0
    for i in range(y.size):
        if ins[i]:
            e = y[i] - A[i] @ theta
            rss += e * e
    return P, theta, rss


@njit
def forward_search(A, y, in0, block, refresh, fstat, fpaper, frank, rmin, msize, s2, order):
    """Run the search to the end; returns the number of steps.

    Outputs (preallocated, length >= n - m0): per step t, `rmin[t]` (smallest deletion
    residual outside the subset before adding), `fstat[t]` (F statistic of
    ``theta(m) - theta(m0)`` with the covariance of the difference, ``sigma^2 (P0 - P)``,
    divided by its rank `frank[t]`), `fpaper[t]` (the paper's form with ``A_m'A_m``, over
    r), `msize[t]` (subset size after adding), `s2[t]` (RSS/(m - r) before adding);
    `order` lists the points in the order they entered.
    """
    n, r = A.shape
    ins = in0.copy()
    ata = np.zeros((r, r))
    aty = np.zeros(r)
    m = 0
    for i in range(n):
        if ins[i]:
            m += 1
            for u in range(r):
                aty[u] += A[i, u] * y[i]
                for v in range(r):
                    ata[u, v] += A[i, u] * A[i, v]
    P, theta, rss = _solve_subset(A, y, ins, ata, aty)
    theta0 = theta.copy()
    P0 = P.copy()
    s0sq = rss / (m - r)
    d = np.empty(n)
    pa = np.empty(r)
    added = 0
    since = 0
    step = 0
    total = n - m
    while added < total:
        s = np.sqrt(max(rss / (m - r), 1e-300))
        ncand = 0
        for i in range(n):
            if ins[i]:
                d[i] = np.inf
                continue
            a = A[i]
            h = 0.0
            for u in range(r):
                acc = 0.0
                for v in range(r):
                    acc += P[u, v] * a[v]
                h += a[u] * acc
            d[i] = abs(y[i] - a @ theta) / (s * np.sqrt(1.0 + h))
            ncand += 1
        k = min(block, ncand)
        if k == 1:
            sel = np.empty(1, dtype=np.int64)
            sel[0] = np.argmin(d)
        else:
            sel = np.argsort(d)[:k]
        rmin[step] = d[sel[0]]
        s2[step] = rss / (m - r)
        for t in range(k):
            i = sel[t]
            a = A[i]
            for u in range(r):
                acc = 0.0
                for v in range(r):
                    acc += P[u, v] * a[v]
                pa[u] = acc
            h = a @ pa
            e = y[i] - a @ theta
            for u in range(r):
                for v in range(r):
                    P[u, v] -= pa[u] * pa[v] / (1.0 + h)
                aty[u] += a[u] * y[i]
                for v in range(r):
                    ata[u, v] += a[u] * a[v]
            theta += pa * (e / (1.0 + h))
            rss += e * e / (1.0 + h)
            ins[i] = True
            order[added] = i
            added += 1
            m += 1
            since += 1
        if since >= refresh:
            since = 0
            P, theta, rss = _solve_subset(A, y, ins, ata, aty)
        diff = theta - theta0
        val, rank = _pinv_form(diff, P0 - P, 1e-9)
        fstat[step] = val / max(rank, 1) / s0sq
        frank[step] = rank
        fpaper[step] = (diff @ (ata @ diff)) / (r * s0sq)
        msize[step] = m
        step += 1
    return step
