"""Segment-level plane models: border refinement and strip segments (seed 003, part 4).

Region growing decides point by point from neighbourhoods, and next to a crease a
neighbourhood straddles it: on a terrestrial scan whose rows run along a horizontal crease
(a fascia under the roof's edge), a roof point's small planar prefix may hold the first row
of the fascia (two parallel rows are always coplanar), and the fascia's row joins the roof.
Once the segments exist their own planes decide instead:

* :func:`segment_plane_models` fits a plane to every segment (total least squares, one
  round of trimming at 3 noise units, refitted on the inliers) and measures it against the noise model: the
  residual of point i from plane (n, c) in noise units is
  ``r_i = |n . (p_i - c)| / s_i(n)`` with ``s_i(n) = sigma_i |d_i . n|`` (floored at
  ``0.1 sigma_i``) for range noise along the unit ray ``d_i``, else ``sigma_i``. A segment
  is *planar* when at least 90 % of its points are inliers (``r <= 3``) and their RMS in
  noise units is at most 2.
* :func:`refine_borders` moves a point of planar segment A that touches planar segment B
  (a kNN neighbour in B) to B when it is an outlier of A's plane (``r_A > 3``) and an
  inlier of B's (``r_B <= 3``), the best-fitting B winning; planes are refitted and this is
  repeated. This is the paper's reintegration of near-edge points "into the segment whose
  local surface they fit", applied to the points the growing put on the wrong side too.
* :func:`strip_segments` finds faces too narrow for any planar neighbourhood: points left
  unlabelled are linked to their unlabelled neighbours, each connected strip gets one
  plane and is a segment when that plane is *identified* and *passes the plane test*
  (see the function).
"""

from __future__ import annotations

import numpy as np
from scipy import special as _sp

from .._shared._jit import kernel_array, njit


def _rays(points, sensor):
    if sensor is None:
        return None
    d = points - np.asarray(sensor, dtype=np.float64)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)


@njit
def _seg_moments(pts, lab, w, s):
    """Per segment (ids 1..s): weight sum, first and second moments about the segment's
    first point (no cancellation for coordinates far from the origin)."""
    ref = np.full((s, 3), np.nan)
    mom = np.zeros((s, 10))
    for i in range(lab.size):
        g = lab[i] - 1
        if g < 0 or w[i] == 0.0:
            continue
        if np.isnan(ref[g, 0]):
            ref[g, 0], ref[g, 1], ref[g, 2] = pts[i, 0], pts[i, 1], pts[i, 2]
        x, y, z = pts[i, 0] - ref[g, 0], pts[i, 1] - ref[g, 1], pts[i, 2] - ref[g, 2]
        m = mom[g]
        m[0] += 1.0
        m[1] += x
        m[2] += y
        m[3] += z
        m[4] += x * x
        m[5] += x * y
        m[6] += x * z
        m[7] += y * y
        m[8] += y * z
        m[9] += z * z
    return ref, mom


def _planes(ref, mom):
    """Centroids, unit normals (smallest eigenvector) and eigenvalues from moments."""
    n = np.maximum(mom[:, 0], 1.0)
    c = mom[:, 1:4] / n[:, None]
    cov = np.empty((len(mom), 3, 3))
    k = 4
    for a in range(3):
        for b in range(a, 3):
            v = mom[:, k] / n - c[:, a] * c[:, b]
            cov[:, a, b] = v
            cov[:, b, a] = v
            k += 1
    ev, evec = np.linalg.eigh(cov)
    return np.nan_to_num(ref) + c, evec[:, :, 0], ev


@njit
def _residual_units(pts, lab, normal, cen, sig, rays, has_rays, out):
    """``|n_L . (p - c_L)| / s_i(n_L)`` of every point on its own segment L (NaN off).

    Serial: a few arithmetic operations per point, less than a parallel launch costs on
    a loaded machine."""
    for i in range(lab.size):
        g = lab[i] - 1
        if g < 0:
            out[i] = np.nan
            continue
        out[i] = _unit(pts, i, normal[g], cen[g], sig, rays, has_rays)


@njit
def _unit(pts, i, nrm, c, sig, rays, has_rays):
    res = abs((pts[i, 0] - c[0]) * nrm[0] + (pts[i, 1] - c[1]) * nrm[1] +
              (pts[i, 2] - c[2]) * nrm[2])
    s = sig[i]
    if has_rays:
        s = max(s * abs(rays[i, 0] * nrm[0] + rays[i, 1] * nrm[1] + rays[i, 2] * nrm[2]),
                0.1 * s)
    return res / max(s, 1e-300)


