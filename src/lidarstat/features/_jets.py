"""Jets with tested reliability: Monge coefficients, their standard deviations and the
chi-square test of every jet (:func:`jets`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from .._shared._choices import Noise
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
from ._noise import height_variance, resolve_noise
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
        hood = (f"radius {self.meta['radius']:g}" if self.meta.get("radius") is not None
                else f"k {self.meta.get('k')}")
        lines = [f"{n} points, jets of degree {self.meta.get('degree')} ({hood}, weight "
                 f"{self.meta.get('weight')}), alpha {self.alpha}",
                 f"sigma {self.sigma:.6g}" + (" (estimated from the data)"
                                             if self.sigma_estimated else ""),
                 f"median neighbours {np.median(self.fields['neighbors']):.0f}"]
        for s in FitStatus:
            c = int(np.count_nonzero(st == s))
            lines.append(f"  {s.name.lower():<20s} {c:>10d} {100.0 * c / max(n, 1):6.2f}%")
        return "\n".join(lines)


def jets(points, *, radius=None, k=None, sigma=None, alpha=0.05, degree=4, monge_degree=None,
         weight="tricube", sensor=None, noise=None, min_neighbors=None, standard_errors=True,
         block_size=131072, progress=None) -> JetResult:
    """Monge coefficients with standard deviations and a chi-square test of every jet.

    Parameters
    ----------
    points : (N, 3) array_like
    radius : float, optional
        Sphere radius (and tricube bandwidth); exactly one of `radius` and `k`.
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
    if (radius is None) == (k is None):
        raise InvalidParameterError(f"{func}: give exactly one of `radius` and `k`")
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
            block_size=block_size, progress=progress, **kw), what=func)
        return map_rows(res, dup.n_unique, dup.inverse)
    if radius is not None:
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
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = fit.q / fit.trace_b
    estimated = sigma is None
    if estimated:
        noise = Noise.NORMAL.value
        sigma = float(np.sqrt(np.median(s0[ok])))
        logger.info("estimated sigma = %g", sigma)
        if not sigma > 0:
            raise InvalidParameterError(
                f"{func}: the estimated sigma is {sigma}: the points lie exactly on the jets; "
                "give `sigma` explicitly")
    else:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    sensor_arr = None if sensor is None else np.asarray(sensor, dtype=np.float64)
    s2 = height_variance(np.where(ok[:, None, None], fit.frame, 0.0), sigma, noise=noise,
                         points=pts, sensor=sensor_arr)
    fields = jet_tests(fit, s2, alpha)
    return JetResult(fields=fields, fit=fit, sigma=float(sigma), sigma_estimated=estimated,
                     alpha=alpha, meta={"radius": radius, "k": k, "degree": degree,
                                        "monge_degree": monge_degree, "weight": weight,
                                        "noise": noise, "min_neighbors": int(min_neighbors),
                                        "standard_errors": bool(standard_errors)})
