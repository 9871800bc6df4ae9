"""Compiled helpers of the moments classification: the canonical point order of the driver
(:mod:`._moments`), and the median absolute deviation of a window's sorted heights
(:func:`sorted_mad`, the ground cut's spread).

The classification must not depend on the order of the points, so every step runs on the
points sorted by x, then y, z and intensity (``np.lexsort`` of the four keys, ties in
input order). A lexsort of four float keys is four stable indirect sorts of the whole
cloud; one sort of x followed by a sort of each run of equal x by the other keys and the
index gives the same permutation in a third of the time (LAS coordinates are quantised,
so runs of equal x are short).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel
from ..neighbors import radix_order

__all__ = ["canonical_order", "compact_rows", "sorted_mad"]

#: Runs of equal x up to this length are sorted by insertion, longer ones by merging.
_INSERTION_RUN = 24


@njit
def _less(y, z, w, x_order, a, b):  # pragma: no cover - compiled
    """Whether point `a` comes before point `b` by y, then z, then w (w empty: left out),
    then the index (as a stable sort of the input would order them). `a` and `b` are
    positions in the x order: `y` is in that order, `z` and `w` in the input's (read
    through `x_order` on ties of y alone)."""
    if y[a] != y[b]:
        return y[a] < y[b]
    ia = x_order[a]
    ib = x_order[b]
    if z[ia] != z[ib]:
        return z[ia] < z[ib]
    if w.size and w[ia] != w[ib]:
        return w[ia] < w[ib]
    return a < b


@njit
def _sort_run(order, lo, hi, y, z, w, x_order, buf):  # pragma: no cover - compiled
    """Stable sort of ``order[lo:hi]`` by y, z, w (insertion for short runs, bottom-up
    merge sort through `buf` otherwise)."""
    m = hi - lo
    if m <= _INSERTION_RUN:
        for i in range(lo + 1, hi):
            p = order[i]
            j = i - 1
            while j >= lo and _less(y, z, w, x_order, p, order[j]):
                order[j + 1] = order[j]
                j -= 1
            order[j + 1] = p
        return
    width = 1
    src = order[lo:hi]
    dst = buf[:m]
    in_buf = False
    while width < m:
        for a in range(0, m, 2 * width):
            mid = min(a + width, m)
            end = min(a + 2 * width, m)
            i, j, k = a, mid, a
            while i < mid and j < end:
                if _less(y, z, w, x_order, src[j], src[i]):
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
        order[lo:hi] = buf[:m]


#: Points per block of :func:`_sort_ties` (blocks of whole runs sorted in parallel).
_TIE_BLOCK = 1 << 16


@njit_parallel
def _sort_ties(first, y, z, w, x_order, out):  # pragma: no cover - compiled
    """Sort every run of equal `first` (sorted) by y (in the same order), z and w (in
    the input's order), and write the order of the points, ``x_order`` composed with it,
    to `out`. The runs are independent: blocks of whole runs are sorted in parallel,
    each through a buffer of its own."""
    n = first.size
    nblk = max(1, n // _TIE_BLOCK)
    bounds = np.empty(nblk + 1, np.int64)
    bounds[0] = 0
    for k in range(1, nblk):
        c = max(k * (n // nblk), bounds[k - 1])
        while 0 < c < n and first[c] == first[c - 1]:  # a block starts at a run's start
            c += 1
        bounds[k] = c
    bounds[nblk] = n
    for k in prange(nblk):
        lo = bounds[k]
        hi = bounds[k + 1]
        if hi <= lo:
            continue
        pos = np.arange(lo, hi)
        buf = np.empty(hi - lo, np.int64)
        a = lo
        while a < hi:
            b = a + 1
            while b < hi and first[b] == first[a]:
                b += 1
            if b - a > 1:
                _sort_run(pos, a - lo, b - lo, y, z, w, x_order, buf)
            a = b
        for i in range(hi - lo):
            out[lo + i] = x_order[pos[i]]


@njit_parallel
def _gather(values, order, out):  # pragma: no cover - compiled
    """``out = values[order]``, in parallel."""
    for i in prange(order.size):
        out[i] = values[order[i]]


def canonical_order(x, y, z, intensity=None) -> np.ndarray:
    """``np.lexsort((intensity, z, y, x))`` (intensity left out when None), computed as a
    stable sort of x and a sort of each run of equal x by y, z, intensity and the index.

    The sort of x is a radix sort of the bits of the values when none is negative (the
    bits of non-negative doubles order as the numbers do), a comparison sort otherwise;
    it gives x in that order too. y is gathered into that order once, so the runs are
    sorted on contiguous memory; z and intensity, compared only between points of equal
    x and y, are read where they are. Inside a run the stable sort left the points in
    input order, so the position in it breaks the last ties as the index does. The radix
    passes, the gather and the runs (in blocks of whole runs) run in parallel; the
    permutation does not depend on the threads.

    Examples
    --------
    >>> x = np.array([1.0, 0.0, 1.0, 0.0, 1.0])
    >>> y = np.array([2.0, 5.0, 1.0, 5.0, 1.0])
    >>> z = np.array([0.0, 1.0, 3.0, 0.0, 3.0])
    >>> canonical_order(x, y, z).tolist() == np.lexsort((z, y, x)).tolist()
    True
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    order, first = _x_order(x)
    n = x.size
    ys = np.empty(n)
    _gather(np.ascontiguousarray(y, dtype=np.float64), order, ys)
    w = (np.empty(0) if intensity is None
         else np.ascontiguousarray(intensity, dtype=np.float64))
    out = np.empty(n, np.int64)
    # inside a run the stable sort of x left the points in input order: their position
    # in the run breaks the last ties as the index does
    _sort_ties(first, ys, np.ascontiguousarray(z, dtype=np.float64), w, order, out)
    return out


def _x_order(x):
    """Stable ascending order of `x` (float64, no NaN) and `x` in that order:
    ``(order, x[order])``."""
    bits = x.view(np.int64)
    if x.size < 2:
        return np.arange(x.size, dtype=np.int64), x.copy()
    lo = int(bits.min())
    if lo < 0:  # a negative value or -0.0: the bits do not order as the numbers
        order = np.argsort(x, kind="stable").astype(np.int64, copy=False)
        return order, np.take(x, order)
    keys = bits - lo  # >= 0, in the order of the numbers; equal only for equal numbers
    span = int(keys.max())
    order, keys = radix_order(keys, max(span, 1).bit_length())
    keys += lo  # the sorted keys back to the bits of the sorted values: no gather of x
    return order, keys.view(np.float64)


@njit
def compact_rows(a, keep):  # pragma: no cover - compiled
    """Move the rows of `a` where `keep` to its front, in order (``a[keep]`` in place);
    returns their number."""
    m = 0
    for i in range(a.shape[0]):
        if keep[i]:
            if m != i:
                for c in range(a.shape[1]):
                    a[m, c] = a[i, c]
            m += 1
    return m


@njit
def sorted_mad(xs, med):  # pragma: no cover - compiled
    """``np.median(np.abs(xs - med))`` of `xs` sorted ascending (no NaN, at least one
    value), without the distances' array and its partition.

    The distances ``|xs[i] - med|`` fall (rounded subtraction is monotone) on the values
    below `med` and rise from the first value at or above it: the median is read by
    merging the two runs outward from that value, up to the middle (the mean of the two
    middle distances, ``(a + b) / 2``, for an even count, as ``np.median`` takes it).
    """
    n = xs.size
    lo, hi = 0, n  # first index with xs >= med: binary search
    while lo < hi:
        mid = (lo + hi) // 2
        if xs[mid] < med:
            lo = mid + 1
        else:
            hi = mid
    left = lo - 1
    right = lo
    want = n // 2  # the distance of rank n // 2 and, for even n, the one before
    prev = 0.0
    d = 0.0
    for _ in range(want + 1):
        prev = d
        if right < n and (left < 0 or abs(xs[right] - med) <= abs(xs[left] - med)):
            d = abs(xs[right] - med)
            right += 1
        else:
            d = abs(xs[left] - med)
            left -= 1
    if n % 2:
        return d
    return (prev + d) / 2.0