@njit
def _propagate(pts, indptr, indices, rows, labels, cand, planar, normal, cen, sig, rays,
               has_rays, nsigma, max_sweeps, moved):
    """Sweeps over the candidate rows: a candidate p (an outlier of its own plane) moves
    to the best-fitting planar segment among its neighbours' labels when it is an inlier
    there; repeated while something moves (a move can bring the next point into reach)."""
    pos = np.full(labels.size, -1, dtype=np.int64)
    for r in range(rows.size):
        pos[rows[r]] = r
    todo = np.flatnonzero(cand)
    for _ in range(max_sweeps):
        changed = 0
        for p in todo:
            if not cand[p]:
                continue
            r = pos[p]
            if r < 0:
                continue
            own = labels[p]
            best = nsigma
            bl = 0
            for e in range(indptr[r], indptr[r + 1]):
                lq = labels[indices[e]]
                if lq <= 0 or lq == own or not planar[lq - 1]:
                    continue
                u = _unit(pts, p, normal[lq - 1], cen[lq - 1], sig, rays, has_rays)
                if u <= best:
                    best = u
                    bl = lq
            if bl > 0:
                labels[p] = bl
                cand[p] = False
                moved[p] = True
                changed += 1
        if changed == 0:
            break


@njit
def _seg_stats(lab, r, nsigma, s):
    """Per segment: points, inliers (r <= nsigma) and the inliers' sum of r^2."""
    n = np.zeros(s)
    ni = np.zeros(s)
    ss = np.zeros(s)
    for i in range(lab.size):
        g = lab[i] - 1
        if g < 0:
            continue
        n[g] += 1.0
        if r[i] <= nsigma:
            ni[g] += 1.0
            ss[g] += r[i] * r[i]
    return n, ni, ss


def _trim_weights(lab, r, nsigma, s):
    """1 for the inliers, 0 for the rest; all 1 in a segment with fewer than 3 inliers
    (it keeps its plain fit)."""
    w = (r <= nsigma).astype(np.float64)
    _, ni, _ = _seg_stats(lab, r, nsigma, s)
    few = np.r_[False, ni < 3]
    w[few[lab]] = 1.0
    return w


class PlaneModels:
    """Trimmed planes of the segments of `labels` (see :func:`segment_plane_models`)."""

    def __init__(self, points, labels, sigma, sensor=None, nsigma=3.0):
        # C, writable arrays: the one type the kernels are compiled for
        self.pts = kernel_array(points)
        self.sig = kernel_array(np.broadcast_to(np.asarray(sigma, dtype=np.float64),
                                                (self.pts.shape[0],)))
        r = _rays(self.pts, sensor)
        self.has_rays = r is not None
        self.rays = np.ascontiguousarray(r) if r is not None else np.zeros((1, 3))
        self.nsigma = float(nsigma)
        self.fit(labels)

    def units(self, labels):
        """Residual of every point from its own segment's plane, in noise units."""
        out = np.empty(labels.size)
        _residual_units(self.pts, np.ascontiguousarray(labels, dtype=np.int64), self.normal,
                        self.centroid, self.sig, self.rays, self.has_rays, out)
        return out

    def fit(self, labels):
        lab = np.ascontiguousarray(labels, dtype=np.int64)
        s = int(lab.max()) if lab.size else 0
        self.labels = lab
        w = np.ones(lab.size)
        for it in range(2):  # fit, trim at nsigma, refit on the inliers
            ref, mom = _seg_moments(self.pts, lab, w, s)
            self.centroid, self.normal, self.eigenvalues = _planes(ref, mom)
            self.centroid = np.ascontiguousarray(self.centroid)
            self.normal = np.ascontiguousarray(self.normal)
            r = self.units(lab)
            if it == 0:
                w = _trim_weights(lab, r, self.nsigma, s)
        n, ni, ss = _seg_stats(lab, r, self.nsigma, s)
        self.n_points = n.astype(np.int64)
        self.inlier_fraction = ni / np.maximum(n, 1)
        self.rms_units = np.sqrt(ss / np.maximum(ni, 1))
        self.planar = (self.inlier_fraction >= 0.9) & (self.rms_units <= 2.0) & (ni >= 3)
        self.r = r
        return self

    def as_dict(self):
        return {"centroid": self.centroid, "normal": self.normal, "n_points": self.n_points,
                "inlier_fraction": self.inlier_fraction, "rms_units": self.rms_units,
                "planar": self.planar}

    def outliers(self):
        """Points of planar segments beyond `nsigma` noise units from their plane."""
        lab = self.labels
        out = np.zeros(lab.size, dtype=bool)
        ins = lab > 0
        out[ins] = self.planar[lab[ins] - 1] & (self.r[ins] > self.nsigma)
        return out


