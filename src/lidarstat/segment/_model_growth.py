"""Growth of surface units by their fitted models (planes and cylinders).

Units grown from per-point decisions (the tested HK classes) leave out the points whose
own neighbourhood failed its test: next to a crease every neighbourhood at the chosen
scale straddles two faces, so a band a few point spacings wide on each side of every
crease has no tested class, and a narrow face between two creases (the rim of a flange)
keeps a fraction of its points. Once the units exist their *own* models decide instead:
each unit gets one model for all its points, a plane (total least squares, trimmed at 3
noise units, :class:`._refine.PlaneModels`) for planar units, a cylinder
(:func:`._cylinders.segment_cylinders`, kept when the circle beats the line by the F
test, refined by :func:`._cylinders.fit_cylinder`) for curved ones, and the model is
accepted by the noise model (at least 90 % inliers, inlier RMS at most 2 noise units).

An unlabelled point with a neighbour in unit U joins U when its residual from U's model,

    r = |distance to the model| / (sigma max(|d . n|, 0.1)),

with n the model's normal at the point and d the noise direction (``sigma`` alone for
noise along the normal), is at most ``nsigma`` (3); the unit of the smallest residual
wins. Sweeps repeat while points join: each sweep advances the front by one neighbour
ring, so a band of any width on a face is filled while points across a crease stay out
(their residual from the other face's model grows with their distance from the crease).
"""

from __future__ import annotations

import numpy as np

#: Residual (noise units) within which a point fits a unit's model.
NSIGMA = 3.0
#: Most sweeps (neighbour rings) of the growth.
MAX_SWEEPS = 200


def _noise_scale(sigma, dirs, idx, normal):
    """``sigma max(|d . n|, 0.1)`` at the points `idx` (``sigma`` when `dirs` is None);
    `sigma` (N,) per point."""
    if dirs is None:
        return sigma[idx]
    return sigma[idx] * np.maximum(np.abs(np.einsum("ij,ij->i", dirs[idx], normal)), 0.1)


class UnitModels:
    """One model per unit of `labels`: ``kind`` 0 none, 1 plane, 2 cylinder (`sigma` a
    float or one per point)."""

    def __init__(self, points, labels, curved, normals, sigma, *, dirs=None, sensor=None):
        from ._cylinders import refine_cylinder_table, segment_cylinders
        from ._refine import PlaneModels

        self.pts = points
        self.sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (points.shape[0],))
        self.dirs = dirs
        s = int(labels.max()) if labels.size else 0
        planes = PlaneModels(points, labels, sigma, sensor)
        self.centroid, self.normal = planes.centroid, planes.normal
        self.kind = np.where(planes.planar, 1, 0).astype(np.uint8)
        cur = np.zeros(s, dtype=bool)
        cur[:curved.size] = curved[:s]
        self.axis = np.full((s, 3), np.nan)
        self.apoint = np.full((s, 3), np.nan)
        self.radius = np.full(s, np.nan)
        if cur.any():
            lab_c = np.where(cur[np.maximum(labels, 1) - 1] & (labels > 0), labels, 0)
            t = segment_cylinders(points, lab_c, normals, sigma, sensor=sensor)
            t = refine_cylinder_table(points, lab_c, t, sigma, sensor=sensor)
            cyl = np.flatnonzero(np.asarray(t["model"]) == 2)
            cyl = cyl[cur[cyl]]
            self.axis[cyl] = np.c_[t["axis_x"], t["axis_y"], t["axis_z"]][cyl]
            self.apoint[cyl] = np.c_[t["axis_point_x"], t["axis_point_y"],
                                     t["axis_point_z"]][cyl]
            self.radius[cyl] = t["radius"][cyl]
            self.kind[cur] = 0
            self.kind[cyl] = 2
            # a cylinder is kept only when the noise model accepts it on its own unit
            for k in cyl:  # a few curved units, not points
                idx = np.flatnonzero(labels == k + 1)
                r = self.residuals(idx, np.full(idx.size, k + 1))
                ins = r <= NSIGMA
                if ins.mean() < 0.9 or np.sqrt(np.mean(r[ins] ** 2)) > 2.0:
                    self.kind[k] = 0

    def residuals(self, idx, lab):
        """Residuals (noise units) of points `idx` from the models of units `lab`
        (1-based; inf where the unit has no model)."""
        g = lab - 1
        kind = self.kind[g]
        p = self.pts[idx]
        res = np.full(idx.size, np.inf)
        nrm = np.zeros((idx.size, 3))
        pl = kind == 1
        if pl.any():
            n = self.normal[g[pl]]
            res[pl] = np.abs(np.einsum("ij,ij->i", p[pl] - self.centroid[g[pl]], n))
            nrm[pl] = n
        cy = kind == 2
        if cy.any():
            a = self.axis[g[cy]]
            w = p[cy] - self.apoint[g[cy]]
            e = w - np.einsum("ij,ij->i", w, a)[:, None] * a
            rho = np.linalg.norm(e, axis=1)
            res[cy] = np.abs(rho - self.radius[g[cy]])
            nrm[cy] = e / np.maximum(rho, 1e-300)[:, None]
        fit = pl | cy
        res[fit] /= _noise_scale(self.sigma, self.dirs, idx[fit], nrm[fit])
        return res


