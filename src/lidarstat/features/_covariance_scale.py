"""Automatic neighbourhood sizes of the covariance features.

Two rules choose, per point, a prefix of its ``OPTIMAL_K_MAX`` nearest neighbours sorted
by distance (one kNN query serves every candidate size):

* **minimum eigenentropy** (:func:`optimal_scale`; Weinmann et al. 2015, PDAL's
  ``filters.optimalneighborhood``): the prefix whose normalised eigenvalues have the
  smallest entropy, the features' automatic scale;
* **tested** (:func:`tested_scale`): the smallest prefix whose plane test, at the
  measurement noise, rejects with power; the whole row where none does. This is the
  scale of the covariance classification: a neighbourhood grows until the crease it
  reaches is detected, so planes and cylinders keep the power of the largest size and
  the edge zone along a crease is as narrow as the noise allows.

:func:`prefix_features` computes the features on the chosen prefixes.
"""

from __future__ import annotations

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ..neighbors import Neighborhoods
from ..stats import chi2_quantile
from ._covariance_scale_blocks import blocked_prefix_features
from ._noise import noise_directions, resolve_noise

#: The plane test's noise share ``|d . n|`` is floored here in the tested scale (as in
#: the noise estimate): on faces almost parallel to the noise direction the predicted
#: noise across is near zero and a prefix would stop on modelling error.
MIN_SHARE = 0.2


def optimal_scale(pts, *, sensor, eigen_mode, keep_neighbors, block_size, progress):
    """Features at every point's minimum-eigenentropy neighbourhood size (see
    :func:`covariance_features` with neither `k` nor `radius`)."""
    from ._covariance import OPTIMAL_K_MAX, OPTIMAL_K_MIN, OPTIMAL_MIN_SPREAD
    from ._covariance_scale_kernels import optimal_k_rows

    n = pts.shape[0]
    if n < 3:
        raise InvalidParameterError(
            f"covariance_features: the automatic scale needs at least 3 points, got {n}")
    k_max = min(OPTIMAL_K_MAX, n)
    k_min = min(OPTIMAL_K_MIN, k_max)

    def choose(local, indptr, idx, rows):
        kopt = np.empty(rows.size, dtype=np.int64)
        optimal_k_rows(local, indptr, idx, k_min, k_max, OPTIMAL_MIN_SPREAD, kopt,
                       np.empty(rows.size))
        return kopt

    return blocked_prefix_features(pts, k_max, choose, sensor=sensor, eigen_mode=eigen_mode,
                                   keep_neighbors=keep_neighbors, block_size=block_size,
                                   progress=progress, rule="eigenentropy", k_min=k_min)


def tested_scale(points, neighborhoods, *, sigma, noise=None, sensor=None, k_min=None,
                 alpha=0.05, power=0.9):
    """Per point, the smallest neighbourhood size whose plane test detects a crease with
    `power`.

    For the prefix of the first k points of a row (sorted by distance) with smallest
    covariance eigenvalue ``lambda0`` (divided by k) and normal n, the plane test's
    statistic is ``k lambda0 / (sigma^2 (d . n)^2) ~ chi2(k - 3)`` for noise `sigma`
    along d (`noise`: ``'z'``, ``'range'`` from `sensor`, ``'normal'``; ``|d . n|``
    floored at ``MIN_SHARE``). The first k from `k_min` at which its upper tail falls
    below ``p_stop = 2 Phi(-(z_{1-alpha/4} + z_power))`` is chosen, else the whole row:
    the evidence the curvature's automatic scale asks of a curvature (eq. 19 of seed
    000; ``4e-4`` at the defaults), so that on a plane a stop by chance is rare and the
    test at the chosen size keeps its level.

    Parameters
    ----------
    points : (N, 3) ndarray
    neighborhoods : Neighborhoods
        kNN rows sorted by distance, the point itself first.
    sigma : float or (N,) array_like
        Noise std along its direction (per point for a range-dependent model).
    noise, sensor
        The shared noise model (:func:`lidarstat.features.resolve_noise`).
    k_min : int, optional
        Smallest size tried (default ``OPTIMAL_K_MIN``).
    alpha, power : float
        Level of the plane test and the power asked of a stop.

    Returns
    -------
    (N,) int64 ndarray
    """
    from ._covariance_scale_kernels import tested_k_rows

    pts = np.asarray(points, dtype=np.float64)
    k_min, k_max, sigma2, dirs, crit = _tested_setup(
        pts, sigma, noise, sensor, k_min, alpha, power, np.diff(neighborhoods.indptr),
        "tested_scale")
    local = pts - pts.mean(axis=0)
    out = np.empty(pts.shape[0], dtype=np.int64)
    tested_k_rows(local, neighborhoods.indptr, neighborhoods.indices, k_min, k_max, sigma2,
                  dirs, crit, MIN_SHARE ** 2, out)
    return out


