"""Jets with tested reliability: Monge coefficients, their standard deviations and the
chi-square test of every jet (:func:`jets`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from .._shared.validation import check_points, check_scalar
from ..errors import InsufficientNeighborsError, InvalidParameterError
from ..io import register_field_descriptions
from ..neighbors import CellIndex, find_duplicates, knn_neighbors, map_rows, run_on_unique
from ..stats import variance_test_satterthwaite
from ._jet_fit import (
    _N_MONGE_OF,
    MONGE_NAMES,
    JetFit,
    _check_options,
    _fit_cells,
    _to_fit,
    fit_jets,
)
from ._jet_scale import CURVATURE_SCALE, choose_rungs, fit_rungs, radius_ladder
from ._noise import height_variance, noise_factor, resolve_noise, sigma_from_fits
from ._quadric import FitStatus, unfitted_reason

logger = logging.getLogger(__name__)

#: Per-point output fields of :func:`jets`, name -> (dtype, description).
JET_FIELDS = {
    "neighbors": ("int32", "points in the neighbourhood (positive weight)"),
    "status": ("uint8", "0 ok,1 few nbrs,2 degenerate,3 rejected"),
    "k1": ("float64", "larger principal curvature"),
    "k2": ("float64", "smaller principal curvature"),
    **{f"d{a}{c}": ("float64", f"principal direction d{a} {c}") for a in (1, 2) for c in "xyz"},
    "NormalX": ("float64", "Monge normal x"),
    "NormalY": ("float64", "Monge normal y"),
    "NormalZ": ("float64", "Monge normal z"),
    **{f"b{i}": ("float64", f"third-order Monge coefficient b{i}") for i in range(4)},
    **{f"c{i}": ("float64", f"fourth-order Monge coefficient c{i}") for i in range(5)},
    **{f"{n}_sd": ("float64", f"standard deviation of {n}") for n in MONGE_NAMES},
    "sigma0_sq": ("float64", "a-posteriori variance factor Q/tr(B)"),
    "chi2_p": ("float64", "p-value of the chi-square test of the jet"),
    "chi2_pass": ("uint8", "1 where the chi-square test accepts the jet"),
    "cond": ("float64", "condition number of the fit"),
    "dz0": ("float64", "fitted minus observed height along the PCA normal"),
    "radius": ("float64", "radius chosen for the point (automatic scale)"),
}
register_field_descriptions(JET_FIELDS)


def jet_tests(fit: JetFit, sigma2, alpha):
    """Per-point fields of a :class:`JetFit`: Monge coefficients, their standard
    deviations and the chi-square test of the jet, for height variance `sigma2`.

    Parameters
    ----------
    fit : JetFit
    sigma2 : float or (N,) ndarray
        Variance of the heights along the normal (see :func:`height_variance`).
    alpha : float
        Level of the Satterthwaite chi-square test of ``Q = v'Wv`` (exact chi-square with
        ``p - m`` degrees of freedom for the unweighted fit).

    Returns
    -------
    dict of str -> (N,) ndarray, named as in ``JET_FIELDS``.
    """
    ok = fit.status == FitStatus.OK
    s2 = np.broadcast_to(np.asarray(sigma2, dtype=np.float64), ok.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = fit.q / fit.trace_b
    test = variance_test_satterthwaite(fit.q, fit.trace_b, fit.trace_b2, s2, alpha)
    chi2_pass = ok & np.isfinite(test.pvalue) & ~test.reject
    status = fit.status.copy()
    status[ok & ~chi2_pass] = FitStatus.MODEL_REJECTED
    fields = {"neighbors": fit.neighbors, "status": status}
    for j, name in enumerate(MONGE_NAMES):
        fields[name] = fit.monge[:, j]
    for a in (1, 2):
        for c, axis in enumerate("xyz"):
            fields[f"d{a}{axis}"] = fit.frame[:, a - 1, c]
    for c, axis in enumerate("XYZ"):
        fields[f"Normal{axis}"] = fit.frame[:, 2, c]
    with np.errstate(invalid="ignore"):
        sd = np.sqrt(np.maximum(fit.monge_cofactor, 0.0) * s2[:, None])
    for j, name in enumerate(MONGE_NAMES):
        fields[f"{name}_sd"] = sd[:, j]
    fields.update(sigma0_sq=s0, chi2_p=test.pvalue, chi2_pass=chi2_pass.astype(np.uint8),
                  cond=fit.cond, dz0=fit.offset)
    nm = _N_MONGE_OF[fit.monge_degree]
    for name in MONGE_NAMES[nm:]:
        fields.pop(name)
        fields.pop(f"{name}_sd")
    if fit.monge_degree < 2:
        for name in ("d1x", "d1y", "d1z", "d2x", "d2y", "d2z"):
            fields.pop(name)
    return fields


@dataclass(frozen=True)
class JetResult:
    """Per-point Monge coefficients, their standard deviations and the model test.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        Named as written to files (see ``JET_FIELDS``), input order.
    fit : JetFit
        The raw fits (jets, frames, cofactors).
    sigma : float
        Measurement standard deviation used (given or estimated).
    sigma_estimated : bool
    alpha : float
    meta : dict
        The neighbourhood and fit options used (radius or k, degrees, weight, noise,
        min_neighbors, standard_errors).
    """

    fields: dict
    fit: JetFit
    sigma: float
    sigma_estimated: bool
    alpha: float
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    def __len__(self):
        return len(self.fit)

    @property
    def params(self) -> dict:
        """The parameters actually used (estimates included): what ``--summary-json`` writes."""
        return {**self.meta, "sigma": self.sigma, "sigma_estimated": self.sigma_estimated,
                "alpha": self.alpha}

    def to_fields(self):
        """Per-point arrays with their file dtypes, for :func:`lidarstat.io.write`."""
        return {k: np.asarray(v, dtype=JET_FIELDS[k][0]) for k, v in self.fields.items()}

    def summary(self) -> str:
        """A short text summary (what a command prints)."""
        st = self.fields["status"]
        n = st.size
        hood = _hood_text(self.meta, self.fields)
        lines = [f"{n} points, jets of degree {self.meta.get('degree')} ({hood}, weight "
                 f"{self.meta.get('weight')}), alpha {self.alpha}",
                 f"sigma {self.sigma:.6g}" + (" (estimated from the data)"
                                             if self.sigma_estimated else ""),
                 f"median neighbours {np.median(self.fields['neighbors']):.0f}"]
        for s in FitStatus:
            c = int(np.count_nonzero(st == s))
            lines.append(f"  {s.name.lower():<20s} {c:>10d} {100.0 * c / max(n, 1):6.2f}%")
        return "\n".join(lines)


def _hood_text(meta, fields):
    """The neighbourhood in words: the radius, k, or the automatic scale's radii."""
    if meta.get("scale") == "auto":
        r = fields["radius"]
        ok = np.isfinite(r)
        if not ok.any():
            return "automatic scale"
        q = np.quantile(r[ok], [0.0, 0.5, 1.0])
        return (f"automatic scale ({meta['scale_criterion']}): radius median {q[1]:.4g}, "
                f"range {q[0]:.4g} to {q[2]:.4g}")
    if meta.get("radius") is not None:
        return f"radius {meta['radius']:g}"
    return f"k {meta.get('k')}"


