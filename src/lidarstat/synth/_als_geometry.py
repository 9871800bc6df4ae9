"""The airborne town's geometry: terrain, houses, materials and class codes.

The terrain is a smooth analytic height field ``z = g(x, y)``; buildings are CSG solids
of convex polyhedra with flat, gable, hip or L-shaped roofs, dormers and chimneys (see
:mod:`lidarstat.synth._als`, which assembles the scenes, and
:mod:`lidarstat.synth._als_scan`, which scans them).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InvalidParameterError
from ._csg import Box, Polyhedron, union

#: material code -> (name, mean reflectance, reflectance std between points)
MATERIALS = {
    0: ("none", 0.0, 0.0),
    1: ("grass", 0.45, 0.05),
    2: ("soil", 0.25, 0.04),
    3: ("asphalt", 0.08, 0.015),
    4: ("roof_tile", 0.30, 0.03),
    5: ("roof_metal", 0.55, 0.05),
    6: ("roof_gravel", 0.20, 0.03),
    7: ("wall", 0.35, 0.04),
    8: ("chimney", 0.25, 0.03),
    9: ("car", 0.40, 0.15),
    10: ("vegetation", 0.50, 0.08),
    11: ("noise", 0.15, 0.08),
}
#: ASPRS class codes used by the airborne scenes
ASPRS_CLASSES = {1: "unclassified (cars, other)", 2: "ground", 3: "low vegetation",
                 4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "noise",
                 11: "road surface"}

_MIN_SEP = 1.5  # minimum range separation of two echoes of a pulse (m)
_CROWN_EXT = 0.35  # echo probability per metre of crown
_ENERGY_SCALE = 40000.0


# ------------------------------------------------------------------------ terrain
class _Terrain:
    """z = z0 + sx x + sy y + A sin(2 pi x / Lx) cos(2 pi y / Ly)."""

    def __init__(self, z0, sx, sy, amp, lx, ly):
        self.z0, self.sx, self.sy, self.amp = z0, sx, sy, amp
        self.kx, self.ky = 2 * np.pi / lx, 2 * np.pi / ly

    def z(self, x, y):
        return (self.z0 + self.sx * x + self.sy * y
                + self.amp * np.sin(self.kx * x) * np.cos(self.ky * y))

    def derivatives(self, x, y):
        s, c = np.sin(self.kx * x), np.cos(self.kx * x)
        sy_, cy_ = np.sin(self.ky * y), np.cos(self.ky * y)
        a, kx, ky = self.amp, self.kx, self.ky
        fx = self.sx + a * kx * c * cy_
        fy = self.sy - a * ky * s * sy_
        fxx = -a * kx * kx * s * cy_
        fyy = -a * ky * ky * s * cy_
        fxy = -a * kx * ky * c * sy_
        return fx, fy, fxx, fxy, fyy

    def hit(self, o, d, iters=8):
        """Ray parameter of the terrain hit (Newton on o_z + t d_z - g(o + t d))."""
        t = (o[:, 2] - self.z(o[:, 0], o[:, 1])) / -d[:, 2]
        for _ in range(iters):
            x, y = o[:, 0] + t * d[:, 0], o[:, 1] + t * d[:, 1]
            fx, fy = self.derivatives(x, y)[:2]
            f = o[:, 2] + t * d[:, 2] - self.z(x, y)
            t = t - f / (d[:, 2] - fx * d[:, 0] - fy * d[:, 1])
        return t

    def truth(self, x, y):
        """Upward unit normal, K and H (Monge patch formulas) at (x, y)."""
        fx, fy, fxx, fxy, fyy = self.derivatives(x, y)
        W = np.sqrt(1 + fx * fx + fy * fy)
        n = np.stack([-fx, -fy, np.ones_like(fx)], axis=1) / W[:, None]
        K = (fxx * fyy - fxy * fxy) / W**4
        H = ((1 + fy * fy) * fxx - 2 * fx * fy * fxy + (1 + fx * fx) * fyy) / (2 * W**3)
        # H is the mean curvature of the upward-oriented graph: convex up (a hill) has
        # fxx < 0, i.e. H < 0, as the library convention wants
        return n, K, H


# ------------------------------------------------------------------------ buildings
def _rot(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _poly(reg, name, planes, R, t):
    """Polyhedron from local planes [(normal, point_on_plane, face_name)] moved by R, t."""
    n = np.array([R @ np.asarray(p[0], float) for p in planes])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pts = np.array([R @ np.asarray(p[1], float) + t for p in planes])
    d = np.einsum("ij,ij->i", n, pts)
    return Polyhedron(reg, name, n, d, tuple(p[2] for p in planes))


def _house_planes(a, b, z0, eave, ridge, roof):
    """Local planes of a house of half-length a (x), half-width b (y): walls, bottom and
    the roof ("flat", "gable": ridge along x, "hip": same slope on all four sides)."""
    P = [((0, 0, -1), (0, 0, z0), "bottom"), ((1, 0, 0), (a, 0, 0), "wall_east"),
         ((-1, 0, 0), (-a, 0, 0), "wall_west"), ((0, 1, 0), (0, b, 0), "wall_north"),
         ((0, -1, 0), (0, -b, 0), "wall_south")]
    if roof == "flat":
        P.append(((0, 0, 1), (0, 0, ridge), "roof"))
        return P
    rise = ridge - eave
    P += [((0, -rise, b), (0, -b, eave), "roof_south"), ((0, rise, b), (0, b, eave),
                                                         "roof_north")]
    if roof == "hip":
        P += [((rise, 0, b), (a, 0, eave), "roof_east"), ((-rise, 0, b), (-a, 0, eave),
                                                          "roof_west")]
    return P


class _Building:
    """One building: its solid, footprint, roof planes and face roles."""

    def __init__(self, reg, bid, spec, terrain):
        self.id = bid
        self.spec = spec
        cx, cy = spec["center"]
        ang = math.radians(spec.get("angle", 0.0))
        R = _rot(ang)
        a, b = spec["half_size"]
        roof = spec["roof"]
        rects = [(-a, a, -b, b)]
        if roof == "L":  # wing along local y at the east end, same span as the main wing
            ext = spec.get("wing", 2 * b)
            rects.append((a - 2 * b, a, 0.0, b + ext))
        corners = np.array([(x, y) for x0, x1, y0, y1 in rects for x in (x0, x1)
                            for y in (y0, y1)])
        wc = corners @ R[:2, :2].T + (cx, cy)
        ground = terrain.z(wc[:, 0], wc[:, 1])
        base = float(ground.max())
        self.ground_min = float(ground.min())
        z0 = float(ground.min()) - 1.0
        eave = base + spec["eave"]
        ridge = base + spec["ridge"]
        self.base, self.eave_z, self.ridge_z = base, eave, ridge
        t = np.array([cx, cy, 0.0])
        name = f"b{bid}"
        parts = []
        main_roof = "gable" if roof == "L" else roof
        parts.append(_poly(reg, f"{name}_main", _house_planes(a, b, z0, eave, ridge,
                                                               main_roof), R, t))
        if roof == "L":
            x0, x1, y0, y1 = rects[1]
            Rw = R @ _rot(math.pi / 2)  # the wing's local x is the world's local y
            tw = t + R @ np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
            parts.append(_poly(reg, f"{name}_wing",
                               _house_planes((y1 - y0) / 2, (x1 - x0) / 2, z0, eave,
                                             ridge, "gable"), Rw, tw))
        rise = ridge - eave
        for k, dm in enumerate(spec.get("dormers", [])):
            # on the south roof plane of the main wing, centred at local x = xd
            xd, w, yf = dm["x"], dm["width"], -b + dm["setback"]
            z_main = eave + rise * (yf + b) / b
            zde = z_main + dm["front"]
            zdr = zde + dm["rise"]
            if zdr >= ridge - 0.2:
                raise InvalidParameterError(f"dormer {k} of building {bid} is too high")
            planes = [((0, 0, -1), (0, 0, eave - 0.5), "bottom"),
                      ((0, -1, 0), (0, yf, 0), "front"),
                      ((0, 1, 0), (0, 0.0, 0), "back"),
                      ((1, 0, 0), (xd + w / 2, 0, 0), "cheek_east"),
                      ((-1, 0, 0), (xd - w / 2, 0, 0), "cheek_west"),
                      ((zdr - zde, 0, w / 2), (xd + w / 2, 0, zde), "roof_east"),
                      ((-(zdr - zde), 0, w / 2), (xd - w / 2, 0, zde), "roof_west")]
            parts.append(_poly(reg, f"{name}_dormer{k}", planes, R, t))
        for k, ch in enumerate(spec.get("chimneys", [])):
            cxl, cyl, s, h = ch["x"], ch["y"], ch["size"], ch["height"]
            top = ridge + h
            c = R @ np.array([cxl, cyl, 0.0]) + t
            zc = 0.5 * (eave - 0.5 + top)
            parts.append(Box(reg, f"{name}_chimney{k}", (c[0], c[1], zc), R,
                             (s / 2, s / 2, 0.5 * (top - eave + 0.5))))
        solid = parts[0]
        for p in parts[1:]:
            solid = union(solid, p)
        self.solid = solid
        # footprint polygon (counter-clockwise) in world coordinates
        if roof == "L":
            x0, x1, y0, y1 = rects[1]
            loc = [(-a, -b), (a, -b), (a, y1), (x0, y1), (x0, b), (-a, b)]
        else:
            loc = [(-a, -b), (a, -b), (a, b), (-a, b)]
        self.footprint = np.asarray(loc) @ R[:2, :2].T + (cx, cy)
        self.rects, self.R, self.t = rects, R, t
        self.material = spec.get("material", 4 if roof != "flat" else 6)

    def face_roles(self, faces):
        """Face id -> 'roof' (a roof plane), 'wall', 'chimney' or 'hidden'."""
        roles = {}
        for fid, f in enumerate(faces):
            nm = f["name"]
            if not nm.startswith(f"b{self.id}_"):
                continue
            part = nm[len(f"b{self.id}_"):]
            if "_chimney" in nm or part.startswith("chimney"):
                roles[fid] = "chimney"
            elif "_roof" in part:
                roles[fid] = "roof"
            elif part.endswith(("bottom", "back")):
                roles[fid] = "hidden"
            else:
                roles[fid] = "wall"
        return roles

    def inside(self, x, y, margin=0.0):
        """True where (x, y) lies within `margin` of the footprint (or inside it)."""
        p = np.stack([x - self.t[0], y - self.t[1]], axis=1) @ self.R[:2, :2]
        out = np.zeros(p.shape[0], dtype=bool)
        for x0, x1, y0, y1 in self.rects:
            out |= ((p[:, 0] >= x0 - margin) & (p[:, 0] <= x1 + margin)
                    & (p[:, 1] >= y0 - margin) & (p[:, 1] <= y1 + margin))
        return out


# ------------------------------------------------------------------------ scene spec
