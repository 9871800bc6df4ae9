"""Terrestrial laser scans (spherical angular grid from a scanner) of CSG solids.

A scanner at ``s`` sends one ray per node of an (elevation, azimuth) grid with the same
angular step in both directions, ``d = (cos e cos a, cos e sin a, sin e)``.  The first
entry point of the ray into the solid (the smallest positive entry parameter of its
interval list) is the true sample; rays that miss or whose hit lies beyond ``max_range``
give no point.  The measured point moves along the ray by Gaussian range noise of std
``sigma(r) = a + b r`` (``range_sigma = (a, b)``).  The density of the samples on a
surface therefore falls as ``cos(incidence) / (r^2 step^2)``, as for a real scanner.

Per point truth (all from the noise-free hit):

* ``face``, ``normal`` (outward = toward the scanner), ``K``, ``H``, ``kmin``,
  ``kmax`` from the face's analytic surface;
* ``edge_distance``: exact distance to the nearest crease of the solid
  (:func:`lidarstat.synth._edges.crease_lines`, segments and circular arcs);
* ``boundary_distance``: distance to where the surface *visible from this station*
  ends (silhouettes, occlusion shadows, openings, free borders, the scan window);
  see :func:`scan_spherical`;
* ``range``, ``incidence`` (angle between the ray and the normal, radians),
  ``row`` / ``col`` (grid node), ``station`` (index into ``meta["scanners"]``),
  ``range_sigma`` (the std used for this point).
"""

from __future__ import annotations

import math

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ._csg import _face_truth
from ._edges import crease_lines, distance_to_creases
from ._truth import SyntheticCloud, surface_type_from_curvature

__all__ = ["scan_spherical"]

_CHUNK = 65536
_BISECT = 18  # bisection steps refining a border between two grid rays


def _directions(az, el):
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def _first_hits(solid, origin, d):
    """Parameter and signed face code of the first entry (t > 0) of rays from `origin`."""
    M = d.shape[0]
    t = np.full(M, np.inf)
    code = np.zeros(M, dtype=np.int64)
    for s in range(0, M, _CHUNK):
        dd = d[s:s + _CHUNK]
        o = np.broadcast_to(origin, dd.shape)
        iv = solid.ray_intervals(np.ascontiguousarray(o), dd)
        t0 = np.where(iv.t0 > 0, iv.t0, np.inf)
        k = np.argmin(t0, axis=1)
        r = np.arange(dd.shape[0])
        t[s:s + _CHUNK] = t0[r, k]
        code[s:s + _CHUNK] = np.where(np.isfinite(t0[r, k]), iv.f0[r, k], 0)
    return t, code


def _cast(solid, origin, az, el, max_range):
    d = _directions(az, el)
    t, code = _first_hits(solid, origin, d)
    hit = np.isfinite(t) & (code != 0) & (t <= max_range)
    face = np.where(hit, np.abs(code) - 1, -1)
    return d, t, face, code


def _grid_neighbour_pairs(shape, wrap):
    """Index pairs (a, b) of 8-neighbour grid nodes, each unordered pair once."""
    nr, nc = shape
    idx = np.arange(nr * nc).reshape(nr, nc)
    out = []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = idx[max(0, -dr):nr - max(0, dr), :]
        rows = np.arange(a.shape[0]) + max(0, -dr) + dr
        if wrap:
            b = idx[rows][:, (np.arange(nc) + dc) % nc]
        else:
            c0, c1 = max(0, -dc), nc - max(0, dc)
            a = a[:, c0:c1]
            b = idx[rows][:, c0 + dc:c1 + dc]
        out.append(np.stack([a.ravel(), b.ravel()], axis=1))
    return np.concatenate(out)


