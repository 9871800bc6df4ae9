"""SAR-FS refinement of one raw cluster within its search area (seed 002, sections 2-3).

1. Spatial weights W: row-standardised binary adjacency of points within `w_radius` in
   plan (the paper's binary W; row standardisation makes rho lie in (-1, 1), which the
   paper's grid over [0, 1] assumes).
2. Polynomial order by t tests on an orthogonal basis over the raw cluster (or given).
3. ML fit of ``z = rho W z + A theta + eps`` on the raw cluster (n_s points).
4. Forward Search over the search area (n_sa points) on ``y = (I - rho W) z`` with rho
   held at its raw-cluster value: each step is a rank-one least-squares update, the paper's
   F test of ``theta(m) - theta(n_s)`` and the deletion-residual envelope are monitored.
5. theta and sigma^2 re-estimated on the m accepted points (eq. 3.1-3.2, rho from step
   3); the surface reported is the least-squares trend of the accepted points, the
   direct estimate of the polynomial closest to the SAR mean ``(I - rho W)^-1 A theta``,
   with its covariance under the SAR model (:func:`lidarstat.stats.sar_trend`).
   :func:`lidarstat.segment.refine_raw_clusters` refits every final segment (rho by ML
   included) on its final points.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .._shared._deprecate import renamed_parameters
from ..stats import PolynomialBasis, SARFit, sar_fit, sar_trend, select_degree, z_critical
from ._forward_search import forward_search
from ._sar_unit import SurfaceUnit

#: Largest subset on which rho is estimated by full ML; larger clusters estimate rho on
#: their `SAR_MAX` points nearest to the medoid (a contiguous patch) and theta on all.
SAR_MAX = 3000
#: Units whose raw cluster's normal is more than this many degrees from vertical (walls)
#: are modelled in their own frame (:func:`refine_cluster`, ``frame='auto'``).
FRAME_SLOPE = 70.0
#: Largest raw cluster the Forward Search grows (see :func:`refine_cluster`).
MAX_SEARCH = 20000


def _adjacency(xy, radius):
    """Binary adjacency (CSR, no self-pairs) of points within `radius` in plan."""
    n = xy.shape[0]
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray")
    i = np.r_[pairs[:, 0], pairs[:, 1]]
    j = np.r_[pairs[:, 1], pairs[:, 0]]
    return sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))


def _standardised(B, idx=None):
    """Row-standardised weights of the binary adjacency `B` restricted to `idx`."""
    if idx is not None:
        B = B[idx][:, idx]
    rs = np.asarray(B.sum(axis=1)).ravel()
    with np.errstate(divide="ignore"):
        inv = np.where(rs > 0, 1.0 / rs, 0.0)
    return sp.csr_matrix(sp.diags(inv) @ B)


#: Half-width of the rho interval searched when a previous estimate is known (the refit
#: of a final segment starts from its raw cluster's rho).
RHO_WINDOW = 0.2


def _ml_fit(z, A, xy, B, rho_hint=None, covariance=True):
    """ML SAR fit (binary adjacency `B` of the points); above SAR_MAX points rho comes
    from a contiguous patch.

    With `rho_hint` the profile likelihood is searched on a 5-point grid over
    ``rho_hint +- RHO_WINDOW`` (then refined), not over the whole admissible interval;
    if the maximum falls on the window's edge the whole interval is searched."""
    n = z.size
    if n > SAR_MAX:
        med = np.median(xy, axis=0)
        patch = np.argsort(np.sum((xy - med) ** 2, axis=1))[:SAR_MAX]
        z_s, A_s, W = z[patch], A[patch], _standardised(B, patch)
    else:
        z_s, A_s, W = z, A, _standardised(B)
    sub = None
    if rho_hint is not None and np.isfinite(rho_hint):
        lo, hi = max(rho_hint - RHO_WINDOW, -0.999), min(rho_hint + RHO_WINDOW, 0.999)
        sub = sar_fit(z_s, A_s, W, bounds=(lo, hi), grid=5, xatol=1e-6,
                      covariance=covariance)
        if min(sub.rho - lo, hi - sub.rho) < 1e-3 * (hi - lo):
            sub = None  # on the edge of the window: search everywhere
    if sub is None:
        sub = sar_fit(z_s, A_s, W, covariance=covariance)
    if n <= SAR_MAX:
        return sub, n
    return _conditional_fit(z, A, _standardised(B), sub), SAR_MAX


