"""Independent analytic surfaces with exact truth, for the curvature tests (issue 17).

Plain NumPy, nothing from ``lidarstat.synth``: planes, spheres, cylinders, cones and tori
sampled on a regular grid of arc length (spacing ``s``), turned to a random orientation
(steep and overhanging ones included), shifted, and given Gaussian noise of std ``sigma``
along z (a range image or airborne scan) or along the ray from a sensor (a terrestrial
scan). Truth per point: the outward unit normal, the principal curvatures ``k1 <= k2``
relative to that normal (negative where the surface is convex, the sign convention of
``lidarstat.features.curvature``), and the distance in arc length to the patch border.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("plane", "sphere", "cylinder", "cone", "torus_outer", "torus_inner")

#: HK type codes (Besl and Jain; the ``surface_type`` field's contract).
PLANAR, RIDGE, VALLEY, PEAK, PIT, SADDLE_RIDGE, SADDLE_VALLEY, MINIMAL_SADDLE = range(1, 9)


@dataclass
class Surface:
    kind: str
    xyz: np.ndarray
    normal: np.ndarray        # outward unit normal, (N, 3)
    k1: np.ndarray            # principal curvatures relative to `normal`, k1 <= k2
    k2: np.ndarray
    border: np.ndarray        # arc-length distance to the patch border
    spacing: float
    sigma: float
    noise: str                # "z" or "range"
    sensor: np.ndarray | None

    def oriented_types(self, normals):
        """True HK types with the curvature signs taken relative to `normals` (the
        orientation the method chose: up, or toward the sensor); where `normals` is NaN the
        method's convention is used (toward the sensor, else up)."""
        ref = np.asarray(normals, dtype=float)
        bad = ~np.isfinite(ref).all(axis=1)
        if bad.any():
            ref = ref.copy()
            if self.sensor is None:
                ref[bad] = [0.0, 0.0, 1.0]
            else:
                ref[bad] = self.sensor - self.xyz[bad]
        sign = np.where(np.einsum("ij,ij->i", ref, self.normal) >= 0, 1.0, -1.0)
        return hk_type(sign * self.k1, sign * self.k2)


def hk_type(k1, k2):
    """HK type of exact principal curvatures (exact zeros mark the flat directions)."""
    K = k1 * k2
    H = 0.5 * (k1 + k2)
    t = np.full(K.shape, PLANAR, dtype=np.uint8)
    par = (K == 0) & (H != 0)
    t[par & (H < 0)] = RIDGE
    t[par & (H > 0)] = VALLEY
    t[(K > 0) & (H < 0)] = PEAK
    t[(K > 0) & (H > 0)] = PIT
    t[(K < 0) & (H < 0)] = SADDLE_RIDGE
    t[(K < 0) & (H > 0)] = SADDLE_VALLEY
    t[(K < 0) & (H == 0)] = MINIMAL_SADDLE
    return t


def random_rotation(rng, tilt=None):
    """A uniformly random rotation, or one turning +z by `tilt` degrees (random azimuth
    and spin)."""
    if tilt is None:
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        return q
    t = np.radians(tilt)
    az, spin = rng.uniform(0, 2 * np.pi, 2)

    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])

    ry = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    return rz(az) @ ry @ rz(spin)


def _grid(n_u, n_v, s):
    u = (np.arange(n_u) - (n_u - 1) / 2) * s
    v = (np.arange(n_v) - (n_v - 1) / 2) * s
    uu, vv = (a.ravel() for a in np.meshgrid(u, v, indexing="ij"))
    border = np.minimum(u.max() - np.abs(uu), v.max() - np.abs(vv))
    return uu, vv, border