def tested_features(points, k_max, *, sigma, noise=None, sensor=None, k_min=None,
                    alpha=0.05, power=0.9, eigen_mode="raw", keep_neighbors=False,
                    block_size=262144, progress=None):
    """Covariance features at every point's tested size among its `k_max` nearest
    neighbours: :func:`prefix_features` of :func:`tested_scale` on the kNN rows, computed
    a block of points at a time (the rows of the whole cloud are never held, unless
    `keep_neighbors`).

    Parameters
    ----------
    points : (N, 3) ndarray
    k_max : int
        Neighbours searched per point (the row length, at most N).
    sigma, noise, sensor, k_min, alpha, power
        As :func:`tested_scale`.
    eigen_mode, keep_neighbors, block_size, progress
        As :func:`lidarstat.features.covariance_features`.

    Returns
    -------
    CovarianceResult
        With ``OptimalKNN`` and ``OptimalRadius``; ``meta['rule'] == 'tested'``.
    """
    from ._covariance_scale_kernels import tested_k_rows

    pts = np.asarray(points, dtype=np.float64)
    k_max = int(k_max)
    k_min, k_max, sigma2, dirs, crit = _tested_setup(
        pts, sigma, noise, sensor, k_min, alpha, power, np.array([k_max]), "tested_features")
    per_sigma = sigma2.size > 1
    per_dir = dirs.shape[0] > 1

    def choose(local, indptr, idx, rows):
        out = np.empty(rows.size, dtype=np.int64)
        tested_k_rows(local, indptr, idx, k_min, k_max,
                      np.ascontiguousarray(sigma2[rows]) if per_sigma else sigma2,
                      np.ascontiguousarray(dirs[rows]) if per_dir else dirs, crit,
                      MIN_SHARE ** 2, out)
        return out

    return blocked_prefix_features(pts, k_max, choose, sensor=sensor, eigen_mode=eigen_mode,
                                   keep_neighbors=keep_neighbors, block_size=block_size,
                                   progress=progress, rule="tested", k_min=k_min)


def _tested_setup(pts, sigma, noise, sensor, k_min, alpha, power, lengths, func):
    """Checked options and the kernel's inputs of the tested scale: ``(k_min, k_max,
    sigma2, dirs, crit)``."""
    from ._covariance import OPTIMAL_K_MIN
    from ._curvature_scale import stop_pvalue

    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0, closed="neither")
    power = check_scalar(power, "power", func=func, low=0.0, high=1.0, closed="neither")
    stop_p = stop_pvalue(alpha, power)
    n = pts.shape[0]
    noise = resolve_noise(noise, sensor, func=func)
    k_min = OPTIMAL_K_MIN if k_min is None else int(k_min)
    k_max = int(lengths.max()) if n else 0
    crit = np.full(k_max + 1, np.inf)
    ks = np.arange(4, k_max + 1)
    crit[ks] = chi2_quantile(1.0 - stop_p, ks - 3)
    sigma2, dirs = _noise_arrays(pts, sigma, noise, sensor, n, func)
    return k_min, k_max, sigma2, dirs, crit


def prefix_features(points, neighborhoods, sizes, *, sensor=None, eigen_mode="raw",
                    keep_neighbors=False, block_size=262144, progress=None,
                    rule="given", k_min=None):
    """Covariance features on the first `sizes[i]` points of each sorted row.

    Fields ``OptimalKNN`` (the size) and ``OptimalRadius`` (distance to its last point)
    are added; the result's ``meta`` records ``scale='optimal'``, the `rule`, `k_min`
    and the row length ``k_max``. The kept neighbourhoods (`keep_neighbors`) are the
    full rows.
    """
    from ._covariance import covariance_features

    full = neighborhoods
    n = full.indptr.size - 1
    kopt = np.minimum(np.asarray(sizes, dtype=np.int64), np.diff(full.indptr))
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(kopt, out=indptr[1:])
    pos = np.repeat(full.indptr[:-1] - indptr[:-1], kopt) + np.arange(indptr[-1])
    prefix = Neighborhoods(indptr, full.indices[pos], full.distances[pos], n,
                           kind="knn", row_order=full.row_order)
    del pos
    res = covariance_features(points, neighborhoods=prefix, sensor=sensor,
                              eigen_mode=eigen_mode, block_size=block_size,
                              progress=progress)
    res.fields["OptimalKNN"] = kopt.astype(np.int32)
    res.fields["OptimalRadius"] = prefix.distances[indptr[1:] - 1]
    object.__setattr__(res, "k", None)
    object.__setattr__(res, "radius", None)
    object.__setattr__(res, "neighborhoods", full if keep_neighbors else None)
    k_max = int(np.diff(full.indptr).max()) if n else 0
    res.meta.update(scale="optimal", rule=rule, k_min=k_min, k_max=k_max)
    return res


def _noise_arrays(pts, sigma, noise, sensor, n, func):
    """Squared sigma (one or per point) and noise directions as the kernels take them
    (no row: along the normal; one row: the same for all)."""
    sigma2 = np.atleast_1d(np.asarray(sigma, dtype=np.float64) ** 2)
    if sigma2.size not in (1, n):
        raise InvalidParameterError(f"{func}: `sigma` must be one value or one per point")
    if noise == "normal":
        dirs = np.zeros((0, 3))
    elif noise == "z":
        dirs = np.array([[0.0, 0.0, 1.0]])
    else:
        dirs = noise_directions(noise, n, points=pts, sensor=sensor)
    return np.ascontiguousarray(sigma2), np.ascontiguousarray(dirs)
