"""Local plane regression with a tricube kernel over planimetric distances (seed 002, eq. 6-7).

Public pieces: :func:`local_planes` (z0 and the two slopes per point with standard
errors and a planarity test) and :func:`geary_bandwidths` (the adaptive bandwidth of
section 4.1 from Geary's local indicator); the bandwidth itself is chosen by
:func:`lidarstat.features.select_plane_bandwidth` (``_plane_bandwidth.py``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import Neighborhoods, radius_neighbors
from ..stats import chi2_quantile, variance_test_satterthwaite
from . import _plane_kernels as _k


class AdaptiveBandwidth(str, enum.Enum):
    """Per-point bandwidths of :func:`local_planes` (``adaptive``; CLI ``--adaptive``)."""

    #: The largest of b, 0.75 b, 0.5 b whose local plane passes the planarity test.
    MULTISCALE = "multiscale"
    #: From Geary's local indicator (seed 002, section 4.1).
    GEARY = "geary"
    #: One bandwidth b for the whole cloud.
    NONE = "none"

    def __str__(self) -> str:
        return self.value


#: Values of :class:`AdaptiveBandwidth`.
ADAPTIVE_MODES = tuple(m.value for m in AdaptiveBandwidth)
#: Bandwidth ratios tried by the multi-scale choice, largest first.
MULTISCALE = (1.0, 0.75, 0.5)

#: Fields written by :meth:`LocalPlaneFit.to_fields`.
PLANE_FIELDS = ("z0", "slope_e", "slope_n", "se_z0", "se_slope_e", "se_slope_n",
                "plane_p", "plane_pass", "bandwidth", "neighbors")


@dataclass(frozen=True)
class LocalPlaneFit:
    """Per-point local plane fits (eq. 7) with their statistics.

    Attributes
    ----------
    beta : (N, 3) ndarray
        ``[z0, dz/dE, dz/dN]`` per point (NaN where not fitted).
    cofactor : (N, 3, 3) ndarray
        Sandwich cofactor ``N^-1 A'Q^2A N^-1``; ``sigma2 * cofactor`` is the covariance
        of `beta` under independent height noise.
    sigma2 : float
        Noise variance used for the standard errors and the planarity test (given, or
        estimated robustly from the local fits).
    local_sigma2 : (N,) ndarray
        Local unbiased variance ``r'Qr / tr(B)``.
    planarity : TestResult
        Satterthwaite chi-square test of the local plane against `sigma2` (rejects where
        the neighbourhood is not planar: ridges, walls, trees).
    leverage : (N,) ndarray
        ``h_ii``, the weight of ``z_i`` in its own fit.
    resid : (N,) ndarray
        ``z_i - z0_i``; the leave-one-out residual is ``resid / (1 - leverage)``.
    neighbors : (N,) ndarray of int32
        Points with positive weight.
    status : (N,) ndarray of uint8
        0 fitted, 1 too few neighbours, 2 degenerate (collinear or coincident points).
    bandwidth : (N,) ndarray
        Kernel half-width b_i used per point.
    """

    beta: np.ndarray
    cofactor: np.ndarray
    sigma2: float
    local_sigma2: np.ndarray
    planarity: object
    leverage: np.ndarray
    resid: np.ndarray
    neighbors: np.ndarray
    status: np.ndarray
    bandwidth: np.ndarray
    params: dict = field(default_factory=dict)

    @property
    def z0(self) -> np.ndarray:
        """Fitted height at each point."""
        return self.beta[:, 0]

    @property
    def se(self) -> np.ndarray:
        """(N, 3) standard errors of z0 and the two slopes."""
        d = np.diagonal(self.cofactor, axis1=1, axis2=2)
        with np.errstate(invalid="ignore"):
            return np.sqrt(self.sigma2 * d)

    @property
    def ok(self) -> np.ndarray:
        """Points with a fitted plane."""
        return self.status == _k.STATUS_OK

    @property
    def press(self) -> float:
        """Prediction sum of squares (leave-one-out through the hat diagonal)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            loo = self.resid / (1.0 - self.leverage)
        return float(np.nansum(loo[self.ok] ** 2))

    def to_fields(self) -> dict:
        """Per-point fields under the names of :data:`PLANE_FIELDS`."""
        se = self.se
        return {"z0": self.beta[:, 0], "slope_e": self.beta[:, 1], "slope_n": self.beta[:, 2],
                "se_z0": se[:, 0], "se_slope_e": se[:, 1], "se_slope_n": se[:, 2],
                "plane_p": self.planarity.pvalue,
                "plane_pass": (self.ok & ~self.planarity.reject).astype(np.uint8),
                "bandwidth": self.bandwidth, "neighbors": self.neighbors}