def _conditional_fit(z, A, W, ref):
    """theta and sigma^2 by eq. 3.1-3.2 with rho fixed at ``ref.rho`` (covariance given rho)."""
    n, r = A.shape
    ystar = z - ref.rho * (W @ z)
    theta, *_ = np.linalg.lstsq(A, ystar, rcond=None)
    resid = ystar - A @ theta
    s2 = float(resid @ resid / n)
    cov = np.full((r + 2, r + 2), np.nan)
    cov[:r, :r] = s2 * np.linalg.inv(A.T @ A)
    cov[r, r] = ref.cov[r, r] if ref.cov.shape[0] == r + 2 else np.nan
    cov[r + 1, r + 1] = 2.0 * s2 * s2 / n
    return SARFit(theta, ref.rho, s2, cov, np.nan, resid, n, "conditional", ref.profile)


@renamed_parameters(alpha_residual="envelope_alpha")
def refine_cluster(points, raw, extra, *, w_radius, degree=1, max_degree=3, alpha=0.01,
                   envelope_alpha=0.001, stop="both", block=1, max_steps=500,
                   max_search=MAX_SEARCH, rho_hint=None, frame="auto", covariance=True):
    """Refine one raw cluster by SAR-FS within its search area.

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    raw : (n_s,) ndarray of int
        Indices of the raw cluster.
    extra : ndarray of int
        Indices of the other points of its search area (disjoint from `raw`).
    w_radius : float
        Planimetric radius of the SAR adjacency W.
    degree : int or None
        Polynomial order; None chooses it by t tests up to `max_degree`.
    alpha, envelope_alpha, stop, block, max_steps
        Forward Search settings (:func:`forward_search`); `alpha` is also the level of
        the t tests of the order when `degree` is None.
    max_search : int
        Raw clusters larger than this (terrain, large flat roofs) are not searched: the
        unit is the raw cluster (``m = n_s``, ``fs_stop`` 3), which bounds the cost of the
        O(n_sa) steps.
    rho_hint : float, optional
        A previous estimate of rho: the ML search starts in a window around it.
    frame : {'auto', 'z'}
        'z': the paper's height field z(E, N). 'auto': the same, unless the raw cluster's
        principal-axis normal is more than :data:`FRAME_SLOPE` degrees from vertical
        (walls, facades), where z(E, N) degenerates (the points are nearly collinear in
        plan); such a unit is modelled as a height field over its own plane (heights
        along the normal, W and the search in the plane's coordinates).
    covariance : bool
        Compute the standard errors (information matrix of the ML fit, sandwich of the
        surface). False leaves them NaN: :func:`refine_raw_clusters` refits every final
        segment, so the search stage skips them.

    Returns
    -------
    SurfaceUnit
    """
    raw, extra, area, rows, origin, xy_area, z_area = _local_frame(points, raw, extra, frame)
    in_raw = np.zeros(area.size, dtype=bool)
    in_raw[:raw.size] = True
    xy_raw, z_raw = xy_area[in_raw], z_area[in_raw]
    B_area = _adjacency(xy_area, w_radius)
    raw_idx = np.flatnonzero(in_raw)
    B_raw = B_area[raw_idx][:, raw_idx] if extra.size else B_area
    if degree is None:
        degree, _, basis = select_degree(z_raw, xy_raw, _standardised(B_raw),
                                         max_degree=max_degree, alpha=alpha)
        basis = PolynomialBasis.fit(xy_raw, degree)
    else:
        basis = PolynomialBasis.fit(xy_raw, int(degree))
    A_area = basis(xy_area)
    fit0, rho_points = _ml_fit(z_raw, A_area[in_raw], xy_raw, B_raw, rho_hint, covariance)
    W_area = _standardised(B_area)
    ystar = z_area - fit0.rho * (W_area @ z_area)
    if raw.size > max_search:
        in_raw = in_raw[:raw.size]
        A_area, ystar, z_area, xy_area, area = (A_area[:raw.size], ystar[:raw.size],
                                                z_area[:raw.size], xy_area[:raw.size],
                                                area[:raw.size])
        max_steps = 1
    fs = forward_search(A_area, ystar, in_raw, block=block, alpha=alpha,
                        envelope_alpha=envelope_alpha, stop=stop, max_steps=max_steps)
    if raw.size > max_search:
        fs = dataclasses.replace(fs, stop_reason="not searched")
    acc = fs.accepted
    full = acc.size == W_area.shape[0] and acc.all()
    W_acc = W_area if full else _standardised(B_area, np.flatnonzero(acc))
    fit = _conditional_fit(z_area[acc], A_area[acc], W_acc, fit0)
    surface, cov = sar_trend(z_area[acc], A_area[acc], W_acc, fit.rho, fit.sigma2,
                             covariance=covariance)
    r = basis.n_terms
    res = z_area[acc] - A_area[acc] @ surface
    sigma = float(np.sqrt(res @ res / max(acc.sum() - r, 1)))
    basis, surface = _to_file_coordinates(basis, surface, origin)
    return SurfaceUnit(area[acc], res, int(raw.size), int(raw.size + extra.size),
                       int(acc.sum()), int(degree), basis, fit, surface, cov, sigma, fs,
                       int(rho_points), raw, rows)


