"""The measurement-noise model every local fit shares.

Three things, in one place so that curvature, jets, ridges, covariance features and SAR
agree on them:

* the **direction** ``d`` of the instrument's noise (:func:`resolve_noise`): along z for
  range images and airborne scans, along the sensor ray for terrestrial scans, or along the
  surface normal (isotropic noise);
* the **variance seen along a fit's height axis** (:func:`noise_factor`,
  :func:`height_variance`): a point displaced by ``eps d`` leaves the surface of unit
  normal ``n`` by ``eps (d . n)`` along ``n``, which a fit whose heights run along ``e``
  sees as ``eps (d . n) / (e . n)``; so the height variance is
  ``sigma^2 (d . n)^2 / (e . n)^2``;
* **one estimate of sigma** from the data (:func:`estimate_sigma`) when it is not given.
"""

from __future__ import annotations

import math

import numpy as np

from .._shared._choices import Noise
from ..errors import InsufficientNeighborsError, InvalidParameterError
from ..stats import chi2_isf_many

__all__ = [
    "FACTOR_FLOOR",
    "Noise",
    "estimate_sigma",
    "fit_factor",
    "fit_factor_spread",
    "fit_height_variance",
    "fit_normals",
    "height_variance",
    "noise_directions",
    "noise_factor",
    "resolve_noise",
    "sigma_from_fits",
]

#: Tricube-weighted mean of u^2 (per planar axis) over a uniformly sampled disc of radius
#: b, in units of b^2: ``(1/2) int (1-t^3)^3 t^3 dt / int (1-t^3)^3 t dt = 11/91``.
TRICUBE_M2 = 11.0 / 91.0

#: Smallest factor (d.n)^2/(e.n)^2 used: a noise direction inside the surface's tangent
#: plane (z noise on an exactly vertical wall) moves no point off the surface; the floor
#: keeps the height variance positive for the rounding of the coordinates.
FACTOR_FLOOR = 1e-6

#: Fits whose factor is below this do not enter the estimate of sigma: there the data
#: hold almost no information about the noise along d.
ESTIMATE_MIN_FACTOR = 0.1


def resolve_noise(noise, sensor, *, func: str) -> str:
    """The noise direction to use: `noise` checked, or its default.

    The default is ``'range'`` when a `sensor` is given (terrestrial scans), else ``'z'``;
    ``'range'`` needs the sensor.
    """
    if noise is None:
        noise = Noise.Z if sensor is None else Noise.RANGE
    noise = Noise.parse(noise, "noise", func=func)
    if noise == Noise.RANGE and sensor is None:
        raise InvalidParameterError(f"{func}: noise='range' needs the `sensor` position")
    return noise


def noise_directions(noise, m, *, points=None, sensor=None):
    """Unit noise direction per point, (M, 3), or None for ``'normal'`` (along the surface
    normal itself)."""
    noise = Noise.parse(noise, "noise", func="noise_directions")
    if noise == Noise.NORMAL:
        return None
    if noise == Noise.Z:
        d = np.zeros((m, 3))
        d[:, 2] = 1.0
        return d
    if points is None or sensor is None:
        raise InvalidParameterError("noise_directions: noise='range' needs `points` and `sensor`")
    d = np.asarray(points, dtype=np.float64) - np.asarray(sensor, dtype=np.float64)
    nrm = np.linalg.norm(d, axis=1, keepdims=True)
    return d / np.where(nrm > 0, nrm, 1.0)