def _run_kernel(points, nbh, bandwidth, min_neighbors):
    m = len(nbh)
    query = nbh.query_indices()
    beta = np.full((m, 3), np.nan)
    cof = np.full((m, 3, 3), np.nan)
    stats = np.full((m, 7), np.nan)
    status = np.zeros(m, dtype=np.uint8)
    local = points - points.min(axis=0)  # local origin keeps UTM precision
    _k.fit_planes(local, query, nbh.indptr, nbh.indices, nbh.distances,
                  np.ascontiguousarray(bandwidth, dtype=np.float64), int(min_neighbors),
                  beta, cof, stats, status)
    beta[:, 0] += points.min(axis=0)[2]
    bad = status != _k.STATUS_OK
    beta[bad] = np.nan
    cof[bad] = np.nan
    stats[bad, :5] = np.nan
    return beta, cof, stats, status


#: Query points per chunk: the CSR of one chunk stays a few hundred MB at most.
CHUNK = 200_000


def _chunks(points, radius, query=None):
    """Yield CSR neighbourhoods (2-D discs) of consecutive spatially coherent chunks of
    the query points (all points by default)."""
    from ..neighbors import CellIndex

    n = points.shape[0]
    m = n if query is None else query.size
    if m <= CHUNK:
        yield radius_neighbors(points, radius, dim=2, query=query)
        return
    index = CellIndex(points, radius, dim=2)
    order = index.order
    if query is not None:
        wanted = np.zeros(n, dtype=bool)
        wanted[query] = True
        order = order[wanted[order]]
    for start in range(0, m, CHUNK):
        q = np.sort(order[start:start + CHUNK])
        indptr, idx, dist = index.query(points[q])
        yield Neighborhoods(indptr, idx, dist, n, kind="disc", radius=radius, query=q)


def _chunked(points, radius, bw, min_neighbors, query=None, out=None):
    """Fit the query points (all by default) into `out` (new NaN arrays by default)."""
    n = points.shape[0]
    if out is None:
        out = (np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan), np.full((n, 7), np.nan),
               np.zeros(n, dtype=np.uint8))
    beta, cof, st, status = out
    for nbh in _chunks(points, radius, query):
        q = nbh.query_indices()
        res = _run_kernel(points, nbh, bw[q], min_neighbors)
        beta[q], cof[q], st[q], status[q] = res
    return out


#: Quantile of the local variances used for the noise estimate.
SIGMA_QUANTILE = 0.25


def _robust_sigma2(local_sigma2, nu, q=SIGMA_QUANTILE):
    """Noise variance from the lower quartile of the local variance estimates.

    Under planar noise ``s_i^2 ~ sigma^2 chi2(nu)/nu``, so the q-quantile of the ``s_i^2``
    divided by ``chi2.ppf(q, nu)/nu`` estimates sigma^2. The lower quartile stays right
    when up to three quarters of the points are not on planes (trees, walls, ridges, cars),
    where the median (or the mean) is pulled up by the clutter.
    """
    good = np.isfinite(local_sigma2) & np.isfinite(nu) & (nu > 0)
    if not good.any():
        return np.nan
    med_nu = float(np.median(nu[good]))
    return float(np.quantile(local_sigma2[good], q) / (chi2_quantile(q, med_nu) / med_nu))


