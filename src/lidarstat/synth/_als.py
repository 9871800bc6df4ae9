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
from ._als_geometry import ASPRS_CLASSES, MATERIALS, _Building, _Terrain
from ._als_scan import _simulate, _strip_bands
from ._csg import FaceRegistry
from ._truth import SyntheticCloud

__all__ = ["make_als_town", "make_hip_roof_scene", "MATERIALS", "ASPRS_CLASSES"]


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