def _borders(solid, origin, az, el, face, t, step, max_range, wrap):
    """Boundary flags of grid nodes and refined border points (see scan_spherical)."""
    nr, nc = face.shape
    f = face.ravel()
    pairs = _grid_neighbour_pairs((nr, nc), wrap)
    pairs = pairs[f[pairs[:, 0]] != f[pairs[:, 1]]]
    pairs = np.concatenate([pairs, pairs[:, ::-1]])
    pairs = pairs[f[pairs[:, 0]] >= 0]  # oriented from a hit node
    A, B = pairs[:, 0], pairs[:, 1]
    AZ, EL = np.broadcast_to(az[None, :], (nr, nc)).ravel(), np.broadcast_to(
        el[:, None], (nr, nc)).ravel()
    aza, ela, azb, elb = AZ[A].copy(), EL[A].copy(), AZ[B].copy(), EL[B].copy()
    if wrap:  # neighbours across the 0 / 2 pi seam
        azb = np.where(azb - aza > np.pi, azb - 2 * np.pi, azb)
        azb = np.where(aza - azb > np.pi, azb + 2 * np.pi, azb)
    fa = f[A]
    ta, tb = t.ravel()[A].copy(), t.ravel()[B].copy()
    fb = f[B].copy()
    for _ in range(_BISECT):
        azm, elm = 0.5 * (aza + azb), 0.5 * (ela + elb)
        _, tm, fm, _ = _cast(solid, origin, azm, elm, max_range)
        same = fm == fa
        aza, ela, ta = np.where(same, azm, aza), np.where(same, elm, ela), np.where(same, tm, ta)
        azb, elb = np.where(same, azb, azm), np.where(same, elb, elm)
        tb, fb = np.where(same, tb, tm), np.where(same, fb, fm)
    pa = origin + ta[:, None] * _directions(aza, ela)
    pb = origin + np.where(fb >= 0, tb, 0.0)[:, None] * _directions(azb, elb)
    gap = step * 0.5 ** _BISECT
    tol = 100.0 * ta * gap + 1e-6
    jump = (fb < 0) | (np.linalg.norm(pa - pb, axis=1) > tol)
    flag = np.zeros(nr * nc, dtype=bool)
    flag[A[jump]] = True
    # the scan window ends the visible surface too (not across the azimuth seam)
    win = np.zeros((nr, nc), dtype=bool)
    win[[0, -1], :] = True
    if not wrap:
        win[:, [0, -1]] = True
    win = win.ravel() & (f >= 0)
    flag |= win
    w_idx = np.flatnonzero(win)
    pw = origin + t.ravel()[w_idx, None] * _directions(AZ[w_idx], EL[w_idx])
    border_pts = np.concatenate([pa[jump], pw])
    border_face = np.concatenate([fa[jump], f[w_idx]])
    return flag.reshape(nr, nc), border_pts, border_face


def _distance_to_borders(p, border_pts):
    from scipy.spatial import cKDTree

    if border_pts.shape[0] == 0:
        return np.full(p.shape[0], np.inf)
    return cKDTree(border_pts).query(p)[0]