def _check_neighborhoods(nbh, n, radius, func):
    if not isinstance(nbh, Neighborhoods):
        raise InvalidParameterError(f"The 'neighborhoods' parameter of {func} must be a "
                                    f"Neighborhoods. Got {type(nbh).__name__} instead.")
    if nbh.n_points != n or nbh.kind != "disc":
        raise InvalidParameterError(f"{func}: `neighborhoods` must be planimetric discs "
                                    f"(dim=2) over the same {n} points")
    if nbh.radius is not None and nbh.radius < radius * (1 - 1e-12):
        raise InvalidParameterError(f"{func}: neighbourhood radius {nbh.radius} is smaller "
                                    f"than the largest bandwidth {radius}")


def local_planes(points, bandwidth, *, sigma=None, alpha=0.05, adaptive=False,
                 adaptive_range=(0.5, 2.0), scales=MULTISCALE, min_neighbors=6,
                 neighborhoods=None):
    """Fit a tricube-weighted local plane around every point (eq. 6-7 of seed 002).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (E, N, height).
    bandwidth : float
        Kernel half-width b (planimetric distance); see :func:`select_plane_bandwidth`.
    sigma : float, optional
        Height noise (standard deviation). Default: estimated from the lower quartile of
        the local variances (:data:`SIGMA_QUANTILE`), corrected by the chi-square quantile.
    alpha : float, optional
        Level of the planarity test.
    adaptive : bool, AdaptiveBandwidth or {'none', 'geary', 'multiscale'}, optional
        Per-point bandwidths. ``True`` or ``'geary'``: from Geary's local indicator
        (:func:`geary_bandwidths`). ``'multiscale'``: the largest ``b * scale`` (over
        `scales`) whose local plane passes the planarity test, so that windows near roof
        edges shrink until they hold one plane (points no scale accepts keep b).
    adaptive_range : (float, float), optional
        Bounds of ``b_i / b`` for the Geary bandwidth.
    scales : sequence of float, optional
        Decreasing bandwidth ratios of the multi-scale choice, starting at 1.
    min_neighbors : int, optional
        Fewest neighbours with positive weight for a fit (at least 3).
    neighborhoods : Neighborhoods, optional
        Precomputed 2-D neighbourhoods of radius >= the largest bandwidth used.

    Returns
    -------
    LocalPlaneFit

    Notes
    -----
    ``beta = (A'QA)^-1 A'Qz`` with rows ``A_j = [1, E_j - E_i, N_j - N_i]`` and
    ``Q = diag((1 - (d_ij/b)^3)^3)``. The covariance of beta is the sandwich
    ``sigma^2 (A'QA)^-1 A'Q^2A (A'QA)^-1`` (the tricube weights are not inverse
    variances). The planarity test refers ``r'Qr`` to ``sigma^2 c chi2(nu)`` with
    Satterthwaite's ``c = tr(B^2)/tr(B)``, ``nu = tr(B)^2/tr(B^2)``,
    ``B = Q - QA(A'QA)^-1A'Q``.

    References
    ----------
    Crosilla F., Visintini D., Sepic F. (2005). A segmentation procedure of LiDAR data by
    applying mixed parametric and nonparametric models. ISPRS WG III/3, V/3 Workshop
    "Laser scanning 2005", Enschede.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.features import local_planes
    >>> g = np.mgrid[0:20, 0:20].reshape(2, -1).T * 0.5
    >>> pts = np.c_[g, 1.0 + 0.2 * g[:, 0] - 0.1 * g[:, 1]]
    >>> fit = local_planes(pts, 1.5, sigma=0.01)
    >>> np.allclose(fit.beta[:, 1:], [0.2, -0.1])
    True
    """
    func = "local_planes"
    points = check_points(points, min_points=3)
    b = check_scalar(bandwidth, "bandwidth", func=func, low=0.0)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    min_neighbors = check_scalar(min_neighbors, "min_neighbors", func=func, low=3,
                                 closed="left", integer=True)
    if sigma is not None:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    mode = _adaptive_mode(adaptive, func)
    lo, hi = (1.0, 1.0)
    if mode == "multiscale":
        scales = np.asarray(scales, dtype=np.float64).ravel()
        if scales.size == 0 or scales[0] != 1.0 or np.any(np.diff(scales) >= 0) \
                or scales[-1] <= 0:
            raise InvalidParameterError(f"The 'scales' parameter of {func} must decrease "
                                        f"from 1 to a positive ratio. Got {scales!r}.")
        return _multiscale_planes(points, b, scales, sigma, alpha, min_neighbors,
                                  neighborhoods, func)
    if mode == "geary":
        lo, hi = (float(v) for v in adaptive_range)
        if not 0 < lo <= 1.0 <= hi:
            raise InvalidParameterError(f"The 'adaptive_range' parameter of {func} must "
                                        f"satisfy 0 < low <= 1 <= high. Got {adaptive_range!r}.")
    radius = b * hi
    n = points.shape[0]
    if neighborhoods is not None:
        _check_neighborhoods(neighborhoods, n, radius, func)
        bw = geary_bandwidths(points, b, neighborhoods=neighborhoods, bounds=(lo, hi)) \
            if mode == "geary" else np.full(n, b)
        beta, cof, st, status = _run_kernel(points, neighborhoods, bw, min_neighbors)
    else:
        bw = geary_bandwidths(points, b, bounds=(lo, hi)) if mode == "geary" \
            else np.full(n, b)
        beta, cof, st, status = _chunked(points, radius, bw, min_neighbors)
    return _assemble(beta, cof, st, status, bw, sigma, alpha,
                     {"bandwidth": b, "adaptive": mode, "alpha": alpha})


