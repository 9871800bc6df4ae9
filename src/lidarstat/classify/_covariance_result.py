"""Result containers of the covariance classification (seed 003)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..features import PointClass
from ..io import register_field_descriptions

#: Per-point output fields of the classification, name -> (dtype, description). The
#: ``'centroid'`` boundary test writes ``boundary_T2`` / ``boundary_p``, the ``'grid'``
#: test ``jump_z`` / ``jump_p`` / ``border_*``.
FIELDS = {
    "point_class": ("uint8", "0 undetermined,1 surface,2 edge,3 boundary"),
    "plane_p": ("float64", "p-value of the chi-square plane (low curvature) test"),
    "variation_p": ("float64", "p-value of the consistent-curvature test"),
    "boundary_T2": ("float64", "Hotelling T2 of the centroid offset"),
    "boundary_p": ("float64", "p-value of the boundary test"),
    "jump_z": ("float64", "largest range-continuity z of the grid edges"),
    "jump_p": ("float64", "p-value: a depth jump at the point"),
    "border_distance": ("float64", "distance to the estimated end of the visible surface"),
    "border_kind": ("uint8", "nearest border: 1 scan window, 2 no return, 3 depth jump"),
    "border_p": ("float64", "continuity-test p-value of the nearest border (0: observed)"),
}
register_field_descriptions(FIELDS)


def _plain(v):
    """A JSON-friendly copy of a parameter value (arrays of 3 as lists, enums as strings)."""
    if isinstance(v, np.ndarray):
        return v.tolist() if v.size <= 3 else None
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, str):
        return str(v.value) if hasattr(v, "value") else v
    return v


@dataclass(frozen=True)
class CovarianceClasses:
    """Per-point classes and the tests behind them.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        ``point_class`` and the test fields (``FIELDS``), input order.
    sigma : float or ndarray
        Noise standard deviation used by the plane test (given or estimated).
    sigma_estimated : bool
    alpha : float
        Level of the plane test.
    boundary_alpha : float or None
        Level of the centroid boundary test (None with the ``'grid'`` test, which places
        borders instead of testing centroids).
    curvature_threshold, variance_threshold : float or None
        User thresholds, when given (they replace tests 1 and 2).
    meta : dict
        The boundary and consistent-curvature tests used, their levels, the estimated
        range-noise line and the per-point cylinder fits.
    """

    fields: dict
    sigma: float | np.ndarray
    sigma_estimated: bool
    alpha: float
    boundary_alpha: float | None
    curvature_threshold: float | None = None
    variance_threshold: float | None = None
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    @property
    def point_class(self) -> np.ndarray:
        return self.fields["point_class"]

    def to_fields(self):
        return {k: np.asarray(v, dtype=FIELDS[k][0]) for k, v in self.fields.items()}

    def counts(self) -> dict:
        pc = self.point_class
        return {c.name.lower(): int(np.count_nonzero(pc == c)) for c in PointClass}

    @property
    def params(self) -> dict:
        """The parameters of the tests as used (after defaults and estimates)."""
        m = self.meta
        sig = self.sigma
        out = {"noise": _plain(m.get("noise")),
               "sigma": float(sig) if np.ndim(sig) == 0 else None,
               "sigma_estimated": self.sigma_estimated,
               "range_noise": list(m["range_noise"]) if "range_noise" in m else None,
               "alpha": self.alpha, "curved": _plain(m.get("curved")),
               "curved_alpha": m.get("curved_alpha"),
               "curvature_threshold": self.curvature_threshold,
               "variance_threshold": self.variance_threshold,
               "boundary": _plain(m.get("boundary")), "boundary_alpha": self.boundary_alpha}
        if m.get("boundary") == "grid":
            out.update(jump_alpha=m.get("jump_alpha"), border_band=m.get("border_band"))
        return out

    def summary(self) -> str:
        n = self.point_class.size
        sig = (f"{self.sigma:.6g}" if np.ndim(self.sigma) == 0 else
               f"per point (median {np.median(self.sigma):.6g})")
        if "range_noise" in self.meta:
            a, b = self.meta["range_noise"]
            sig = f"along the rays {a:.3g} + {b:.3g} r"
        bnd = self.meta.get("boundary")
        if bnd == "grid":
            test = (f"boundary: grid test, band {self.meta['border_band']}, jump alpha "
                    f"{self.meta['jump_alpha']}")
        else:
            test = f"boundary: centroid test at {self.boundary_alpha}"
        lines = [f"{n} points, sigma {sig}" + (" (estimated)" if self.sigma_estimated else "")
                 + f", alpha {self.alpha}", test]
        if "curved" in self.meta:
            lines.append(f"consistent curvature: {self.meta['curved']} test at "
                         f"{self.meta['curved_alpha']}")
        if self.curvature_threshold is not None:
            lines.append(f"SurfaceVariation threshold {self.curvature_threshold} (user)")
        if self.variance_threshold is not None:
            lines.append(f"CurvatureVariance threshold {self.variance_threshold} (user)")
        for name, k in self.counts().items():
            lines.append(f"  {name:<13s} {k:>10d} {100.0 * k / max(n, 1):6.2f}%")
        return "\n".join(lines)


@dataclass(frozen=True)
class CovarianceClassification:
    """Features and classes of :func:`covariance` (what ``lidarstat covariance`` writes).

    Attributes
    ----------
    features : CovarianceResult
    classes : CovarianceClasses
    """

    features: object
    classes: CovarianceClasses

    def __getitem__(self, name):
        if name in self.classes.fields:
            return self.classes.fields[name]
        return self.features.fields[name]

    @property
    def point_class(self) -> np.ndarray:
        return self.classes.point_class

    def to_fields(self):
        """Every per-point field with its file dtype: ``point_class`` first."""
        c = self.classes.to_fields()
        return {"point_class": c.pop("point_class"), **self.features.to_fields(), **c}

    @property
    def params(self) -> dict:
        """The parameters actually used (neighbourhood, noise, tests; what
        ``--summary-json`` writes beside the counts)."""
        f = self.features
        out = {"k": f.k, "radius": f.radius, "eigen_mode": _plain(f.eigen_mode),
               "sensor": _plain(f.sensor), **self.classes.params}
        if f.meta.get("scale") == "optimal":
            kopt = f.fields["OptimalKNN"]
            out.update(scale="optimal", scale_rule=f.meta.get("rule", "eigenentropy"),
                       k_min=f.meta["k_min"], k_max=f.meta["k_max"],
                       optimal_k_median=float(np.median(kopt)),
                       optimal_radius_median=float(np.median(f.fields["OptimalRadius"])))
        return out

    def summary(self) -> str:
        f = self.features
        if f.meta.get("scale") == "optimal":
            q = np.percentile(f.fields["OptimalKNN"], [10, 50, 90])
            r = np.median(f.fields["OptimalRadius"])
            rule = ("plane test with power" if f.meta.get("rule") == "tested"
                    else "minimum eigenentropy")
            nb = (f"automatic ({rule}, k {f.meta['k_min']} to "
                  f"{f.meta['k_max']}): k 10/50/90 % {q[0]:.0f}/{q[1]:.0f}/{q[2]:.0f}, "
                  f"radius median {r:.4g}")
        else:
            nb = f"k {f.k}" if f.k is not None else f"radius {f.radius}"
        return (f"neighbourhoods: {nb}, median {np.median(f.counts):.0f} points\n"
                + self.classes.summary())