def _estimate_sigma(fit, ok, func, *, noise, points, sensor):
    """Sigma along the noise direction from the fitted jets (the shared estimator,
    :func:`lidarstat.features.sigma_from_fits`): the median over the jets of each jet's
    median-unbiased variance ``Q / (c chi2_0.5(nu))``, divided by the factor
    ``(d . n)^2`` that turns noise along d into heights along the jet's normal n.

    The median-unbiased form matters at the automatic scale's smallest rung (``nu`` about
    16, where the plain ``Q / tr(B)`` is low by 4 %); the factor matters wherever the
    cloud has steep faces: z noise seen along the normal of a face of slope theta has
    std ``sigma cos(theta)``, so a median of the normal residuals over flat and steep jets
    underestimates the noise of the flat ones, whose jets the chi-square test then
    rejects.
    """
    normals = fit.frame[ok, 2, :]
    f = noise_factor(normals, normals, noise,
                     points=None if points is None else points[ok], sensor=sensor)
    with np.errstate(divide="ignore"):  # nu -> 0 (nearly exact jets): no information
        sigma = sigma_from_fits(fit.q[ok], fit.trace_b[ok], fit.trace_b2[ok], f)
    logger.info("estimated sigma = %g (noise along %s)", sigma, noise)
    if not sigma > 0:
        raise InvalidParameterError(
            f"{func}: the estimated sigma is {sigma}: the points lie exactly on the jets; "
            "give `sigma` explicitly")
    return sigma