def segment_plane_models(points, labels, sigma, *, sensor=None, nsigma=3.0):
    """A trimmed plane per segment and whether the noise model accepts it.

    Parameters
    ----------
    points : (N, 3) ndarray
    labels : (N,) ndarray of int
        Segment ids 1..S, 0 for none.
    sigma : float or (N,) array_like
        Noise std per point (along the rays with a `sensor`, else across the surface).
    sensor : (3,) array_like, optional
    nsigma : float
        Trimming distance in noise units.

    Returns
    -------
    dict of str -> (S,) or (S, 3) ndarray
        ``centroid``, ``normal`` (unit), ``n_points``, ``inlier_fraction``, ``rms_units``
        (RMS of the inliers' residuals in noise units) and ``planar``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = np.c_[rng.uniform(0, 1, (500, 2)), rng.normal(0, 0.01, 500)]
    >>> m = segment_plane_models(p, np.ones(500, dtype=int), 0.01)
    >>> bool(m["planar"][0]), round(abs(float(m["normal"][0, 2])), 3)
    (True, 1.0)
    """
    return PlaneModels(points, labels, sigma, sensor, nsigma).as_dict()


def plane_outliers(points, labels, sigma, *, sensor=None, nsigma=3.0):
    """Points of planar segments farther than `nsigma` noise units from their plane."""
    return PlaneModels(points, labels, sigma, sensor, nsigma).outliers()


def refine_borders(points, labels, nbh, sigma, *, sensor=None, nsigma=3.0, rounds=1,
                   models=None):
    """Move border points to the touching planar segment whose plane they fit.

    A point of planar segment A with a neighbour (in `nbh`) in planar segment B moves to B
    when its residual from A's plane exceeds `nsigma` noise units and its residual from B's
    plane does not (the smallest residual among such B wins); sweeps repeat while points
    move (a moved point brings the next into reach). Planes are then refitted; with
    ``rounds > 1`` the whole is repeated on the refitted planes (one round gives the same
    labels on the synthetic scenes).

    Returns
    -------
    labels : (N,) ndarray of int32
        Refined labels (same ids; no segment is created or renumbered).
    moved : (N,) ndarray of bool
        Points whose segment changed.
    models : PlaneModels
        The planes of the returned labels.
    """
    lab = np.ascontiguousarray(labels, dtype=np.int64).copy()
    m = models if models is not None else PlaneModels(points, lab, sigma, sensor, nsigma)
    moved = np.zeros(lab.size, dtype=bool)
    for _ in range(rounds):
        cand = m.outliers()
        if not cand.any():
            break
        before = moved.sum()
        _propagate(m.pts, nbh.indptr, nbh.indices, np.ascontiguousarray(nbh.query_indices()),
                   lab, cand, np.ascontiguousarray(m.planar), m.normal, m.centroid, m.sig,
                   m.rays, m.has_rays, m.nsigma, 50, moved)
        if moved.sum() == before:
            break
        m.fit(lab)
    return lab.astype(np.int32), moved, m


def _across(sig, rays, idx, normal):
    """Noise std across planes with unit normals `normal` (rows) at points `idx`."""
    if rays is None:
        return sig[idx] if normal.ndim == 2 else sig[idx][None, :] + 0 * normal[:, :1]
    if normal.ndim == 2 and normal.shape[0] == idx.size:
        c = np.abs(np.einsum("ij,ij->i", rays[idx], normal))
        return np.maximum(sig[idx] * c, 0.1 * sig[idx])
    c = np.abs(normal @ rays[idx].T)  # (H, n): every hypothesis at every point
    return np.maximum(sig[idx][None, :] * c, 0.1 * sig[idx][None, :])


