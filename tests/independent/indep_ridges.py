"""Independent ridge scenes: crests and trenches with exact truth, plain NumPy.

Written without ``lidarstat.synth``: a profile extruded along a straight or a circular
axis on flat ground, sampled on a jittered grid, randomly rotated about z and shifted,
with Gaussian noise along z. Truth per point: the true normal, the true principal
curvatures where defined, and the distance to the nearest true ridge line.

Profiles (height h(s) of the signed distance s across the axis; ``sign`` +1 crest, -1
trench):

* ``gauss``: ``h = sign A exp(-s^2 / 2 w^2)``. Ridge lines: the axis (crest of a crest,
  ravine of a trench) and, on each flank, the line where the profile curvature
  ``kappa = h'' / (1 + h'^2)^1.5`` is extremal (ravines of a crest, crests of a trench).
* ``cyl``: a circular arc of radius R rising ``A`` above the ground (``A < R``), width
  ``2 sqrt(2 R A - A^2)``; its feet are creases (normal discontinuities), the true
  lines (type ``CREASE``, the ``ridge`` code of a crease point). The arc itself has
  constant curvature: no ridge on it.

For a circular axis (radius ``R0`` much larger than the profile) the surface is one of
revolution; its meridian curvature is the profile curvature of ``s = r - R0``, whose
extrema sit at the same ``s`` as for a straight axis (``h' = h''' = 0`` on the axis).

For the size of the automatic scale's test: tilted planes with seeds whose
neighbourhoods do not overlap (:func:`disjoint_plane_seeds`), and the scale's k''
statistic read there (:func:`plane_scale_statistic`, which calls lidarstat).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

CREST, RAVINE, CREASE = 1, 2, 3


@dataclass
class RidgeScene:
    """Points and exact truth of one scene."""

    xyz: np.ndarray
    spacing: float
    sigma: float
    params: dict
    lines: list  # (ridge type, (M, 3) samples every spacing / 4)
    normal: np.ndarray
    kmin: np.ndarray  # true principal curvatures, normal up; NaN on a crease
    kmax: np.ndarray
    line_distance: np.ndarray  # distance of each point to the nearest true ridge line


def _profile(kind, s, amp, width, sign):
    """Height h(s), slope h'(s) and curvature h''(s) of a profile."""
    if kind == "gauss":
        e = np.exp(-s * s / (2 * width * width))
        h = amp * e
        h1 = -amp * s / width**2 * e
        h2 = amp * (s * s / width**4 - 1 / width**2) * e
    else:  # circular arc of radius `width` rising `amp` above the ground
        r = width
        half = np.sqrt(2 * r * amp - amp * amp)
        inside = np.abs(s) < half
        root = np.sqrt(np.maximum(r * r - s * s, 1e-300))
        h = np.where(inside, root - (r - amp), 0.0)
        h1 = np.where(inside, -s / root, 0.0)
        h2 = np.where(inside, -r * r / root**3, 0.0)
    return sign * h, sign * h1, sign * h2


def ridge_offsets(kind, amp, width, sign):
    """Offsets s of the true ridge lines across the axis, with their types."""
    if kind == "gauss":
        s = np.linspace(0.3 * width, 4.0 * width, 200001)
        _, h1, h2 = _profile(kind, s, amp, width, 1.0)
        kap = h2 / (1 + h1 * h1) ** 1.5
        sf = float(s[np.argmax(kap)])
        main, flank = (CREST, RAVINE) if sign > 0 else (RAVINE, CREST)
        return [(0.0, main), (-sf, flank), (sf, flank)]
    half = float(np.sqrt(2 * width * amp - amp * amp))
    return [(-half, CREASE), (half, CREASE)]