def _auto_fit(pts, *, criterion, sigma, noise, sensor, alpha, kw, block_size, progress, func,
              scales=None):
    """Jets at the automatic scale (``_jet_scale``): the fit, sigma, and the scale's record."""
    radii = radius_ladder(pts) if scales is None else np.asarray(scales, dtype=np.float64)
    sensor_arr = None if sensor is None else np.asarray(sensor, dtype=np.float64)
    state = {"sigma": sigma, "noise": noise}

    def tests(sub, rows):
        ok = sub.status == FitStatus.OK
        if state["sigma"] is None:  # the smallest rung: least smoothing bias in Q
            if not ok.any():
                raise InsufficientNeighborsError(
                    f"{func}: no jet could be fitted at the smallest radius of the automatic "
                    f"scale ({radii[0]:.4g}): {unfitted_reason(sub.status, sub.neighbors, kw['min_neighbors'])}")
            state["sigma"] = _estimate_sigma(sub, ok, func, noise=state["noise"],
                                             points=pts[rows], sensor=sensor_arr)
        s2 = height_variance(np.where(ok[:, None, None], sub.frame, 0.0), state["sigma"],
                             noise=state["noise"], points=pts[rows], sensor=sensor_arr)
        return jet_tests(sub, s2, alpha)

    rung, seeds, _ = choose_rungs(pts, radii, criterion, alpha, tests, kw,
                                     block_size=block_size)
    out = fit_rungs(pts, radii, rung, kw, block_size=block_size, progress=progress)
    fit = _to_fit(out, kw["degree"], kw["monge_degree"], kw["weight"])
    counts = np.bincount(rung, minlength=len(radii))
    info = {"scale": "auto", "scale_criterion": criterion.name,
            "radii": [float(r) for r in radii],
            "points_per_radius": [int(c) for c in counts], "scale_seeds": int(seeds.size)}
    return fit, state["sigma"], state["noise"], radii[rung], info


