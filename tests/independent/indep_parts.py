"""Independent scenes of machined parts: flanged and bored parts with 90-degree creases.

Plain NumPy, no import from ``lidarstat``: the parts are unions of analytic faces (bounded
planes and circular cylinders), rigidly placed at a random tilt, and sampled by casting
rays - vertical rays on a regular xy grid for a range image (noise along z), rays on an
(azimuth, elevation) grid from a sensor for a terrestrial scan (noise along the ray). Every
point carries its exact truth: the face it was sampled on, the face's true normal there
and the distance to the nearest true crease line (the circles and segments where two faces
meet).

Parts (local frame, the floor plate z = 0 under the part):

* ``flange``: a flange disc (rim cylinder radius R1, height t1) under a hub (radius R2,
  height h2), optionally bored (a blind bore of radius rb, depth db, in the hub).
* ``block``: a rectangular block with a blind bore in its top face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PLANE, CYLINDER = 0, 1


@dataclass
class Face:
    kind: int  # PLANE or CYLINDER
    # plane: point p0, unit normal n, inside(local xyz) -> bool
    # cylinder: axis along local z through (0, 0); radius r, z range, inward-facing flag
    p0: np.ndarray | None = None
    n: np.ndarray | None = None
    inside: object = None
    r: float = 0.0
    z0: float = 0.0
    z1: float = 0.0
    inward: bool = False


@dataclass
class Part:
    faces: list
    circles: list  # (radius, z) creases about the local z axis
    segments: list  # (a, b) crease segments, local coordinates
    size: float  # half-width of the floor plate

    def crease_distance(self, q):
        """Distance of local points `q` to the nearest crease line."""
        d = np.full(q.shape[0], np.inf)
        rho = np.hypot(q[:, 0], q[:, 1])
        for r, z in self.circles:
            d = np.minimum(d, np.hypot(rho - r, q[:, 2] - z))
        for a, b in self.segments:
            a, b = np.asarray(a, float), np.asarray(b, float)
            ab = b - a
            t = np.clip((q - a) @ ab / (ab @ ab), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(q - (a + t[:, None] * ab), axis=1))
        return d


def _disc(rmin, rmax, z):
    return Face(PLANE, np.array([0, 0, z], float), np.array([0, 0, 1.0]),
                lambda q: (np.hypot(q[:, 0], q[:, 1]) >= rmin)
                & (np.hypot(q[:, 0], q[:, 1]) <= rmax))


def flange_part(rng, spacing):
    """A flange with a hub, bored or not; sizes in units of the point spacing."""
    s = spacing
    r1 = s * rng.uniform(30, 40)
    r2 = r1 * rng.uniform(0.5, 0.65)
    t1 = s * rng.uniform(10, 16)
    h2 = s * rng.uniform(10, 16)
    bored = bool(rng.integers(2))
    rb = r2 * rng.uniform(0.45, 0.6) if bored else 0.0
    db = rb * rng.uniform(0.4, 0.7)
    size = r1 * rng.uniform(1.5, 1.7)
    top = t1 + h2
    faces = [
        Face(PLANE, np.zeros(3), np.array([0, 0, 1.0]),
             lambda q: (np.abs(q[:, :2]).max(axis=1) <= size)
             & (np.hypot(q[:, 0], q[:, 1]) >= r1)),
        Face(CYLINDER, r=r1, z0=0.0, z1=t1),
        _disc(r2, r1, t1),
        Face(CYLINDER, r=r2, z0=t1, z1=top),
        _disc(rb, r2, top),
    ]
    circles = [(r1, 0.0), (r1, t1), (r2, t1), (r2, top)]
    if bored:
        faces += [Face(CYLINDER, r=rb, z0=top - db, z1=top, inward=True),
                  _disc(0.0, rb, top - db)]
        circles += [(rb, top), (rb, top - db)]
    return Part(faces, circles, [], size)


def block_part(rng, spacing):
    """A rectangular block on the floor plate with a blind bore in its top face."""
    s = spacing
    a = s * rng.uniform(25, 35)
    b = s * rng.uniform(20, 30)
    h = s * rng.uniform(12, 18)
    rb = min(a, b) * rng.uniform(0.35, 0.5)
    db = rb * rng.uniform(0.4, 0.7)
    size = max(a, b) * rng.uniform(1.6, 1.8)
    faces = [
        Face(PLANE, np.zeros(3), np.array([0, 0, 1.0]),
             lambda q: (np.abs(q[:, :2]).max(axis=1) <= size)
             & ((np.abs(q[:, 0]) >= a) | (np.abs(q[:, 1]) >= b))),
        Face(PLANE, np.array([a, 0, 0]), np.array([1.0, 0, 0]),
             lambda q: (np.abs(q[:, 1]) <= b) & (q[:, 2] >= 0) & (q[:, 2] <= h)),
        Face(PLANE, np.array([-a, 0, 0]), np.array([-1.0, 0, 0]),
             lambda q: (np.abs(q[:, 1]) <= b) & (q[:, 2] >= 0) & (q[:, 2] <= h)),
        Face(PLANE, np.array([0, b, 0]), np.array([0, 1.0, 0]),
             lambda q: (np.abs(q[:, 0]) <= a) & (q[:, 2] >= 0) & (q[:, 2] <= h)),
        Face(PLANE, np.array([0, -b, 0]), np.array([0, -1.0, 0]),
             lambda q: (np.abs(q[:, 0]) <= a) & (q[:, 2] >= 0) & (q[:, 2] <= h)),
        Face(PLANE, np.array([0, 0, h]), np.array([0, 0, 1.0]),
             lambda q: (np.abs(q[:, 0]) <= a) & (np.abs(q[:, 1]) <= b)
             & (np.hypot(q[:, 0], q[:, 1]) >= rb)),
        Face(CYLINDER, r=rb, z0=h - db, z1=h, inward=True),
        _disc(0.0, rb, h - db),
    ]
    corners = [(a, b), (-a, b), (-a, -b), (a, -b)]
    segs = []
    for i in range(4):
        (x0, y0), (x1, y1) = corners[i], corners[(i + 1) % 4]
        segs += [((x0, y0, 0.0), (x1, y1, 0.0)), ((x0, y0, h), (x1, y1, h)),
                 ((x0, y0, 0.0), (x0, y0, h))]
    return Part(faces, [(rb, h), (rb, h - db)], segs, size)


def _cast(part, o, d):
    """First visible hit of rays o + t d (local frame): t, face id (1-based), normal."""
    m = o.shape[0]
    best = np.full(m, np.inf)
    face = np.zeros(m, dtype=np.int32)
    normal = np.zeros((m, 3))
    for fid, f in enumerate(part.faces, start=1):
        if f.kind == PLANE:
            den = d @ f.n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((f.p0 - o) @ f.n) / den
            ok = (den < 0) & (t > 0) & np.isfinite(t)
            q = o + np.where(ok, t, 0.0)[:, None] * d
            ok &= f.inside(q)
            nn = np.broadcast_to(f.n, (m, 3))
            cand = [(t, ok, nn)]
        else:
            a = d[:, 0] ** 2 + d[:, 1] ** 2
            b = 2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1])
            c = o[:, 0] ** 2 + o[:, 1] ** 2 - f.r ** 2
            disc = b * b - 4 * a * c
            good = (disc >= 0) & (a > 1e-15)
            sq = np.sqrt(np.where(good, disc, 0.0))
            cand = []
            for sgn in (-1.0, 1.0):
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = (-b + sgn * sq) / (2 * np.where(good, a, 1.0))
                q = o + np.where(good, t, 0.0)[:, None] * d
                nn = np.c_[q[:, 0], q[:, 1], np.zeros(m)] / f.r
                if f.inward:
                    nn = -nn
                ok = good & (t > 0) & (q[:, 2] >= f.z0) & (q[:, 2] <= f.z1) \
                    & (np.einsum("ij,ij->i", nn, d) < 0)
                cand.append((t, ok, nn))
        for t, ok, nn in cand:
            win = ok & (t < best)
            best[win] = t[win]
            face[win] = fid
            normal[win] = nn[win]
    return best, face, normal


def _rotation(rng, tilt_deg):
    """A rotation tilting the local z axis by `tilt_deg` toward a random azimuth."""
    az = rng.uniform(0, 2 * np.pi)
    spin = rng.uniform(0, 2 * np.pi)
    t = np.radians(tilt_deg)
    rz = np.array([[np.cos(spin), -np.sin(spin), 0], [np.sin(spin), np.cos(spin), 0],
                   [0, 0, 1.0]])
    ax = np.array([-np.sin(az), np.cos(az), 0.0])  # tilt axis, horizontal
    k = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    rt = np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * (k @ k)
    return rt @ rz


@dataclass
class Scan:
    points: np.ndarray
    face: np.ndarray  # 1-based face id per point
    normal: np.ndarray  # true unit normal (world)
    crease_distance: np.ndarray
    spacing: float
    sigma: float
    noise: str  # 'z' or 'range'
    sensor: np.ndarray | None


def _finish(part, rot, shift, o_loc, d_loc, spacing, sigma, noise, sensor, rng, d_world):
    t, face, normal = _cast(part, o_loc, d_loc)
    hit = np.isfinite(t)
    q = o_loc[hit] + t[hit, None] * d_loc[hit]
    dist = part.crease_distance(q)
    pts = q @ rot.T + shift
    pts = pts + rng.normal(0.0, sigma, hit.sum())[:, None] * d_world[hit]
    return Scan(pts, face[hit], normal[hit] @ rot.T, dist, spacing, sigma, noise, sensor)


def range_image(rng, kind="flange", *, tilt=(25.0, 45.0)):
    """A range image of a part: heights along z on a regular xy grid, noise along z."""
    spacing = rng.uniform(1.0, 2.0)  # millimetres
    part = (flange_part if kind == "flange" else block_part)(rng, spacing)
    rot = _rotation(rng, rng.uniform(*tilt))
    shift = rng.uniform(-1e3, 1e3, 3)
    g = np.arange(-part.size, part.size + spacing / 2, spacing) + rng.uniform(0, spacing)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    top = 10 * part.size
    o = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, top)]
    d = np.broadcast_to(np.array([0, 0, -1.0]), o.shape)
    # the rays in the part's frame: world = rot @ local (+ shift, applied to the points)
    sigma = spacing * rng.uniform(0.03, 0.08)
    return _finish(part, rot, shift, o @ rot, d @ rot, spacing, sigma, "z", None, rng,
                   np.broadcast_to(np.array([0, 0, 1.0]), o.shape))


def tls_scan(rng, kind="flange", *, tilt=(0.0, 20.0)):
    """A terrestrial scan of a part from one station: an (azimuth, elevation) grid of rays,
    noise along the ray."""
    spacing = rng.uniform(1.0, 2.0)
    part = (flange_part if kind == "flange" else block_part)(rng, spacing)
    rot = _rotation(rng, rng.uniform(*tilt))
    shift = rng.uniform(-1e3, 1e3, 3)
    dist = part.size * rng.uniform(3.0, 5.0)
    elev = np.radians(rng.uniform(30, 55))
    az = rng.uniform(0, 2 * np.pi)
    sensor_loc = dist * np.array([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az),
                                  np.sin(elev)])
    step = spacing / dist
    half = np.arctan(1.3 * part.size / dist)
    a = np.arange(-half, half, step)
    e = np.arange(-half, half, step)
    ga, ge = np.meshgrid(a, e, indexing="ij")
    fwd = -sensor_loc / np.linalg.norm(sensor_loc)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    d = (np.cos(ge) * np.cos(ga)).ravel()[:, None] * fwd \
        + (np.cos(ge) * np.sin(ga)).ravel()[:, None] * right + np.sin(ge).ravel()[:, None] * up
    o = np.broadcast_to(sensor_loc, d.shape)
    sigma = spacing * rng.uniform(0.03, 0.08)
    # sensor_loc and d are in the part's frame; the world frame rotates both
    sensor = sensor_loc @ rot.T + shift
    return _finish(part, rot, shift, o, d, spacing, sigma, "range", sensor, rng, d @ rot.T)


def other_face_distance(scan):
    """Distance of every point to the nearest sampled point of another face."""
    from scipy.spatial import cKDTree

    out = np.full(scan.face.size, np.inf)
    for f in np.unique(scan.face):
        on = scan.face == f
        if (~on).any():
            out[on] = cKDTree(scan.points[~on]).query(scan.points[on])[0]
    return out


def edge_scores(scan, edge, reach):
    """Edge precision and recall of a per-point `edge` mask.

    Recall over the points within one spacing of a true crease whose other face is
    sampled there (within two spacings: both faces visible, so every neighbourhood of such
    a point holds points of two faces; a crease whose other face is hidden is the end of
    the visible surface, a boundary); precision over the flagged points: a flagged point
    is right when its neighbourhood (of radius `reach`) holds a point of another face - a
    crease or a depth jump lies in it.
    """
    other = other_face_distance(scan)
    near = (scan.crease_distance < scan.spacing) & (other < 2 * scan.spacing)
    support = other <= reach
    recall = float(edge[near].mean()) if near.any() else np.nan
    precision = float(support[edge].mean()) if edge.any() else np.nan
    return precision, recall


#: Faces of fewer points than this are not scored by Hoover's measure (truth label 0 in
#: :func:`hoover_counts`): a bore's wall seen through its opening is a few dozen points.
MIN_SURFACE = 300


def hoover_counts(scan, labels, threshold=0.8):
    """(correct detections, scored faces) of a segmentation's `labels` against the faces
    of `scan` with at least :data:`MIN_SURFACE` points, at Hoover's `threshold`."""
    from lidarstat.segment import hoover

    cnt = np.bincount(scan.face)
    truth = np.where(cnt[scan.face] >= MIN_SURFACE, scan.face, 0)
    h = hoover(labels, truth, threshold)
    return h.correct, h.n_truth