def _local(kind, rng, s, half):
    """Points, outward normals, k1, k2, border distance of one patch in its own frame."""
    n = 2 * half + 1
    uu, vv, border = _grid(n, n, s)
    zeros = np.zeros_like(uu)
    if kind == "plane":
        p = np.c_[uu, vv, zeros]
        nrm = np.tile([0.0, 0.0, 1.0], (uu.size, 1))
        return p, nrm, zeros, zeros.copy(), border
    if kind == "sphere":
        R = rng.uniform(1.5, 3.0) * half * s
        th, ph = uu / R, vv / R  # arc-length grid in two angles
        nrm = np.c_[np.sin(th) * np.cos(ph), np.sin(ph), np.cos(th) * np.cos(ph)]
        k = np.full(uu.size, -1.0 / R)
        return R * nrm, nrm, k, k.copy(), border
    if kind == "cylinder":
        R = rng.uniform(1.0, 2.5) * half * s
        th = uu / R
        nrm = np.c_[np.sin(th), zeros, np.cos(th)]
        p = np.c_[R * np.sin(th), vv, R * np.cos(th)]
        return p, nrm, np.full(uu.size, -1.0 / R), zeros, border
    if kind == "cone":
        beta = np.radians(rng.uniform(20, 40))
        rho0 = rng.uniform(1.5, 2.5) * half * s / np.sin(beta) + half * s
        rho = rho0 + vv
        r = rho * np.sin(beta)
        ph = uu / (rho0 * np.sin(beta))  # arc-length at the middle ring
        p = np.c_[r * np.cos(ph), r * np.sin(ph), rho * np.cos(beta)]
        nrm = np.c_[np.cos(beta) * np.cos(ph), np.cos(beta) * np.sin(ph), -np.sin(beta) * np.ones_like(ph)]
        k = -np.cos(beta) / r
        return p, nrm, k, zeros, border
    # torus: major radius Rm, tube radius rt; outer part (v near 0) elliptic, inner saddle
    rt = rng.uniform(1.5, 2.5) * half * s
    Rm = rt + rng.uniform(1.5, 3.0) * half * s
    v0 = 0.0 if kind == "torus_outer" else np.pi
    v = v0 + vv / rt
    ring = Rm + rt * np.cos(v)
    ph = uu / (Rm + rt * np.cos(v0))
    nrm = np.c_[np.cos(v) * np.cos(ph), np.cos(v) * np.sin(ph), np.sin(v)]
    p = np.c_[ring * np.cos(ph), ring * np.sin(ph), rt * np.sin(v)]
    kv = np.full(uu.size, -1.0 / rt)
    ku = -np.cos(v) / ring
    return p, nrm, np.minimum(kv, ku), np.maximum(kv, ku), border


def make_surface(kind, seed, *, noise="z", tilt=None, spacing=None, sigma=None, half=20):
    """One randomised patch of `kind` (see :data:`KINDS`).

    Parameters
    ----------
    kind : str
    seed : int
    noise : {'z', 'range'}
        Noise along z, or along the ray from a sensor placed on the outward side.
    tilt : float, optional
        Angle (degrees) between the patch's mean outward normal and +z; default a uniformly
        random orientation (steep and overhanging ones included).
    spacing, sigma : float, optional
        Default: spacing uniform in [0.5, 2], sigma uniform in [0.002, 0.02] spacings.
    half : int
        The patch is (2 half + 1)^2 points.
    """
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.5, 2.0) if spacing is None else float(spacing)
    sig = rng.uniform(0.002, 0.02) * s if sigma is None else float(sigma)
    p, nrm, k1, k2, border = _local(kind, rng, s, half)
    centre = p.mean(axis=0)
    mean_n = nrm.mean(axis=0)
    mean_n /= np.linalg.norm(mean_n)
    # bring the mean normal to +z first, then apply the orientation
    rot0 = _align(mean_n)
    rot = random_rotation(rng, tilt) @ rot0
    offset = rng.uniform(-1000, 1000, 3)
    xyz = (p - centre) @ rot.T + offset
    nrm = nrm @ rot.T
    sensor = None
    if noise == "z":
        xyz[:, 2] += rng.normal(0, sig, xyz.shape[0])
    elif noise == "range":
        look = rot @ np.array([0.0, 0.0, 1.0]) + 0.3 * rng.normal(size=3)
        look /= np.linalg.norm(look)
        sensor = offset + rng.uniform(3, 6) * half * s * look
        ray = xyz - sensor
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        xyz += rng.normal(0, sig, (xyz.shape[0], 1)) * ray
    else:
        raise ValueError(noise)
    return Surface(kind, xyz, nrm, k1, k2, border, s, sig, noise, sensor)


def _align(a):
    """Rotation taking unit vector `a` to +z."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(a, z)
    c = float(a @ z)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def lattice(surface, step):
    """Indices of points at least `step` apart along both grid directions (independent
    neighbourhoods when `step` exceeds twice the radius), interior ones only."""
    n = int(round(np.sqrt(surface.xyz.shape[0])))
    i, j = np.divmod(np.arange(n * n), n)
    k = max(int(np.ceil(step / surface.spacing)), 1)
    keep = (i % k == 0) & (j % k == 0) & (surface.border > step / 2)
    return np.flatnonzero(keep)