def free_pairs(nbh, free):
    """The neighbour pairs of both directions that start at a `free` point.

    Equal, pair for pair and in the same order, to ``src[e], dst[e]`` with ``e =
    free[src]`` of ``src, dst = r_[s, d], r_[d, s]`` for ``s, d = nbh.edges()`` (what
    :func:`grow_by_models` keeps of every pair), without those four arrays of one entry
    per pair and direction (32 bytes a CSR entry): the pairs of the free rows, then the
    entries whose neighbour is free, reversed.

    Returns
    -------
    src, dst : (E,) ndarray of int64
    """
    free = np.asarray(free, dtype=bool)
    rows = nbh.query_indices()
    fr = np.flatnonzero(free[rows])
    cnt = nbh.indptr[fr + 1] - nbh.indptr[fr]
    first = np.zeros(fr.size, dtype=np.int64)
    np.cumsum(cnt[:-1], out=first[1:])
    pos = np.repeat(nbh.indptr[fr] - first, cnt) + np.arange(int(cnt.sum()), dtype=np.int64)
    back = np.flatnonzero(free[nbh.indices])
    row_of = np.searchsorted(nbh.indptr, back, side="right") - 1
    src = np.concatenate([np.repeat(rows[fr], cnt), nbh.indices[back]]).astype(np.int64)
    dst = np.concatenate([nbh.indices[pos], rows[row_of]]).astype(np.int64)
    return src, dst


def grow_by_models(points, labels, src, dst, models, *, candidates=None, nsigma=NSIGMA):
    """Give unlabelled points, front by front, the touching unit whose model they fit.

    Parameters
    ----------
    points : (N, 3) ndarray
    labels : (N,) ndarray of int
        Units 1..S, 0 none.
    src, dst : (E,) ndarray of int
        Neighbour pairs (both directions).
    models : UnitModels
        The models of the units of `labels`.
    candidates : (N,) ndarray of bool, optional
        Points that may join (default every unlabelled point).
    nsigma : float
        Largest residual, noise units.

    Returns
    -------
    labels : (N,) ndarray of int32
        Same unit ids, more points.
    joined : (N,) ndarray of bool
        Points that joined a unit.
    """
    lab = np.asarray(labels).astype(np.int32).copy()
    free = (lab == 0) if candidates is None else (np.asarray(candidates) & (lab == 0))
    e = free[src]
    src, dst = src[e], dst[e]
    joined = np.zeros(lab.size, dtype=bool)
    for _ in range(MAX_SWEEPS):
        live = free[src] & (lab[dst] > 0)
        if not live.any():
            break
        p, q = src[live], lab[dst[live]]
        r = models.residuals(p, q)
        ok = r <= nsigma
        if not ok.any():
            break
        p, q, r = p[ok], q[ok], r[ok]
        order = np.lexsort((r, p))
        p, q = p[order], q[order]
        first = np.r_[True, p[1:] != p[:-1]]
        lab[p[first]] = q[first]
        free[p[first]] = False
        joined[p[first]] = True
    return lab, joined
