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
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    xy = np.asarray(xy, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    n = z.size
    if n < 2 * min_points:
        return np.zeros(n, bool)
    kk = min(k + 1, n)
    tree = cKDTree(xy)
    si, sj, ci, cj, cup = [], [], [], [], []
    for s in range(0, n, chunk):
        q = np.arange(s, min(n, s + chunk))
        d, nb = tree.query(xy[q], k=kk, workers=-1)
        i = np.repeat(q, kk - 1).astype(np.int32)
        j = nb[:, 1:].ravel().astype(np.int32)
        dz = z[j] - z[i]
        ok = np.abs(dz) <= step + slope * d[:, 1:].ravel()
        si.append(i[ok])
        sj.append(j[ok])
        ci.append(i[~ok])
        cj.append(j[~ok])
        cup.append(dz[~ok] < 0)  # i higher than j
    si, sj = np.concatenate(si), np.concatenate(sj)
    g = coo_matrix((np.ones(si.size, np.int8), (si, sj)), shape=(n, n))
    del si, sj
    ncomp, lab = connected_components(g, directed=False)
    del g
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
