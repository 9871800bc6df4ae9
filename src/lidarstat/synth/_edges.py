"""True crease lines of a CSG solid and exact point-to-crease distances.

A *crease* is a curve where two faces of the solid's boundary meet at an angle.  For the
primitives of :mod:`lidarstat.synth._csg` (convex polyhedra, boxes, finite cylinders)
every crease lies on

* the intersection line of two face planes (straight edges), or
* a circle where a plane perpendicular to a cylinder's axis cuts its side (cap rims,
  a tank standing on the ground, a pipe entering a wall at right angles).

Candidates are cut into pieces at every crossing with another face surface (plane or
cylinder side), so that, along a piece, the solid looks the same.  A piece is a crease
when, at its midpoint ``q``, exactly one or exactly three of the four wedge points
``q + eps (s1 n1 + s2 n2)`` (``s1, s2 = +/-1``, ``n1, n2`` the normals of the two
surfaces) are inside the solid: one for a convex edge, three for a concave one (two
means the surfaces continue smoothly or one of them is not a boundary there, zero or four
that the candidate is not on the boundary).  Straight pieces are therefore exact;
circles are classified on 1440 sample angles, so the end angles of a partial arc are
exact to 2*pi/1440 (full circles, the usual case, are exact).

The faces meeting at a crease are identified by probing: on each of the two surfaces, a
point ``eps`` away from the crease on the side where that surface is a boundary is hit by
a short ray from outside, whose entry face code is the face id.
"""

from __future__ import annotations

import numpy as np

__all__ = ["crease_lines", "distance_to_creases"]

_PROBE = 1e-5  # distance from a crease of the probe points (scene units: metres)
_WEDGE = 1e-6
_ARC_SAMPLES = 1440


