"""HK surface types (Besl and Jain 1986; Haala et al. 2004; Crosilla et al. 2009 Table 1)."""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class SurfaceType(IntEnum):
    """Codes written to the ``surface_type`` field (a contract: never renumber)."""

    UNCLASSIFIED = 0
    PLANAR = 1
    PARABOLIC_RIDGE = 2   # K = 0, H < 0
    PARABOLIC_VALLEY = 3  # K = 0, H > 0
    ELLIPTIC_PEAK = 4     # K > 0, H < 0
    ELLIPTIC_PIT = 5      # K > 0, H > 0
    SADDLE_RIDGE = 6      # K < 0, H < 0
    SADDLE_VALLEY = 7     # K < 0, H > 0
    MINIMAL_SADDLE = 8    # K < 0, H = 0


def hk_surface_types(K, H, *, tested, planar, K_sig, H_sig):
    """Surface type codes from curvature signs and significance decisions.

    Parameters
    ----------
    K, H : (N,) ndarray
        Gaussian and mean curvature (H < 0 convex).
    tested : (N,) ndarray of bool
        Points whose local model was fitted and accepted; others get 0.
    planar : (N,) ndarray of bool
        Points whose curvature is not significant as a whole (planarity not rejected).
    K_sig, H_sig : (N,) ndarray of bool
        K and H significantly different from zero.

    Returns
    -------
    (N,) ndarray of uint8
        Codes of :class:`SurfaceType`.

    Notes
    -----
    Where planarity is rejected but neither K nor H alone is significant (possible with
    the Bonferroni-corrected individual tests) the point is called planar. Where K is
    significant and positive, the sign of H decides peak or pit whether or not H is
    significant (K > 0 implies H != 0).
    """
    K = np.asarray(K)
    H = np.asarray(H)
    out = np.zeros(K.shape, dtype=np.uint8)
    curved = tested & ~planar
    out[tested & planar] = SurfaceType.PLANAR
    out[curved & ~K_sig & ~H_sig] = SurfaceType.PLANAR
    par = curved & ~K_sig & H_sig
    out[par & (H < 0)] = SurfaceType.PARABOLIC_RIDGE
    out[par & (H > 0)] = SurfaceType.PARABOLIC_VALLEY
    ell = curved & K_sig & (K > 0)
    out[ell & (H < 0)] = SurfaceType.ELLIPTIC_PEAK
    out[ell & (H >= 0)] = SurfaceType.ELLIPTIC_PIT
    hyp = curved & K_sig & (K < 0)
    out[hyp & H_sig & (H < 0)] = SurfaceType.SADDLE_RIDGE
    out[hyp & H_sig & (H > 0)] = SurfaceType.SADDLE_VALLEY
    out[hyp & ~H_sig] = SurfaceType.MINIMAL_SADDLE
    return out