def make_ridge_scene(rng, *, kind="gauss", sign=1.0, curved=False, spacing=None, sigma=None,
                     amp=None, width=None, length=None):
    """One randomised scene; unset parameters are drawn from `rng`.

    Straight scenes: a rectangle ``length`` along the axis and ``2 (reach + margin)``
    across. Curved scenes: an annulus sector of the circular axis of radius ``R0`` (4 to 6
    times the profile's reach), spanning ``length`` along the axis.
    """
    rng = np.random.default_rng(rng)
    spacing = float(rng.uniform(0.01, 0.02)) if spacing is None else spacing
    sigma = float(rng.uniform(0.0005, 0.002)) if sigma is None else sigma
    if kind == "gauss":
        width = float(rng.uniform(0.12, 0.22)) if width is None else width
        amp = float(rng.uniform(0.15, 0.4)) if amp is None else amp
        reach = 4.0 * width
    else:
        width = float(rng.uniform(0.25, 0.5)) if width is None else width
        amp = float(rng.uniform(0.3, 0.6) * width) if amp is None else amp
        reach = np.sqrt(2 * width * amp - amp * amp) + 0.25
    length = float(rng.uniform(0.6, 0.9)) if length is None else length
    margin = 0.15
    half_across = reach + margin
    if curved:
        r0 = float(rng.uniform(4.0, 6.0) * half_across)
        ext = r0 + half_across
        g = np.arange(-ext, ext + spacing / 2, spacing)
        x, y = [a.ravel() for a in np.meshgrid(g, g)]
        x = x + rng.uniform(-0.3, 0.3, x.size) * spacing
        y = y + rng.uniform(-0.3, 0.3, y.size) * spacing
        r = np.hypot(x, y)
        phi = np.arctan2(y, x)
        span = length / r0
        keep = (np.abs(r - r0) <= half_across) & (np.abs(phi) <= span / 2)
        x, y, r, phi = x[keep], y[keep], r[keep], phi[keep]
        s = r - r0
        radial = np.c_[x / r, y / r]
        along = phi * r0
    else:
        ga = np.arange(-length / 2, length / 2 + spacing / 2, spacing)
        gc = np.arange(-half_across, half_across + spacing / 2, spacing)
        a, c = [v.ravel() for v in np.meshgrid(ga, gc)]
        a = a + rng.uniform(-0.3, 0.3, a.size) * spacing
        c = c + rng.uniform(-0.3, 0.3, c.size) * spacing
        x, y, s, along = c, a, c, a
        radial = np.tile([1.0, 0.0], (x.size, 1))
    h, h1, h2 = _profile(kind, s, amp, width, sign)
    norm = np.sqrt(1 + h1 * h1)
    normal = np.c_[-h1[:, None] * radial / norm[:, None], 1 / norm]
    k_prof = h2 / norm**3
    if curved:
        k_par = h1 / (np.hypot(x, y) * norm)  # parallel curvature of the revolution
    else:
        k_par = np.zeros_like(s)
    kmax, kmin = np.maximum(k_prof, k_par), np.minimum(k_prof, k_par)
    offsets = ridge_offsets(kind, amp, width, sign)
    if kind == "cyl":
        crease = np.min([np.abs(s - o) for o, _ in offsets], axis=0) < 1e-12
        kmax[crease] = kmin[crease] = np.nan
    # true lines, sampled every spacing / 4 along the axis
    lines = []
    dist = np.full(s.size, np.inf)
    for off, t in offsets:
        hl = _profile(kind, np.array([off]), amp, width, sign)[0][0]
        if curved:
            rl = r0 + off
            ph = np.arange(-span / 2, span / 2, spacing / 4 / rl)
            line = np.c_[rl * np.cos(ph), rl * np.sin(ph), np.full(ph.size, hl)]
            d_plan = np.abs(s - off)
        else:
            t_ = np.arange(-length / 2, length / 2, spacing / 4)
            line = np.c_[np.full(t_.size, off), t_, np.full(t_.size, hl)]
            d_plan = np.abs(s - off)
        lines.append((t, line))
        dist = np.minimum(dist, np.hypot(d_plan, h - hl))
    z = h + rng.normal(0.0, sigma, s.size)
    xyz = np.c_[x, y, z]
    # random rotation about z and shift
    th = float(rng.uniform(0, 2 * np.pi))
    rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    shift = np.r_[rng.uniform(-1e3, 1e3, 2), rng.uniform(-10, 10)]
    xyz = xyz @ rot.T + shift
    normal = normal @ rot.T
    lines = [(t, ln @ rot.T + shift) for t, ln in lines]
    params = dict(kind=kind, sign=sign, curved=curved, spacing=spacing, sigma=sigma, amp=amp,
                  width=width, length=length, along_extent=(float(along.min()),
                                                            float(along.max())))
    return RidgeScene(xyz=xyz, spacing=spacing, sigma=sigma, params=params, lines=lines,
                      normal=normal, kmin=kmin, kmax=kmax, line_distance=dist)


