"""Noise scale of the covariance classification's plane test, estimated from the data.

Without a sensor one standard deviation across the surface (:func:`estimate_plane_sigma`);
with a sensor the range-noise model ``sigma_r(r) = a + b r`` of a terrestrial scan, from
the residuals of the best smooth model of every neighbourhood
(:func:`estimate_smooth_range_noise`, the classification's scale) and from the plane
residuals (:func:`estimate_range_noise`, the segmentation's scale for whole-segment models,
which includes the typical model error of real surfaces).
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidParameterError
from ..stats import chi2_critical
from ._covariance_tests import _cylinder_axes, _neighbour_rows

#: Neighbourhoods whose share of the noise across them, ``|d . n|``, is below this are
#: left out of the noise estimate (steep faces of a z-noise cloud: their residual is
#: mostly the noise the model does not carry).
MIN_NOISE_SHARE = 0.2

#: Height of the point from which ``noise='z'`` runs, above the coordinates' origin: rays
#: from it are vertical to within 1e-5 radians for points within 1e7 of the origin (any
#: projected CRS), and the same for every tile of an area (no cloud-dependent position).
Z_NOISE_HEIGHT = 1e12


def noise_sensor(noise, sensor, points):
    """The point the noise runs from, for models that weight each point by the share of
    its noise across the fitted surface (cylinder fits, segment models): the `sensor` for
    ``'range'``, the point `Z_NOISE_HEIGHT` above the origin for ``'z'`` (vertical rays),
    None for ``'normal'``."""
    if noise == "range":
        return sensor
    if noise == "z" and points is not None:
        return np.array([0.0, 0.0, Z_NOISE_HEIGHT])
    return None


def estimate_plane_sigma(evals, counts, share=None):
    """Robust noise estimate: ``sigma^2 = median((n-1) lambda0 / s^2 / median(chi2(n-3)))``.

    `share` is the share ``s = |d . n|`` of the noise across each neighbourhood (1: the
    noise is across the surface); neighbourhoods with ``s < MIN_NOISE_SHARE`` are left
    out. Each term has median sigma^2 on a plane whatever its size n (so the estimate
    holds for per-point neighbourhood sizes), and the median ignores edges and curved
    parts while most neighbourhoods are planar.

    Returns
    -------
    float
    """
    n = np.asarray(counts, dtype=np.float64)
    l0 = np.asarray(evals)[:, 0]
    s2 = np.ones_like(l0) if share is None else np.asarray(share, dtype=np.float64) ** 2
    with np.errstate(invalid="ignore"):
        ok = (n >= 4) & np.isfinite(l0) & (s2 >= MIN_NOISE_SHARE ** 2)
    if not ok.any():
        raise InvalidParameterError("cannot estimate sigma: no neighbourhood has 4 points")
    ss = (n[ok] - 1) * l0[ok] / s2[ok]
    sizes, which = np.unique(n[ok], return_inverse=True)
    med = chi2_critical(0.5, sizes - 3)[which]  # median of chi2(n - 3), per point
    return float(np.sqrt(np.median(ss / med)))


#: Re-estimations of the range noise on the points its plane test accepts (see
#: :func:`estimate_range_noise`); 0 by default, the plain per-bin medians. The trimmed
#: estimate is the consistent one for "planes with range noise": on tls_plant the median
#: gives b = 2.9e-4 (truth 5e-5: sigma 6.3 mm at 12 m against 2.6 mm) and three
#: re-estimations 9.8e-5, on tls_building both about 5e-5. But on the real pump scan the
#: trimmed estimate converges to the smoothest patches (a = 2.1 mm, b = 1.9e-5 against the
#: median's b = 1.2e-3) and the plane test then calls 41 % of the points edges (28 % with
#: the median): real surfaces are not planes with range noise at the millimetre level.
RANGE_NOISE_ITERATIONS = 0


def _range_line(rho, r, med, bins, keep=None):
    """Least-squares line ``a + b r`` through per-range-bin ``sqrt(median(rho) / med)``."""
    edges = np.unique(np.quantile(r, np.linspace(0, 1, bins + 1)))
    which = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, edges.size - 2)
    rc, sc = [], []
    for b in range(edges.size - 1):
        sel = which == b
        if keep is not None:
            sel &= keep
        if sel.sum() >= 10:
            rc.append(np.median(r[sel]))
            sc.append(np.sqrt(np.median(rho[sel]) / med))
    rc, sc = np.asarray(rc), np.asarray(sc)
    if rc.size == 0:
        return np.nan, 0.0
    if rc.size < 2 or np.ptp(rc) == 0:
        return float(np.median(sc)), 0.0
    b, a = np.polyfit(rc, sc, 1)
    if b < 0 or not a + b * rc.min() > 0:
        # a line through the bins' noise must stay positive over the scanned ranges
        return float(np.median(sc)), 0.0
    return float(a), float(b)


def estimate_range_noise(evals, counts, ray_range, ray_cos, *, bins=8,
                         alpha=0.05, iterations=RANGE_NOISE_ITERATIONS):
    """Range-noise model ``sigma_r(r) = a + b r`` of a terrestrial scan, from the data.

    Per point, ``(n-1) lambda0 / cos^2(theta)`` estimates ``sigma_r^2 chi2(n-3)`` on planes
    (theta: angle between ray and normal). Medians in range quantile bins, divided by the
    chi-square median, give ``sigma_r`` per bin; a least-squares line through them gives
    ``a, b`` (b clipped at 0). Points at grazing incidence (cos < 0.2) are left out.
    Then, `iterations` times, the same fit on the points the plane test accepts at
    `alpha` with the current line, their medians divided by the chi-square's
    ``(1 - alpha) / 2`` quantile (the median of a chi-square truncated at its ``1 -
    alpha`` quantile): curved surfaces only raise lambda0, and where they fill most of a
    range bin (pipes and tanks) the plain median follows them.

    Returns
    -------
    a, b : float
    """
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = (n - 1) * evals[:, 0] / ray_cos ** 2
    ok = (n >= 4) & np.isfinite(rho) & (ray_cos >= 0.2)
    if ok.sum() < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    df = float(np.median(n[ok])) - 3
    rho, r, nn = rho[ok], ray_range[ok], n[ok]
    a, b = _range_line(rho, r, chi2_critical(0.5, df), bins)
    trunc = chi2_critical(1.0 - (1.0 - alpha) / 2, df)
    for _ in range(iterations):
        with np.errstate(invalid="ignore", divide="ignore"):
            accepted = rho / (a + b * r) ** 2 < chi2_critical(alpha, nn - 3)
        a1, b1 = _range_line(rho, r, trunc, bins, keep=accepted)
        if not (np.isfinite(a1) and a1 + b1 * r.max() > 0 and a1 + b1 * r.min() > 0):
            break
        a, b = a1, b1
    return float(a), float(b)


#: Largest number of points whose cylinder fit enters :func:`estimate_smooth_range_noise`
#: (an even stride through the usable points beyond it): eight range-bin medians need a
#: few thousand, and the fit costs about a tenth of the classification per point.
SMOOTH_NOISE_POINTS = 8000


def estimate_smooth_range_noise(points, features, *, bins=8, max_points=SMOOTH_NOISE_POINTS):
    """Range-noise model ``sigma_r(r) = a + b r`` from the best smooth model of every
    neighbourhood (the default estimate with a sensor).

    :func:`estimate_range_noise` takes per-bin medians of the plane residual ``(n - 1)
    lambda0 / cos^2(theta)``; curved surfaces only raise it, and where pipes and tanks
    fill a range bin the median follows them (tls_plant: b = 2.9e-4 against the true
    5e-5). Here the residual is that of the smooth model of the cylinder test (a circular
    cylinder with its axis tilt fitted, of which the plane is the limit of infinite
    radius): the weighted RSS with unit range noise, each neighbour weighted by ``1 /
    max(|d . rho|, 0.1)^2`` (the share of the range noise across the surface), estimates
    ``sigma_r^2 chi2(n - 5)`` on planes and cylinders alike. Per point it is divided by
    the median of its chi-square; medians in eight range quantile bins and a least-squares
    line through their square roots give ``a, b`` (b clipped at 0), as in
    :func:`estimate_range_noise`. Edges still raise their RSS, but they are a minority in
    every range bin, where curved surfaces were not. Points at grazing incidence (cos
    theta < 0.2) are left out; at most `max_points` points (an even stride) are fitted.

    Parameters
    ----------
    points : (N, 3) ndarray
        The coordinates the features were computed on.
    features : CovarianceResult
        Computed with a sensor.
    bins : int
    max_points : int

    Returns
    -------
    a, b : float
    """
    from ..features import cylinder_test

    n = np.asarray(features.fields["neighbors"], dtype=np.float64)
    ok = (n >= 7) & np.isfinite(features.eigenvalues).all(axis=1) & (features.ray_cos >= 0.2)
    query = np.flatnonzero(ok)
    if query.size < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    if query.size > max_points:
        query = query[np.linspace(0, query.size - 1, max_points).astype(np.int64)]
    indptr, idx = _neighbour_rows(points, features, query)
    stat, dof, _ = cylinder_test(points, query, indptr, idx, _cylinder_axes(features, query),
                                 1.0, sensor=features.sensor, refine_axis=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        s2 = stat / chi2_critical(0.5, np.where(dof > 0, dof, np.nan))
    good = np.isfinite(s2)
    if good.sum() < 20:
        raise InvalidParameterError("cannot estimate the range noise: too few usable points")
    return _range_line(s2[good], features.ray_range[query][good], 1.0, bins)