def _unit_rows(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _surfaces(solid):
    """Planes (normal, offset, face id) and cylinder sides of the solid's primitives."""
    faces = solid.registry.faces
    prims = solid.primitives() if hasattr(solid, "primitives") else [solid]
    planes, cyls = [], []
    for prim in prims:
        for attr in ("face_ids", "cap_top", "cap_bottom"):
            ids = np.atleast_1d(getattr(prim, attr, np.empty(0, dtype=int))).ravel()
            for fid in ids:
                f = faces[int(fid)]
                n = np.asarray(f["normal"], float)
                planes.append((n, float(n @ np.asarray(f["point"], float)), int(fid)))
        if hasattr(prim, "side"):
            cyls.append(prim)
    return planes, cyls


def _wedge_count(solid, q, n1, n2, eps=_WEDGE):
    cnt = np.zeros(q.shape[0], dtype=np.int64)
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            cnt += solid.contains(q + eps * (s1 * n1 + s2 * n2))
    return cnt


def _probe_faces(solid, x, n):
    """Face id of the boundary at points `x` lying on surfaces of normal `n`; -1 if the
    surface is not a boundary of the solid at `x`."""
    a = solid.contains(x + _WEDGE * n)
    b = solid.contains(x - _WEDGE * n)
    out = np.full(x.shape[0], -1, dtype=np.int64)
    bnd = a != b
    if not bnd.any():
        return out
    n_out = np.where(a[:, None], -n, n)[bnd]
    o = x[bnd] + 100 * _WEDGE * n_out
    iv = solid.ray_intervals(o, -n_out)
    t0 = np.where(iv.t0 > 0, iv.t0, np.inf)
    k = np.argmin(t0, axis=1)
    code = iv.f0[np.arange(o.shape[0]), k]
    out[bnd] = np.abs(code) - 1
    return out


def _side_faces(solid, q, n, u):
    """Face of the surface with normal `n` beside the crease at `q`, on side +u or -u."""
    f_plus = _probe_faces(solid, q + _PROBE * u, n)
    f_minus = _probe_faces(solid, q - _PROBE * u, n)
    return np.where(f_plus >= 0, f_plus, f_minus)


def _straight_creases(solid, planes, cyls, lo, hi):
    # distinct geometric planes (n, d) up to sign
    geo = {}
    for n, d, _ in planes:
        k = int(np.argmax(np.abs(n)))
        sg = 1.0 if n[k] > 0 else -1.0
        key = tuple(np.round(np.r_[sg * n, sg * d], 9))
        geo.setdefault(key, (sg * n, sg * d))
    N = np.array([g[0] for g in geo.values()]).reshape(-1, 3)
    D = np.array([g[1] for g in geo.values()])
    I, J = np.triu_indices(N.shape[0], k=1)
    ell = np.cross(N[I], N[J])
    norm = np.linalg.norm(ell, axis=1)
    ok = norm > 1e-9
    I, J, ell = I[ok], J[ok], ell[ok] / norm[ok, None]
    if I.size == 0:
        return []
    A = np.stack([N[I], N[J], ell], axis=1)
    rhs = np.stack([D[I], D[J], np.zeros(I.size)], axis=1)[..., None]
    p0 = np.linalg.solve(A, rhs)[..., 0]
    # Every pair of planes is a candidate, even when three or more planes share a line:
    # which two of them are the faces meeting there can change from piece to piece (a
    # roof, its fascia and the top plane of the wall behind the fascia share the eave
    # line; keeping one pair per line lost the roof-fascia crease).  A piece is kept
    # below only where both planes are boundaries beside it, and repeated pieces are
    # dropped at the end.
    # clip to the bounding box
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - p0) / ell, (hi - p0) / ell
    par = np.abs(ell) < 1e-15
    out_par = np.any(par & ((p0 < lo) | (p0 > hi)), axis=1)
    t_lo = np.max(np.where(par, -np.inf, np.minimum(ta, tb)), axis=1)
    t_hi = np.min(np.where(par, np.inf, np.maximum(ta, tb)), axis=1)
    keep = ~out_par & (t_hi > t_lo)
    I, J, ell, p0, t_lo, t_hi = I[keep], J[keep], ell[keep], p0[keep], t_lo[keep], t_hi[keep]
    if I.size == 0:
        return []
    # crossings with every plane and cylinder, clipped to [t_lo, t_hi]
    den = ell @ N.T
    with np.errstate(divide="ignore", invalid="ignore"):
        T = [np.where(np.abs(den) > 1e-12, (D[None, :] - p0 @ N.T) / den, np.nan)]
        for c in cyls:
            w = p0 - c.center
            wa, la = w @ c.axis, ell @ c.axis
            wp, lp = w - wa[:, None] * c.axis, ell - la[:, None] * c.axis
            a2 = np.einsum("ij,ij->i", lp, lp)
            b2 = np.einsum("ij,ij->i", wp, lp)
            c2 = np.einsum("ij,ij->i", wp, wp) - c.radius ** 2
            disc = b2 * b2 - a2 * c2
            okc = (a2 > 1e-12) & (disc >= 0)
            sq = np.sqrt(np.where(okc, disc, 0.0))
            axial = np.abs(la) > 1e-12
            T.append(np.stack([np.where(okc, (-b2 - sq) / a2, np.nan),
                               np.where(okc, (-b2 + sq) / a2, np.nan),
                               np.where(axial, (-c.length / 2 - wa) / la, np.nan),
                               np.where(axial, (c.length / 2 - wa) / la, np.nan)], axis=1))
    T = np.concatenate(T + [t_lo[:, None], t_hi[:, None]], axis=1)
    T = np.clip(T, t_lo[:, None], t_hi[:, None])
    T = np.sort(np.where(np.isnan(T), np.inf, T), axis=1)
    a, b = T[:, :-1], T[:, 1:]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(b) & (b - a > 1e-9)
    li, ci = np.nonzero(valid)  # pieces, in order along each line
    ta_, tb_ = a[li, ci], b[li, ci]
    ell_p, p0_p = ell[li], p0[li]
    q = p0_p + 0.5 * (ta_ + tb_)[:, None] * ell_p
    na, nb = N[I[li]], N[J[li]]
    cnt = _wedge_count(solid, q, na, nb)
    keep = (cnt == 1) | (cnt == 3)
    li, q, na, nb, cnt = li[keep], q[keep], na[keep], nb[keep], cnt[keep]
    ell_p, p0_p, ta_, tb_ = ell_p[keep], p0_p[keep], ta_[keep], tb_[keep]
    fa = _side_faces(solid, q, na, _unit_rows(np.cross(ell_p, na)))
    fb = _side_faces(solid, q, nb, _unit_rows(np.cross(ell_p, nb)))
    out, lines, seen = [], [], set()
    for k in range(q.shape[0]):
        if fa[k] < 0 or fb[k] < 0 or fa[k] == fb[k]:
            continue  # one of the planes is not a face beside this piece
        f = tuple(sorted((int(fa[k]), int(fb[k]))))
        key = (f, tuple(np.round(q[k], 9)))
        if key in seen:
            continue  # the same piece from another pair of planes through its line
        seen.add(key)
        start, end = p0_p[k] + ta_[k] * ell_p[k], p0_p[k] + tb_[k] * ell_p[k]
        if (out and lines[-1] == li[k] and out[-1]["faces"] == f
                and np.allclose(out[-1]["vertices"][1], start, atol=1e-9)):
            out[-1]["vertices"][1] = end
            continue
        out.append({"kind": "segment", "faces": f, "convex": bool(cnt[k] == 1),
                    "vertices": np.stack([start, end]), "direction": ell_p[k].copy()})
        lines.append(li[k])
    return out


