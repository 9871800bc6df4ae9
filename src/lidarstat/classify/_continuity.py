"""Surface continuity of the ground cluster: raised patches are not ground.

The moments cut decides per tile by heights above one ground surface.  Where a roof is
wider than the opening window (or a tile is filled by roofs) the surface runs over the roof
and the roof's points come out as ground.  Such a patch is recognisable by its border, as
in segment-based filters (Sithole & Vosselman 2005, cited by the seed paper): every point
is joined to those of its k nearest planimetric neighbours whose elevation differs by at
most ``step + slope x distance`` (smooth patches; walls break them), and a patch that is
*higher* than its
neighbours across at least ``above_fraction`` of its step edges (walls all round) is
raised.  Ground points in a raised patch other than the largest patch become objects.  A
terrace or an embankment top is higher than the terrain below it but lower than, or
smoothly joined to, the terrain above it, so it keeps its label.  Limitation: a terrace
with no smooth join anywhere in the data (a retaining wall running across the whole
cloud) is judged raised.  Exempting patches that reach the border of the cloud avoids
that but was measured worse on ISPRS (mean 9.31 % against 8.63 %: many roofs the surface
ran over reach a sample's border).  (A cheaper variant on
the lowest point of each grid cell was measured worse on ISPRS: samp21 8.3 % against 6.3 %,
samp41 11.5 % against 10.9 %.)
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import njit

__all__ = ["raised_patches"]


def raised_patches(xy, z, *, k: int = 8, step: float = 0.3, slope: float = 1.0,
                   above_fraction: float = 0.95, min_points: int = 10,
                   chunk: int = 1_000_000) -> np.ndarray:
    """Points whose smooth patch stands above its surroundings on (almost) every side.

    Parameters
    ----------
    xy : (N, 2) ndarray
        Planimetric coordinates.
    z : (N,) ndarray
        Elevations.
    k : int, optional
        Planimetric nearest neighbours per point (the graph's edges).
    step, slope : float, optional
        Two neighbours are joined when their elevations differ by at most
        ``step + slope * distance`` (slopes up to 45 degrees stay joined; walls do not).
    above_fraction : float, optional
        Share of a patch's step edges (to other patches) on which it must be the higher
        side.
    min_points : int, optional
        Smallest patch that is judged.
    chunk : int, optional
        Points queried at a time (bounds the memory of the neighbour table).

    Returns
    -------
    (N,) ndarray of bool
        True for points in a raised patch (never the largest patch).

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(0)
    >>> xy = g.uniform(0, 80, (8000, 2))
    >>> z = 0.2 * xy[:, 0] + g.normal(0, 0.03, 8000)
    >>> roof = (np.abs(xy - 40) < 12).all(axis=1)
    >>> z[roof] += 7
    >>> r = raised_patches(xy, z)
    >>> bool(r[roof].mean() > 0.95 and r[~roof].mean() < 0.01)
    True
    """
    from scipy.spatial import cKDTree

    xy = np.asarray(xy, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    n = z.size
    if n < 2 * min_points:
        return np.zeros(n, bool)
    kk = min(k + 1, n)
    tree = cKDTree(xy)
    parent = np.arange(n, dtype=np.int64)
    ci, cj, cup = [], [], []
    for s in range(0, n, chunk):
        stop = min(n, s + chunk)
        d, nb = tree.query(xy[s:stop], k=kk, workers=-1)
        i, j, up = _join_smooth(parent, z, nb, d, s, step, slope)
        ci.append(i)
        cj.append(j)
        cup.append(up)
    lab, ncomp = _component_labels(parent)
    ci, cj, cup = np.concatenate(ci), np.concatenate(cj), np.concatenate(cup)
    other = lab[ci] != lab[cj]
    li = lab[ci[other]]
    up = cup[other]
    n_above = np.bincount(li[up], minlength=ncomp)
    n_step = np.bincount(li, minlength=ncomp)
    size = np.bincount(lab, minlength=ncomp)
    raised = (n_step > 0) & (n_above >= above_fraction * n_step) & (size >= min_points)
    raised[np.argmax(size)] = False
    return raised[lab]


@njit
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit
def _join_smooth(parent, z, nb, d, start, step, slope):
    """Union the smooth kNN edges of rows ``start..`` into `parent`; return the others.

    Row ``r`` of `nb`/`d` is point ``start + r``; column 0 is the point itself.  An edge
    is smooth when ``|z[j] - z[i]| <= step + slope * d``.  Returns the non-smooth edges
    (i, j as int32, and whether i is the higher end) in row order.
    """
    m, kk = nb.shape
    n_cut = 0
    for r in range(m):
        i = start + r
        for c in range(1, kk):
            j = nb[r, c]
            if abs(z[j] - z[i]) <= step + slope * d[r, c]:
                a = _find(parent, i)
                b = _find(parent, j)
                if a != b:
                    if a < b:
                        parent[b] = a
                    else:
                        parent[a] = b
            else:
                n_cut += 1
    ci = np.empty(n_cut, np.int32)
    cj = np.empty(n_cut, np.int32)
    up = np.empty(n_cut, np.bool_)
    t = 0
    for r in range(m):
        i = start + r
        for c in range(1, kk):
            j = nb[r, c]
            dz = z[j] - z[i]
            if not abs(dz) <= step + slope * d[r, c]:
                ci[t] = i
                cj[t] = j
                up[t] = dz < 0
                t += 1
    return ci, cj, up


@njit
def _component_labels(parent):
    """Component ids numbered by each component's lowest point index (scipy's order)."""
    n = parent.size
    lab = np.empty(n, np.int64)
    root_label = np.full(n, -1, np.int64)
    nlab = 0
    for i in range(n):
        root = _find(parent, i)
        if root_label[root] < 0:
            root_label[root] = nlab
            nlab += 1
        lab[i] = root_label[root]
    return lab, nlab
