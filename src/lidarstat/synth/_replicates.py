"""Many independent copies of one noisy neighbourhood, for testing tests by simulation."""

from __future__ import annotations

import numpy as np


def _height(kind, u, v, c):
    if kind == "plane":
        return 0.3 * u - 0.2 * v
    if kind == "quadric":
        return 0.2 * u + 0.5 * (c * u * u + 0.4 * c * u * v + 0.6 * c * v * v)
    if kind == "cylinder":  # K = 0 everywhere, H != 0
        return 0.5 * c * u * u
    if kind == "minimal_saddle":  # H = 0 at the centre, K < 0
        return 0.5 * c * (u * u - v * v)
    if kind == "ridge":  # two planes meeting in a crease: the quadric does not hold
        return -c * np.abs(u)
    raise ValueError(f"unknown replicate kind {kind!r}")


REPLICATE_KINDS = ("plane", "quadric", "cylinder", "minimal_saddle", "ridge")


def make_replicates(kind, *, n_replicates=2000, radius=1.0, spacing=0.2, curvature=0.5,
                    sigma=0.01, rng=None):
    """Independent noisy copies of one neighbourhood under a known null or alternative.

    Each replicate is a square grid patch (half-width `radius` * 1.5) of the height field
    `kind` with independent Gaussian noise on z; patches are laid side by side far enough
    apart that no neighbourhood of radius `radius` reaches a neighbour patch. The centre
    point of each patch is the query point.

    Parameters
    ----------
    kind : {'plane', 'quadric', 'cylinder', 'minimal_saddle', 'ridge'}
        ``'plane'`` (the planarity null), ``'quadric'`` (a general paraboloid: the
        chi-square null), ``'cylinder'`` (K = 0, H != 0: the null of the K test),
        ``'minimal_saddle'`` (H = 0 at the centre: the null of the H test), ``'ridge'``
        (a crease, where the quadric model is wrong: an alternative).
    n_replicates : int
    radius, spacing : float
        Neighbourhood radius and grid step.
    curvature : float
        Curvature scale c of the surface.
    sigma : float
        Noise standard deviation on z.
    rng : numpy.random.Generator or int, optional

    Returns
    -------
    points : (n_replicates * m, 3) ndarray
    centres : (n_replicates,) ndarray of int
        Index of each patch's centre point.
    """
    rng = np.random.default_rng(rng)
    half = int(np.ceil(1.5 * radius / spacing))
    g = np.arange(-half, half + 1) * spacing
    u, v = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    z = _height(kind, u, v, curvature)
    m = u.size
    centre = int(np.flatnonzero((u == 0) & (v == 0))[0])
    pitch = 2 * g[-1] + 4 * radius
    offsets = np.arange(n_replicates) * pitch
    pts = np.empty((n_replicates, m, 3))
    pts[:, :, 0] = u[None, :] + offsets[:, None]
    pts[:, :, 1] = v[None, :]
    pts[:, :, 2] = z[None, :] + rng.normal(0.0, sigma, size=(n_replicates, m))
    return pts.reshape(-1, 3), np.arange(n_replicates) * m + centre
