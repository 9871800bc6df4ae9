"""The airborne scan simulation: pulses along flight lines, ray casting and echoes.

Each pulse is a ray from the aircraft: its last echo is the first hit on the terrain, a
building or a car (exact ray casting); on its way it may cross tree crowns, which give up
to three earlier echoes (see :mod:`lidarstat.synth._als` for the model).
"""

from __future__ import annotations

import math

import numpy as np

from ._als_geometry import (
    _CROWN_EXT,
    _ENERGY_SCALE,
    _MIN_SEP,
    ASPRS_CLASSES,
    MATERIALS,
    _Building,
    _rot,
)
from ._csg import Box, FaceRegistry, _aabb_hit
from ._edges import crease_lines, distance_to_creases
from ._truth import SyntheticCloud, principal_curvatures, surface_type_from_curvature


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
