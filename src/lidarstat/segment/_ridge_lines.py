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


def join_lines(chains, vert, ridge, join):
    """Greedily join chains of the same type whose ends are within `join` and aligned.

    Tracing stops at gaps of a few points where a test failed by chance; two pieces are
    joined when the gap vector continues both end directions (cosines above 0.7). Runs
    once per pair of lines, not per point. Returns the joined chains and, per input chain,
    the index of the chain it ended in.
    """
    chains = [c for c in chains]
    owner = list(range(len(chains)))
    alive = [len(c) >= 2 for c in chains]

    def end(c, first):
        a, b = (c[0], c[1]) if first else (c[-1], c[-2])
        t = vert[a] - vert[b]
        n = np.linalg.norm(t)
        return vert[a], (t / n if n > 0 else t)

    merged = True
    while merged:
        merged = False
        for i in range(len(chains)):
            if not alive[i]:
                continue
            for j in range(i + 1, len(chains)):
                if not alive[j] or ridge[chains[i][0]] != ridge[chains[j][0]]:
                    continue
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
                            owner = [i if o == j else o for o in owner]
                            merged = True
                            break
                    if not alive[j]:
                        break
    return chains, alive, owner
