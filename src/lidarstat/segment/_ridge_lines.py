"""Chaining of traced ridge and crease points into lines: moving-average vertices and
joins across small aligned gaps (used by :func:`lidarstat.segment.ridges`)."""

from __future__ import annotations

import numpy as np


def smooth_vertices(v, w):
    """Moving average of polyline vertices over `w` vertices (shrinking at the ends)."""
    if w <= 1 or len(v) < 3:
        return v
    h = w // 2
    c = np.vstack([np.zeros((1, 3)), np.cumsum(v, axis=0)])
    i = np.arange(len(v))
    lo = np.maximum(i - np.minimum(h, np.minimum(i, len(v) - 1 - i)), 0)
    hi = np.minimum(i + (i - lo), len(v) - 1) + 1
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def group_rows(label, n_groups):
    """Rows of each label ``0 .. n_groups - 1``, ascending within a group: one stable sort,
    not a scan of every row per group."""
    label = np.asarray(label, np.int64)
    order = np.argsort(label, kind="stable")
    first = np.searchsorted(label[order], np.arange(n_groups + 1))
    return [order[first[g]:first[g + 1]] for g in range(n_groups)]


def join_lines(chains, vert, ridge, join):
    """Greedily join chains of the same type whose ends are within `join` and aligned.

    Tracing stops at gaps of a few points where a test failed by chance; two pieces are
    joined when the gap vector continues both end directions (cosines above 0.7). Chains
    are visited in order, each against the later ones, until a pass joins none; only the
    chains with an end point within `join` of the visiting chain's ends are tested (a
    k-d tree of the chains' end points). Returns the joined chains and, per input chain,
    the index of the chain it ended in.
    """
    from scipy.spatial import cKDTree

    chains = [c for c in chains]
    nc = len(chains)
    owner = np.arange(nc)
    alive = [len(c) >= 2 for c in chains]
    live = np.flatnonzero(alive)
    if live.size < 2:
        return chains, alive, owner.tolist()
    # a joined chain's ends are ends of the input chains: the tree of those finds every
    # pair within reach (a margin over `join`; the test below is the exact one)
    ends = np.concatenate([[chains[c][0], chains[c][-1]] for c in live])
    tree = cKDTree(vert[ends])
    end_chain = np.repeat(live, 2)
    reach = join * (1.0 + 1e-9) + 1e-12

    def end(c, first):
        a, b = (c[0], c[1]) if first else (c[-1], c[-2])
        t = vert[a] - vert[b]
        n = np.linalg.norm(t)
        return vert[a], (t / n if n > 0 else t)

    def near(i, after):
        """Chains after `after` with an end within reach of an end of chain `i`."""
        c = chains[i]
        hits = tree.query_ball_point(vert[[c[0], c[-1]]], reach)
        cand = np.unique(owner[end_chain[np.concatenate([hits[0], hits[1]]).astype(np.int64)]])
        return [int(j) for j in cand[cand > after] if alive[j]]

    def joined(i, j):
        if ridge[chains[i][0]] != ridge[chains[j][0]]:
            return False
        for fi in (False, True):
            for fj in (True, False):
                pi, ti = end(chains[i], fi)
                pj, tj = end(chains[j], fj)
                gap = pj - pi
                d = np.linalg.norm(gap)
                if not 0 < d <= join:
                    continue
                g = gap / d
                if g @ ti > 0.7 and -(g @ tj) > 0.7:
                    ci = chains[i][::-1] if fi else chains[i]
                    cj = chains[j] if fj else chains[j][::-1]
                    chains[i] = np.concatenate([ci, cj])
                    alive[j] = False
                    owner[owner == j] = i
                    return True
        return False

    merged = True
    while merged:
        merged = False
        for i in range(nc):
            if not alive[i]:
                continue
            cand = near(i, i)
            while cand:
                j = cand.pop(0)
                if joined(i, j):  # new ends: the chains after j within their reach
                    merged = True
                    cand = near(i, j)
    return chains, alive, owner.tolist()