def _ransac_plane(x, sig, rays, idx, rng, nsigma, hypotheses=256):
    """The plane (normal, point) of three sampled points with the most inliers."""
    n = idx.size
    tri = np.stack([rng.choice(n, 3, replace=False) for _ in range(hypotheses)])
    p0, p1, p2 = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    nrm = np.cross(p1 - p0, p2 - p0)
    ln = np.linalg.norm(nrm, axis=1)
    good = ln > 1e-12
    if not good.any():
        return None
    nrm, p0 = nrm[good] / ln[good, None], p0[good]
    res = np.abs(x @ nrm.T - np.einsum("ij,ij->i", p0, nrm)[None, :]).T  # (H, n)
    score = (res <= nsigma * _across(sig, rays, idx, nrm)).sum(axis=1)
    b = int(np.argmax(score))
    return nrm[b], p0[b]


def _link_groups(points, free, nbh, reach):
    """Connected groups of the `free` points, two being linked within `reach` times the
    larger of their k-th neighbour distances (a narrow face seen on a row or two has gaps
    along it where no row hits it; its pieces must still meet). Returns the group of every
    point (0 off `free`) and the link graph over the free points (CSR, free-point order).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(free)
    k = np.diff(nbh.indptr)
    last = nbh.distances[np.maximum(nbh.indptr[1:] - 1, 0)]
    rk = np.where(k > 0, last, 0.0)[idx] if len(nbh) == free.size else np.zeros(idx.size)
    a, b = _link_pairs(points[idx], reach * rk)
    g = coo_matrix((np.ones(a.size, dtype=np.int8), (a, b)),
                   shape=(idx.size, idx.size)).tocsr()
    _, c = connected_components(g, directed=False)
    out = np.zeros(free.size, dtype=np.int64)
    out[idx] = c + 1
    pos = np.full(free.size, -1, dtype=np.int64)
    pos[idx] = np.arange(idx.size)
    return out, (g, pos)


def _link_pairs(p, r, block=16384, ratio=1.25):
    """The pairs ``i < j`` of `p` with ``|p_i - p_j| <= max(r_i, r_j)``, each once.

    Every point is searched with its own radius, never with the largest: on airborne data
    a few isolated points reach metres, and one search at their radius over every point
    holds hundreds of millions of pairs. Points are searched in blocks of nearly equal
    radii (within `ratio`, at most `block` points) against all points; a block's pairs are
    cut to the query's own radius at once, so only the graph's own pairs are ever held.
    A pair is kept from the query of its smaller index when within that point's radius,
    else from the other's (points of radius 0 are not searched: their pairs come from the
    other point's search).
    """
    from scipy.spatial import cKDTree

    m = p.shape[0]
    if m < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    tree = cKDTree(p)
    order = np.argsort(r, kind="stable")
    rs = r[order]
    a_parts, b_parts = [], []
    start = int(np.searchsorted(rs, 0.0, side="right"))  # radius 0 links through others
    while start < m:
        stop = int(np.searchsorted(rs, rs[start] * ratio, side="right"))
        stop = min(max(stop, start + 1), start + block)
        q = order[start:stop]
        sdm = cKDTree(p[q]).sparse_distance_matrix(tree, float(rs[stop - 1]),
                                                   output_type="ndarray")
        qi, j, d = q[sdm["i"]], sdm["j"].astype(np.int64), sdm["v"]
        other = (r[j] > 0) & (d <= r[j])  # the pair the query of j keeps
        keep = (d <= r[qi]) & (qi != j) & ((j > qi) | ~other)
        qi, j = qi[keep], j[keep]
        a_parts.append(np.minimum(qi, j))
        b_parts.append(np.maximum(qi, j))
        start = stop
    return np.concatenate(a_parts), np.concatenate(b_parts)


def _pieces(link, members, min_points):
    """Connected pieces (ids 1.., by size; 0 below `min_points`) of `members` in `link`."""
    from scipy.sparse.csgraph import connected_components

    from ._grow import relabel

    g, pos = link
    p = pos[members]
    _, c = connected_components(g[p][:, p], directed=False)
    return relabel(c + 1, min_points=min_points)


def strip_segments(points, labels, nbh, sigma, *, candidates, sensor=None, alpha=0.05,
                   nsigma=3.0, min_points=50, max_planes=4, reach=2.0, seed=0):
    """Segments of narrow faces: planes through connected strips of unlabelled points.

    On a face narrower than the smallest planar neighbourhood (the soffit under the eaves,
    seen on one or two scan rows) every neighbourhood is nearly a line: its own plane is
    not identified, so no point passes a plane test and region growing never starts
    there. A plane *is* identified by the whole strip as soon as its points do not lie on
    one line: two rows, or one row on a curve (a scan row on a plane is a conic, a circle
    arc on a horizontal face). So the `candidates` (the points no segment explains:
    unlabelled, or outliers of their segment's plane, :func:`plane_outliers`) are linked
    to the candidates of their neighbourhood rows; in every connected group of at
    least `min_points` points, planes are sought by RANSAC (three points, inliers within
    `nsigma` noise units across the hypothesis; deterministic with `seed`), refined by
    total least squares on their inliers, and each becomes a segment when

    1. the plane is identified: the inliers' spread along the plane's second direction
       e1 (the middle eigenvector) is more than the noise along e1 makes,
       ``sum_i ((q_i . e1) / s_i(e1))^2 > chi2_{1-alpha}(m - 2)`` (m inliers, q centred,
       ``s_i(e1)`` the noise std along e1 as for a normal; under "the strip is a straight
       line" that sum is about chi2(m - 2)), and
    2. the plane passes the plane test on its m inliers: ``sum r_i^2 <=
       chi2_{1-alpha}(m - 3)`` (r in noise units), with ``m >= min_points``.

    The inliers of an accepted plane leave the group and the search goes on (at most
    `max_planes` per group).

    Returns
    -------
    (N,) ndarray of int32
        Labels with the accepted planes added as new ids after the existing ones.
    """
    from ._grow import relabel

    labels = np.asarray(labels).astype(np.int32, copy=True)
    pts = np.asarray(points, dtype=np.float64)
    sig = kernel_array(np.broadcast_to(np.asarray(sigma, dtype=np.float64), labels.shape))
    free = np.asarray(candidates, dtype=bool)
    if free.sum() < min_points:
        return labels
    comp, link = _link_groups(pts, free, nbh, reach)
    comp = relabel(comp, min_points=min_points)
    if not comp.any():
        return labels
    rays = _rays(pts, sensor)
    rng = np.random.default_rng(seed)
    order = np.argsort(comp, kind="stable")
    bounds = np.searchsorted(comp[order], np.arange(1, comp.max() + 2))
    nxt = labels.max() + 1
    for g in range(comp.max()):  # groups of unlabelled points, not points
        rest = order[bounds[g]:bounds[g + 1]]
        for _ in range(max_planes):
            if rest.size < min_points:
                break
            org = pts[rest].mean(axis=0)
            hyp = _ransac_plane(pts[rest] - org, sig, rays, rest, rng, nsigma)
            if hyp is None:
                break
            nrm, p0 = hyp
            inl = None
            for _ in range(3):  # TLS on the inliers, twice
                r = np.abs((pts[rest] - org - p0) @ nrm) / _across(sig, rays, rest,
                                                                  np.tile(nrm, (rest.size, 1)))
                new = r <= nsigma
                if new.sum() < 3 or (inl is not None and np.array_equal(new, inl)):
                    break
                inl = new
                q = pts[rest[inl]] - org
                p0 = q.mean(axis=0)
                ev, evec = np.linalg.eigh(np.cov(q.T))
                nrm = evec[:, 0]
            if inl is None or inl.sum() < min_points:
                break
            m = int(inl.sum())
            q = pts[rest[inl]] - org - p0
            q = q - q.mean(axis=0)
            e1 = np.linalg.eigh(np.cov(q.T))[1][:, 1]  # the strip's second direction
            r = np.abs(q @ nrm) / _across(sig, rays, rest[inl], np.tile(nrm, (m, 1)))
            # "the strip is a line": its spread along e1 is the noise along e1 only
            t1 = (q @ e1) / _across(sig, rays, rest[inl], np.tile(e1, (m, 1)))
            identified = float(np.sum(t1 * t1)) > _sp.chdtri(m - 2.0, alpha)
            passes = float(np.sum(r * r)) <= _sp.chdtri(m - 3.0, alpha)
            if not (identified and passes):
                break
            # an accepted plane is a segment per connected piece of its inliers
            piece = _pieces(link, rest[inl], min_points)
            for k in range(1, piece.max() + 1):
                labels[rest[inl][piece == k]] = nxt
                nxt += 1
            rest = rest[~inl]
    return labels