def _scan_station(solid, faces, scanner, az_rng, el_rng, step, max_range):
    n_az = int(math.floor((az_rng[1] - az_rng[0]) / step + 1e-9)) + 1
    wrap = az_rng[1] - az_rng[0] >= 2 * np.pi - 1.5 * step
    if wrap:
        n_az = int(round(2 * np.pi / step))
        step_az = 2 * np.pi / n_az
    else:
        step_az = step
    n_el = int(math.floor((el_rng[1] - el_rng[0]) / step + 1e-9)) + 1
    if n_az * n_el > 20_000_000:
        raise InvalidParameterError(
            f"scan_spherical: {n_az} x {n_el} rays is too many; increase `step` or narrow "
            "the azimuth / elevation windows")
    az = az_rng[0] + step_az * np.arange(n_az)
    el = el_rng[0] + step * np.arange(n_el)
    AZ, EL = np.meshgrid(az, el)
    d, t, face, code = _cast(solid, scanner, AZ.ravel(), EL.ravel(), max_range)
    hit = face >= 0
    p = scanner + t[hit, None] * d[hit]
    fid = face[hit]
    flipped = code[hit] < 0
    normal, K, H, kmin, kmax = _face_truth(faces.faces, fid, flipped, p)
    cosi = -np.einsum("ij,ij->i", normal, d[hit])
    front = cosi > 1e-9  # grazing hits (rounding) are dropped
    flag, bpts, _ = _borders(solid, scanner, az, el, np.where(hit, face, -1).reshape(
        n_el, n_az), np.where(hit, t, np.inf).reshape(n_el, n_az), step, max_range, wrap)
    rows, cols = np.divmod(np.flatnonzero(hit), n_az)
    sel = front
    p, fid = p[sel], fid[sel]
    out = {
        "xyz_true": p, "face": fid, "normal": normal[sel], "K": K[sel], "H": H[sel],
        "kmin": kmin[sel], "kmax": kmax[sel], "range": t[hit][sel],
        "incidence": np.arccos(np.clip(cosi[sel], -1.0, 1.0)),
        "row": rows[sel].astype(np.int32), "col": cols[sel].astype(np.int32),
        "direction": d[hit][sel],
        "boundary": flag.ravel()[hit][sel],
    }
    out["boundary_distance"] = _distance_to_borders(p, bpts)
    grid = {"azimuth0": float(az[0]), "elevation0": float(el[0]), "step_azimuth": step_az,
            "step_elevation": step, "shape": (n_el, n_az), "wrap": bool(wrap)}
    return out, grid


def _pair_arg(value, name, func):
    v = np.asarray(value, dtype=np.float64).ravel()
    if v.size != 2 or not np.all(np.isfinite(v)) or v[1] <= v[0]:
        raise InvalidParameterError(
            f"The {name!r} parameter of {func} must be a pair (low, high) with low < high. "
            f"Got {value!r} instead.")
    return float(v[0]), float(v[1])


