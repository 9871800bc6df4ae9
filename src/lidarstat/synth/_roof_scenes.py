"""Small airborne scenes of houses for building and roof-plane tests (exact truth).

Each scene is a handful of houses on a gently sloping terrain with a road along its
south side, scanned by one flight line (the scan model of
:func:`~lidarstat.synth.make_als_town`: exact ray casting, range noise, up to three
vegetation echoes per pulse, occlusion by crowns).  The houses are chosen to hold the
cases that defeat building classifiers and roof-plane segmentations:

* gable, hip and flat roofs, an L-shaped house (two gables meeting in a valley);
* gable dormers (each dormer roof face is a small plane of a few square metres);
* steep roof planes (50-62 degrees) and the small triangular end planes of short hip
  roofs;
* a large low flat roof (about 24 x 16 m, 3.5-4.5 m high), which a ground filter
  easily takes for terrain;
* trees *next to* a house (the crown touches the wall, its top between the eave and
  2 m above the ridge), trees *over* a roof (the crown overhangs a corner, as in
  :func:`~lidarstat.synth.make_als_town`), free-standing trees and shrubs.

Every tree dict in ``meta["trees"]`` carries its ``role`` (``"next"``, ``"over"``,
``"free"`` or ``"shrub"``) and the house it belongs to (``house``, 0 for none).
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_option, check_scalar
from ._als_geometry import _Building, _Terrain
from ._als_scan import _simulate
from ._csg import FaceRegistry
from ._truth import SyntheticCloud

__all__ = ["make_roof_scene", "ROOF_SCENE_KINDS"]

#: scene kinds of :func:`make_roof_scene`
ROOF_SCENE_KINDS = ("mixed", "gable", "hip", "flat", "dormers", "steep")


def _house(lay, roof, *, pitch=(25.0, 42.0), size=((5.0, 8.0), (3.5, 5.0)),
           eave=(3.0, 6.5), dormers=0, chimney=False, material=None):
    a = lay.uniform(*size[0])
    b = lay.uniform(size[1][0], min(size[1][1], a - 0.5))
    e = lay.uniform(*eave)
    p = math.radians(lay.uniform(*pitch))
    ridge = e + b * math.tan(p) if roof != "flat" else e
    spec = {"half_size": (a, b), "roof": roof, "eave": e, "ridge": ridge,
            "angle": lay.uniform(-15.0, 15.0) + (90.0 if lay.uniform() < 0.3 else 0.0),
            "material": material if material is not None
            else (int(lay.choice([4, 4, 5])) if roof != "flat" else 6)}
    if roof == "L":
        spec["wing"] = lay.uniform(3.0, 5.0)
        spec["half_size"] = (a, min(b, a / 2 - 0.5))
        spec["angle"] = lay.uniform(-15.0, 15.0)
    if dormers:
        # a dormer (front 0.9 + rise 0.5 above the roof at 0.3 b from the eave) must stay
        # 0.2 below the ridge: raise the pitch until it fits
        rise = ridge - e
        need = (0.9 + 0.5 + 0.2 + 0.05) / 0.7
        if rise < need:
            spec["ridge"] = e + need + 0.1
        xs = [0.0] if dormers == 1 else [-a / 2, a / 2]
        spec["dormers"] = [{"x": xd, "width": 1.8, "setback": 0.3 * b, "front": 0.9,
                            "rise": 0.5} for xd in xs]
    if chimney:
        spec["chimneys"] = [{"x": lay.uniform(-a / 3, a / 3), "y": 0.4 * b, "size": 0.7,
                             "height": 0.6}]
    return spec


def _houses(kind, lay):
    steep = {"pitch": (50.0, 62.0), "size": ((3.5, 5.5), (2.5, 3.5))}
    if kind == "gable":
        return [_house(lay, "gable") for _ in range(4)]
    if kind == "hip":
        return [_house(lay, "hip", chimney=k % 2 == 1) for k in range(4)]
    if kind == "flat":
        return [_house(lay, "flat", size=((11.0, 12.5), (7.0, 8.5)), eave=(3.5, 4.5)),
                _house(lay, "flat"), _house(lay, "flat", eave=(6.0, 9.0)),
                _house(lay, "flat", size=((3.0, 4.0), (2.5, 3.0)), eave=(2.6, 3.2))]
    if kind == "dormers":
        return [_house(lay, "gable", dormers=1 + k % 2, pitch=(35.0, 45.0),
                       size=((5.5, 8.0), (4.0, 5.0))) for k in range(4)]
    if kind == "steep":
        return [_house(lay, "gable", **steep), _house(lay, "hip", **steep),
                _house(lay, "hip", pitch=(45.0, 55.0), size=((4.0, 4.6), (3.5, 4.0))),
                _house(lay, "gable", **steep)]
    return [_house(lay, "gable", chimney=True),
            _house(lay, "hip"),
            _house(lay, "flat", size=((11.0, 12.5), (7.0, 8.5)), eave=(3.5, 4.5)),
            _house(lay, "gable", dormers=2, pitch=(35.0, 45.0),
                   size=((6.0, 8.0), (4.0, 5.0))),
            _house(lay, "gable", **steep),
            _house(lay, "L", size=((6.0, 8.0), (3.5, 5.0))),
            _house(lay, "hip", pitch=(45.0, 55.0), size=((4.0, 4.6), (3.5, 4.0)),
                   chimney=True)]


def _layout(specs, terrain, y_road):
    """Place the houses in rows (west to east, then north) with room for trees."""
    x, y, row_h, per_row = 3.0, y_road + 7.0, 0.0, 3
    placed = []
    for k, s in enumerate(specs):
        a, b = s["half_size"]
        r = math.hypot(a, b + s.get("wing", 0.0))
        if k and k % per_row == 0:
            x, y, row_h = 3.0, y + row_h, 0.0
        s["center"] = (x + r + 3.0, y + r + 3.0)
        x += 2 * r + 6.0
        row_h = max(row_h, 2 * r + 6.0)
        placed.append(s)
    width = max(s["center"][0] + math.hypot(*s["half_size"]) + s.get("wing", 0.0)
                for s in placed) + 7.0
    return placed, (width, y + row_h + 3.0)


def make_roof_scene(kind="mixed", *, density=10.0, sigma=0.03, rng=None, layout_seed=0,
                    trees=True, altitude=400.0, noise_fraction=0.0) -> SyntheticCloud:
    """Airborne scan of a few houses with exact building and roof-plane truth.

    Parameters
    ----------
    kind : str
        One of :data:`ROOF_SCENE_KINDS`: ``"mixed"`` (seven houses: gable with a
        chimney, hip, large low flat roof, gable with two dormers, steep gable, L-shaped
        house, short steep hip with a chimney), or four houses of one family:
        ``"gable"``, ``"hip"``, ``"flat"`` (one large and low, one tall, one small and
        low), ``"dormers"`` (one or two dormers each), ``"steep"`` (50-62 degree planes
        and short hip roofs with small end planes).
    density : float
        Pulses per square metre.
    sigma : float
        Range noise std (m).
    rng : numpy.random.Generator or int or None
        Random source of the scan.
    layout_seed : int
        Seed of the house sizes, pitches, rotations and trees.
    trees : bool
        Add trees next to and over the houses, free-standing trees and shrubs.
    altitude : float
        Flying height above the terrain (m).
    noise_fraction : float
        Outlier points per echo.

    Returns
    -------
    SyntheticCloud
        The fields, attributes and meta of :func:`~lidarstat.synth.make_als_town`
        (``classification`` is the exact ASPRS truth, ``roof_plane`` and
        ``building_id`` the exact plane and house of every point), with
        ``meta["kind"]`` and each tree's ``role`` and ``house``.

    Examples
    --------
    >>> c = make_roof_scene("gable", density=4, rng=0)
    >>> int((c.attributes["classification"] == 6).sum()) > 500
    True
    """
    func = "make_roof_scene"
    kind = check_option(kind, "kind", ROOF_SCENE_KINDS, func=func)
    density = check_scalar(density, "density", func=func, low=0.5, high=60.0,
                           closed="both")
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0, high=0.5, closed="both")
    altitude = check_scalar(altitude, "altitude", func=func, low=150.0, high=5000.0,
                            closed="both")
    noise_fraction = check_scalar(noise_fraction, "noise_fraction", func=func, low=0.0,
                                  high=0.1, closed="both")
    lay = np.random.default_rng(layout_seed)
    terrain = _Terrain(20.0, 0.012, 0.006, 0.3, 90.0, 70.0)
    y_road = 4.0
    specs, extent = _layout(_houses(kind, lay), terrain, y_road)
    W, Hy = extent
    roads = [{"axis": ((0.0, y_road), (W, y_road)), "width": 6.0, "name": "road"}]
    cars = [{"center": (x, y_road - 1.5), "half_size": (2.2, 0.9),
             "height": float(lay.uniform(1.4, 1.7)), "angle": 0.0}
            for x in (0.3 * W, 0.7 * W)]
    tree_list = []
    if trees:
        reg = FaceRegistry()
        blds = [_Building(reg, k + 1, s, terrain) for k, s in enumerate(specs)]
        for k, b in enumerate(blds):
            cen = b.footprint.mean(0)
            if k % 2 == 0:  # a crown over a corner of the roof
                corner = b.footprint[(k // 2) % len(b.footprint)]
                u = (corner - cen) / np.linalg.norm(corner - cen)
                rad = lay.uniform(2.5, 3.5)
                p = corner + u * 0.6 * rad
                hh = lay.uniform(2.0, 3.0)
                top = b.ridge_z + lay.uniform(1.0, 2.5)
                role = "over"
            else:  # a crown touching a long wall
                a, bb = b.spec["half_size"]
                side = 1.0 if lay.uniform() < 0.5 else -1.0
                rad = lay.uniform(2.0, 3.0)
                off = b.R[:2, :2] @ np.array([lay.uniform(-a / 2, a / 2),
                                              side * (bb + rad + 0.3)])
                p = cen + off
                hh = lay.uniform(1.5, 2.5)
                top = lay.uniform(b.eave_z + 1.0, b.ridge_z + 2.0)
                role = "next"
            gz = float(terrain.z(p[None, 0], p[None, 1])[0])
            tree_list.append({"center": (float(p[0]), float(p[1]),
                                         max(top - hh, gz + 2.5 + hh) if role == "next"
                                         else top - hh),
                              "radius": rad, "half_height": hh, "ground": gz,
                              "role": role, "house": b.id})
        tries = 0
        n_free = len(blds) // 2 + 2
        while sum(t["role"] in ("free", "shrub") for t in tree_list) < n_free and tries < 2000:
            tries += 1
            p = lay.uniform((3.0, y_road + 5.0), (W - 3.0, Hy - 3.0))
            shrub = lay.uniform() < 0.4
            rad = lay.uniform(0.8, 1.6) if shrub else lay.uniform(1.5, 3.5)
            if any(b.inside(p[None, 0], p[None, 1], margin=rad + 1.0)[0] for b in blds):
                continue
            if any(math.hypot(p[0] - t["center"][0], p[1] - t["center"][1])
                   < rad + t["radius"] for t in tree_list):
                continue
            gz = float(terrain.z(p[None, 0], p[None, 1])[0])
            if shrub:
                hh = lay.uniform(0.3, 0.8)
                tree_list.append({"center": (p[0], p[1], gz + hh), "radius": rad,
                                  "half_height": hh, "ground": gz, "foliage": 1.5,
                                  "role": "shrub", "house": 0})
            else:
                hh = lay.uniform(2.0, 3.5)
                tree_list.append({"center": (p[0], p[1], gz + lay.uniform(3.0, 7.0) + hh),
                                  "radius": rad, "half_height": hh, "ground": gz,
                                  "role": "free", "house": 0})
        for tr in tree_list:
            c = np.array(tr["center"][:2])
            tr["overhangs"] = [b.id for b in blds
                               if b.inside(c[None, 0], c[None, 1], margin=tr["radius"])[0]
                               and tr["center"][2] - tr["half_height"] < b.ridge_z + 3]

    def soil(x, y):
        return np.sin(x / 5.0 + 0.4) * np.sin(y / 6.0 + 0.9) > 0.6

    def road_mask(x, y):
        return np.abs(np.asarray(y) - y_road) <= 3.0

    spec = {"terrain": terrain, "extent": (W, Hy), "buildings": specs,
            "trees": tree_list, "cars": cars, "roads": roads, "road_mask": road_mask,
            "soil_mask": soil}
    return _simulate(spec, density=density, sigma=sigma, rng=np.random.default_rng(rng),
                     altitude=altitude, noise_fraction=noise_fraction,
                     name=f"roof_scene_{kind}",
                     extra_meta={"extent": (W, Hy), "layout_seed": layout_seed,
                                 "kind": kind})
