"""CSG solids answered by interval lists along rays (the scenes' exact geometry).

A solid answers, for M rays at once, an *interval list*: arrays ``t0, t1`` of shape
(M, k) (entry and exit parameters, sorted, padded with +inf) and signed face codes
``f0, f1`` (``+(id + 1)`` for a face of a primitive with its own outward normal,
``-(id + 1)`` when the normal is flipped because the primitive was subtracted; 0 = none).
Primitives are convex, so they give at most one interval per ray; :func:`union` and
:func:`difference` combine lists by a sweep over the sorted end points.  The first entry
point of a ray (smallest finite ``t0``) is the sample; its face code gives the face id,
the true outward normal and the exact curvature (:func:`_face_truth`).
"""

from __future__ import annotations

import numpy as np

from ._csg_primitives import (
    Box,
    Cylinder,
    FaceRegistry,
    Intervals,
    Polyhedron,
    _face_truth,  # noqa: F401 (the scanners' import)
    _vertical_rays,
)

__all__ = ["Cylinder", "Box", "Polyhedron", "union", "difference", "FaceRegistry"]


class _Op:
    def __init__(self, kind, a, b):
        self.kind, self.a, self.b = kind, a, b

    def xy_bounds(self):
        la, ha = self.a.xy_bounds()
        if self.kind == "difference":
            return la, ha
        lb, hb = self.b.xy_bounds()
        return np.minimum(la, lb), np.maximum(ha, hb)

    @property
    def registry(self):
        return self.a.registry

    def bounds(self):
        la, ha = self.a.bounds()
        if self.kind == "difference":
            return la, ha
        lb, hb = self.b.bounds()
        return np.minimum(la, lb), np.maximum(ha, hb)

    def contains(self, p):
        if self.kind == "union":
            return self.a.contains(p) | self.b.contains(p)
        return self.a.contains(p) & ~self.b.contains(p)

    def primitives(self):
        """The primitives of the tree, left to right."""
        out = []
        for s in (self.a, self.b):
            out.extend(s.primitives() if isinstance(s, _Op) else [s])
        return out

    def intervals(self, x, y) -> Intervals:
        return self.ray_intervals(*_vertical_rays(x, y))

    def ray_intervals(self, origin, direction) -> Intervals:
        """Entry/exit intervals of the rays ``origin + t * direction`` (each (M, 3)).

        Only the rays whose line meets the bounding box of `b` are combined with it;
        the others keep the intervals of `a` unchanged.
        """
        A = self.a.ray_intervals(origin, direction)
        m = _aabb_hit(origin, direction, *self.b.bounds())
        if not m.any():
            return A
        if m.all():
            return _combine(A, self.b.ray_intervals(origin, direction), self.kind)
        C = _combine(Intervals(*(x[m] for x in A)),
                     self.b.ray_intervals(origin[m], direction[m]), self.kind)
        k = max(A.t0.shape[1], C.t0.shape[1])
        out = []
        for xa, xc, fill in zip(A, C, (np.inf, np.inf, 0, 0)):
            z = np.full((xa.shape[0], k), fill, dtype=xa.dtype)
            z[:, :xa.shape[1]] = xa
            z[m] = fill
            z[m, :xc.shape[1]] = xc
            out.append(z)
        return Intervals(*out)


def _aabb_hit(origin, direction, lo, hi, pad=1e-9):
    """True where the line ``origin + t direction`` (any t) meets the box [lo, hi]."""
    lo = lo - pad * (1 + np.abs(lo))
    hi = hi + pad * (1 + np.abs(hi))
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - origin) / direction
        tb = (hi - origin) / direction
    par = direction == 0
    outside = par & ((origin < lo) | (origin > hi))
    t_in = np.where(par, -np.inf, np.minimum(ta, tb)).max(axis=1)
    t_out = np.where(par, np.inf, np.maximum(ta, tb)).min(axis=1)
    return (t_in <= t_out) & ~outside.any(axis=1)


def union(a, b):
    """CSG union of two solids (primitives or results of :func:`union` / :func:`difference`)."""
    return _Op("union", a, b)


def difference(a, b):
    """CSG difference ``a - b``; faces of `b` seen in the result have flipped normals."""
    return _Op("difference", a, b)


def _combine(A: Intervals, B: Intervals, kind: str) -> Intervals:
    M = A.t0.shape[0]
    ka, kb = A.t0.shape[1], B.t0.shape[1]
    t = np.concatenate([A.t0, A.t1, B.t0, B.t1], axis=1)
    bsign = -1 if kind == "difference" else 1
    code = np.concatenate([A.f0, A.f1, bsign * B.f0, bsign * B.f1], axis=1)
    da = np.concatenate([np.ones(ka), -np.ones(ka), np.zeros(2 * kb)])
    db = np.concatenate([np.zeros(2 * ka), np.ones(kb), -np.ones(kb)])
    order = np.argsort(t, axis=1, kind="stable")
    t = np.take_along_axis(t, order, 1)
    code = np.take_along_axis(code, order, 1)
    in_a = np.cumsum(da[order], axis=1) > 0
    in_b = np.cumsum(db[order], axis=1) > 0
    member = (in_a | in_b) if kind == "union" else (in_a & ~in_b)
    prev = np.concatenate([np.zeros((M, 1), bool), member[:, :-1]], axis=1)
    starts = member & ~prev & np.isfinite(t)
    ends = ~member & prev & np.isfinite(t)
    # an interval that starts at a finite t always ends at a finite t (bounded primitives)
    kmax = max(int(starts.sum(1).max(initial=0)), 1)

    def compact(mask):
        tt = np.where(mask, t, np.inf)
        o = np.argsort(tt, axis=1, kind="stable")[:, :kmax]
        return (np.take_along_axis(tt, o, 1),
                np.where(np.take_along_axis(mask, o, 1), np.take_along_axis(code, o, 1), 0))

    t0, f0 = compact(starts)
    t1, f1 = compact(ends)
    return Intervals(t0, t1, f0, f1)
