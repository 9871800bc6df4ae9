"""Joining traced ridge pieces into lines: the end-point tree finds exactly the joins of the
exhaustive pairwise pass, on pieces of broken polylines over a seed sweep."""

import numpy as np
import pytest

from lidarstat.segment._ridge_lines import group_rows, join_lines


def _exhaustive(chains, vert, ridge, join):
    """Every later chain tested against each chain, pass after pass (the reference)."""
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


def _pieces(rng):
    """Wiggly polylines cut into pieces at random gaps, shuffled, some reversed, of two
    types, with single-point and crossing clutter."""
    verts, chains = [], []
    for _ in range(rng.integers(3, 12)):
        m = rng.integers(20, 80)
        heading = np.cumsum(rng.normal(0, 0.15, m)) + rng.uniform(0, 2 * np.pi)
        xy = rng.uniform(-5, 5, 2) + np.cumsum(0.1 * np.c_[np.cos(heading), np.sin(heading)],
                                               axis=0)
        p = np.c_[xy, rng.normal(0, 0.01, m)]
        base = sum(len(v) for v in verts)
        verts.append(p)
        keep = rng.random(m) > 0.15  # gaps where a point is not traced
        cut = np.flatnonzero(~keep | (rng.random(m) < 0.05))
        for piece in np.split(np.arange(m), cut):
            piece = piece[keep[piece]]
            if piece.size:
                chains.append(base + (piece[::-1] if rng.random() < 0.5 else piece))
    for _ in range(rng.integers(0, 10)):  # clutter: single points and short stubs
        base = sum(len(v) for v in verts)
        s = rng.integers(1, 4)
        verts.append(np.c_[rng.uniform(-6, 6, (1, 2)) + 0.1 * np.arange(s)[:, None],
                           np.zeros(s)])
        chains.append(base + np.arange(s))
    vert = np.vstack(verts)
    order = rng.permutation(len(chains))
    chains = [chains[i].astype(np.int64) for i in order]
    ridge = rng.integers(1, 3, vert.shape[0]).astype(np.uint8)
    for c in chains:  # one type per chain, as traced
        ridge[c] = ridge[c[0]] if rng.random() < 0.8 else 1
    return chains, vert, ridge


@pytest.mark.parametrize("seed", range(40))
def test_join_lines_equals_exhaustive_pass(seed):
    rng = np.random.default_rng(seed)
    chains, vert, ridge = _pieces(rng)
    join = float(rng.uniform(0.15, 0.6))
    want = _exhaustive(chains, vert, ridge, join)
    got = join_lines(chains, vert, ridge, join)
    assert got[1] == want[1]
    assert got[2] == want[2]
    assert len(got[0]) == len(want[0])
    for a, b in zip(got[0], want[0]):
        np.testing.assert_array_equal(a, b)


def test_join_lines_sweep_joins():
    """The sweep exercises joins (a test of equality on pieces never joined is empty)."""
    joins = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        chains, vert, ridge = _pieces(rng)
        alive = join_lines(chains, vert, ridge, float(rng.uniform(0.15, 0.6)))[1]
        joins += sum(len(c) >= 2 for c in chains) - sum(alive)
    assert joins > 100


@pytest.mark.parametrize("seed", range(20))
def test_group_rows_equals_scan(seed):
    rng = np.random.default_rng(seed)
    n_groups = int(rng.integers(1, 60))
    label = rng.integers(0, n_groups, int(rng.integers(0, 3000)))
    got = group_rows(label, n_groups)
    assert len(got) == n_groups
    for g in range(n_groups):
        np.testing.assert_array_equal(got[g], np.flatnonzero(label == g))