def _adaptive_mode(adaptive, func):
    if adaptive is False or adaptive is None:
        return "none"
    if adaptive is True:
        return "geary"
    check_option(adaptive, "adaptive", ADAPTIVE_MODES, func=func)
    return AdaptiveBandwidth(adaptive).value


def _local_variances(st):
    with np.errstate(invalid="ignore", divide="ignore"):
        return st[:, 0] / st[:, 1], st[:, 1] ** 2 / st[:, 2]


def _assemble(beta, cof, st, status, bw, sigma, alpha, params, sigma2=None):
    local_s2, nu = _local_variances(st)
    if sigma2 is None:
        sigma2 = sigma ** 2 if sigma is not None else _robust_sigma2(local_s2, nu)
    planarity = variance_test_satterthwaite(st[:, 0], st[:, 1], st[:, 2], sigma2, alpha)
    return LocalPlaneFit(beta=beta, cofactor=cof, sigma2=float(sigma2), local_sigma2=local_s2,
                         planarity=planarity, leverage=st[:, 3], resid=st[:, 4],
                         neighbors=np.nan_to_num(st[:, 5]).astype(np.int32), status=status,
                         bandwidth=bw, params=params)


def _multiscale_planes(points, b, scales, sigma, alpha, min_neighbors, neighborhoods, func):
    """Per point, the largest bandwidth ``b * scale`` whose local plane passes the
    planarity test (an intersection-of-confidence-intervals / Lepski-type choice: the
    widest window still consistent with one plane); points no scale accepts keep b.

    sigma^2 is estimated once at b (lower quartile of the local variances), so every scale
    is tested against the same noise level.
    """
    n = points.shape[0]
    bw = np.full(n, b)
    if neighborhoods is not None:
        _check_neighborhoods(neighborhoods, n, b, func)
        out = _run_kernel(points, neighborhoods, bw, min_neighbors)
    else:
        out = _chunked(points, b, bw, min_neighbors)
    beta, cof, st, status = out
    local_s2, nu = _local_variances(st)
    sigma2 = sigma ** 2 if sigma is not None else _robust_sigma2(local_s2, nu)

    def failing(st_, status_):
        test = variance_test_satterthwaite(st_[:, 0], st_[:, 1], st_[:, 2], sigma2, alpha)
        return (status_ != _k.STATUS_OK) | test.reject

    todo = np.flatnonzero(failing(st, status))
    for scale in scales[1:]:
        if todo.size == 0:
            break
        bw_s = np.full(n, b * scale)
        if neighborhoods is not None:
            sub = _subset_neighborhoods(neighborhoods, todo)
            res = _run_kernel(points, sub, bw_s[todo], min_neighbors)
        else:
            res = _fit_subset(points, b * scale, bw_s, min_neighbors, todo)
        ok = ~failing(res[2], res[3])
        take = todo[ok]
        beta[take], cof[take], st[take], status[take] = (a[ok] for a in res)
        bw[take] = b * scale
        todo = todo[~ok]
    return _assemble(beta, cof, st, status, bw, sigma, alpha,
                     {"bandwidth": b, "adaptive": "multiscale", "alpha": alpha,
                      "scales": tuple(float(v) for v in scales)}, sigma2=sigma2)


