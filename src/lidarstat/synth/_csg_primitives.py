"""Convex CSG primitives (cylinder, box, polyhedron) answering interval lists along rays,
the registry of their faces and the exact truth (normal, curvatures) of a sample on a face.

The interval lists and face codes are described in ``_csg``, which combines primitives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..errors import InvalidParameterError

__all__ = ["Cylinder", "Box", "Polyhedron", "FaceRegistry"]

_EPS = 1e-12


class Intervals(NamedTuple):
    """Interval lists of M rays: entry/exit parameters (M, k) and signed face codes."""

    t0: np.ndarray
    t1: np.ndarray
    f0: np.ndarray
    f1: np.ndarray


def _unit(v, name):
    v = np.asarray(v, dtype=np.float64).ravel()
    if v.size != 3 or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise InvalidParameterError(f"`{name}` must be a finite non-zero 3-vector; got {v}")
    return v / np.linalg.norm(v)


class FaceRegistry:
    """Ordered list of faces; each is a dict with ``name`` and ``kind`` ("plane" or
    "cylinder") plus its geometry (plane: ``point``, ``normal`` = primitive outward normal;
    cylinder: ``center``, ``axis``, ``radius``)."""

    def __init__(self):
        self.faces: list[dict] = []

    def add(self, **face) -> int:
        if any(f["name"] == face["name"] for f in self.faces):
            raise InvalidParameterError(f"duplicate face name {face['name']!r}")
        self.faces.append(face)
        return len(self.faces) - 1


@dataclass
class Cylinder:
    """Finite solid cylinder with end caps; ``axis`` arbitrary, ``center`` at mid-length.

    Faces registered: ``{name}_side``, ``{name}_cap_top`` (at ``center + L/2 axis``) and
    ``{name}_cap_bottom`` (at ``center - L/2 axis``).
    """

    registry: FaceRegistry
    name: str
    center: np.ndarray
    axis: np.ndarray
    radius: float
    length: float

    def __post_init__(self):
        self.center = np.asarray(self.center, dtype=np.float64).reshape(3)
        self.axis = _unit(self.axis, "axis")
        self.radius = float(self.radius)
        self.length = float(self.length)
        if not (self.radius > 0 and self.length > 0):
            raise InvalidParameterError("cylinder radius and length must be positive")
        h = self.length / 2
        reg, c, a = self.registry, self.center, self.axis
        self.side = reg.add(name=f"{self.name}_side", kind="cylinder", center=c.tolist(),
                            axis=a.tolist(), radius=self.radius, length=self.length)
        self.cap_top = reg.add(name=f"{self.name}_cap_top", kind="plane",
                               point=(c + h * a).tolist(), normal=a.tolist())
        self.cap_bottom = reg.add(name=f"{self.name}_cap_bottom", kind="plane",
                                  point=(c - h * a).tolist(), normal=(-a).tolist())

    def xy_bounds(self):
        h = self.length / 2
        ends = np.stack([self.center + h * self.axis, self.center - h * self.axis])
        ext = self.radius * np.sqrt(np.maximum(1.0 - self.axis[:2] ** 2, 0.0))
        return ends[:, :2].min(0) - ext, ends[:, :2].max(0) + ext

    def bounds(self):
        """Axis-aligned 3-D bounding box ``(lo, hi)``."""
        h = self.length / 2
        ends = np.stack([self.center + h * self.axis, self.center - h * self.axis])
        ext = self.radius * np.sqrt(np.maximum(1.0 - self.axis ** 2, 0.0))
        return ends.min(0) - ext, ends.max(0) + ext

    def contains(self, p):
        """True for points `p` (M, 3) inside the closed solid."""
        w = np.asarray(p, dtype=np.float64) - self.center
        wa = w @ self.axis
        wp = w - wa[:, None] * self.axis
        return (np.abs(wa) <= self.length / 2) & (np.einsum("ij,ij->i", wp, wp)
                                                   <= self.radius ** 2)

    def intervals(self, x, y) -> Intervals:
        return self.ray_intervals(*_vertical_rays(x, y))

    def ray_intervals(self, origin, direction) -> Intervals:
        """Entry/exit parameters of the rays ``origin + t * direction`` (each (M, 3))."""
        a, c, R, h = self.axis, self.center, self.radius, self.length / 2
        w = origin - c
        wa = w @ a
        da = direction @ a
        wp = w - wa[:, None] * a
        dp = direction - da[:, None] * a
        A = np.einsum("ij,ij->i", dp, dp)
        B = np.einsum("ij,ij->i", wp, dp)
        C = np.einsum("ij,ij->i", wp, wp) - R * R
        with np.errstate(divide="ignore", invalid="ignore"):
            par = A <= _EPS  # ray parallel to the axis
            disc = B * B - A * C
            ok = (disc >= 0) & ~par
            sq = np.sqrt(np.where(ok, disc, 0.0))
            q = -(B + np.copysign(sq, B))
            r1 = q / A
            r2 = np.where(q != 0, C / q, r1)
            inside = C <= 0
            s_in = np.where(ok, np.minimum(r1, r2),
                            np.where(par & inside, -np.inf, np.inf))
            s_out = np.where(ok, np.maximum(r1, r2),
                             np.where(par & inside, np.inf, -np.inf))
            cpar = np.abs(da) <= _EPS
            ta = (-h - wa) / da
            tb = (h - wa) / da
            in_slab = np.abs(wa) <= h
            c_in = np.where(cpar, np.where(in_slab, -np.inf, np.inf), np.minimum(ta, tb))
            c_out = np.where(cpar, np.where(in_slab, np.inf, -np.inf), np.maximum(ta, tb))
        up = da > 0
        cap_in = np.where(up, self.cap_bottom, self.cap_top)
        cap_out = np.where(up, self.cap_top, self.cap_bottom)
        t0 = np.maximum(s_in, c_in)
        t1 = np.minimum(s_out, c_out)
        f0 = np.where(s_in >= c_in, self.side, cap_in) + 1
        f1 = np.where(s_out <= c_out, self.side, cap_out) + 1
        hit = t0 < t1
        return _single(t0, t1, f0, f1, hit)


@dataclass
class Box:
    """Solid box: ``center``, ``rotation`` (3x3, columns = local axes in world
    coordinates) and ``half_extents`` along the local axes.

    Faces registered: ``{name}_+x, {name}_-x, {name}_+y, {name}_-y, {name}_+z, {name}_-z``
    (local axes).
    """

    registry: FaceRegistry
    name: str
    center: np.ndarray
    rotation: np.ndarray
    half_extents: np.ndarray

    def __post_init__(self):
        self.center = np.asarray(self.center, dtype=np.float64).reshape(3)
        Rm = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if not np.allclose(Rm.T @ Rm, np.eye(3), atol=1e-10) or np.linalg.det(Rm) < 0:
            raise InvalidParameterError("box rotation must be a proper rotation matrix")
        self.rotation = Rm
        self.half_extents = np.asarray(self.half_extents, dtype=np.float64).reshape(3)
        if not np.all(self.half_extents > 0):
            raise InvalidParameterError("box half extents must be positive")
        self.face_ids = np.empty((3, 2), dtype=np.int64)  # [axis, 0 -> +, 1 -> -]
        for i, ax in enumerate("xyz"):
            for j, sg in enumerate((1.0, -1.0)):
                nrm = sg * Rm[:, i]
                pt = self.center + sg * self.half_extents[i] * Rm[:, i]
                self.face_ids[i, j] = self.registry.add(
                    name=f"{self.name}_{'+' if sg > 0 else '-'}{ax}", kind="plane",
                    point=pt.tolist(), normal=nrm.tolist())

    def corners(self):
        sg = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
        return self.center + (sg * self.half_extents) @ self.rotation.T

    def xy_bounds(self):
        c = self.corners()[:, :2]
        return c.min(0), c.max(0)

    def _planes(self):
        # half-spaces n . x <= d in the face order +x, -x, +y, -y, +z, -z
        n = np.stack([sg * self.rotation[:, i] for i in range(3) for sg in (1.0, -1.0)])
        d = n @ self.center + np.repeat(self.half_extents, 2)
        return n, d, self.face_ids.ravel()

    def bounds(self):
        """Axis-aligned 3-D bounding box ``(lo, hi)``."""
        c = self.corners()
        return c.min(0), c.max(0)

    def contains(self, p):
        """True for points `p` (M, 3) inside the closed solid."""
        n, d, _ = self._planes()
        return np.all(np.asarray(p, dtype=np.float64) @ n.T <= d, axis=1)

    def intervals(self, x, y) -> Intervals:
        return self.ray_intervals(*_vertical_rays(x, y))

    def ray_intervals(self, origin, direction) -> Intervals:
        """Entry/exit parameters of the rays ``origin + t * direction`` (each (M, 3))."""
        return _convex_intervals(origin, direction, *self._planes())


@dataclass
class Polyhedron:
    """Convex polyhedron, the intersection of half-spaces ``normals[k] . x <= offsets[k]``.

    Faces registered: ``{name}_{face_names[k]}`` with outward normal ``normals[k]``
    (normalised).  The polyhedron must be bounded; its vertices are found once by
    enumerating plane triples (fine for the few tens of planes of a house).
    """

    registry: FaceRegistry
    name: str
    normals: np.ndarray
    offsets: np.ndarray
    face_names: tuple

    def __post_init__(self):
        n = np.asarray(self.normals, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(self.offsets, dtype=np.float64).reshape(-1)
        if n.shape[0] != d.size or d.size != len(self.face_names) or d.size < 4:
            raise InvalidParameterError("polyhedron needs >= 4 planes, one name per plane")
        norm = np.linalg.norm(n, axis=1)
        if np.any(norm == 0) or not np.all(np.isfinite(n)) or not np.all(np.isfinite(d)):
            raise InvalidParameterError("polyhedron planes must be finite with non-zero normals")
        self.normals, self.offsets = n / norm[:, None], d / norm
        self.vertices = _polyhedron_vertices(self.normals, self.offsets)
        if self.vertices.shape[0] < 4:
            raise InvalidParameterError(f"polyhedron {self.name!r} is empty or unbounded")
        self.face_ids = np.array([
            self.registry.add(name=f"{self.name}_{fn}", kind="plane",
                              point=(self.offsets[k] * self.normals[k]).tolist(),
                              normal=self.normals[k].tolist())
            for k, fn in enumerate(self.face_names)], dtype=np.int64)

    def bounds(self):
        """Axis-aligned 3-D bounding box ``(lo, hi)``."""
        return self.vertices.min(0), self.vertices.max(0)

    def xy_bounds(self):
        lo, hi = self.bounds()
        return lo[:2], hi[:2]

    def contains(self, p):
        """True for points `p` (M, 3) inside the closed solid."""
        return np.all(np.asarray(p, dtype=np.float64) @ self.normals.T <= self.offsets, axis=1)

    def intervals(self, x, y) -> Intervals:
        return self.ray_intervals(*_vertical_rays(x, y))

    def ray_intervals(self, origin, direction) -> Intervals:
        """Entry/exit parameters of the rays ``origin + t * direction`` (each (M, 3))."""
        return _convex_intervals(origin, direction, self.normals, self.offsets, self.face_ids)


def _polyhedron_vertices(n, d, tol=1e-9):
    K = n.shape[0]
    tri = np.array([(i, j, k) for i in range(K) for j in range(i + 1, K)
                    for k in range(j + 1, K)])
    A = n[tri]  # (T, 3, 3)
    det = np.linalg.det(A)
    good = np.abs(det) > 1e-12
    v = np.linalg.solve(A[good], d[tri[good]][..., None])[..., 0]
    scale = max(1.0, float(np.abs(d).max()))
    inside = np.all(v @ n.T <= d + tol * scale, axis=1)
    return v[inside]


def _vertical_rays(x, y):
    """Rays of the orthographic scans: origin (x, y, 0), direction -z (t = -z)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    o = np.stack([x, y, np.zeros_like(x)], axis=1)
    d = np.zeros_like(o)
    d[:, 2] = -1.0
    return o, d


