"""Numba kernels that select CSR edges by the labels or classes of their two ends.

The vectorised form of these selections (``src, dst = nbh.edges()`` and boolean masks over
them) allocates several arrays of one entry per neighbour pair: at 2 million points and
k = 50 that is 100 million pairs and gigabytes per step. These kernels walk the CSR rows
once to count and once to fill, so only the selected pairs are stored. Each returns
exactly what the mask expression it replaces returns (same pairs, in CSR order). Rows are
independent: the kernels that do work per entry run in parallel over rows (a
count-then-fill kernel counts per row, then each row that holds a selected edge fills
from its prefix-sum offset, so the order is CSR order whatever the threads do);
:func:`pair_edges` and :func:`first_columns`, which mostly skip rows or copy, run in one
thread: two do not make them faster (``benchmarks/results_first_run.json``, key
``parallel_runtime``) and cost about four times the compile time. :func:`adaptive_edges`, whose gathers (the prefix
normals: 24 bytes a point) do not fit in the cache, visits the rows in the order
``visit`` (:meth:`lidarstat.neighbors.Neighborhoods.visit_order`: the kNN search's grid
order), so consecutive rows gather nearby points from cache; the kernels that gather
only labels or flags read the rows in CSR order (measured faster: the label array stays
in the cache and the rows stream).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._shared._jit import njit, njit_parallel

_ROWS = 4096  # rows per chunk


@njit_parallel
def prefix_ok(indptr, indices, rows, good, out):
    """``out[e]``: no neighbour before or at entry e of its row is a non-`good` point.

    The row's own point never counts as a non-`good` one (``dst == src``). This is
    ``cumsum(~good[dst] & (dst != src))`` restarted per row, equal to 0.
    """
    for r in prange(indptr.size - 1):
        p = rows[r]
        bad = False
        for e in range(indptr[r], indptr[r + 1]):
            q = indices[e]
            if q != p and not good[q]:
                bad = True
            out[e] = not bad


#: modes of :func:`pair_edges`
LABELS_ASCENDING = 0  # 0 < labels[p] < labels[q]
LABELS_DIFFERENT = 1  # labels[p] != labels[q], both > 0
REINTEGRATION = 2  # p an unlabelled candidate, q labelled


@njit
def _row_ok(mode, lp, candidate):
    """Whether the row of a point labelled `lp` can hold a selected edge."""
    if mode == REINTEGRATION:
        return candidate and lp == 0
    return lp > 0


@njit
def _pair_ok(mode, lp, lq):
    """Whether the edge from a point labelled `lp` to one labelled `lq` is selected (the
    row passed :func:`_row_ok`)."""
    if mode == REINTEGRATION:
        return lq > 0
    if lq <= 0:
        return False
    if mode == LABELS_ASCENDING:
        return lp < lq
    return lp != lq


@njit
def pair_edges(indptr, indices, rows, labels, candidates, mode, width, fill, offs, src, dst):
    """Edges (p, q) selected by `mode` (:func:`_pair_ok`; `candidates` only for
    ``REINTEGRATION``) among the first `width` entries of each row (every entry when
    `width` < 0).

    Count-then-fill over chunks of `_ROWS` rows (see :func:`_two_pass`): returns the
    number of edges of every row; with `fill` writes them, in CSR order, to `src`, `dst`
    from ``offs[row]``, skipping the rows without any (most rows: the second pass only
    reads the rows that hold a selected edge).
    """
    m = indptr.size - 1
    nch = (m + _ROWS - 1) // _ROWS
    counts = np.zeros(0 if fill else m, dtype=np.int32)
    for ch in range(nch):
        for r in range(ch * _ROWS, min(m, (ch + 1) * _ROWS)):
            if fill and offs[r + 1] == offs[r]:
                continue
            p = rows[r]
            lp = labels[p]
            if not _row_ok(mode, lp, mode == REINTEGRATION and candidates[p]):
                continue
            c = offs[r] if fill else 0
            end = indptr[r + 1]
            if width >= 0 and indptr[r] + width < end:
                end = indptr[r] + width
            for e in range(indptr[r], end):
                q = indices[e]
                if _pair_ok(mode, lp, labels[q]):
                    if fill:
                        src[c] = p
                        dst[c] = q
                    c += 1
            if not fill:
                counts[r] = c
    return counts


def _two_pass(kernel, *args):
    """Run a count-then-fill edge kernel: the selected ``(src, dst)`` as int64 arrays.

    The first call counts the edges of every row, the second writes each row's from the
    prefix sum of the counts: the pairs come in CSR order.
    """
    none = np.empty(0, dtype=np.int64)
    counts = kernel(*args, False, none, none, none)
    offs = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=offs[1:])
    del counts
    src = np.empty(offs[-1], dtype=np.int64)
    dst = np.empty(offs[-1], dtype=np.int64)
    kernel(*args, True, offs, src, dst)
    return src, dst


def _compact(labels):
    """`labels` as int32 when the values allow (the kernels gather one label per CSR
    entry at random: half the bytes keep more of them in cache, measured 25-35 % less
    CPU for 2M points, k = 50); the selections compare labels only, so they are equal."""
    labels = np.ascontiguousarray(labels)
    if labels.dtype.kind in "iu" and (not labels.size or (labels.min() >= -2**31
                                                         and labels.max() < 2**31)):
        return labels.astype(np.int32, copy=False)  # also empty or narrower: one variant
    return labels


def reintegration_pairs(nbh, candidates, labels):
    """``(src, dst)`` of the edges from an unlabelled `candidates` point to a labelled one."""
    return _two_pass(pair_edges, nbh.indptr, nbh.indices, nbh.query_indices(),
                     _compact(labels),
                     np.ascontiguousarray(candidates, dtype=np.bool_), REINTEGRATION, -1)


@njit
def first_in_row(indptr, indices, rows, clean, labels, ref):
    """``ref[p]``: the first neighbour q of p's row with ``clean[q]`` and the same label."""
    for r in range(indptr.size - 1):
        p = rows[r]
        for e in range(indptr[r], indptr[r + 1]):
            q = indices[e]
            if clean[q] and labels[q] == labels[p]:
                ref[p] = q
                break