@renamed_parameters(scanner="sensor")
def scan_spherical(solid, *, sensor, azimuth=(-np.pi, np.pi), elevation=(-0.6, 0.6),
                   step=0.003, range_sigma=(0.002, 0.0), max_range=150.0, rng=None,
                   reflectance=None, name="tls_scan", meta=None) -> SyntheticCloud:
    """Terrestrial laser scan of a CSG solid from one or several scanner stations.

    Parameters
    ----------
    solid : Box, Cylinder, Polyhedron or a union / difference of them
        The scene; all its primitives must share one :class:`FaceRegistry`.
    sensor : array_like, shape (3,) or (S, 3)
        Scanner position(s).  With several stations the scans are concatenated and
        ``fields["station"]`` tells them apart.
    azimuth : (float, float) or sequence of them
        Azimuth window (radians from +x, counter-clockwise), one per station or one for
        all.  A window of 2 pi is a full turn (the grid wraps around).
    elevation : (float, float) or sequence of them
        Elevation window (radians above the horizontal).
    step : float
        Angular step (radians) in azimuth and elevation.
    range_sigma : (float, float)
        ``(a, b)``: the range noise std is ``a + b * range``.
    max_range : float
        Hits farther than this are dropped (no return).
    rng : numpy.random.Generator or int or None
        Random source of the range noise and the intensity speckle.
    reflectance : dict of str to float, optional
        Reflectance (0-1) of the faces whose name starts with a key (the longest matching
        key wins); 0.4 for the others.  Used for the simulated ``intensity``.
    name : str
        Scene name stored in the result.
    meta : dict, optional
        Extra entries for ``meta``.

    Returns
    -------
    SyntheticCloud
        Coordinates with range noise and the truth of the module docstring.  ``sensor``
        is the station position with one station, None with several (positions in
        ``meta["scanners"]``, per point in ``fields["station"]``).  ``sigma`` is ``a``.
        ``fields``: ``boundary_distance``, ``boundary`` (uint8: 1 for grid nodes next to
        a border), ``range``, ``incidence``, ``range_sigma``, ``row``, ``col``,
        ``station``.  ``meta``: ``face_names``, ``faces`` (geometry and ``n_points``),
        ``edges`` (list of crease dicts: ``kind``, ``faces``, ``convex``, ``vertices``,
        arcs with ``center``, ``axis``, ``radius``, ``u``, ``v``, ``phi0``, ``phi1``),
        ``edge_segments`` ((S, 2, 3) straight creases) with ``edge_segment_faces``
        ((S, 2)), ``scanners``, ``grids`` (per station: ``azimuth0``, ``elevation0``,
        ``step_azimuth``, ``step_elevation``, ``shape``, ``wrap``), ``xyz_true``,
        ``range_sigma``, ``solid`` (the scene itself: ``solid.contains(p)``,
        ``solid.ray_intervals(o, d)``).  ``attributes``: ``intensity`` (uint16,
        ``50000 reflectance cos(incidence) / (1 + (range / 30)^2)`` times a lognormal
        speckle of 10 %), ``return_number`` = ``number_of_returns`` = 1.

    Notes
    -----
    ``boundary_distance`` is the 3-D distance from the true hit to the nearest *border
    point* of the same station's scan (on any face: what matters for a neighbourhood
    sphere is how far the nearest end of the visible surface is).  Border points are found on the scan grid: for every pair
    of 8-neighbour nodes where the face changes or one ray misses, the angular segment
    between the two rays is bisected 18 times following the first node's face; if the
    far end then misses, or the two hits are still apart by more than
    ``100 r step / 2**18 + 1e-6`` (a jump in range, not a crease), the last point on the
    first node's face is a border point and the node is flagged as ``boundary``.
    Nodes on the first/last row and column of the scan window are border points too
    (except across the seam of a full turn).  Border points are about one grid step apart
    along a border, so the distance is exact at the border and accurate to about half a
    local point spacing near it.  Creases between visible faces are not borders.

    Examples
    --------
    >>> from lidarstat.synth import Box, FaceRegistry
    >>> reg = FaceRegistry()
    >>> box = Box(reg, "box", (5.0, 0.0, 0.0), np.eye(3), (1.0, 1.0, 1.0))
    >>> c = scan_spherical(box, sensor=(0.0, 0.0, 0.0), azimuth=(-0.3, 0.3),
    ...                    elevation=(-0.3, 0.3), step=0.02, range_sigma=(0.0, 0.0))
    >>> sorted({c.meta["face_names"][f] for f in c.face})
    ['box_-x']
    >>> bool(np.allclose(c.xyz[:, 0], 4.0))
    True
    """
    func = "scan_spherical"
    rng = np.random.default_rng(rng)
    faces = solid.registry
    sc = np.asarray(sensor, dtype=np.float64)
    if sc.ndim == 1:
        sc = sc[None, :]
    if sc.ndim != 2 or sc.shape[1] != 3 or not np.all(np.isfinite(sc)) or sc.shape[0] < 1:
        raise InvalidParameterError(f"The 'sensor' parameter of {func} must be a finite "
                                    f"3-vector or (S, 3) array. Got {sensor!r} instead.")
    S = sc.shape[0]

    def per_station(value, pname):
        v = np.asarray(value, dtype=np.float64)
        if v.ndim == 1:
            return [_pair_arg(v, pname, func)] * S
        if v.ndim == 2 and v.shape[0] == S:
            return [_pair_arg(x, pname, func) for x in v]
        raise InvalidParameterError(f"The {pname!r} parameter of {func} must be a pair or "
                                    f"one pair per station. Got {value!r} instead.")

    azs, els = per_station(azimuth, "azimuth"), per_station(elevation, "elevation")
    for lo, hi in els:
        if lo < -np.pi / 2 or hi > np.pi / 2:
            raise InvalidParameterError(f"The 'elevation' parameter of {func} must lie in "
                                        f"[-pi/2, pi/2]. Got {elevation!r} instead.")
    for lo, hi in azs:
        if hi - lo > 2 * np.pi + 1e-9:
            raise InvalidParameterError(f"The 'azimuth' window of {func} must span at most "
                                        f"2 pi. Got {azimuth!r} instead.")
    step = check_scalar(step, "step", func=func, low=1e-5, high=0.5, closed="both")
    rs = np.asarray(range_sigma, dtype=np.float64).ravel()
    if rs.size != 2 or not np.all(np.isfinite(rs)) or np.any(rs < 0):
        raise InvalidParameterError(f"The 'range_sigma' parameter of {func} must be a pair "
                                    f"(a, b) of non-negative floats. Got {range_sigma!r}.")
    max_range = check_scalar(max_range, "max_range", func=func, low=0.0)
    parts, grids = [], []
    for s in range(S):
        part, grid = _scan_station(solid, faces, sc[s], azs[s], els[s], step, max_range)
        part["station"] = np.full(part["face"].shape[0], s, dtype=np.uint8)
        parts.append(part)
        grids.append(grid)
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    creases = crease_lines(solid)
    edge = distance_to_creases(cat["xyz_true"], creases)
    sig = rs[0] + rs[1] * cat["range"]
    noise = sig * rng.standard_normal(sig.size)
    xyz = cat["xyz_true"] + noise[:, None] * cat["direction"]
    counts = np.bincount(cat["face"], minlength=len(faces.faces))
    face_info = [dict(f, id=i, n_points=int(counts[i])) for i, f in enumerate(faces.faces)]
    refl = np.full(len(faces.faces), 0.4)
    for i, f in enumerate(faces.faces):
        keys = [k for k in (reflectance or {}) if f["name"].startswith(k)]
        if keys:
            refl[i] = float(reflectance[max(keys, key=len)])
    for i, f in enumerate(face_info):
        f["reflectance"] = float(refl[i])
    inten = (50000.0 * refl[cat["face"]] * np.cos(cat["incidence"])
             / (1.0 + (cat["range"] / 30.0) ** 2) * rng.lognormal(0.0, 0.1, sig.size))
    attributes = {
        "intensity": np.clip(np.round(inten), 0, 65535).astype(np.uint16),
        "return_number": np.ones(sig.size, np.uint8),
        "number_of_returns": np.ones(sig.size, np.uint8),
    }
    segs = [c for c in creases if c["kind"] == "segment"]
    m = dict(meta or {})
    m.update({
        "scene": name, "units": "m", "face_names": [f["name"] for f in faces.faces],
        "faces": face_info, "edges": creases,
        "edge_segments": (np.array([c["vertices"] for c in segs]) if segs
                          else np.zeros((0, 2, 3))),
        "edge_segment_faces": (np.array([c["faces"] for c in segs], dtype=np.int64)
                               if segs else np.zeros((0, 2), dtype=np.int64)),
        "solid": solid, "scanners": sc.copy(), "grids": grids, "range_sigma": (float(rs[0]), float(rs[1])),
        "step": step, "max_range": max_range, "xyz_true": cat["xyz_true"],
        "edge_distance": "exact 3-D distance to the nearest crease (segments and arcs in "
                         "meta['edges'])",
    })
    K, H = cat["K"] + 0.0, cat["H"] + 0.0
    fields = {
        "boundary_distance": cat["boundary_distance"],
        "boundary": cat["boundary"].astype(np.uint8),
        "range": cat["range"], "incidence": cat["incidence"], "range_sigma": sig,
        "row": cat["row"], "col": cat["col"], "station": cat["station"],
    }
    return SyntheticCloud(
        xyz=xyz, normal=cat["normal"], K=K, H=H, kmin=cat["kmin"] + 0.0,
        kmax=cat["kmax"] + 0.0, surface_type=surface_type_from_curvature(K, H),
        face=cat["face"], edge_distance=edge, sigma=float(rs[0]),
        scanner=sc[0] if S == 1 else None, name=name, meta=m, fields=fields,
        attributes=attributes)