def _local_frame(points, raw, extra, frame):
    """Indices (raw first) and local coordinates of a unit: the wall frame of the raw
    cluster when `frame` is 'auto' and it is steep, shifted to the area's minimum."""
    raw = np.asarray(raw, dtype=np.int64)
    extra = np.asarray(extra, dtype=np.int64)
    area = np.concatenate([raw, extra])
    coords = points[area]
    rows = _steep_frame(points[raw]) if frame == "auto" else None
    if rows is not None:
        coords = (coords - rows[0]) @ rows[1:].T
    origin = coords.min(axis=0)
    return raw, extra, area, rows, origin, coords[:, :2] - origin[:2], coords[:, 2] - origin[2]


def _to_file_coordinates(basis, surface, origin):
    """Basis centre and constant term shifted from the local origin back to the file's."""
    basis = PolynomialBasis(basis.degree, basis.center + origin[:2], basis.scale, basis.R,
                            basis.powers)
    surface = surface.copy()
    # orthogonal column 0 is constant (= 1 / R00): add the origin height
    surface[0] += origin[2] * basis.R[0, 0]
    return basis, surface


#: Level of the Wald test of rho = 0 that decides whether the surface covariance uses
#: the SAR dependence (:func:`refit_unit`).
RHO_ALPHA = 0.05


def _trend(z, A, W, fit, covariance):
    """Least-squares trend of a raw cluster and its covariance.

    When the Wald test of rho = 0 rejects at :data:`RHO_ALPHA`, the covariance is the
    SAR sandwich (:func:`lidarstat.stats.sar_trend`) with the innovation variance
    corrected to ``n/(n - r)`` of its ML value. Otherwise the data do not show the
    dependence and the covariance is the ordinary ``s^2 (A'A)^-1`` (``s^2`` with n - r
    degrees of freedom): a spurious negative rho (edge effects of the row-standardised W
    on a small face) would shrink the sandwich by up to ``(1 - rho)^2`` and the confidence
    cones of the normals would cover the true normal too rarely (measured on the
    synthetic town: 49 of 57 at 95 % with the sandwich always, docs/methods/sar.md).
    """
    n, r = A.shape
    if not covariance:
        return sar_trend(z, A, W, fit.rho, fit.sigma2, covariance=False)
    se = fit.se_rho
    dependent = np.isfinite(se) and se > 0 and abs(fit.rho) / se > z_critical(RHO_ALPHA)
    if dependent:
        return sar_trend(z, A, W, fit.rho, fit.sigma2 * n / max(n - r, 1))
    coef, _ = sar_trend(z, A, W, 0.0, 1.0, covariance=False)
    res = z - A @ coef
    return sar_trend(z, A, W, 0.0, float(res @ res) / max(n - r, 1))