def label_pairs(nbh, labels, *, different_only=False, width=None):
    """``(src, dst)`` of the edges between two labelled points of different segments.

    Default: ``0 < labels[src] < labels[dst]`` (each touching pair of points once per CSR
    direction it appears in); `different_only`: ``labels[src] != labels[dst]``, both > 0.
    `width`: only the first `width` entries of each row (the `width` nearest neighbours
    of sorted kNN rows: the pairs of :func:`lidarstat.segment._covariance_segments.truncate_rows`
    without its copy of the rows).
    """
    return _two_pass(pair_edges, nbh.indptr, nbh.indices, nbh.query_indices(),
                     _compact(labels), np.zeros(0, dtype=np.bool_),
                     LABELS_DIFFERENT if different_only else LABELS_ASCENDING,
                     -1 if width is None else int(width))


@njit_parallel
def prefix_lengths(indptr, lengths, out):
    """``out[e]``: entry e lies within the first ``lengths[r]`` entries of its row r."""
    for r in prange(indptr.size - 1):
        s = indptr[r]
        for e in range(s, indptr[r + 1]):
            out[e] = e - s < lengths[r]


@njit_parallel
def adaptive_edges(visit, indptr, indices, rows, joinable, surface, kstar, pn, grow_k,
                   cos_min, out):
    """Edges of the scale-adaptive region growing, one pass over the CSR rows.

    ``out[e]`` for the entry e (position t in row r of point p, neighbour q) is

    * Fig. 4 on the first `grow_k` neighbours of surface points: ``t < grow_k``, p is
      `surface`, no non-`joinable` neighbour other than p itself comes before or at e,
      and, when both have a planar prefix, their prefix normals agree (a ground point
      seen at grazing incidence passes its plane test with the foot of a wall in its
      row: the wall's points there are surface or boundary, nothing cuts the row); or
    * the largest planar prefix of the row: ``t < kstar[r]`` and q has no planar prefix
      (``kstar[q] == 0``) or the two prefix normals agree: ``|pn[p] . pn[q]| >= cos_min``
      (summed as NumPy's einsum does, so equal to it bit for bit here).

    Rows are visited in the order `visit` (a permutation of the rows).
    """
    for rr in prange(visit.size):
        r = visit[rr]
        p = rows[r]
        s = indptr[r]
        bad = False
        grow = surface[p]
        kp = kstar[r]
        for e in range(s, indptr[r + 1]):
            q = indices[e]
            t = e - s
            if q != p and not joinable[q]:
                bad = True
            agree = True  # two planar prefixes: their normals must agree
            if kp > 0 and kstar[q] > 0:
                c = abs((pn[p, 0] * pn[q, 0] + pn[p, 2] * pn[q, 2]) + pn[p, 1] * pn[q, 1])
                agree = c >= cos_min
            ok = grow and not bad and t < grow_k and agree
            if not ok and t < kp:
                ok = kstar[q] == 0 or agree
            out[e] = ok


@njit
def first_columns(indices, distances, k, m, out_idx, out_dist):
    """The first `m` of every `k` entries of fixed-length rows (a copy: memory-bound, one
    thread is as fast as two)."""
    n = indices.size // k
    for r in range(n):
        for t in range(m):
            out_idx[r * m + t] = indices[r * k + t]
            out_dist[r * m + t] = distances[r * k + t]