def make_null_scene(rng, kind, *, spacing=None, sigma=None, half=0.4):
    """A surface with no ridge: ``plane`` (tilted up to 60 degrees), ``sphere`` cap or the
    interior of a ``cylinder`` (axis horizontal, random azimuth). Noise along z."""
    rng = np.random.default_rng(rng)
    spacing = float(rng.uniform(0.01, 0.02)) if spacing is None else spacing
    sigma = float(rng.uniform(0.0005, 0.002)) if sigma is None else sigma
    g = np.arange(-half, half + spacing / 2, spacing)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    x = x + rng.uniform(-0.3, 0.3, x.size) * spacing
    y = y + rng.uniform(-0.3, 0.3, y.size) * spacing
    if kind == "plane":
        tilt = np.radians(rng.uniform(0, 60))
        z = np.tan(tilt) * x
        k = np.zeros(x.size), np.zeros(x.size)
    elif kind == "sphere":
        r = float(rng.uniform(1.0, 3.0))
        z = np.sqrt(r * r - x * x - y * y) - r
        k = np.full(x.size, -1 / r), np.full(x.size, -1 / r)
    else:
        r = float(rng.uniform(0.8, 2.0))
        z = np.sqrt(r * r - x * x) - r
        k = np.zeros(x.size), np.full(x.size, -1 / r)
    xyz = np.c_[x, y, z + rng.normal(0, sigma, x.size)]
    th = float(rng.uniform(0, 2 * np.pi))
    rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    xyz = xyz @ rot.T
    border = half - np.maximum(np.abs(x), np.abs(y))
    return xyz, dict(kind=kind, spacing=spacing, sigma=sigma, kmax=k[0], kmin=k[1],
                     border=border)


def line_recall(scene, ridge, xyz, *, margin, tol=None):
    """Share of each true line's length (beyond `margin` from the scene's ends along the
    axis) with a detected point of the line's type within `tol` (default one spacing).

    Returns a list of (type, recall) per true line.
    """
    from scipy.spatial import cKDTree

    tol = scene.spacing if tol is None else tol
    lo, hi = scene.params["along_extent"]
    out = []
    for t, line in scene.lines:
        n = line.shape[0]
        pos = np.linspace(lo, hi, n)  # samples run uniformly along the axis
        inner = (pos > lo + margin) & (pos < hi - margin)
        sel = ridge == t
        if not sel.any():
            out.append((t, 0.0))
            continue
        d, _ = cKDTree(xyz[sel]).query(line[inner])
        out.append((t, float(np.mean(d <= tol))))
    return out


def ridge_precision(scene, ridge, *, tol_factor=2.5):
    """Share of detected ridge points within `tol_factor` spacings of a true ridge line."""
    sel = ridge > 0
    if not sel.any():
        return 1.0
    return float(np.mean(scene.line_distance[sel] <= tol_factor * scene.spacing))


def tilted_plane(rng, tilt_deg, nx, ny, sigma):
    """A plane z = tan(tilt) x with noise `sigma` along z, sampled on a jittered unit grid
    of `nx` by `ny` nodes in plan (each node moved uniformly within its cell): stretched
    by ``1 / cos(tilt)`` along the slope."""
    gx, gy = np.arange(nx, dtype=np.float64), np.arange(ny, dtype=np.float64)
    x, y = (a.ravel() for a in np.meshgrid(gx, gy))
    x = x + rng.uniform(-0.5, 0.5, x.size)
    y = y + rng.uniform(-0.5, 0.5, y.size)
    z = np.tan(np.radians(tilt_deg)) * x + rng.normal(0.0, sigma, x.size)
    return np.c_[x, y, z]


