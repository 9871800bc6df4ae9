"""Airborne laser scans of a small town with exact truth (ASPRS classes, roof planes).

The scene is geometry plus a scan simulation:

* terrain: a smooth analytic height field ``z = g(x, y)`` (a tilted plane plus a gentle
  undulation); its material is *road* inside the road strips, *soil* on garden patches,
  *grass* elsewhere;
* buildings: CSG solids of convex polyhedra (:class:`~lidarstat.synth.Polyhedron`) with
  flat, gable, hip or L-shaped (two crossing gables: four planes and two valleys) roofs,
  gable dormers and box chimneys; walls reach 1 m below the terrain;
* cars: boxes on the roads; trees and shrubs: ellipsoidal crowns; noise: isolated
  points 1.5-8 m (along the pulse) below the terrain (multipath) or 15-60 m above the
  first surface (birds, haze).

One or several (``strips``, 30 % overlap) flight lines along x at ``altitude`` above the
mean terrain fire pulses on scan lines across the track (an oscillating mirror: the lines zig-zag), with a random phase
and along-track offset per line and a small jitter per pulse, at ``density`` pulses per
square metre.  Each pulse is a ray from the aircraft: its last echo is the first hit on
the terrain, a building or a car (exact ray casting); on its way it may cross tree
crowns, which give up to three earlier echoes (exponential free paths in the crown
with rate ``foliage`` per metre: 0.35 for trees, 1.5 for shrubs; echoes at least 1.5 m
apart in range, energy shared), and may be blocked (no last echo) with probability
``1 - exp(-0.35 foliage path)``.  Range noise of std `sigma` moves every echo along its ray.  Intensity is
``reflectance x cos(incidence) x (H / range)^2 x energy share`` with a multiplicative
speckle, scaled to 16 bits; asphalt has reflectance about 0.08, grass 0.45, soil 0.25.
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ._csg import Box, FaceRegistry, Polyhedron, _aabb_hit, union
from ._edges import crease_lines, distance_to_creases
from ._truth import SyntheticCloud, principal_curvatures, surface_type_from_curvature

__all__ = ["make_als_town", "make_hip_roof_scene", "MATERIALS", "ASPRS_CLASSES"]

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
class _RayIndex:
    """Candidate rays of a box quickly: rays sorted by their x at a reference height, then
    the exact slab test on the few whose x range can reach the box."""

    def __init__(self, o, d, z_ref):
        self.o, self.d = o, d
        t = (z_ref - o[:, 2]) / d[:, 2]
        self.xg = o[:, 0] + t * d[:, 0]
        self.order = np.argsort(self.xg, kind="stable")
        self.xs = self.xg[self.order]
        self.z_ref = z_ref
        self.slope = float(np.max(np.abs(d[:, 0] / d[:, 2]))) + 1e-12

    def candidates(self, lo, hi):
        dz = max(abs(lo[2] - self.z_ref), abs(hi[2] - self.z_ref))
        m = self.slope * dz + 1e-6
        i0, i1 = np.searchsorted(self.xs, [lo[0] - m, hi[0] + m])
        idx = np.sort(self.order[i0:i1])
        ok = _aabb_hit(self.o[idx], self.d[idx], lo, hi)
        return idx[ok]


def _first_solid_hits(objects, index):
    """Smallest positive entry parameter over CSG objects, with object index and face."""
    o, d = index.o, index.d
    M = o.shape[0]
    t = np.full(M, np.inf)
    obj = np.full(M, -1, dtype=np.int64)
    code = np.zeros(M, dtype=np.int64)
    for k, solid in enumerate(objects):
        m = index.candidates(*solid.bounds())
        if m.size == 0:
            continue
        iv = solid.ray_intervals(o[m], d[m])
        t0 = np.where(iv.t0 > 0, iv.t0, np.inf)
        j = np.argmin(t0, axis=1)
        r = np.arange(m.size)
        tk = t0[r, j]
        better = tk < t[m]
        sel = m[better]
        t[sel] = tk[better]
        obj[sel] = k
        code[sel] = iv.f0[r, j][better]
    return t, obj, code


def _ellipsoid_hits(trees, index):
    """Entry/exit parameters of the first crown crossed by each ray (inf if none)."""
    o, d = index.o, index.d
    M = o.shape[0]
    t_in = np.full(M, np.inf)
    t_out = np.full(M, np.inf)
    tid = np.full(M, -1, dtype=np.int64)
    for k, tr in enumerate(trees):
        c, rh, rv = np.asarray(tr["center"], float), tr["radius"], tr["half_height"]
        r = np.array([rh, rh, rv])
        m = index.candidates(c - r, c + r)
        if m.size == 0:
            continue
        oo = (o[m] - c) / r
        dd = d[m] / r
        A = np.einsum("ij,ij->i", dd, dd)
        B = np.einsum("ij,ij->i", oo, dd)
        C = np.einsum("ij,ij->i", oo, oo) - 1.0
        disc = B * B - A * C
        ok = disc > 0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        a_in = np.where(ok, (-B - sq) / A, np.inf)
        a_out = np.where(ok, (-B + sq) / A, np.inf)
        better = a_in < t_in[m]
        sel = m[better]
        t_in[sel], t_out[sel], tid[sel] = a_in[better], a_out[better], k
    return t_in, t_out, tid


def _strip_bands(height, strips, overlap):
    """(y_start, y_end, y_flight) of each flight strip across [0, height]."""
    if strips == 1:
        return [(0.0, height, height / 2)]
    delta = height / strips
    out = []
    for s in range(strips):
        yc = (s + 0.5) * delta
        half = 0.5 * delta * (1 + overlap)
        out.append((max(0.0, yc - half), min(height, yc + half), yc))
    return out


def _pulses(extent, density, altitude, terrain, rng, strips=1, overlap=0.3):
    """Aircraft positions, unit directions, GPS times and strip ids of the pulses."""
    W, Htot = extent
    step = 1.0 / math.sqrt(density)
    zm = terrain.z(np.array([W / 2]), np.array([Htot / 2]))[0]
    parts = []
    for s, (y0, y1, y_fl) in enumerate(_strip_bands(Htot, strips, overlap)):
        H = y1 - y0
        n_lines = int(math.ceil(W / step)) + 1
        n_per = int(math.ceil(H / step)) + 1
        line = np.repeat(np.arange(n_lines), n_per)
        k = np.tile(np.arange(n_per), n_lines)
        phase = rng.uniform(0, 1, n_lines)[line]
        shift = rng.uniform(-0.25, 0.25, n_lines)[line] * step
        y = y0 + (k + phase - 0.5) * step
        frac = (y - y0) / H
        zig = np.where(line % 2 == 0, frac, 1 - frac) - 0.5
        x = line * step + shift + zig * step * 0.5
        x = x + rng.normal(0, 0.05 * step, x.size)
        y = y + rng.normal(0, 0.05 * step, y.size)
        keep = (x >= 0) & (x <= W) & (y >= y0) & (y <= y1)
        x, y, line = x[keep], y[keep], line[keep]
        plane = np.stack([x, np.full(x.size, y_fl), np.full(x.size, zm + altitude)], axis=1)
        target = np.stack([x, y, np.full(x.size, zm)], axis=1)
        d = target - plane
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        gps = 1000.0 * s + line * 0.01 + (y - y0) / H * 0.009
        parts.append((plane, d, gps, np.full(x.size, s, dtype=np.int64)))
    return tuple(np.concatenate(a) for a in zip(*parts))


def _simulate(spec, *, density, sigma, rng, altitude, noise_fraction, name, extra_meta):
    terrain = spec["terrain"]
    reg = FaceRegistry()
    buildings = [_Building(reg, i + 1, b, terrain) for i, b in enumerate(spec["buildings"])]
    cars = []
    for k, car in enumerate(spec["cars"]):
        cx, cy = car["center"]
        zc = float(terrain.z(np.array([cx]), np.array([cy]))[0])
        hl, hw, h = car["half_size"][0], car["half_size"][1], car["height"]
        cars.append(Box(reg, f"car{k + 1}", (cx, cy, zc - 0.3 + (h + 0.3) / 2),
                        _rot(math.radians(car.get("angle", 0.0))), (hl, hw, (h + 0.3) / 2)))
    objects = [b.solid for b in buildings] + cars
    faces = reg.faces
    role = {}
    fid_building = {}
    for b in buildings:
        for fid, r in b.face_roles(faces).items():
            role[fid] = r
            fid_building[fid] = b.id
    # roof plane table: one id per roof face, in building order
    roof_fids = [fid for fid in range(len(faces)) if role.get(fid) == "roof"]
    plane_of_face = np.zeros(len(faces) + 1, dtype=np.int32)
    for pid, fid in enumerate(roof_fids, start=1):
        plane_of_face[fid] = pid
    trees = spec["trees"]
    o, d, gps, strip = _pulses(spec["extent"], density, altitude, terrain, rng,
                               spec.get("strips", 1))
    P = o.shape[0]
    t_ter = terrain.hit(o, d)
    index = _RayIndex(o, d, float(np.median(o[:, 2] + t_ter * d[:, 2])))
    t_obj, _, code = _first_solid_hits(objects, index)
    on_obj = t_obj < t_ter
    t_surf = np.where(on_obj, t_obj, t_ter)
    surf_face = np.where(on_obj, np.abs(code) - 1, -1)
    t_in, t_out, tid = _ellipsoid_hits(trees, index)
    t_in = np.maximum(t_in, 0.0)
    foliage = np.array([tr.get("foliage", _CROWN_EXT) for tr in trees] + [_CROWN_EXT])
    lam = foliage[tid]
    crown_end = np.minimum(t_out, t_surf)
    # vegetation echoes: up to three, exponential free paths, >= _MIN_SEP apart
    veg_t = np.full((P, 3), np.inf)
    cur = t_in.copy()
    active = np.isfinite(t_in) & (t_in < t_surf)
    for j in range(3):
        step_ = rng.exponential(1.0, P) / lam
        cand = cur + step_
        ok = active & (cand < crown_end)
        veg_t[ok, j] = cand[ok]
        cur = np.where(ok, cand + _MIN_SEP, cur + step_)
        active = ok
    n_veg = np.isfinite(veg_t).sum(axis=1)
    path = np.where(np.isfinite(t_in) & (t_in < t_surf), crown_end - t_in, 0.0)
    blocked = rng.uniform(size=P) > np.exp(-0.35 * lam * path)  # no energy left for the surface
    last_veg = np.where(n_veg > 0, veg_t[np.arange(P), np.maximum(n_veg - 1, 0)], -np.inf)
    surf_ok = ~blocked & np.isfinite(t_surf) & (t_surf - last_veg >= _MIN_SEP)
    n_ret = n_veg + surf_ok
    # echo list: (pulse, t, kind) kind 0 vegetation, 1 surface
    pv, jv = np.nonzero(np.isfinite(veg_t))
    ps = np.flatnonzero(surf_ok)
    pulse = np.concatenate([pv, ps])
    t_echo = np.concatenate([veg_t[pv, jv], t_surf[ps]])
    is_veg = np.concatenate([np.ones(pv.size, bool), np.zeros(ps.size, bool)])
    order = np.lexsort((t_echo, pulse))
    pulse, t_echo, is_veg = pulse[order], t_echo[order], is_veg[order]
    first = np.r_[True, pulse[1:] != pulse[:-1]]
    start = np.flatnonzero(first)
    rn = np.arange(pulse.size) - np.repeat(start, np.diff(np.r_[start, pulse.size]))
    ret_num = (rn + 1).astype(np.uint8)
    nor = n_ret[pulse].astype(np.uint8)
    xyz_true = o[pulse] + t_echo[:, None] * d[pulse]
    dirs = d[pulse]
    x, y = xyz_true[:, 0], xyz_true[:, 1]
    gz = terrain.z(x, y)
    hag = xyz_true[:, 2] - gz
    face = np.where(is_veg, -1, surf_face[pulse])
    on_terrain = ~is_veg & (face < 0)
    # classes, materials
    cls = np.zeros(pulse.size, dtype=np.uint8)
    mat = np.zeros(pulse.size, dtype=np.uint8)
    road = spec["road_mask"](x, y)
    soil = spec["soil_mask"](x, y)
    cls[on_terrain] = np.where(road[on_terrain], 11, 2)
    mat[on_terrain] = np.where(road[on_terrain], 3, np.where(soil[on_terrain], 2, 1))
    cls[is_veg] = np.where(hag[is_veg] < 0.5, 3, np.where(hag[is_veg] < 2.0, 4, 5))
    mat[is_veg] = 10
    fid = np.where(face >= 0, face, len(faces))
    frole = np.array([role.get(i, "car") for i in range(len(faces))] + ["none"])
    r = frole[fid]
    is_bld = np.isin(r, ("roof", "wall", "chimney"))
    is_car = (r == "car") & (face >= 0)
    cls[is_bld] = 6
    cls[is_car] = 1
    bmat = np.zeros(len(faces) + 1, dtype=np.uint8)
    for b in buildings:
        for fi in b.face_roles(faces):
            bmat[fi] = b.material
    mat[is_bld] = np.where(r[is_bld] == "roof", bmat[fid[is_bld]],
                           np.where(r[is_bld] == "chimney", 8, 7))
    mat[is_car] = 9
    roof_plane = np.where(face >= 0, plane_of_face[fid], 0).astype(np.int32)
    bld_of_face = np.zeros(len(faces) + 1, dtype=np.int32)
    for fi, bi in fid_building.items():
        bld_of_face[fi] = bi
    building_id = np.where(is_bld, bld_of_face[fid], 0).astype(np.int32)
    tree_id = np.where(is_veg, tid[pulse] + 1, 0).astype(np.int32)
    # truth normals and curvatures
    normal = np.full((pulse.size, 3), np.nan)
    K = np.full(pulse.size, np.nan)
    H = np.full(pulse.size, np.nan)
    nt, Kt, Ht = terrain.truth(x[on_terrain], y[on_terrain])
    normal[on_terrain], K[on_terrain], H[on_terrain] = nt, Kt, Ht
    solid_pts = face >= 0
    fn = np.array([faces[i]["normal"] for i in face[solid_pts]]).reshape(-1, 3)
    normal[solid_pts] = fn
    K[solid_pts] = 0.0
    H[solid_pts] = 0.0
    # noise points: isolated pulses far below / above the surface
    n_noise = int(round(noise_fraction * pulse.size))
    kk = rng.integers(0, P, n_noise)
    hi = rng.uniform(size=n_noise) < 0.5
    tn = np.where(hi, t_surf[kk] - rng.uniform(15, 60, n_noise),
                  t_ter[kk] + rng.uniform(1.5, 8, n_noise))
    pn = o[kk] + tn[:, None] * d[kk]
    # incidence and intensity
    cosi = np.where(np.isnan(normal[:, 0]), 1.0, np.abs(np.einsum("ij,ij->i", normal, dirs)))
    share = np.where(is_veg, 0.6 / np.maximum(nor, 1), 1.0 / np.maximum(nor, 1) ** 0.5)
    refl_mean = np.array([MATERIALS[k][1] for k in range(len(MATERIALS))])
    refl_sd = np.array([MATERIALS[k][2] for k in range(len(MATERIALS))])
    refl = np.clip(refl_mean[mat] + refl_sd[mat] * rng.standard_normal(mat.size), 0.01, 1)
    rng_echo = t_echo
    inten = (_ENERGY_SCALE * refl * cosi * (altitude / rng_echo) ** 2 * share
             * rng.lognormal(0.0, 0.12, mat.size))
    # assemble with the noise points
    xyz_true = np.concatenate([xyz_true, pn])
    dirs = np.concatenate([dirs, d[kk]])
    t_all = np.concatenate([t_echo, tn])
    gz_n = terrain.z(pn[:, 0], pn[:, 1])
    hag = np.concatenate([hag, pn[:, 2] - gz_n])
    cls = np.concatenate([cls, np.full(n_noise, 7, np.uint8)])
    mat = np.concatenate([mat, np.full(n_noise, 11, np.uint8)])
    inten = np.concatenate([inten, _ENERGY_SCALE * rng.uniform(0.01, 0.2, n_noise)
                            * (altitude / tn) ** 2])
    ret_num = np.concatenate([ret_num, np.ones(n_noise, np.uint8)])
    nor = np.concatenate([nor, np.ones(n_noise, np.uint8)])
    pulse_all = np.concatenate([pulse, P + np.arange(n_noise)])
    gps_all = np.concatenate([gps[pulse], gps[kk] + 1e-7])
    strip_all = np.concatenate([strip[pulse], strip[kk]])
    org = np.concatenate([o[pulse], o[kk]])
    pad = np.full(n_noise, np.nan)
    normal = np.concatenate([normal, np.full((n_noise, 3), np.nan)])
    K, H = np.concatenate([K, pad]), np.concatenate([H, pad])
    face = np.concatenate([face, np.full(n_noise, -1)])
    roof_plane = np.concatenate([roof_plane, np.zeros(n_noise, np.int32)])
    building_id = np.concatenate([building_id, np.zeros(n_noise, np.int32)])
    tree_id = np.concatenate([tree_id, np.zeros(n_noise, np.int32)])
    # time order (pulse order, then return number)
    order = np.lexsort((ret_num, gps_all))
    noise = sigma * rng.standard_normal(t_all.size)
    xyz = xyz_true + noise[:, None] * dirs
    scan_angle = np.degrees(np.arctan2(xyz_true[:, 1] - org[:, 1], org[:, 2]
                                       - xyz_true[:, 2]))
    # edge distances of building points to the creases of their building
    edge = np.full(t_all.size, np.nan)
    creases = {}
    for b in buildings:
        creases[b.id] = crease_lines(b.solid)
        m = building_id == b.id
        if m.any():
            edge[m] = distance_to_creases(xyz_true[m], creases[b.id])
    kmin, kmax = principal_curvatures(K, H)
    # plane table
    tbl_n = np.array([faces[f]["normal"] for f in roof_fids]).reshape(-1, 3)
    tbl_d = np.array([np.dot(faces[f]["normal"], faces[f]["point"]) for f in roof_fids])
    plane_counts = np.bincount(roof_plane, minlength=len(roof_fids) + 1)[1:]
    meta = dict(extra_meta)
    meta.update({
        "scene": name, "units": "m", "density": density, "altitude": altitude,
        "sigma": sigma,
        "roof_planes": {
            "id": np.arange(1, len(roof_fids) + 1, dtype=np.int32),
            "building_id": np.array([fid_building[f] for f in roof_fids], dtype=np.int32),
            "normal": tbl_n, "offset": tbl_d,
            "face": np.array(roof_fids, dtype=np.int64),
            "name": [faces[f]["name"] for f in roof_fids],
            "n_points": plane_counts.astype(np.int64),
        },
        "buildings": [{"id": b.id, "roof": b.spec["roof"], "footprint": b.footprint,
                       "eave_z": b.eave_z, "ridge_z": b.ridge_z, "base_z": b.base,
                       "n_dormers": len(b.spec.get("dormers", [])),
                       "n_chimneys": len(b.spec.get("chimneys", []))} for b in buildings],
        "footprints": [b.footprint for b in buildings],
        "trees": [dict(t, id=k + 1) for k, t in enumerate(trees)],
        "cars": spec["cars"], "roads": spec["roads"],
        "face_names": [f["name"] for f in faces], "faces": faces,
        "edges": creases, "materials": {k: v[0] for k, v in MATERIALS.items()},
        "classes": ASPRS_CLASSES, "terrain": terrain, "n_pulses": P,
        "solids": objects, "pulse_origin": o, "pulse_direction": d,
        "xyz_true": xyz_true[order],
        "edge_distance": "building points: exact 3-D distance to the nearest crease of "
                         "their building (meta['edges'][building_id]); NaN elsewhere",
    })
    fields = {
        "true_class": cls[order], "roof_plane": roof_plane[order],
        "building_id": building_id[order], "height_above_ground": hag[order],
        "material": mat[order], "tree_id": tree_id[order], "pulse_id": pulse_all[order],
        "range": t_all[order],
    }
    attributes = {
        "intensity": np.clip(np.round(inten[order]), 0, 65535).astype(np.uint16),
        "return_number": ret_num[order], "number_of_returns": nor[order],
        "classification": cls[order],
        "scan_angle": np.round(scan_angle[order] / 0.006).astype(np.int16),
        "gps_time": gps_all[order],
        "point_source_id": (strip_all[order] + 1).astype(np.uint16),
    }
    Ko, Ho = K[order] + 0.0, H[order] + 0.0
    st = surface_type_from_curvature(Ko, Ho)
    return SyntheticCloud(
        xyz=xyz[order], normal=normal[order], K=Ko, H=Ho, kmin=kmin[order] + 0.0,
        kmax=kmax[order] + 0.0, surface_type=st, face=face[order].astype(np.int32),
        edge_distance=edge[order], sigma=float(sigma), scanner=None, name=name, meta=meta,
        fields=fields, attributes=attributes)


# ------------------------------------------------------------------------ scenes
def _strip_mask(roads):
    def mask(x, y):
        m = np.zeros(np.shape(x), dtype=bool)
        for r in roads:
            (x0, y0), (x1, y1) = r["axis"]
            v = np.array([x1 - x0, y1 - y0])
            L = np.linalg.norm(v)
            u = v / L
            s = (x - x0) * u[0] + (y - y0) * u[1]
            q = -(x - x0) * u[1] + (y - y0) * u[0]
            m |= (s >= 0) & (s <= L) & (np.abs(q) <= r["width"] / 2)
        return m
    return mask


def _soil_mask(x, y):
    return (np.sin(x / 6.0 + 0.7) * np.sin(y / 7.5 + 0.3) > 0.55)


def _check_common(func, density, sigma, altitude, noise_fraction):
    density = check_scalar(density, "density", func=func, low=0.5, high=100.0,
                           closed="both")
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0, high=1.0, closed="both")
    altitude = check_scalar(altitude, "altitude", func=func, low=50.0, high=5000.0,
                            closed="both")
    noise_fraction = check_scalar(noise_fraction, "noise_fraction", func=func, low=0.0,
                                  high=0.1, closed="both")
    return density, sigma, altitude, noise_fraction


def make_als_town(*, extent=(160.0, 120.0), density=8.0, sigma=0.03, rng=None,
                  layout_seed=0, altitude=500.0, noise_fraction=0.002,
                  strips=1) -> SyntheticCloud:
    """Airborne scan of a small town with exact truth (module docstring).

    The town: a main road along x through the middle (8 m wide) and a cross road along
    y (7 m); four blocks of lots with buildings whose roofs cycle through gable, hip,
    flat, L-shaped (four planes), gable with one or two dormers, and hip with a chimney
    (chimneys also on some gables), rotated up to 10 degrees off the road directions;
    trees in the gardens (every third building has one whose crown overhangs its roof),
    shrubs, cars parked along the roads; terrain rising about 3 % in x and 1 % in y with
    a 1.2 m undulation.  With the defaults about 150,000 points in 3 s.

    Parameters
    ----------
    extent : (float, float)
        Size (m) of the area in x and y (origin at (0, 0)); at least 60 x 60.
    density : float
        Pulses per square metre (2-15 is realistic; echoes from trees add points).
    sigma : float
        Range noise std (m), along each pulse.
    rng : numpy.random.Generator or int or None
        Random source of the scan (pulse jitter, echoes, noise, intensities).
    layout_seed : int
        Seed of the town layout: the same layout for every `rng`.
    altitude : float
        Flying height above the mean terrain (m); every strip's swath must stay within
        +/- 20 degrees of nadir (checked).
    noise_fraction : float
        Outlier points per echo (half far below the surface, half above).
    strips : int
        Number of parallel flight lines along x, evenly spread across y, each covering
        its share of the extent plus 30 % overlap with its neighbours (overlap zones get
        twice the density, as in real surveys); ``point_source_id`` is the strip
        number (1, 2, ...), GPS times of strip s start at 1000 s.

    Returns
    -------
    SyntheticCloud
        ``attributes``: ``intensity`` (uint16), ``return_number``, ``number_of_returns``,
        ``classification`` (ASPRS truth: 2 ground, 11 road, 6 building, 3/4/5 vegetation
        below 0.5 m / 0.5-2 m / above 2 m over the terrain, 1 cars, 7 noise),
        ``scan_angle`` (int16, 0.006 degree units), ``gps_time``, ``point_source_id``.
        ``fields``: ``true_class`` (copy of the class), ``roof_plane`` (0 = not on a
        roof plane; chimneys, walls and dormer cheeks/fronts are 0, dormer roof faces
        are planes), ``building_id`` (0 = none), ``height_above_ground``, ``material``
        (codes in :data:`MATERIALS`), ``tree_id``, ``pulse_id``, ``range``.
        ``normal``, ``K``, ``H`` are exact on the terrain (analytic height field) and on
        faces (planes: K = H = 0), NaN on vegetation and noise; ``face`` indexes
        ``meta["faces"]`` (-1 for terrain, vegetation and noise); ``edge_distance`` is
        the exact distance of building points to their building's creases (NaN
        elsewhere).  ``meta``: ``roof_planes`` (dict of arrays over planes: ``id``,
        ``building_id``, unit upward ``normal``, ``offset`` d with ``normal . x = d``,
        ``face``, ``name``, ``n_points``), ``buildings`` (``id``, ``roof``,
        ``footprint`` polygon (k, 2), heights, counts), ``footprints``, ``trees``
        (``center``, ``radius``, ``half_height``, ``overhangs`` = building ids),
        ``cars``, ``roads`` (``axis`` end points, ``width``), ``materials``,
        ``classes``, ``edges`` (creases per building id), ``xyz_true``, ``terrain``
        (``terrain.z(x, y)``), ``solids`` (the CSG solids of the buildings, then the
        cars), ``pulse_origin`` / ``pulse_direction`` (per ``pulse_id``, noise points
        excluded).

    Examples
    --------
    >>> c = make_als_town(extent=(60, 60), density=2, rng=0)
    >>> {2, 6, 11} <= set(c.attributes["classification"].tolist())
    True
    """
    func = "make_als_town"
    density, sigma, altitude, noise_fraction = _check_common(func, density, sigma, altitude,
                                                             noise_fraction)
    ext = np.asarray(extent, dtype=np.float64).ravel()
    if ext.size != 2 or not np.all(np.isfinite(ext)) or np.any(ext < 60) or np.any(ext > 2000):
        raise InvalidParameterError(f"The 'extent' parameter of {func} must be a pair of "
                                    f"sizes in [60, 2000] m. Got {extent!r} instead.")
    W, Hy = float(ext[0]), float(ext[1])
    strips = check_scalar(strips, "strips", func=func, low=1, high=20, closed="both",
                          integer=True)
    half = max(max(yf - y0, y1 - yf) for y0, y1, yf in _strip_bands(Hy, strips, 0.3))
    if half > altitude * math.tan(math.radians(20.0)):
        raise InvalidParameterError(f"{func}: the swath at altitude {altitude} m does not "
                                    f"cover {Hy} m across the track within 20 degrees "
                                    f"with {strips} strip(s)")
    if W * Hy * density * (1 + 0.3 * (strips > 1)) > 3e7:
        raise InvalidParameterError(f"{func}: {W:.0f} x {Hy:.0f} m at {density} pulses per "
                                    "square metre is too many pulses (> 30 million)")
    lay = np.random.default_rng(layout_seed)
    terrain = _Terrain(100.0, 0.03, 0.01, 1.2, 140.0, 110.0)
    ym, xm = Hy / 2, W / 2
    roads = [{"axis": ((0.0, ym), (W, ym)), "width": 8.0, "name": "main"},
             {"axis": ((xm, 0.0), (xm, Hy)), "width": 7.0, "name": "cross"}]
    road_mask = _strip_mask(roads)
    roofs = ["gable", "hip", "flat", "L", "gable_dormer", "hip_chimney"]
    buildings, trees, cars = [], [], []
    lot = (23.0, 20.0)
    for qx0, qx1 in ((0.0, xm - 3.5), (xm + 3.5, W)):
        for qy0, qy1, side in ((0.0, ym - 4.0, -1), (ym + 4.0, Hy, 1)):
            nx = max(int((qx1 - qx0 - 4) // lot[0]), 1)
            ny = max(int((qy1 - qy0 - 4) // lot[1]), 1)
            for i in range(nx):
                for j in range(ny):
                    cx = qx0 + 2 + (i + 0.5) * (qx1 - qx0 - 4) / nx
                    cy = qy0 + 2 + (j + 0.5) * (qy1 - qy0 - 4) / ny
                    if lay.uniform() < 0.12:
                        continue
                    kind = roofs[len(buildings) % len(roofs)]
                    roof = kind.split("_")[0]
                    a = lay.uniform(5.0, 8.0) if roof != "L" else lay.uniform(6.0, 8.0)
                    b = lay.uniform(3.5, min(5.0, a - 1.0))
                    eave = lay.uniform(3.0, 7.0)
                    pitch = math.radians(lay.uniform(25, 42))
                    ridge = eave + b * math.tan(pitch) if roof != "flat" else eave
                    spec = {"center": (cx, cy), "half_size": (a, b), "roof": roof,
                            "eave": eave, "ridge": ridge,
                            "angle": lay.uniform(-10, 10) + (90.0 if lay.uniform() < 0.3
                                                             and roof != "L" else 0.0),
                            "material": int(lay.choice([4, 4, 5])) if roof != "flat" else 6}
                    if roof == "L":
                        spec["wing"] = lay.uniform(3.0, 5.0)
                        spec["half_size"] = (a, min(b, a / 2 - 0.5))
                    if kind == "gable_dormer":
                        nd = 1 + int(lay.uniform() < 0.5)
                        xs = [0.0] if nd == 1 else [-a / 2, a / 2]
                        # A dormer (front 0.9 + rise 0.5 above the roof at 0.3 b from
                        # the eave) must stay 0.2 below the ridge: low roofs get none.
                        if 0.7 * (ridge - eave) > 1.4 + 0.2 + 0.05:
                            spec["dormers"] = [{"x": xd, "width": 1.8, "setback": 0.3 * b,
                                                "front": 0.9, "rise": 0.5} for xd in xs]
                    if kind == "hip_chimney" or (roof == "gable" and lay.uniform() < 0.5):
                        spec["chimneys"] = [{"x": lay.uniform(-a / 3, a / 3),
                                             "y": 0.4 * b, "size": 0.7, "height": 0.6}]
                    buildings.append(spec)
    # trees: one overhanging tree for every third building, others in gardens
    tmp_reg = FaceRegistry()
    blds = [_Building(tmp_reg, k + 1, s, terrain) for k, s in enumerate(buildings)]
    for k, b in enumerate(blds):
        if k % 3 != 0:
            continue
        corner = b.footprint[0]
        cen = b.footprint.mean(0)
        u = (corner - cen) / np.linalg.norm(corner - cen)
        rad = lay.uniform(3.0, 4.0)
        p = corner + u * 0.6 * rad
        gz = float(terrain.z(np.array([p[0]]), np.array([p[1]]))[0])
        hh = lay.uniform(2.5, 3.5)
        top = b.ridge_z + lay.uniform(1.0, 3.0)
        trees.append({"center": (p[0], p[1], top - hh), "radius": rad, "half_height": hh,
                      "ground": gz})
    tries = 0
    n_want = max(6, len(blds)) + len(blds) // 3 + len(blds)
    while len(trees) < n_want and tries < 4000:
        tries += 1
        p = lay.uniform((3, 3), (W - 3, Hy - 3))
        rad = lay.uniform(1.5, 4.0)
        if road_mask(np.array([p[0]]), np.array([p[1]]))[0]:
            continue
        if any(b.inside(np.array([p[0]]), np.array([p[1]]), margin=rad)[0] for b in blds):
            continue
        if abs(p[1] - ym) < 4 + rad or abs(p[0] - xm) < 3.5 + rad:
            continue
        gz = float(terrain.z(np.array([p[0]]), np.array([p[1]]))[0])
        if lay.uniform() < 0.5:  # shrub: dense foliage
            hh = lay.uniform(0.2, 0.8)
            trees.append({"center": (p[0], p[1], gz + hh), "radius": lay.uniform(0.8, 1.8),
                          "half_height": hh, "ground": gz, "foliage": 1.5})
        else:
            hh = lay.uniform(2.0, 4.0)
            trees.append({"center": (p[0], p[1], gz + lay.uniform(4.0, 9.0) + hh),
                          "radius": rad, "half_height": hh, "ground": gz})
    for tr in trees:
        c = np.array(tr["center"][:2])
        tr["overhangs"] = [b.id for b in blds if b.inside(c[None, 0], c[None, 1],
                                                            margin=tr["radius"])[0]
                           and tr["center"][2] - tr["half_height"] < b.ridge_z + 3]
    # cars parked along both sides of both roads
    for r in roads:
        (x0, y0), (x1, y1) = r["axis"]
        L = math.hypot(x1 - x0, y1 - y0)
        u = np.array([x1 - x0, y1 - y0]) / L
        nrm = np.array([-u[1], u[0]])
        ang = math.degrees(math.atan2(u[1], u[0]))
        s = 4.0
        while s < L - 4.0:
            s += lay.uniform(6.0, 20.0)
            if s > L - 4:
                break
            side = 1 if lay.uniform() < 0.5 else -1
            p = np.array([x0, y0]) + s * u + side * (r["width"] / 2 - 1.3) * nrm
            if abs(p[0] - xm) < 6 and abs(p[1] - ym) < 6:
                continue  # keep the crossing free
            cars.append({"center": (float(p[0]), float(p[1])), "half_size": (2.2, 0.9),
                         "height": float(lay.uniform(1.4, 1.7)), "angle": ang})
    spec = {"terrain": terrain, "extent": (W, Hy), "buildings": buildings, "trees": trees,
            "cars": cars, "roads": roads, "road_mask": road_mask, "soil_mask": _soil_mask,
            "strips": strips}
    rng = np.random.default_rng(rng)
    return _simulate(spec, density=density, sigma=sigma, rng=rng, altitude=altitude,
                     noise_fraction=noise_fraction, name="als_town",
                     extra_meta={"extent": (W, Hy), "layout_seed": layout_seed,
                                 "strips": _strip_bands(Hy, strips, 0.3)})


def make_hip_roof_scene(*, density=15.0, sigma=0.03, rng=None, altitude=400.0,
                        noise_fraction=0.001) -> SyntheticCloud:
    """The first data set of Crosilla, Visintini and Sepic (seed 002, section 6).

    A 46 x 44 m area scanned at 15 points per square metre (the 2004 Gorizia flight):
    a building with a four-plane hip roof (18 m east-west by 20 m north-south, eaves 7 m,
    pitch 30 degrees; planes North, East, South, West with two chimneys on the North and
    South planes) beside a two-plane gable house (12 x 9 m, ridge east-west), a tree
    whose crown overhangs the gable house, a garden (soil and grass), a road along the
    south side with two parked cars, a few shrubs (low vegetation).  About 30,000 points
    (the paper: 29,662).  Roof planes of the hip roof are ``meta["roof_planes"]`` ids 1-4
    named ``b1_main_roof_north``, ``..._east``, ``..._south``, ``..._west`` (also in
    ``meta["hip_planes"]``: compass name -> id).

    Parameters
    ----------
    density, sigma, rng, altitude, noise_fraction
        As for :func:`make_als_town`.

    Returns
    -------
    SyntheticCloud
        Same fields as :func:`make_als_town`.

    Examples
    --------
    >>> c = make_hip_roof_scene(density=2, rng=0)
    >>> sorted(c.meta["hip_planes"])
    ['East', 'North', 'South', 'West']
    """
    func = "make_hip_roof_scene"
    density, sigma, altitude, noise_fraction = _check_common(func, density, sigma, altitude,
                                                             noise_fraction)
    terrain = _Terrain(50.0, 0.01, 0.005, 0.2, 90.0, 70.0)
    W, Hy = 46.0, 44.0
    # local x of the hip house along the world y (north-south), so the long roof planes
    # face east and west
    b_w = 9.0
    hip = {"center": (14.0, 24.0), "half_size": (10.0, b_w), "roof": "hip", "eave": 7.0,
           "ridge": 7.0 + b_w * math.tan(math.radians(30.0)), "angle": 90.0,
           "material": 4,
           "chimneys": [{"x": 5.5, "y": 0.0, "size": 0.8, "height": 0.8},
                        {"x": -5.0, "y": -2.5, "size": 0.6, "height": 0.8}]}
    gable = {"center": (36.0, 26.0), "half_size": (6.0, 4.5), "roof": "gable", "eave": 5.0,
             "ridge": 5.0 + 4.5 * math.tan(math.radians(35.0)), "angle": 0.0,
             "material": 4}
    roads = [{"axis": ((0.0, 4.0), (W, 4.0)), "width": 7.0, "name": "road"}]
    trees = [{"center": (29.0, 33.0, 59.0), "radius": 4.0, "half_height": 3.5},
             {"center": (40.0, 14.0, 51.2), "radius": 1.2, "half_height": 0.7,
              "foliage": 1.5},
             {"center": (43.0, 16.0, 50.9), "radius": 1.0, "half_height": 0.4,
              "foliage": 1.5}]
    cars = [{"center": (12.0, 5.5), "half_size": (2.2, 0.9), "height": 1.5, "angle": 0.0},
            {"center": (30.0, 2.5), "half_size": (2.3, 0.95), "height": 1.6, "angle": 180.0}]
    for tr in trees:
        tr["overhangs"] = []
        tr["ground"] = float(terrain.z(np.array(tr["center"][:1]),
                                       np.array(tr["center"][1:2]))[0])
    trees[0]["overhangs"] = [2]

    def soil(x, y):  # the garden east of the gable house
        return (x > 32) & (x < 45) & (y > 11) & (y < 19)

    spec = {"terrain": terrain, "extent": (W, Hy), "buildings": [hip, gable],
            "trees": trees, "cars": cars, "roads": roads, "road_mask": _strip_mask(roads),
            "soil_mask": soil}
    rng = np.random.default_rng(rng)
    c = _simulate(spec, density=density, sigma=sigma, rng=rng, altitude=altitude,
                  noise_fraction=noise_fraction, name="hip_roof",
                  extra_meta={"extent": (W, Hy), "paper_table6": {
                      "North": (644, 1993, 1220), "East": (749, 1777, 1511),
                      "South": (664, 2022, 1069), "West": (517, 2398, 1601)}})
    # compass names of the hip planes from their normals
    rp = c.meta["roof_planes"]
    names = {}
    for pid, bid, n in zip(rp["id"], rp["building_id"], rp["normal"]):
        if bid != 1:
            continue
        ang = math.degrees(math.atan2(n[1], n[0])) % 360
        names[["East", "North", "West", "South"][int(((ang + 45) % 360) // 90)]] = int(pid)
    c.meta["hip_planes"] = names
    return c
