"""Analytic surface patches by name: one height field per surface type code, with
parameters for which every point of the default patch has that type."""

from __future__ import annotations

from .._shared.validation import check_option
from ._surfaces import make_cylinder, make_paraboloid, make_plane, make_scherk, make_sphere_cap
from ._truth import SyntheticCloud

__all__ = ["SURFACE_KINDS", "make_surface"]

# kind -> (expected surface type, generator, fixed keyword arguments)
_KINDS = {
    "plane": (1, make_plane, {"normal": (0.1, -0.2, 1.0)}),
    "cylinder": (2, make_cylinder, {"radius": 1.0, "convex": True}),
    "ridge": (2, make_paraboloid, {"a": -1.0, "b": 0.0}),
    "trough": (3, make_cylinder, {"radius": 1.0, "convex": False}),
    "valley": (3, make_paraboloid, {"a": 1.0, "b": 0.0}),
    "sphere": (4, make_sphere_cap, {"radius": 1.0, "convex": True}),
    "peak": (4, make_paraboloid, {"a": -1.0, "b": -0.5}),
    "bowl": (5, make_sphere_cap, {"radius": 1.0, "convex": False}),
    "pit": (5, make_paraboloid, {"a": 1.0, "b": 0.5}),
    "saddle_ridge": (6, make_paraboloid, {"a": -1.0, "b": 0.4}),
    "saddle_valley": (7, make_paraboloid, {"a": 1.0, "b": -0.4}),
    "minimal_saddle": (8, make_scherk, {"scale": 1.0}),
}

#: Names accepted by :func:`make_surface`, mapped to the surface type code of every point.
SURFACE_KINDS = {k: v[0] for k, v in _KINDS.items()}


def make_surface(kind, *, spacing=0.02, n=None, sigma=0.0, jitter=0.0, rng=None,
                 **kwargs) -> SyntheticCloud:
    """One patch of a given surface type, with exact truth, by name.

    ============== ==== =========================================================
    kind           type patch (unit curvature scale, XY domain about 2 x 2)
    ============== ==== =========================================================
    plane          1    plane with normal (0.1, -0.2, 1)
    cylinder       2    :func:`make_cylinder`, R = 1, convex
    ridge          2    :func:`make_paraboloid`, a = -1, b = 0 (parabolic cylinder)
    trough         3    :func:`make_cylinder`, R = 1, concave
    valley         3    :func:`make_paraboloid`, a = 1, b = 0
    sphere         4    :func:`make_sphere_cap`, R = 1, dome
    peak           4    :func:`make_paraboloid`, a = -1, b = -0.5
    bowl           5    :func:`make_sphere_cap`, R = 1, bowl
    pit            5    :func:`make_paraboloid`, a = 1, b = 0.5
    saddle_ridge   6    :func:`make_paraboloid`, a = -1, b = 0.4
    saddle_valley  7    :func:`make_paraboloid`, a = 1, b = -0.4
    minimal_saddle 8    :func:`make_scherk`, c = 1 (H = 0 exactly)
    ============== ==== =========================================================

    The parameters are chosen so that the type is the same at *every* point of the default
    patch: for the saddles, the numerator of H is ``(a + b) + a b (b y^2 + a x^2)``, which
    keeps the sign of a + b for |x|, |y| <= 1 since |a b| max(|a|, |b|) < |a + b|.
    (Overriding ``extent`` may break this; the per-point ``surface_type`` stays exact.)

    Parameters
    ----------
    kind : str
        One of :data:`SURFACE_KINDS`.
    spacing, n, sigma, jitter, rng
        As in :func:`make_plane`.
    **kwargs
        Further keywords passed to the generator (they override the defaults above).

    Returns
    -------
    SyntheticCloud
        ``name`` is `kind`.

    Examples
    --------
    >>> c = make_surface("saddle_valley", spacing=0.1)
    >>> sorted(set(c.surface_type.tolist()))
    [7]
    """
    check_option(kind, "kind", _KINDS, func="make_surface")
    _, gen, fixed = _KINDS[kind]
    args = {**fixed, **kwargs}
    cloud = gen(spacing=spacing, n=n, sigma=sigma, jitter=jitter, rng=rng, **args)
    meta = dict(cloud.meta)
    meta["surface_kind"] = kind
    object.__setattr__(cloud, "name", kind)
    object.__setattr__(cloud, "meta", meta)
    return cloud
