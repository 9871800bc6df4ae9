"""Numba kernels of segmentation: union-find components and seeded region growing.

Every kernel walks CSR neighbourhoods (``indptr``, ``indices``) whose row ``r`` belongs to
point ``rows[r]``; ``row_of[p]`` is the row of point ``p`` (-1 when ``p`` has none). An
edge is the CSR entry ``e``; ``edge_ok[e]`` says whether regions may grow across it.
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit
from .._shared._kernels import uf_find as _find


@njit
def _union(parent, a, b):
    # Union by smaller index, so a root is always the smallest member: deterministic.
    ra = _find(parent, a)
    rb = _find(parent, b)
    if ra == rb:
        return
    if ra < rb:
        parent[rb] = ra
    else:
        parent[ra] = rb


@njit
def _accepted(e, p, q, mask, edge_ok, use_edge_ok):
    # An edge is walked when it joins two distinct masked points and passes the criterion.
    return q != p and mask[q] and (not use_edge_ok or edge_ok[e])


@njit
def union_find_roots(indptr, indices, rows, edge_ok, use_edge_ok, mask, n_points):
    """Root (smallest member index) of every masked point's component; -1 if unmasked."""
    parent = np.arange(n_points)
    for r in range(indptr.size - 1):
        p = rows[r]
        if not mask[p]:
            continue
        for e in range(indptr[r], indptr[r + 1]):
            if _accepted(e, p, indices[e], mask, edge_ok, use_edge_ok):
                _union(parent, p, indices[e])
    roots = np.empty(n_points, np.int64)
    for p in range(n_points):
        roots[p] = _find(parent, p) if mask[p] else -1
    return roots


@njit
def grow_kernel(indptr, indices, row_of, edge_ok, use_edge_ok, order, can_grow, mask,
                merge, n_points):
    """Seeded region growing (breadth first) with optional merging of touching regions.

    Seeds are taken in `order`; an unlabelled masked point that may grow starts a region,
    which expands through accepted edges. Points with ``can_grow`` False join the first
    region that reaches them but do not expand it. With `merge`, a growing point that
    reaches a point of another region through an accepted edge, both able to grow, merges
    the two regions (union-find on region ids).
    """
    labels = np.zeros(n_points, np.int64)
    queue = np.empty(n_points, np.int64)
    parent = np.arange(n_points + 1)  # region ids 1..n_regions
    n_regions = 0
    for s in order:
        if labels[s] != 0 or not mask[s] or not can_grow[s]:
            continue
        n_regions += 1
        labels[s] = n_regions
        head = 0
        tail = 1
        queue[0] = s
        while head < tail:
            p = queue[head]
            head += 1
            r = row_of[p]
            if r < 0:
                continue
            for e in range(indptr[r], indptr[r + 1]):
                q = indices[e]
                if not _accepted(e, p, q, mask, edge_ok, use_edge_ok):
                    continue
                lq = labels[q]
                if lq == 0:
                    labels[q] = n_regions
                    if can_grow[q]:
                        queue[tail] = q
                        tail += 1
                elif merge and lq != n_regions and can_grow[q]:
                    _union(parent, lq, n_regions)
    if merge:
        for p in range(n_points):
            if labels[p] != 0:
                labels[p] = _find(parent, labels[p])
    return labels