def noise_factor(axes, normals, noise, *, points=None, sensor=None):
    """``(d . n)^2 / (e . n)^2``: the height variance per unit sigma^2 of a fit whose heights
    run along `axes` (e), on a surface of unit normal `normals` (n), for noise along d.

    Parameters
    ----------
    axes, normals : (M, 3) ndarray
        Height axis of each fit and the surface normal (need not be oriented alike).
    noise : {'z', 'range', 'normal'} or Noise
    points, sensor : ndarray, optional
        Point coordinates (M, 3) and sensor position, for ``'range'``.

    Returns
    -------
    (M,) ndarray
        At least :data:`FACTOR_FLOOR`; NaN where the normal is undefined.
    """
    axes = np.asarray(axes, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    d = noise_directions(noise, axes.shape[0], points=points, sensor=sensor)
    en = np.einsum("ij,ij->i", axes, normals) ** 2
    dn = np.ones(en.shape) if d is None else np.einsum("ij,ij->i", d, normals) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        f = dn / en
    return np.maximum(f, FACTOR_FLOOR)


def fit_normals(beta, frames):
    """Unit surface normal at the fitted point, file coordinates, from the slopes a1, a2 of
    a local fit in `frames` (rows e1, e2, n); oriented along +n."""
    a1, a2 = beta[:, 1], beta[:, 2]
    nl = np.stack([-a1, -a2, np.ones_like(a1)], axis=1)
    nl /= np.linalg.norm(nl, axis=1, keepdims=True)
    return np.einsum("nij,ni->nj", frames, nl)


def height_variance(frames, sigma, *, noise="z", points=None, sensor=None, normals=None):
    """Variance of the local heights implied by measurement noise of std `sigma`.

    The local model's heights run along the frame axis e (the third row of `frames`), the
    instrument's noise along a direction d: z for range images and airborne data
    (``noise='z'``), the sensor-to-point ray for terrestrial scans (``'range'``), or the
    surface normal (``'normal'``, isotropic noise). On a surface of normal n the height
    noise has variance ``sigma^2 (d . n)^2 / (e . n)^2`` (:func:`noise_factor`); in the
    ``'z'`` frame with ``noise='z'`` this is sigma^2, as in the paper.

    Parameters
    ----------
    frames : (M, 3, 3) ndarray
        Local frames (rows e1, e2, e).
    sigma : float
    noise : {'z', 'range', 'normal'} or Noise
    points, sensor : ndarray, optional
        Point coordinates (M, 3) and sensor position, needed for ``'range'``.
    normals : (M, 3) ndarray, optional
        Surface normals (e.g. :func:`fit_normals`); default the frame axis e itself (a
        frame that follows the surface, such as PCA).

    Returns
    -------
    (M,) ndarray
    """
    e = frames[:, 2, :]
    n = e if normals is None else np.asarray(normals, dtype=np.float64)
    f = noise_factor(e, n, noise, points=points, sensor=sensor)
    return sigma * sigma * np.where(np.isfinite(f), f, 1.0)


def _factor_terms(beta, frames, noise, *, points=None, sensor=None):
    """Per fit, the factor at a neighbour at planar offset u as ``(a + g . u)^2``: returns
    ``a`` and ``|g|^2`` (None for ``'normal'`` noise)."""
    beta = np.asarray(beta, dtype=np.float64)
    d = noise_directions(noise, beta.shape[0], points=points, sensor=sensor)
    if d is None:
        return None
    g0 = beta[:, 1:3]
    a3, a4, a5 = beta[:, 3], beta[:, 4], beta[:, 5]
    dl = np.einsum("nij,nj->ni", frames, d)
    dt, de = dl[:, :2], dl[:, 2]
    gd0 = a3 * dt[:, 0] + a4 * dt[:, 1]
    gd1 = a4 * dt[:, 0] + a5 * dt[:, 1]
    return de - (g0 * dt).sum(axis=1), gd0 * gd0 + gd1 * gd1


def fit_factor(beta, frames, noise, *, radius, points=None, sensor=None):
    """Mean height variance per unit sigma^2 over a fitted quadric's neighbourhood.

    At a neighbour at planar offset u the surface normal is that of the fitted quadric,
    with slopes ``g(u) = g0 + G u`` (``g0 = (a1, a2)``, ``G = [[a3, a4], [a4, a5]]``), and a
    displacement ``eps d`` (local components ``(d_t, d_e)``) changes the residual by
    ``eps (d_e - g(u) . d_t)``: the factor (d.n)^2/(e.n)^2 at that neighbour. Its
    tricube-weighted mean over the disc of radius b (``E[u u'] = m2 b^2 I``,
    ``m2 =`` :data:`TRICUBE_M2`) is ``(d_e - g0 . d_t)^2 + m2 b^2 |G d_t|^2``: on a curved
    surface the noise's tangential part adds residual variance, which matters where the
    noise runs nearly inside the tangent plane (z noise on steep faces). For ``'normal'``
    noise the factor is ``1 + |g0|^2 + m2 b^2 |G|_F^2``.

    Parameters
    ----------
    beta : (M, 6) ndarray
        ``a0..a5`` of the local fits.
    frames : (M, 3, 3) ndarray
        Their frames (rows e1, e2, e).
    noise : {'z', 'range', 'normal'} or Noise
    radius : float
        Kernel radius b.
    points, sensor : ndarray, optional
        For ``'range'``.

    Returns
    -------
    (M,) ndarray
        At least :data:`FACTOR_FLOOR` (1 where the fit is undefined).
    """
    beta = np.asarray(beta, dtype=np.float64)
    terms = _factor_terms(beta, frames, noise, points=points, sensor=sensor)
    return _factor_from_terms(terms, beta, radius)


def _factor_from_terms(terms, beta, radius):
    """:func:`fit_factor` from the :func:`_factor_terms` of the fits."""
    m2 = TRICUBE_M2 * float(radius) ** 2
    if terms is None:
        g0 = beta[:, 1:3]
        a3, a4, a5 = beta[:, 3], beta[:, 4], beta[:, 5]
        f = 1.0 + (g0 ** 2).sum(axis=1) + m2 * (a3 * a3 + 2 * a4 * a4 + a5 * a5)
    else:
        a, g2 = terms
        f = a * a + m2 * g2
    f = np.where(np.isfinite(f), f, 1.0)
    return np.maximum(f, FACTOR_FLOOR)


def _tricube_power_moment(power, k):
    """``int (1-t^3)^power t^(k+1) dt / int (1-t^3)^power t dt`` over [0, 1]: the mean of
    ``|u/b|^k`` over a uniformly sampled disc under the weight ``w^(power/3)``."""
    def integral(j):
        x = (j + 2) / 3.0
        return math.gamma(x) * math.gamma(power + 1) / math.gamma(x + power + 1) / 3.0
    return integral(k) / integral(0)


#: Mean of u1^2 / b^2 and of u1^4 / b^4 over the disc under the squared tricube weight
#: (2-D isotropy: ``E[u1^2] = E|u|^2 / 2``, ``E[u1^4] = 3 E|u|^4 / 8``).
TRICUBE2_M2 = _tricube_power_moment(6, 2) / 2.0
TRICUBE2_M4 = 3.0 * _tricube_power_moment(6, 4) / 8.0


def fit_factor_spread(beta, frames, noise, *, radius, points=None, sensor=None):
    """How unequal the height variance is across a fitted quadric's neighbourhood.

    The residual sum ``Q = sum w_j v_j^2`` of a fit whose neighbours' height variances are
    ``sigma^2 f_j`` (:func:`fit_factor`: ``f(u) = (a + g . u)^2`` for noise along d) has,
    to first order in the fit's leverage, mean ``sigma^2 sum w f`` and variance
    ``2 sigma^4 sum w^2 f^2``. The Satterthwaite chi-square of equal variances
    (``sigma^2 f_bar``, ``f_bar`` the w-weighted mean) has the same mean but the variance
    ``2 sigma^4 f_bar^2 sum w^2``; the ratio

    ``rho = E_{w^2}[f^2] / E_w[f]^2 >= 1``

    multiplies its scale c and divides its degrees of freedom. On a plane ``g = 0`` and
    ``rho = 1``; it grows where the noise runs nearly inside the tangent plane and the
    normal turns across the neighbourhood (z noise on steep curved faces), where
    ``f`` vanishes at some neighbours and not at others. Closed form under isotropy
    (odd moments vanish): ``E_{w^2}[f^2] = a^4 + 6 a^2 |g|^2 M2 b^2 + |g|^4 M4 b^4`` with
    the squared-tricube moments ``M2``, ``M4`` (:data:`TRICUBE2_M2`,
    :data:`TRICUBE2_M4`). For ``'normal'`` noise ``f >= 1`` barely varies: 1.

    Returns
    -------
    (M,) ndarray
        At least 1 (1 where the fit is undefined).
    """
    beta = np.asarray(beta, dtype=np.float64)
    terms = _factor_terms(beta, frames, noise, points=points, sensor=sensor)
    if terms is None:
        return np.ones(beta.shape[0])
    return _spread_from_terms(terms, radius)


def _spread_from_terms(terms, radius):
    """:func:`fit_factor_spread` from the (not None) :func:`_factor_terms` of the fits."""
    a, g2 = terms
    b2 = float(radius) ** 2
    a2 = a * a
    mean = a2 + TRICUBE_M2 * b2 * g2
    fourth = a2 * a2 + 6.0 * a2 * g2 * TRICUBE2_M2 * b2 + g2 * g2 * TRICUBE2_M4 * b2 * b2
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = fourth / (mean * mean)
    rho = np.where(np.isfinite(rho), rho, 1.0)
    return np.maximum(rho, 1.0)


def fit_height_variance(beta, frames, sigma, *, noise, radius, points=None, sensor=None):
    """``sigma^2`` times :func:`fit_factor`: the height variance the tests of a local
    quadric fit use."""
    return sigma * sigma * fit_factor(beta, frames, noise, radius=radius, points=points,
                                      sensor=sensor)


def fit_variance_and_spread(beta, frames, sigma, *, noise, radius, points=None, sensor=None):
    """:func:`fit_height_variance` and :func:`fit_factor_spread` of the same fits, from one
    evaluation of the noise direction in each fit's frame."""
    beta = np.asarray(beta, dtype=np.float64)
    terms = _factor_terms(beta, frames, noise, points=points, sensor=sensor)
    variance = sigma * sigma * _factor_from_terms(terms, beta, radius)
    spread = np.ones(beta.shape[0]) if terms is None else _spread_from_terms(terms, radius)
    return variance, spread


def sigma_from_fits(q, trace_b, trace_b2, factor):
    """Robust noise sigma along d from local fits: the median of the unbiased local
    variance estimates, each scaled to the noise direction and median-unbiased.

    For a fit that holds, ``Q / tr(B)`` estimates the height variance ``sigma^2 f`` with
    ``Q / (sigma^2 f) ~ c chi2(nu)`` (Satterthwaite, ``c = tr(B^2)/tr(B)``,
    ``nu = tr(B)^2/tr(B^2)``), whose median is ``sigma^2 f m(nu)``,
    ``m(nu) = chi2_{0.5}(nu) / nu``. So ``Q / (tr(B) f m(nu))`` has median sigma^2 at every
    point where the model holds; the median over the points ignores the minority where it
    does not (creases, edges). Fits with ``f <`` :data:`ESTIMATE_MIN_FACTOR` (noise almost
    inside the tangent plane) are left out unless nothing else is left.

    Returns
    -------
    float
        sigma (not squared); NaN when no fit is usable.
    """
    q, tb, tb2, f = (np.asarray(a, dtype=np.float64) for a in (q, trace_b, trace_b2, factor))
    ok = np.isfinite(q) & (tb > 0) & (tb2 > 0) & np.isfinite(f)
    if not ok.any():
        return float("nan")
    strong = ok & (f >= ESTIMATE_MIN_FACTOR)
    if strong.sum() >= max(10, 0.05 * ok.sum()):
        ok = strong
    nu = tb[ok] ** 2 / tb2[ok]
    median = np.empty_like(nu)
    chi2_isf_many(0.5, nu, median)  # the chi2(nu) medians, in a kernel: no SciPy import
    s2 = q[ok] / (tb[ok] * f[ok] * (median / nu))
    return float(np.sqrt(np.median(s2)))


def estimate_sigma(points, radius, *, noise=None, sensor=None, frame="pca", min_neighbors=7,
                   sample=20000, rng=0):
    """The noise std along its direction, estimated from the data (one estimator for every
    method).

    A weighted quadric is fitted in a sphere of `radius` around up to `sample` random
    points (in `frame`), and :func:`sigma_from_fits` turns their residuals into one sigma
    along the noise direction `noise` (default ``'range'`` with a `sensor`, else ``'z'``),
    using the fitted normals for the factor ``(d . n)^2 / (e . n)^2``.

    Parameters
    ----------
    points : (N, 3) array_like
    radius : float
        Fit radius (a small one: the quadric must hold in most neighbourhoods).
    noise : {'z', 'range', 'normal'} or Noise, optional
    sensor : (3,) array_like, optional
    frame : {'z', 'auto', 'pca'} or Frame
    min_neighbors : int
    sample : int
        Largest number of fits.
    rng : int or numpy.random.Generator

    Returns
    -------
    float
    """
    from .._shared.validation import check_points
    from ..neighbors import CellIndex, find_duplicates

    noise = resolve_noise(noise, sensor, func="estimate_sigma")
    pts = check_points(points)
    pts = pts[find_duplicates(pts).first]  # a copy is no new observation of the noise
    return estimate_sigma_index(CellIndex(pts, radius), noise=noise, frame=frame,
                                sensor=sensor, min_neighbors=min_neighbors, sample=sample,
                                rng=rng)


def estimate_sigma_index(index, *, noise, frame, sensor, min_neighbors, sample=20000, rng=0):
    """:func:`estimate_sigma` on an existing :class:`~lidarstat.neighbors.CellIndex` (its
    radius is the fit radius)."""
    from . import _quadric_kernels as _k
    from ._quadric import _run_kernel, unfitted_reason

    radius = index.radius
    gen = np.random.default_rng(rng)
    n = index.n_points
    pos = np.sort(gen.choice(n, size=min(int(sample), n), replace=False))
    indptr, idx, dist = index._query_local(index.sorted_points[pos])
    sensor_local = None if sensor is None else np.asarray(sensor, float) - index.origin
    out = _run_kernel(index.sorted_points, pos, indptr, idx, dist, bandwidth=radius, frame=frame,
                      sensor=sensor_local, min_neighbors=min_neighbors, covariance="sandwich")
    ok = out["status"] == _k.OK
    if not ok.any():
        why = unfitted_reason(out["status"], out["npts"], min_neighbors)
        raise InsufficientNeighborsError(
            f"cannot estimate sigma: no quadric could be fitted within radius {radius:g}: "
            f"{why}; enlarge the radius or give sigma")
    f = fit_factor(out["beta"][ok], out["frames"][ok], noise, radius=radius,
                   points=index.sorted_points[pos[ok]], sensor=sensor_local)
    st = out["stats"][ok]
    return sigma_from_fits(st[:, 0], st[:, 2], st[:, 3], f)
