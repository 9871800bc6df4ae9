"""What :func:`lidarstat.features.curvature` returns: per-point fields and their file names."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io import register_field_descriptions
from ._hk import SurfaceType
from ._quadric import FitStatus

#: Per-point output fields, name -> (dtype, description). The first eleven are the contract
#: of ARCHITECTURE.md; the rest extend it.
FIELDS = {
    "neighbors": ("int32", "points in the neighbourhood (positive weight)"),
    "z0": ("float64", "z of the fitted surface point at the point"),
    "sigma0_sq": ("float64", "a-posteriori variance factor"),
    "chi2_pass": ("uint8", "1 where the chi-square test accepts the quadric"),
    "K": ("float64", "Gaussian curvature"),
    "H": ("float64", "mean curvature (H<0 convex)"),
    "kmin": ("float64", "smaller principal curvature"),
    "kmax": ("float64", "larger principal curvature"),
    "K_sig": ("uint8", "1 where K differs significantly from 0"),
    "H_sig": ("uint8", "1 where H differs significantly from 0"),
    "surface_type": ("uint8", "HK surface type code"),
    "status": ("uint8", "0 ok,1 few nbrs,2 degenerate,3 rejected"),
    "dz0": ("float64", "fitted minus observed height (local)"),
    "chi2_p": ("float64", "p-value of the chi-square test"),
    "planar_p": ("float64", "p-value of the planarity/F test"),
    "K_p": ("float64", "p-value of the K test"),
    "H_p": ("float64", "p-value of the H test"),
    "NormalX": ("float64", "surface normal x"),
    "NormalY": ("float64", "surface normal y"),
    "NormalZ": ("float64", "surface normal z"),
}
register_field_descriptions(FIELDS)
OPTIONAL_FIELDS = {
    "K_min": ("float64", "minimal detectable |K| (eq. 19)"),
    "H_min": ("float64", "minimal detectable |H| (eq. 19)"),
    "radius": ("float64", "radius chosen per point (automatic scale, multi-scale)"),
}
register_field_descriptions(OPTIONAL_FIELDS)


@dataclass(frozen=True)
class CurvatureResult:
    """Per-point curvature, tests and surface types, plus what produced them
    (:func:`lidarstat.features.curvature`).

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        Per-point outputs, in input order, named as written to files (see ``FIELDS``).
    radius : float or tuple of float
        Bandwidth(s) used.
    sigma : float
        Measurement standard deviation used by the tests (given or estimated).
    sigma_estimated : bool
        True when `sigma` was estimated from the data.
    alpha : float
        Significance level.
    test : str
        ``'calibrated'`` or ``'paper'``.
    frame : str
        Local frame.
    noise : str
        Direction of `sigma` used by the tests (``'normal'`` when `sigma` was estimated:
        the estimate is of the local heights).
    min_neighbors : int
        Smallest neighbourhood a quadric was fitted on.
    minimal_detectable : bool
        Whether ``K_min`` and ``H_min`` were computed.
    automatic : bool
        True when the radius was chosen per point (`radius` is then the ladder).
    power : float or None
        Detection probability of the automatic scale.
    """

    fields: dict
    radius: float | tuple
    sigma: float
    sigma_estimated: bool
    alpha: float
    test: str
    frame: str
    meta: dict = field(default_factory=dict)
    noise: str = "z"
    min_neighbors: int = 7
    minimal_detectable: bool = False
    automatic: bool = False
    power: float | None = None

    @property
    def params(self) -> dict:
        """The parameters actually used (estimates included): what ``--summary-json`` writes."""
        radius = self.radius if isinstance(self.radius, float) else list(self.radius)
        scale = {}
        if self.automatic:
            scale = {"radius": "auto", "scales": radius, "power": self.power,
                     **self.radius_stats()}
            radius = "auto"
        return {**scale, "radius": radius, "sigma": self.sigma, "sigma_estimated": self.sigma_estimated,
                "alpha": self.alpha, "test": str(self.test), "frame": str(self.frame),
                "noise": str(self.noise), "min_neighbors": self.min_neighbors,
                "minimal_detectable": self.minimal_detectable}

    def __getitem__(self, name):
        return self.fields[name]

    def __len__(self):
        return self.fields["surface_type"].size

    def to_fields(self):
        """The per-point arrays with their file dtypes, ready for :func:`lidarstat.io.write`."""
        spec = {**FIELDS, **OPTIONAL_FIELDS}
        return {k: np.asarray(v, dtype=spec[k][0]) for k, v in self.fields.items()}

    def radius_stats(self) -> dict:
        """Median, 10 % and 90 % quantiles of the chosen radius over the fitted points (empty
        without a per-point radius)."""
        r = self.fields.get("radius")
        if r is None:
            return {}
        ok = np.asarray(self.fields["status"]) != FitStatus.TOO_FEW_NEIGHBORS
        r = np.asarray(r)[ok] if ok.any() else np.asarray(r)
        if r.size == 0:
            return {}
        q10, q50, q90 = np.quantile(r, [0.1, 0.5, 0.9])
        return {"radius_median": float(q50), "radius_p10": float(q10), "radius_p90": float(q90)}

    def counts(self):
        """Counts per surface type and per status reason."""
        st = self.fields["surface_type"]
        status = self.fields["status"]
        types = {t.name.lower(): int(np.count_nonzero(st == t)) for t in SurfaceType}
        reasons = {s.name.lower(): int(np.count_nonzero(status == s)) for s in FitStatus}
        return {"surface_type": types, "status": reasons}

    def summary(self) -> str:
        """A one-screen text summary (what the CLI prints)."""
        n = len(self)
        c = self.counts()
        rad = (f"{self.radius:.6g}" if isinstance(self.radius, float)
               else ", ".join(f"{r:.6g}" for r in self.radius))
        if self.automatic:
            st = self.radius_stats()
            rad = (f"automatic {st.get('radius_median', float('nan')):.6g} (median; 10-90 %: "
                   f"{st.get('radius_p10', float('nan')):.6g}-{st.get('radius_p90', float('nan')):.6g}"
                   f"; ladder {rad})")
        lines = [
            f"{n} points, radius {rad}, frame {self.frame}, test {self.test}, alpha {self.alpha}",
            f"sigma {self.sigma:.6g} along {self.noise}"
            + (" (estimated from the data)" if self.sigma_estimated else ""),
            f"median neighbours {np.median(self.fields['neighbors']):.0f}",
            "surface types:",
        ]
        for t in SurfaceType:
            k = c["surface_type"][t.name.lower()]
            lines.append(f"  {int(t)} {t.name.lower():<17s} {k:>10d} {100.0 * k / max(n, 1):6.2f}%")
        lines.append("not classified, by reason:")
        for s in FitStatus:
            if s == FitStatus.OK:
                continue
            k = c["status"][s.name.lower()]
            lines.append(f"  {s.name.lower():<20s} {k:>10d} {100.0 * k / max(n, 1):6.2f}%")
        return "\n".join(lines)