def _circle_creases(solid, planes, cyls):
    out = []
    phi = (np.arange(_ARC_SAMPLES) + 0.5) * (2 * np.pi / _ARC_SAMPLES)
    for c in cyls:
        a = c.axis
        u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(a, u)
        s_vals = {}
        for n, d, _ in planes:
            if abs(abs(n @ a) - 1.0) < 1e-12:
                s = (d - n @ c.center) / (n @ a)
                if abs(s) <= c.length / 2 + 1e-12:
                    s_vals.setdefault(round(float(s), 9), float(s))
        radial = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
        for s in s_vals.values():
            centre = c.center + s * a
            q = centre + c.radius * radial
            na = np.broadcast_to(a, q.shape)
            cnt = _wedge_count(solid, q, na, radial)
            ok = (cnt == 1) | (cnt == 3)
            if not ok.any():
                continue
            fp = _side_faces(solid, q, na, radial)  # plane: inside or outside the circle
            fc = _side_faces(solid, q, radial, na)
            key = np.where(ok, fp * 1_000_003 + fc, -1)
            # runs of equal keys along the circle (wrapping around)
            if np.all(key == key[0]):
                runs = [(0, _ARC_SAMPLES)] if key[0] >= 0 else []
            else:
                start = int(np.argmax(key != np.roll(key, 1)))
                kk = np.roll(key, -start)
                cuts = np.r_[0, np.flatnonzero(kk[1:] != kk[:-1]) + 1, _ARC_SAMPLES]
                runs = [(start + b0, start + b1) for b0, b1 in zip(cuts[:-1], cuts[1:])
                        if kk[b0] >= 0]
            step = 2 * np.pi / _ARC_SAMPLES
            for b0, b1 in runs:
                i0 = b0 % _ARC_SAMPLES
                full = (b1 - b0) == _ARC_SAMPLES
                phi0, phi1 = (0.0, 2 * np.pi) if full else (b0 * step, b1 * step)
                tt = np.linspace(phi0, phi1, max(int((phi1 - phi0) / step) + 1, 2))
                verts = centre + c.radius * (np.cos(tt)[:, None] * u + np.sin(tt)[:, None] * v)
                out.append({"kind": "arc", "faces": tuple(sorted((int(fp[i0]), int(fc[i0])))),
                            "convex": bool(cnt[i0] == 1), "vertices": verts,
                            "center": centre, "axis": a.copy(), "radius": c.radius,
                            "u": u.copy(), "v": v.copy(), "phi0": phi0, "phi1": phi1})
    return out


def crease_lines(solid) -> list[dict]:
    """Every crease of a CSG solid (module docstring).

    Parameters
    ----------
    solid : Box, Cylinder, Polyhedron or a union / difference of them

    Returns
    -------
    list of dict
        One dict per crease: ``kind`` ("segment" or "arc"), ``faces`` (sorted pair of face
        ids of the solid's registry), ``convex`` (bool: True for a salient edge, False for a
        re-entrant one), ``vertices`` ((2, 3) end points of a segment, or (m, 3) points
        along an arc every 0.25 degree).  Arcs also carry ``center``, ``axis``, ``radius``,
        ``u``, ``v`` (in-plane unit vectors) and ``phi0 <= phi1`` (the arc is
        ``center + radius (cos(phi) u + sin(phi) v)``); segments carry ``direction``.
    """
    planes, cyls = _surfaces(solid)
    lo, hi = solid.bounds()
    pad = 1e-6 * max(1.0, float(np.max(hi - lo)))
    return (_straight_creases(solid, planes, cyls, lo - pad, hi + pad)
            + _circle_creases(solid, planes, cyls))


def distance_to_creases(p, creases) -> np.ndarray:
    """Exact 3-D distance of points `p` (N, 3) to the nearest crease of `creases`.

    Segments: distance to the closed segment; arcs: distance to the circle when the
    point's azimuth about the axis lies within the arc, else to the nearer arc end.
    Returns +inf when there are no creases.
    """
    p = np.asarray(p, dtype=np.float64)
    best = np.full(p.shape[0], np.inf)
    for cr in creases:
        if cr["kind"] == "segment":
            a, b = cr["vertices"]
            ab = b - a
            t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
            d = np.linalg.norm(p - a - t[:, None] * ab, axis=1)
        else:
            w = p - cr["center"]
            h = w @ cr["axis"]
            x, y = w @ cr["u"], w @ cr["v"]
            rho = np.hypot(x, y)
            ang = np.mod(np.arctan2(y, x) - cr["phi0"], 2 * np.pi)
            within = ang <= (cr["phi1"] - cr["phi0"]) + 1e-15
            d_in = np.hypot(h, rho - cr["radius"])
            ends = cr["vertices"][[0, -1]]
            d_end = np.min(np.linalg.norm(p[:, None, :] - ends[None], axis=2), axis=1)
            d = np.where(within, d_in, d_end)
        np.minimum(best, d, out=best)
    return best
