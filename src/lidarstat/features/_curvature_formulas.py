"""Curvatures of a Monge patch z = f(u, v) from its Taylor coefficients, with Jacobians.

Crosilla et al. (2009), eq. 11-12 and the principal curvatures k = H -/+ sqrt(H^2 - K).
With the normal oriented along +h (up / toward the sensor), H < 0 on convex surfaces.
"""

from __future__ import annotations

import numpy as np


def curvatures(a):
    """Gaussian K, mean H and principal curvatures from coefficients a1..a5.

    Parameters
    ----------
    a : (M, 5) ndarray
        ``[a1, a2, a3, a4, a5]`` (first and second derivatives at the point).

    Returns
    -------
    K, H, kmin, kmax : (M,) ndarrays
    """
    a1, a2, a3, a4, a5 = (a[:, i] for i in range(5))
    g = 1.0 + a1 * a1 + a2 * a2
    K = (a3 * a5 - a4 * a4) / (g * g)
    H = (a3 * (1.0 + a2 * a2) + a5 * (1.0 + a1 * a1) - 2.0 * a1 * a2 * a4) / (2.0 * g**1.5)
    disc = np.sqrt(np.maximum(H * H - K, 0.0))
    return K, H, H - disc, H + disc


def curvature_jacobian(a):
    """Jacobian of (K, H) with respect to (a1..a5), eq. 16, analytically.

    Returns
    -------
    J : (M, 2, 5) ndarray
        Row 0: dK/da, row 1: dH/da.
    """
    a1, a2, a3, a4, a5 = (a[:, i] for i in range(5))
    g = 1.0 + a1 * a1 + a2 * a2
    det = a3 * a5 - a4 * a4
    num = a3 * (1.0 + a2 * a2) + a5 * (1.0 + a1 * a1) - 2.0 * a1 * a2 * a4
    J = np.empty((a.shape[0], 2, 5))
    g2 = g * g
    g3 = g2 * g
    J[:, 0, 0] = -4.0 * a1 * det / g3
    J[:, 0, 1] = -4.0 * a2 * det / g3
    J[:, 0, 2] = a5 / g2
    J[:, 0, 3] = -2.0 * a4 / g2
    J[:, 0, 4] = a3 / g2
    g15 = 2.0 * g**1.5
    g25 = g**2.5
    J[:, 1, 0] = (2.0 * a1 * a5 - 2.0 * a2 * a4) / g15 - 1.5 * num * a1 / g25
    J[:, 1, 1] = (2.0 * a2 * a3 - 2.0 * a1 * a4) / g15 - 1.5 * num * a2 / g25
    J[:, 1, 2] = (1.0 + a2 * a2) / g15
    J[:, 1, 3] = -2.0 * a1 * a2 / g15
    J[:, 1, 4] = (1.0 + a1 * a1) / g15
    return J


def principal_jacobian(K, H, J_kh):
    """Jacobians of kmin and kmax from that of (K, H) (undefined at umbilics).

    ``k = H -/+ sqrt(H^2 - K)`` so ``dk = dH -/+ (2 H dH - dK) / (2 sqrt(H^2 - K))``.

    Returns
    -------
    J : (M, 2, 5) ndarray
        Row 0: d kmin / da, row 1: d kmax / da (NaN where H^2 = K).
    """
    disc = np.sqrt(np.maximum(H * H - K, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (2.0 * H[:, None] * J_kh[:, 1, :] - J_kh[:, 0, :]) / (2.0 * disc[:, None])
    t = np.where(disc[:, None] > 0, t, np.nan)
    out = np.empty_like(J_kh)
    out[:, 0, :] = J_kh[:, 1, :] - t
    out[:, 1, :] = J_kh[:, 1, :] + t
    return out
