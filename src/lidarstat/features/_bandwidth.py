"""Smallest Taylor bandwidth whose tests detect given curvatures (eq. 19-21)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._shared._choices import Test
from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ..stats import normal_quantile, z_critical
from ._curvature_formulas import curvature_jacobian, curvatures, principal_jacobian
from ._quadric import _run_kernel


@dataclass(frozen=True)
class BandwidthResult:
    """Outcome of :func:`optimal_bandwidth`.

    Attributes
    ----------
    radius : float
        Smallest radius tried at which K0 and H0 are detectable (NaN if none is).
    radii, neighbors, K_min, H_min : ndarray
        Every radius tried, the expected number of neighbours, and the minimal detectable
        |K| and |H| there (eq. 19 with the chosen test's covariance).
    params : dict
        The design inputs (K0, H0, sigma, density, alpha, power, test) and the radius.
    """

    radius: float
    radii: np.ndarray
    neighbors: np.ndarray
    K_min: np.ndarray
    H_min: np.ndarray
    params: dict = field(default_factory=dict)

    def to_fields(self) -> dict:
        """No per-point arrays: the design works on an ideal neighbourhood, not a cloud."""
        return {}

    def summary(self) -> str:
        """The table of radii and the chosen one (what the CLI prints)."""
        p = self.params
        if self.radius == self.radius:
            last = (f"smallest radius detecting K0={p.get('K0')}, H0={p.get('H0')}: "
                    f"{self.radius:.6g}")
        else:
            last = "no radius tried detects these curvatures; lower the noise or raise the density"
        return self.table() + "\n" + last

    def table(self) -> str:
        rows = [f"{'radius':>12s} {'neighbours':>10s} {'K_min':>12s} {'H_min':>12s}"]
        for r, n, k, h in zip(self.radii, self.neighbors, self.K_min, self.H_min):
            mark = "  <-" if r == self.radius else ""
            rows.append(f"{r:12.6g} {n:10d} {k:12.4g} {h:12.4g}{mark}")
        return "\n".join(rows)


def optimal_bandwidth(*, K0, H0, sigma, density, alpha=0.05, power=0.5, test="calibrated",
                      radii=None):
    """Smallest sphere radius whose Bonferroni tests detect curvatures K0 and H0.

    The paper's design procedure (Crosilla et al. 2009, eq. 20-21): an ideal neighbourhood
    (square grid of the given planimetric `density`) on the paraboloid with principal
    curvatures from (K0, H0) is fitted at increasing radii; the cofactor of (K, H) gives
    the minimal detectable values ``(z_{1-alpha/4} + z_power) * sd`` (eq. 19; the paper's
    criterion is ``power=0.5``, i.e. the statistic's expectation reaching the critical
    value). H0 must be detectable, and K0 too when it is not zero (for the calibrated
    test, through both principal curvatures).

    Parameters
    ----------
    K0, H0 : float
        Expected Gaussian and mean curvature (H0 != 0; H0^2 >= K0).
    sigma : float
        Measurement noise standard deviation.
    density : float
        Points per unit area.
    alpha : float
        Global significance level (each of K, H at alpha/2).
    power : float
        Required detection probability, in [0.5, 1).
    test : {'calibrated', 'paper'} or Test
        Covariance used: sandwich (calibrated) or ``(X'WX)^-1`` (paper).
    radii : sequence of float, optional
        Candidate radii; default 40 values from 3 to 60 point spacings.

    Returns
    -------
    BandwidthResult
    """
    func = "optimal_bandwidth"
    K0 = check_scalar(K0, "K0", func=func)
    H0 = check_scalar(H0, "H0", func=func)
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    density = check_scalar(density, "density", func=func, low=0.0)
    alpha = check_scalar(alpha, "alpha", func=func, low=0.0, high=1.0)
    power = check_scalar(power, "power", func=func, low=0.5, high=1.0, closed="left")
    test = Test.parse(test, "test", func=func)
    if H0 == 0 or H0 * H0 < K0:
        raise InvalidParameterError(f"{func}: need H0 != 0 and H0^2 >= K0 (got K0={K0}, H0={H0})")
    spacing = 1.0 / np.sqrt(density)
    if radii is None:
        radii = spacing * np.geomspace(3.0, 60.0, 40)
    radii = np.sort(np.asarray(radii, dtype=np.float64))
    disc = np.sqrt(H0 * H0 - K0)
    k1, k2 = H0 - disc, H0 + disc
    z = z_critical(alpha / 2) + normal_quantile(power)  # each of K, H two-sided at alpha/2
    cov_mode = "paper" if test == Test.PAPER else "sandwich"
    n_nb, kmin_det, hmin_det = [], [], []
    ok = np.zeros(radii.size, dtype=bool)
    for t, r in enumerate(radii):
        half = int(np.ceil(r / spacing))
        g = np.arange(-half, half + 1) * spacing
        u, v = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
        pts = np.c_[u, v, 0.5 * (k1 * u * u + k2 * v * v)]
        d = np.linalg.norm(pts, axis=1)
        keep = d <= r
        centre = int(np.flatnonzero((u == 0) & (v == 0))[0])
        idx = np.flatnonzero(keep)
        out = _run_kernel(pts, np.array([centre]), np.array([0, idx.size]), idx, d[idx],
                          bandwidth=r, frame="z", sensor=None, min_neighbors=7,
                          covariance=cov_mode)
        n_nb.append(int(out["npts"][0]))
        if out["status"][0] != 0:
            kmin_det.append(np.nan)
            hmin_det.append(np.nan)
            continue
        a = out["beta"][:, 1:]
        cov = sigma * sigma * out["cof"][:, 1:, 1:]
        J = curvature_jacobian(a)
        C = J @ cov @ np.swapaxes(J, 1, 2)
        sdK, sdH = np.sqrt(C[0, 0, 0]), np.sqrt(C[0, 1, 1])
        kmin_det.append(z * sdK)
        hmin_det.append(z * sdH)
        det_h = abs(H0) >= z * sdH
        if K0 == 0:
            det_k = True
        elif test == Test.PAPER:
            det_k = abs(K0) >= z * sdK
        else:
            K, H, _, _ = curvatures(a)
            Jp = principal_jacobian(K, H, J)
            Cp = Jp @ cov @ np.swapaxes(Jp, 1, 2)
            det_k = abs(k1) >= z * np.sqrt(Cp[0, 0, 0]) and abs(k2) >= z * np.sqrt(Cp[0, 1, 1])
        ok[t] = det_h and det_k
    best = float(radii[np.argmax(ok)]) if ok.any() else float("nan")
    params = {"K0": K0, "H0": H0, "sigma": sigma, "density": density, "alpha": alpha,
              "power": power, "test": test, "radius": best}
    return BandwidthResult(best, radii, np.array(n_nb), np.array(kmin_det), np.array(hmin_det),
                           params=params)
