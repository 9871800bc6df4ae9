"""Compiled helpers of the moments driver (:mod:`._moments`): the canonical point order.

The classification must not depend on the order of the points, so every step runs on the
points sorted by x, then y, z and intensity (``np.lexsort`` of the four keys, ties in
input order). A lexsort of four float keys is four stable indirect sorts of the whole
cloud; one sort of x followed by a sort of each run of equal x by the other keys and the
index gives the same permutation in a fraction of the time (LAS coordinates are
quantised, so runs of equal x are short).
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit

__all__ = ["canonical_order"]

#: Runs of equal x up to this length are sorted by insertion, longer ones by merging.
_INSERTION_RUN = 24


@njit
def _less(y, z, w, r, a, b):  # pragma: no cover - compiled
    """Whether position `a` comes before position `b` by y, then z, then w (w empty: left
    out), then r (the input index, as a stable sort of the input would order them)."""
    if y[a] != y[b]:
        return y[a] < y[b]
    if z[a] != z[b]:
        return z[a] < z[b]
    if w.size and w[a] != w[b]:
        return w[a] < w[b]
    return r[a] < r[b]


@njit
def _sort_run(pos, lo, hi, y, z, w, r, buf):  # pragma: no cover - compiled
    """Stable sort of ``pos[lo:hi]`` by y, z, w and r at those positions (insertion for
    short runs, bottom-up merge sort through `buf` otherwise)."""
    m = hi - lo
    if m <= _INSERTION_RUN:
        for i in range(lo + 1, hi):
            p = pos[i]
            j = i - 1
            while j >= lo and _less(y, z, w, r, p, pos[j]):
                pos[j + 1] = pos[j]
                j -= 1
            pos[j + 1] = p
        return
    width = 1
    src = pos[lo:hi]
    dst = buf[:m]
    in_buf = False
    while width < m:
        for a in range(0, m, 2 * width):
            mid = min(a + width, m)
            end = min(a + 2 * width, m)
            i, j, k = a, mid, a
            while i < mid and j < end:
                if _less(y, z, w, r, src[j], src[i]):
                    dst[k] = src[j]
                    j += 1
                else:
                    dst[k] = src[i]
                    i += 1
                k += 1
            while i < mid:
                dst[k] = src[i]
                i += 1
                k += 1
            while j < end:
                dst[k] = src[j]
                j += 1
                k += 1
        src, dst = dst, src
        in_buf = not in_buf
        width *= 2
    if in_buf:
        pos[lo:hi] = buf[:m]


@njit
def _sort_ties(order, x, y, z, w):  # pragma: no cover - compiled
    """Sort every run of equal x by y, z, w and the index `order`; all four keys are
    given in the order `order` (sorted by x), so the runs read contiguous memory.
    Returns the sorted `order`."""
    n = order.size
    pos = np.arange(n)
    buf = np.empty(0, np.int64)
    a = 0
    while a < n:
        b = a + 1
        while b < n and x[b] == x[a]:
            b += 1
        if b - a > 1:
            if b - a > _INSERTION_RUN and buf.size < b - a:
                buf = np.empty(b - a, np.int64)
            _sort_run(pos, a, b, y, z, w, order, buf)
        a = b
    out = np.empty(n, np.int64)
    for i in range(n):
        out[i] = order[pos[i]]
    return out


def canonical_order(x, y, z, intensity=None) -> np.ndarray:
    """``np.lexsort((intensity, z, y, x))`` (intensity left out when None), computed as a
    sort of x and a sort of each run of equal x by y, z, intensity and the index.

    Examples
    --------
    >>> x = np.array([1.0, 0.0, 1.0, 0.0, 1.0])
    >>> y = np.array([2.0, 5.0, 1.0, 5.0, 1.0])
    >>> z = np.array([0.0, 1.0, 3.0, 0.0, 3.0])
    >>> canonical_order(x, y, z).tolist() == np.lexsort((z, y, x)).tolist()
    True
    """
    x = np.asarray(x, dtype=np.float64)
    order = np.argsort(x).astype(np.int64, copy=False)
    # the keys gathered into the order of x once (vectorised gathers), so that sorting
    # the runs of equal x reads contiguous memory instead of jumping across the cloud
    keys = [np.take(np.asarray(a, dtype=np.float64), order) for a in (x, y, z)]
    w = (np.empty(0) if intensity is None
         else np.take(np.asarray(intensity), order).astype(np.float64, copy=False))
    return _sort_ties(order, *keys, w)