def refit_unit(points, raw, extra, *, w_radius, degree=1, rho_hint=None, frame="auto",
               covariance=True, fs=None):
    """A final segment refitted without a search: the surface from its raw cluster only.

    The unit's points are `raw` (its raw cluster, possibly a merged group's) and `extra`
    (the points the Forward Search and the best-fit assignment added). rho and sigma^2
    are fitted by ML on the raw cluster and the surface is the least-squares trend of the
    raw cluster (:func:`lidarstat.stats.sar_trend`) with its SAR covariance; residuals
    are given for every point. The raw cluster is selected by the local planarity and
    growth tests, not by residuals from this surface, whereas the added points are
    selected *by* their residuals (the search admits the smallest, and points near a
    crease go to the unit they fit best): a plane fitted to them is biased towards the
    noise that selection kept (docs/methods/sar.md, "Final refit").

    Returns
    -------
    SurfaceUnit
        ``accepted`` is `raw` then `extra`; ``n_s = n_sa = m`` = their sizes (callers
        restore the Table 6 sizes), ``fs`` as given.
    """
    if np.size(raw) < max(10, 3 * (int(degree) + 1) * (int(degree) + 2) // 2):
        raw, extra = np.concatenate([raw, extra]), np.empty(0, np.int64)  # too few: all
    raw, extra, area, rows, origin, xy_area, z_area = _local_frame(points, raw, extra, frame)
    n_s = raw.size
    xy_raw, z_raw = xy_area[:n_s], z_area[:n_s]
    basis = PolynomialBasis.fit(xy_raw, int(degree))
    A_raw = basis(xy_raw)
    B_raw = _adjacency(xy_raw, w_radius)
    fit, rho_points = _ml_fit(z_raw, A_raw, xy_raw, B_raw, rho_hint, covariance)
    surface, cov = _trend(z_raw, A_raw, _standardised(B_raw), fit, covariance)
    A_area = basis(xy_area)
    res = z_area - A_area @ surface
    if covariance and area.size > n_s:
        # the raw cluster's scatter is biased low (the local planarity test kept its
        # smoothest windows): the noise scale is at least the robust scale of all the
        # unit's residuals, which no test selected (1.4826 MAD, robust to the few points
        # of other surfaces among them)
        s2_raw = float(res[:n_s] @ res[:n_s]) / max(n_s - basis.n_terms, 1)
        mad2 = (1.4826 * float(np.median(np.abs(res)))) ** 2
        if s2_raw > 0 and mad2 > s2_raw:
            cov = cov * (mad2 / s2_raw)
    # sigma: scatter of all the unit's points about their own least-squares surface (as
    # the search stage reports it; the noise re-estimate of segment_sar uses it)
    own = z_area - A_area @ np.linalg.lstsq(A_area, z_area, rcond=None)[0]
    sigma = float(np.sqrt(own @ own / max(area.size - basis.n_terms, 1)))
    basis, surface = _to_file_coordinates(basis, surface, origin)
    return SurfaceUnit(area, res, int(n_s), int(area.size), int(area.size), int(degree),
                       basis, fit, surface, cov, sigma, fs, int(rho_points), raw, rows)


def _steep_frame(xyz):
    """(4, 3) frame [origin; u; v; n] of a point set whose principal-axis normal is more
    than FRAME_SLOPE degrees from vertical, else None."""
    if xyz.shape[0] < 3:
        return None
    c = xyz.mean(axis=0)
    _, vec = np.linalg.eigh(np.cov((xyz - c).T))
    n = vec[:, 0]
    if np.degrees(np.arccos(min(abs(n[2]), 1.0))) <= FRAME_SLOPE:
        return None
    u = np.cross([0.0, 0.0, 1.0], n)
    u /= np.linalg.norm(u)  # horizontal axis in the plane
    v = np.cross(n, u)  # up the plane
    return np.vstack([c, u, v, n])
