"""One refined SAR-FS surface unit: its points, fit, surface and the surface's normals.

:class:`SurfaceUnit` is what :func:`lidarstat.segment.refine_cluster` returns and what
``Segmentation.units`` of the SAR method holds (one per segment).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..stats import PolynomialBasis, SARFit
from ._forward_search import ForwardSearchResult


@dataclass(frozen=True)
class SurfaceUnit:
    """One refined surface unit.

    Attributes
    ----------
    accepted : (m,) ndarray of int64
        Point indices accepted by the Forward Search (raw cluster included).
    residuals : (m,) ndarray
        Height residuals of the accepted points from the fitted surface.
    n_s, n_sa, m : int
        Raw cluster, search area and accepted sizes (Table 6 of the paper).
    degree : int
        Polynomial order.
    basis : PolynomialBasis
        Orthogonal basis (fitted on the raw cluster).
    fit : SARFit
        Final fit on the accepted points: rho (and its standard error) from the ML fit
        on the raw cluster, theta and sigma^2 by eq. 3.1-3.2 on the m accepted points.
    surface : (r,) ndarray
        Orthogonal-basis coefficients of the surface: the least-squares trend of the
        accepted points (:func:`lidarstat.stats.sar_trend`), which estimates the
        polynomial closest to the SAR mean ``(I - rho W)^-1 A theta``.
    surface_cov : (r, r) ndarray
        Covariance of `surface` under the fitted SAR model (sandwich).
    sigma : float
        Residual standard deviation of the accepted points about `surface`.
    fs : ForwardSearchResult
        Monitoring of the search.
    rho_points : int
        Points used for the ML estimate of rho (the raw cluster, or a patch of
        :data:`SAR_MAX` of its points).
    raw : (n_s,) ndarray of int64
        Indices of the raw cluster.
    frame : (4, 3) ndarray or None
        None: the surface is a height field z(E, N) (the paper's model). Otherwise the
        unit is steeper than :data:`FRAME_SLOPE` and is modelled in its own frame: row 0
        the origin, rows 1-3 the unit vectors u, v, n (n the raw cluster's normal);
        local coordinates are ``(x - origin) @ rows[1:].T``, the "height" is along n
        and `basis`, `surface`, `residuals` are in that frame.
    """

    accepted: np.ndarray
    residuals: np.ndarray
    n_s: int
    n_sa: int
    m: int
    degree: int
    basis: PolynomialBasis
    fit: SARFit
    surface: np.ndarray
    surface_cov: np.ndarray
    sigma: float
    fs: ForwardSearchResult
    rho_points: int
    raw: np.ndarray
    frame: np.ndarray | None = None

    def height(self, xy):
        """Surface height at planimetric positions `xy` (file coordinates; only for units
        modelled as z(E, N), ``frame is None``)."""
        return self.basis.evaluate(self.surface, xy)

    def normal(self, xyz):
        """Unit normals (3,) of the surface at points `xyz` (k, 3), in file coordinates,
        upward (or, for a vertical unit, as its frame's third axis)."""
        xyz = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        if self.frame is None:
            g = self.basis.gradient(self.surface, xyz[:, :2])
            n = np.c_[-g, np.ones(len(g))]
            return n / np.linalg.norm(n, axis=1, keepdims=True)
        origin, rot = self.frame[0], self.frame[1:]
        local = (xyz - origin) @ rot.T
        g = self.basis.gradient(self.surface, local[:, :2])
        n = np.c_[-g, np.ones(len(g))] @ rot
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return np.where(n[:, 2:3] < 0, -n, n)

    def _local_xy(self, xyz):
        xyz = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        if self.frame is None:
            return xyz[:, :2]
        return ((xyz - self.frame[0]) @ self.frame[1:].T)[:, :2]

    def gradient_cov(self, xyz):
        """Gradient ``g = (dz/dE, dz/dN)`` (k, 2) of the surface at points `xyz` (k, 3)
        and its covariance (k, 2, 2) propagated from `surface_cov` (in the unit's own
        frame for a wall)."""
        xy = self._local_xy(xyz)
        g = self.basis.gradient(self.surface, xy)
        r = self.basis.n_terms
        # the gradient is linear in the coefficients: columns of the Jacobian
        J = np.stack([self.basis.gradient(np.eye(r)[k], xy) for k in range(r)], axis=-1)
        return g, J @ self.surface_cov @ np.swapaxes(J, 1, 2)

    def normal_error(self, xyz, true_normal=None):
        """Propagated standard error of the normal and, given the truth, its error.

        Returns ``se_deg`` (k,): the angular standard error (degrees) along the worst
        direction, the square root of the largest eigenvalue of ``M C`` with C the
        gradient covariance and ``M = ((1 + |g|^2) I - g g') / (1 + |g|^2)^2`` the
        metric of the angle between normals ``(-g, 1)`` (to first order,
        ``angle^2 = dg' M dg``). With `true_normal` (3,) (file coordinates, any sign)
        also ``angle_deg`` (k,), the angle to it, and ``t2`` (k,), the Mahalanobis
        distance ``dg' C^-1 dg`` of the true gradient, chi-square(2) when the surface is
        unbiased and C right: the 95 % confidence cone covers the true normal when
        ``t2 <= chi2_2(0.95) = 5.99``.
        """
        g, C = self.gradient_cov(xyz)
        q = 1.0 + np.einsum("ki,ki->k", g, g)
        M = (q[:, None, None] * np.eye(2) - g[:, :, None] * g[:, None, :]) / \
            (q * q)[:, None, None]
        ev = np.linalg.eigvals(M @ C).real
        se = np.degrees(np.sqrt(np.maximum(ev.max(axis=1), 0.0)))
        if true_normal is None:
            return se
        n = np.asarray(true_normal, dtype=np.float64)
        if self.frame is not None:
            n = self.frame[1:] @ n
        n = n if n[2] > 0 else -n
        dg = g - (-n[:2] / n[2])
        t2 = np.einsum("ki,ki->k", dg, np.linalg.solve(C, dg[..., None])[..., 0])
        fitted = self.normal(np.atleast_2d(xyz))
        ang = np.degrees(np.arccos(np.minimum(1.0, np.abs(
            fitted @ np.asarray(true_normal, dtype=np.float64)) /
            np.linalg.norm(true_normal))))
        return se, ang, t2

    def monomials(self):
        """Coefficients in metres of ``(E - E0)^p (N - N0)^q`` and their standard errors.

        Returns ``powers (r, 2)``, ``coef (r,)``, ``se (r,)``; ``(E0, N0)`` is
        ``basis.center``.
        """
        b = self.basis
        rinv = np.linalg.inv(b.R)
        scale = b.scale ** -b.term_degree.astype(float)
        coef = (rinv @ self.surface) * scale
        cov = rinv @ self.surface_cov @ rinv.T
        se = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale
        return b.powers, coef, se
