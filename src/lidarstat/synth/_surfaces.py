"""Analytic height fields z = f(x, y) sampled on a regular or jittered XY grid.

Every generator returns a :class:`SyntheticCloud` whose curvature truth is evaluated in
closed form at the noise-free sample positions, with the normal pointing up (+z) and
H < 0 where the surface is convex seen from above.  For a Monge patch with gradient
(fx, fy) and Hessian (fxx, fxy, fyy), W = sqrt(1 + fx^2 + fy^2)::

    K = (fxx fyy - fxy^2) / W^4
    H = ((1 + fy^2) fxx - 2 fx fy fxy + (1 + fx^2) fyy) / (2 W^3)
    n = (-fx, -fy, 1) / W

``edge_distance`` of a height field is the distance *in the XY plane* from the sample to
the border of the sampled domain (a lower bound of the 3-D and of the along-surface
distance); these patches have no creases.
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ._height_grid import _common, _finish, _grid, _monge, _pair, _radius_slope, _unit2
from ._truth import SyntheticCloud

__all__ = ["make_plane", "make_cylinder", "make_sphere_cap", "make_paraboloid", "make_scherk"]


# ----------------------------------------------------------------------------- surfaces
def make_plane(n=None, *, extent=2.0, spacing=0.02, normal=(0.0, 0.0, 1.0), sigma=0.0,
               jitter=0.0, rng=None) -> SyntheticCloud:
    """A (tilted) plane through the origin, sampled on a square XY grid.

    Parameters
    ----------
    n : int, optional
        Approximate number of points; when given it sets the spacing
        ``sqrt(extent_x * extent_y / n)`` (overriding `spacing`).
    extent : float or (float, float)
        Side lengths of the XY domain, centred on the origin.
    spacing : float or (float, float)
        Grid steps in x and y.
    normal : 3-vector
        Plane normal (a, b, c) with c != 0; the plane is a x + b y + c z = 0.  It is
        normalised and oriented up.
    sigma : float
        Standard deviation of the Gaussian noise added to z.
    jitter : float
        Uniform jitter of the XY positions, as a fraction (< 0.5) of the spacing.
    rng : numpy.random.Generator or int or None
        Random source (seed) for jitter and noise.

    Returns
    -------
    SyntheticCloud
        K = H = kmin = kmax = 0 and type 1 everywhere; face 0.

    Examples
    --------
    >>> c = make_plane(extent=1.0, spacing=0.1, normal=(0, 0.1, 1), sigma=0.01, rng=0)
    >>> len(c), int(c.surface_type[0])
    (121, 1)
    """
    func = "make_plane"
    rng = np.random.default_rng(rng)
    ex, ey = _pair(extent, "extent", func)
    spacing, sigma, jitter = _common(func, spacing, sigma, jitter, n, ex * ey)
    nv = np.asarray(normal, dtype=np.float64).ravel()
    if nv.size != 3 or not np.all(np.isfinite(nv)) or np.linalg.norm(nv) == 0:
        raise InvalidParameterError(
            f"The 'normal' parameter of {func} must be a non-zero 3-vector. Got {normal!r}."
        )
    nv = nv / np.linalg.norm(nv)
    if abs(nv[2]) < 0.05:
        raise InvalidParameterError(
            f"The 'normal' parameter of {func} must not be (nearly) horizontal: a vertical "
            f"plane is no height field. Got {normal!r} instead."
        )
    nv = nv * np.sign(nv[2])
    x, y, ij = _grid(ex / 2, ey / 2, spacing, jitter, rng)
    inside = (np.abs(x) <= ex / 2) & (np.abs(y) <= ey / 2)
    x, y, ij = x[inside], y[inside], ij[inside]
    z = -(nv[0] * x + nv[1] * y) / nv[2]
    zeros = np.zeros(x.size)
    edge = np.minimum(ex / 2 - np.abs(x), ey / 2 - np.abs(y))
    meta = {"kind": "plane", "extent": (ex, ey), "spacing": spacing, "plane_normal": nv.tolist(),
            "jitter": jitter}
    return _finish("plane", x, y, z, np.tile(nv, (x.size, 1)), zeros, zeros, edge, ij,
                   sigma, rng, meta, kmin=zeros, kmax=zeros)


def make_cylinder(radius=1.0, *, length=None, axis=(1.0, 0.0), convex=True, max_slope=70.0,
                  spacing=0.02, n=None, sigma=0.0, jitter=0.0, rng=None) -> SyntheticCloud:
    """Upper half of a horizontal cylinder (a ridge) or lower half (a trough) as a height field.

    With ``d`` the signed XY distance across the axis and ``s`` the coordinate along it,
    ``z = sqrt(R^2 - d^2)`` (convex) or ``z = -sqrt(R^2 - d^2)`` (concave trough, seen
    from inside); the axis lies at z = 0 through the origin.  Samples are kept where
    ``|s| <= length/2`` and the slope is below `max_slope`, i.e. ``|d| <= R sin(max_slope)``.

    Parameters
    ----------
    radius : float
        Cylinder radius R.
    length : float, optional
        Length along the axis (default 2 R).
    axis : 2-vector
        Axis direction in the XY plane.
    convex : bool
        True: ridge, K = 0, H = -1/(2R), kmin = -1/R, kmax = 0, type 2.  False: trough,
        K = 0, H = +1/(2R), kmin = 0, kmax = 1/R, type 3.
    max_slope : float
        Largest surface slope kept, in degrees (0, 89].
    spacing, n, sigma, jitter, rng
        As in :func:`make_plane` (`n` counts points of the kept domain).

    Returns
    -------
    SyntheticCloud

    Examples
    --------
    >>> c = make_cylinder(0.5, spacing=0.05)
    >>> float(c.H[0]), int(c.surface_type[0])
    (-1.0, 2)
    """
    func = "make_cylinder"
    rng = np.random.default_rng(rng)
    R, slope, dmax = _radius_slope(func, radius, max_slope)
    L = 2 * R if length is None else check_scalar(length, "length", func=func, low=0.0)
    a = _unit2(axis, func)
    spacing, sigma, jitter = _common(func, spacing, sigma, jitter, n, L * 2 * dmax)
    # bounding box of the rotated rectangle |s| <= L/2, |d| <= dmax
    hx = abs(a[0]) * L / 2 + abs(a[1]) * dmax
    hy = abs(a[1]) * L / 2 + abs(a[0]) * dmax
    x, y, ij = _grid(hx, hy, spacing, jitter, rng)
    s = x * a[0] + y * a[1]
    d = -x * a[1] + y * a[0]
    keep = (np.abs(s) <= L / 2) & (np.abs(d) <= dmax)
    x, y, ij, s, d = x[keep], y[keep], ij[keep], s[keep], d[keep]
    h = np.sqrt(R * R - d * d)
    across = np.array([-a[1], a[0]])
    sgn = 1.0 if convex else -1.0
    z = sgn * h
    # convex: n = (d*across, h)/R; trough: n = (-d*across, h)/R  (both point up)
    normal = np.column_stack([sgn * d * across[0], sgn * d * across[1], h]) / R
    N = x.size
    K = np.zeros(N)
    H = np.full(N, -sgn / (2 * R))
    kmin = np.full(N, -1.0 / R) if convex else np.zeros(N)
    kmax = np.zeros(N) if convex else np.full(N, 1.0 / R)
    edge = np.minimum(L / 2 - np.abs(s), dmax - np.abs(d))
    name = "cylinder" if convex else "trough"
    meta = {"kind": name, "radius": R, "length": L, "axis": a.tolist(), "convex": bool(convex),
            "max_slope": slope, "spacing": spacing, "jitter": jitter}
    return _finish(name, x, y, z, normal, K, H, edge, ij, sigma, rng, meta, kmin=kmin, kmax=kmax)


def make_sphere_cap(radius=1.0, *, convex=True, max_slope=70.0, spacing=0.02, n=None,
                    sigma=0.0, jitter=0.0, rng=None) -> SyntheticCloud:
    """A spherical dome (convex) or bowl (concave) centred on the origin.

    ``z = +sqrt(R^2 - r^2)`` (dome) or ``-sqrt(R^2 - r^2)`` (bowl seen from inside), kept
    where ``r <= R sin(max_slope)``.

    Parameters
    ----------
    radius : float
        Sphere radius R.
    convex : bool
        True: dome, K = 1/R^2, H = kmin = kmax = -1/R, type 4.  False: bowl,
        H = kmin = kmax = +1/R, type 5.
    max_slope : float
        Largest slope kept, in degrees (0, 89].
    spacing, n, sigma, jitter, rng
        As in :func:`make_plane` (`n` counts points of the kept disc).

    Returns
    -------
    SyntheticCloud

    Examples
    --------
    >>> c = make_sphere_cap(2.0, spacing=0.1)
    >>> float(c.K[0]), float(c.H[0])
    (0.25, -0.5)
    """
    func = "make_sphere_cap"
    rng = np.random.default_rng(rng)
    R, slope, rmax = _radius_slope(func, radius, max_slope)
    spacing, sigma, jitter = _common(func, spacing, sigma, jitter, n, math.pi * rmax ** 2)
    x, y, ij = _grid(rmax, rmax, spacing, jitter, rng)
    r = np.hypot(x, y)
    keep = r <= rmax
    x, y, ij, r = x[keep], y[keep], ij[keep], r[keep]
    h = np.sqrt(R * R - r * r)
    sgn = 1.0 if convex else -1.0
    normal = np.column_stack([sgn * x, sgn * y, h]) / R
    N = x.size
    K = np.full(N, 1.0 / (R * R))
    H = np.full(N, -sgn / R)
    name = "sphere" if convex else "bowl"
    meta = {"kind": name, "radius": R, "convex": bool(convex), "max_slope": slope,
            "spacing": spacing, "jitter": jitter}
    return _finish(name, x, y, sgn * h, normal, K, H, rmax - r, ij, sigma, rng, meta,
                   kmin=H.copy(), kmax=H.copy())


def make_paraboloid(a=-1.0, b=-0.5, *, angle=0.0, extent=2.0, spacing=0.02, n=None,
                    sigma=0.0, jitter=0.0, rng=None) -> SyntheticCloud:
    """The quadric ``z = (a u^2 + b v^2)/2`` with (u, v) = (x, y) rotated by `angle`.

    K and H vary over the patch (closed Monge forms, see the module docstring) and so may
    the surface type, which is computed per point from the exact K, H.  At the origin
    K = a b and H = (a + b)/2.  ``b = 0`` gives a parabolic cylinder with K exactly 0.
    Note that ``a = -b`` is *not* a minimal surface (H = 0 only on the diagonals |u| = |v|);
    use :func:`make_scherk` for H = 0 everywhere.

    Parameters
    ----------
    a, b : float
        Curvatures at the origin along the rotated u and v axes.
    angle : float
        Rotation of the (u, v) axes from (x, y), degrees.
    extent : float or (float, float)
        Side lengths of the square XY domain centred on the origin.
    spacing, n, sigma, jitter, rng
        As in :func:`make_plane`.

    Returns
    -------
    SyntheticCloud

    Examples
    --------
    >>> c = make_paraboloid(-1.0, 0.0, extent=1.0, spacing=0.5)
    >>> sorted(set(c.surface_type.tolist()))
    [2]
    """
    func = "make_paraboloid"
    rng = np.random.default_rng(rng)
    a = check_scalar(a, "a", func=func)
    b = check_scalar(b, "b", func=func)
    ang = math.radians(check_scalar(angle, "angle", func=func))
    ex, ey = _pair(extent, "extent", func)
    spacing, sigma, jitter = _common(func, spacing, sigma, jitter, n, ex * ey)
    x, y, ij = _grid(ex / 2, ey / 2, spacing, jitter, rng)
    keep = (np.abs(x) <= ex / 2) & (np.abs(y) <= ey / 2)
    x, y, ij = x[keep], y[keep], ij[keep]
    c, s = math.cos(ang), math.sin(ang)
    if ang == 0.0:
        hxx, hxy, hyy = a, 0.0, b
    else:
        hxx = a * c * c + b * s * s
        hxy = (a - b) * c * s
        hyy = a * s * s + b * c * c
    fx = hxx * x + hxy * y
    fy = hxy * x + hyy * y
    z = 0.5 * (hxx * x * x + 2 * hxy * x * y + hyy * y * y)
    N = x.size
    normal, K, H = _monge(fx, fy, np.full(N, hxx), np.full(N, hxy), np.full(N, hyy))
    edge = np.minimum(ex / 2 - np.abs(x), ey / 2 - np.abs(y))
    meta = {"kind": "paraboloid", "a": a, "b": b, "angle": math.degrees(ang),
            "extent": (ex, ey), "spacing": spacing, "jitter": jitter}
    return _finish("paraboloid", x, y, z, normal, K, H, edge, ij, sigma, rng, meta)


def make_scherk(scale=1.0, *, extent=None, spacing=0.02, n=None, sigma=0.0, jitter=0.0,
                rng=None) -> SyntheticCloud:
    """Scherk's minimal surface ``z = (ln cos(c y) - ln cos(c x)) / c`` (H = 0 exactly).

    Its principal curvatures are ``-/+ sqrt(-K)`` with
    ``K = -c^2 sec^2(cx) sec^2(cy) / (1 + tan^2(cx) + tan^2(cy))^2 < 0``; at the origin
    they are -c and +c.  H is set to exactly 0 (it vanishes analytically), so every point
    has surface type 8 (minimal saddle).

    Parameters
    ----------
    scale : float
        c, the principal curvature magnitude at the origin.
    extent : float or (float, float), optional
        Side lengths of the XY domain (default 2/c, i.e. |c x| <= 1, slope <= 66 degrees);
        must satisfy ``c * extent / 2 < 1.4``.
    spacing, n, sigma, jitter, rng
        As in :func:`make_plane`.

    Returns
    -------
    SyntheticCloud

    Examples
    --------
    >>> c = make_scherk(spacing=0.25)
    >>> bool((c.H == 0).all()), sorted(set(c.surface_type.tolist()))
    (True, [8])
    """
    func = "make_scherk"
    rng = np.random.default_rng(rng)
    cc = check_scalar(scale, "scale", func=func, low=0.0)
    ex, ey = (2.0 / cc, 2.0 / cc) if extent is None else _pair(extent, "extent", func)
    if cc * max(ex, ey) / 2 >= 1.4:
        raise InvalidParameterError(
            f"The 'extent' parameter of {func} must satisfy scale*extent/2 < 1.4 (the "
            f"surface is only defined for |c x|, |c y| < pi/2). Got {extent!r} instead."
        )
    spacing, sigma, jitter = _common(func, spacing, sigma, jitter, n, ex * ey)
    x, y, ij = _grid(ex / 2, ey / 2, spacing, jitter, rng)
    keep = (np.abs(x) <= ex / 2) & (np.abs(y) <= ey / 2)
    x, y, ij = x[keep], y[keep], ij[keep]
    cx, cy = np.cos(cc * x), np.cos(cc * y)
    z = (np.log(cy) - np.log(cx)) / cc
    fx, fy = np.tan(cc * x), -np.tan(cc * y)
    fxx, fyy = cc / (cx * cx), -cc / (cy * cy)
    normal, K, _ = _monge(fx, fy, fxx, np.zeros_like(x), fyy)
    H = np.zeros_like(x)
    root = np.sqrt(-K)
    edge = np.minimum(ex / 2 - np.abs(x), ey / 2 - np.abs(y))
    meta = {"kind": "scherk", "scale": cc, "extent": (ex, ey), "spacing": spacing,
            "jitter": jitter}
    return _finish("scherk", x, y, z, normal, K, H, edge, ij, sigma, rng, meta,
                   kmin=-root, kmax=root)