def _convex_intervals(origin, direction, normals, offsets, face_ids):
    """Ray / convex polyhedron intervals (Kay-Kajiya slabs generalised to K planes)."""
    den = direction @ normals.T  # (M, K)
    num = offsets[None, :] - origin @ normals.T  # > 0 where the origin is inside plane k
    enter = den < -_EPS
    leave = den > _EPS
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    lo = np.where(enter, t, -np.inf)
    hi = np.where(leave, t, np.inf)
    outside_par = np.any(~enter & ~leave & (num < 0), axis=1)
    k0 = np.argmax(lo, axis=1)
    k1 = np.argmin(hi, axis=1)
    r = np.arange(origin.shape[0])
    t0, t1 = lo[r, k0], hi[r, k1]
    return _single(t0, t1, face_ids[k0] + 1, face_ids[k1] + 1, (t0 < t1) & ~outside_par)


def _single(t0, t1, f0, f1, hit) -> Intervals:
    return Intervals(
        np.where(hit, t0, np.inf)[:, None], np.where(hit, t1, np.inf)[:, None],
        np.where(hit, f0, 0).astype(np.int64)[:, None],
        np.where(hit, f1, 0).astype(np.int64)[:, None],
    )


def _face_truth(faces, face_id, flipped, p):
    """True outward normal (toward the viewer) and curvatures of samples `p` on faces."""
    N = p.shape[0]
    normal = np.zeros((N, 3))
    K = np.zeros(N)
    H = np.zeros(N)
    kmin = np.zeros(N)
    kmax = np.zeros(N)
    sgn = np.where(flipped, -1.0, 1.0)
    for fid in np.unique(face_id):
        m = face_id == fid
        f = faces[fid]
        if f["kind"] == "plane":
            normal[m] = np.asarray(f["normal"])
        else:
            c, a, R = np.asarray(f["center"]), np.asarray(f["axis"]), f["radius"]
            w = p[m] - c
            radial = w - (w @ a)[:, None] * a
            normal[m] = radial / np.linalg.norm(radial, axis=1, keepdims=True)
            # outward normal of a convex cylinder: kmin = -1/R, kmax = 0; flipped (a bore
            # seen from inside): kmin = 0, kmax = +1/R
            H[m] = -sgn[m] / (2 * R)
            kmin[m] = np.where(flipped[m], 0.0, -1.0 / R)
            kmax[m] = np.where(flipped[m], 1.0 / R, 0.0)
    normal *= sgn[:, None]
    return normal, K, H, kmin, kmax