def jets(points, *, radius=None, k=None, sigma=None, alpha=0.05, degree=4, monge_degree=None,
         weight="tricube", sensor=None, noise=None, min_neighbors=None, standard_errors=True,
         scale_criterion=None, scales=None, block_size=131072, progress=None) -> JetResult:
    """Monge coefficients with standard deviations and a chi-square test of every jet.

    Parameters
    ----------
    points : (N, 3) array_like
    radius : float, optional
        Sphere radius (and tricube bandwidth); at most one of `radius` and `k`. With
        neither, the scale is chosen per point from the data (the automatic scale,
        docs/methods/jets.md): the smallest radius of a ladder at which
        `scale_criterion` detects its quantity at the noise; the radius is written to
        the ``radius`` field.
    k : int, optional
        Number of nearest neighbours (the point itself included).
    sigma : float, optional
        Measurement standard deviation; estimated as the median of ``sqrt(Q/tr(B))``
        when omitted (the chi-square then only flags locally unusual residuals).
    alpha : float
        Level of the chi-square test of the jet.
    degree, monge_degree, weight, sensor, min_neighbors, standard_errors
        See :func:`fit_jets`.
    noise : {'z', 'range', 'normal'} or Noise, optional
        Direction of the measurement noise (see
        :func:`lidarstat.features.height_variance`); default ``'range'`` with a sensor,
        else ``'z'``.
    scale_criterion : JetScaleCriterion, optional
        What the automatic scale must detect (default
        :data:`lidarstat.features.CURVATURE_SCALE`: a significant principal curvature);
        :func:`lidarstat.segment.ridges` asks for a significant k'' of a ridge.
    scales : sequence of float, optional
        Automatic scale: the ladder of radii, increasing (default
        :func:`lidarstat.features.radius_ladder` of `points`; a catalogue of tiles gives
        every tile the area's ladder).
    block_size : int
        Points per block of the fused radius driver.
    progress : callable(done, total), optional

    Returns
    -------
    JetResult

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.synth import make_sphere_cap
    >>> from lidarstat.features import jets
    >>> cloud = make_sphere_cap(1.0, spacing=0.03, sigma=0.0005, rng=0)
    >>> res = jets(cloud.xyz, radius=0.25, sigma=0.0005, degree=4)
    >>> inner = cloud.edge_distance > 0.25
    >>> H = 0.5 * (res["k1"] + res["k2"])[inner]
    >>> print(round(float(np.median(H)), 2))   # -1/R, normal up
    -1.0
    """
    func = "jets"
    pts = check_points(points)
    if radius is not None and k is not None:
        raise InvalidParameterError(f"{func}: give at most one of `radius` and `k`")
    degree, monge_degree, min_neighbors, weight = _check_options(
        func, degree, monge_degree, weight, min_neighbors, sensor)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    noise = resolve_noise(noise, sensor, func=func)
    kw = dict(degree=degree, monge_degree=monge_degree, weight=weight, sensor=sensor,
              min_neighbors=min_neighbors, standard_errors=standard_errors)
    dup = find_duplicates(pts)
    if dup.any:  # every location once, its result to every point at it (_duplicates)
        res = run_on_unique(dup, lambda: jets(
            pts[dup.first], radius=radius, k=k, sigma=sigma, alpha=alpha, noise=noise,
            scale_criterion=scale_criterion, scales=scales, block_size=block_size,
            progress=progress, **kw),
            what=func)
        return map_rows(res, dup.n_unique, dup.inverse)
    scale_info, chosen = {}, None
    estimated = sigma is None
    if not estimated:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    if scales is not None:
        scales = np.atleast_1d(np.asarray(scales, dtype=np.float64))
        if scales.ndim != 1 or not scales.size or not np.all(np.isfinite(scales) & (scales > 0)) \
                or np.any(np.diff(scales) <= 0):
            raise InvalidParameterError(f"The 'scales' parameter of {func} must be increasing "
                                        "positive radii.")
        if radius is not None or k is not None:
            raise InvalidParameterError(f"{func}: `scales` is the automatic scale's ladder: "
                                        "give it without `radius` and `k`")
    if radius is None and k is None:
        if pts.shape[0] <= (degree + 1) * (degree + 2) // 2:
            raise InsufficientNeighborsError(
                f"{func}: {pts.shape[0]} distinct points, too few for a jet of degree {degree}")
        fit, sigma, noise, chosen, scale_info = _auto_fit(
            pts, criterion=CURVATURE_SCALE if scale_criterion is None else scale_criterion,
            sigma=sigma, noise=noise, sensor=sensor, alpha=alpha, kw=kw,
            block_size=block_size, progress=progress, func=func, scales=scales)
    elif radius is not None:
        radius = check_scalar(radius, "radius", func=func, low=0.0)
        index = CellIndex(pts, radius)
        out = _fit_cells(index, block_size=block_size, progress=progress, **kw)
        fit = _to_fit(out, degree, monge_degree, weight)
    else:
        k = check_scalar(k, "k", func=func, low=2, closed="left", integer=True)
        if k > pts.shape[0]:
            raise InvalidParameterError(
                f"The 'k' parameter of {func} must be at most the number of points: the "
                f"cloud has {pts.shape[0]:,} (distinct locations), fewer than k = {k}")
        fit = fit_jets(pts, knn_neighbors(pts, k), **kw)
    ok = fit.status == FitStatus.OK
    if not ok.any():
        why = unfitted_reason(fit.status, fit.neighbors, min_neighbors)
        raise InsufficientNeighborsError(
            f"{func}: no jet could be fitted: {why} (degree {degree} needs "
            f"{(degree + 1) * (degree + 2) // 2 + 1} points, not all on one line); "
            "enlarge `radius`/`k`")
    sensor_arr = None if sensor is None else np.asarray(sensor, dtype=np.float64)
    if sigma is None:
        sigma = _estimate_sigma(fit, ok, func, noise=noise, points=pts, sensor=sensor_arr)
    s2 = height_variance(np.where(ok[:, None, None], fit.frame, 0.0), sigma, noise=noise,
                         points=pts, sensor=sensor_arr)
    fields = jet_tests(fit, s2, alpha)
    if chosen is not None:
        fields["radius"] = chosen
    return JetResult(fields=fields, fit=fit, sigma=float(sigma), sigma_estimated=estimated,
                     alpha=alpha, meta={"radius": radius, "k": k, "degree": degree,
                                        "monge_degree": monge_degree, "weight": weight,
                                        "noise": noise, "min_neighbors": int(min_neighbors),
                                        "standard_errors": bool(standard_errors),
                                        **scale_info})