def disjoint_plane_seeds(rng, tilt_deg, radius, samples, sigma):
    """A :func:`tilted_plane` and `samples` seed points on it whose balls of `radius` (in
    3-D) do not overlap, so that statistics read at the seeds are independent draws.

    The seeds are the points nearest the nodes of a grid in plan of steps
    ``2 radius cos(tilt) + 2`` along the slope and ``2 radius + 2`` across it (the 2: a
    point lies within one unit of its node), at least ``2 radius`` from the plane's edges.
    """
    from scipy.spatial import cKDTree

    c = np.cos(np.radians(tilt_deg))
    sx, sy = 2.0 * radius * c + 2.0, 2.0 * radius + 2.0
    mx = int(np.ceil(np.sqrt(samples * sy / sx)))
    my = int(np.ceil(samples / mx))
    x0 = 2.0 * radius + 1.0
    nx, ny = int(mx * sx + 2 * x0) + 1, int(my * sy + 2 * x0) + 1
    xyz = tilted_plane(rng, tilt_deg, nx, ny, sigma)
    gx, gy = (a.ravel()[:samples] for a in np.meshgrid(x0 + sx * np.arange(mx),
                                                       x0 + sy * np.arange(my)))
    seeds = np.unique(cKDTree(xyz[:, :2]).query(np.c_[gx, gy])[1])
    return xyz, seeds


@functools.cache
def _plane_field(tilt_deg, seed, top_rung, samples=2000):
    """A plane tilted by `tilt_deg` (noise along z) with `samples` seeds whose
    neighbourhoods at rung `top_rung` (and so at every smaller rung) are disjoint, and
    the ladder of its pattern (read on a 120 x 120 patch of it)."""
    from lidarstat.features._jet_scale import radius_ladder

    rng = np.random.default_rng(seed)
    sigma = 0.01
    radii = radius_ladder(tilted_plane(rng, tilt_deg, 120, 120, sigma))
    xyz, seeds = disjoint_plane_seeds(rng, tilt_deg, float(radii[top_rung]), samples, sigma)
    return xyz, seeds, radii, sigma


def plane_scale_statistic(tilt_deg, rung, seed, top_rung, alpha=0.01):
    """The k'' selection statistic of the automatic scale at the fitted seeds of
    :func:`_plane_field` at rung `rung` (the tests' fields at the plane's z noise)."""
    from scipy.spatial import cKDTree

    from lidarstat.features import height_variance, jet_tests
    from lidarstat.features._jet_fit import _allocate, _to_fit
    from lidarstat.features._jet_scale import _fit_into
    from lidarstat.segment._ridges import _ridge_statistic

    xyz, seeds, radii, sigma = _plane_field(tilt_deg, seed, top_rung)
    r = float(radii[rung])
    # the check: no two seeds within 2 r in 3-D, so their balls of radius r are disjoint
    # and the counts below are independent Bernoulli draws
    assert not cKDTree(xyz[seeds]).query_pairs(2.0 * r), "overlapping neighbourhoods"
    mask = np.zeros(len(xyz), bool)
    mask[seeds] = True
    slot = np.full(len(xyz), -1, np.int64)
    slot[seeds] = np.arange(seeds.size)
    out = _allocate(seeds.size)
    _fit_into(xyz, r, mask, dict(degree=4, monge_degree=4, weight="tricube", sensor=None,
                                 min_neighbors=16, standard_errors=True), 131072, out, slot)
    fit = _to_fit(out, 4, 4, "tricube")
    fields = jet_tests(fit, height_variance(fit.frame, sigma, noise="z"), alpha)
    return _ridge_statistic(fit, fields)[fit.status == 0]