def _fit_subset(points, radius, bw, min_neighbors, query):
    """Fits of the `query` points only, as (len(query), ...) arrays."""
    full = _chunked(points, radius, bw, min_neighbors, query=query)
    return tuple(a[query] for a in full)


def _subset_neighborhoods(nbh, rows):
    """The CSR rows `rows` of `nbh` as a query-subset Neighborhoods."""
    starts, ends = nbh.indptr[rows], nbh.indptr[rows + 1]
    counts = ends - starts
    indptr = np.concatenate(([0], np.cumsum(counts))).astype(nbh.indptr.dtype)
    take = np.concatenate([np.arange(a, e) for a, e in zip(starts, ends)]) if rows.size \
        else np.empty(0, np.int64)
    q = nbh.query_indices()[rows]
    return Neighborhoods(indptr, nbh.indices[take], nbh.distances[take], nbh.n_points,
                         kind=nbh.kind, radius=nbh.radius, query=q)


def geary_bandwidths(points, bandwidth, *, neighborhoods=None, bounds=(0.5, 2.0)):
    """Adaptive bandwidths from Geary's local indicator (seed 002, section 4.1).

    ``c_i = sum_j d_ij (h_i - h_j)^2 / (n^-1 sum_k h_k^2)`` with ``h = z - mean(z)`` and
    tricube contiguity weights ``d_ij`` at `bandwidth`; ``gamma_i = c_i sum_j d_ij /
    sum_j d_ij c_j`` (Sclocco and Di Marzio 2004). The paper multiplies b by gamma_i and
    says this "reduces the amount of smoothing if the local morphology is complex"; but
    gamma_i > 1 exactly where point i is more heterogeneous than its neighbours, so
    ``b gamma_i`` would *increase* smoothing there. We follow the stated intent:
    ``b_i = b / gamma_i``, clipped to ``bounds`` times b (documented in docs/methods/sar.md).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates.
    bandwidth : float
        Global bandwidth b.
    neighborhoods : Neighborhoods, optional
        2-D neighbourhoods of radius >= b.
    bounds : (float, float)
        Smallest and largest ratio ``b_i / b``.

    Returns
    -------
    (N,) ndarray
        Per-point bandwidths.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.features import geary_bandwidths
    >>> g = np.mgrid[0:10, 0:10].reshape(2, -1).T.astype(float)
    >>> pts = np.c_[g, 0.1 * g[:, 0]]
    >>> b = geary_bandwidths(pts, 2.5)
    >>> bool((b >= 1.25).all() and (b <= 5.0).all())
    True
    """
    func = "geary_bandwidths"
    points = check_points(points, min_points=2)
    b = check_scalar(bandwidth, "bandwidth", func=func, low=0.0)
    lo, hi = (float(v) for v in bounds)
    if neighborhoods is not None:
        _check_neighborhoods(neighborhoods, points.shape[0], b, func)
    z = np.ascontiguousarray(points[:, 2] - points[:, 2].mean())
    n = points.shape[0]
    c = np.empty(n)
    gamma = np.empty(n)
    chunks = [neighborhoods] if neighborhoods is not None else None
    m2 = float(np.mean(z * z)) or 1.0
    for nb in (chunks or _chunks(points, b)):
        q = nb.query_indices()
        cq = np.empty(q.size)
        _k.geary_local(z, q, nb.indptr, nb.indices, nb.distances, b, m2, cq)
        c[q] = cq
    for nb in (chunks or _chunks(points, b)):
        q = nb.query_indices()
        gq = np.empty(q.size)
        _k.geary_gamma(c, q, nb.indptr, nb.indices, nb.distances, b, gq)
        gamma[q] = gq
    with np.errstate(divide="ignore"):
        ratio = np.where(gamma > 0, 1.0 / gamma, hi)
    return b * np.clip(ratio, lo, hi)
