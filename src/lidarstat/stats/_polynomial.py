"""Orthogonal polynomial trend bases and the choice of their order (seed 002, section 2).

The SAR units model heights as a total-degree polynomial in (E, N); on a basis
orthonormal over the fitting points every coefficient's t test is independent of which
other terms are kept, so the order is the highest degree with a significant term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg as sla

from ._critical import t_critical
from ._sar import sar_fit

__all__ = ["PolynomialBasis", "select_degree"]


@dataclass(frozen=True)
class PolynomialBasis:
    """A total-degree polynomial basis in (E, N), orthonormalised over a set of points.

    ``orthogonal(xy) = monomials(xy) @ inv(R)`` where the monomials are in centred,
    scaled coordinates and ``R`` comes from the QR decomposition over the fitting points,
    so columns are orthogonal there (orthogonal polynomials) and coefficients map back to
    the monomials with :meth:`to_monomial`.
    """

    degree: int
    center: np.ndarray
    scale: float
    R: np.ndarray
    powers: np.ndarray

    @classmethod
    def fit(cls, xy, degree):
        xy = np.asarray(xy, dtype=np.float64)
        center = xy.mean(axis=0)
        scale = float(np.sqrt(np.mean(np.sum((xy - center) ** 2, axis=1)))) or 1.0
        powers = np.array([(i - j, j) for i in range(degree + 1) for j in range(i + 1)])
        mono = _monomials((xy - center) / scale, powers)
        _, R = np.linalg.qr(mono)
        sgn = np.sign(np.diag(R))
        sgn[sgn == 0] = 1.0
        R = R * sgn[:, None]
        R = R / np.sqrt(xy.shape[0])
        return cls(int(degree), center, scale, R, powers)

    @property
    def n_terms(self) -> int:
        """Number of basis columns r."""
        return self.powers.shape[0]

    @property
    def term_degree(self) -> np.ndarray:
        """Total degree of each column."""
        return self.powers.sum(axis=1)

    def monomials(self, xy):
        """Monomials of the centred, scaled coordinates."""
        return _monomials((np.asarray(xy, dtype=np.float64) - self.center) / self.scale,
                          self.powers)

    def __call__(self, xy):
        """Orthogonal design matrix at `xy`."""
        return sla.solve_triangular(self.R, self.monomials(xy).T, trans="T").T

    def to_monomial(self, coef):
        """Coefficients on the monomials of the centred, scaled coordinates."""
        return sla.solve_triangular(self.R, np.asarray(coef, dtype=np.float64))

    def evaluate(self, coef, xy):
        """Height of the polynomial with orthogonal-basis coefficients `coef` at `xy`."""
        return self.monomials(xy) @ self.to_monomial(coef)

    def gradient(self, coef, xy):
        """(m, 2) gradient dz/dE, dz/dN of the polynomial at `xy`."""
        c = self.to_monomial(coef)
        u = (np.asarray(xy, dtype=np.float64) - self.center) / self.scale
        g = np.zeros((u.shape[0], 2))
        for (pe, pn), ck in zip(self.powers, c):
            if pe:
                g[:, 0] += ck * pe * u[:, 0] ** (pe - 1) * u[:, 1] ** pn
            if pn:
                g[:, 1] += ck * pn * u[:, 0] ** pe * u[:, 1] ** (pn - 1)
        return g / self.scale


def _monomials(u, powers):
    return np.column_stack([u[:, 0] ** pe * u[:, 1] ** pn for pe, pn in powers])


def select_degree(z, xy, W, *, max_degree=3, alpha=0.05, logdet="auto"):
    """Polynomial order by t tests on an orthogonal basis (seed 002, section 2).

    Fit the SAR model with the redundant degree `max_degree` on an orthogonal polynomial
    basis; the order s is the highest degree with at least one coefficient whose t test
    rejects ``theta_i = 0`` (two-sided, Bonferroni over the terms of that degree).
    Orthogonality makes each coefficient's test independent of which other terms are kept.

    Returns
    -------
    degree : int
        Selected order s (at least 1).
    fit : SARFit
        The fit at `max_degree`.
    basis : PolynomialBasis
    """
    basis = PolynomialBasis.fit(xy, max_degree)
    A = basis(xy)
    fit = sar_fit(z, A, W, logdet=logdet)
    t = np.abs(fit.theta / fit.se_theta)
    df = fit.n - fit.theta.size - 1
    deg = basis.term_degree
    for d in range(max_degree, 1, -1):
        sel = deg == d
        crit = t_critical(alpha / sel.sum(), df)  # two-sided, Bonferroni over the terms
        if np.any(t[sel] > crit):
            return d, fit, basis
    return 1, fit, basis
