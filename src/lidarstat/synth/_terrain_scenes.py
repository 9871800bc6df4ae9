"""Airborne scenes of the hard cases of ground filtering, with exact ground truth.

Each scene is a height field sampled at random planimetric positions (an airborne scan
seen from straight above: the highest surface at a position is the one the pulse hits),
with Gaussian noise along z and one uniform intensity. The truth is whether the surface
hit is terrain:

* ``ramp``: two terrain levels 4 m apart, split by a retaining wall and joined by a 10 m
  wide ramp (15 %); a few buildings;
* ``embankment``: a road embankment 5 m high (top 12 m, sides 1:1.5) across flat terrain;
  a few buildings;
* ``bridge``: a deck 6 m above a road, between two embankments; the deck is an object;
* ``quarry``: a pit 12 m deep cut in three benches (faces 1:0.5, 4 m high);
* ``flat_roof``: one flat roof of 60 x 40 m, 8 m high, wider than any opening window;
* ``platform``: a round plinth 22 m across, 0.8 m above flat terrain on a vertical rim
  (terrain, as a raised square or terrace is), beside a flat-roofed garage 2.5 m high and
  two cars 1.5 m high (objects);
* ``low_objects``: gently sloping terrain (2 %) with low objects 0.25-0.45 m high and
  1-1.5 m wide (low walls, planters, kerbs of raised beds: objects), within the fixed 0.5 m tolerance of a
  ground filter but far above the noise of a dense scan.

:func:`make_garden_scene` is the hard case of building classification: flat-roofed
houses with walls and a garden shed, trees whose crowns stand on trunks beside and over
the roofs (the pulses enter the foliage, some give a second echo below), a clipped hedge
as high as the shed beside a low garden wall; with the returns and the true classes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["GARDEN_PARTS", "TERRAIN_SCENES", "TerrainScene", "make_garden_scene",
           "make_terrain_scene"]

TERRAIN_SCENES = ("ramp", "embankment", "bridge", "quarry", "flat_roof", "platform",
                  "low_objects")


@dataclass(frozen=True)
class TerrainScene:
    """A synthetic airborne cloud with its true ground.

    Attributes
    ----------
    xyz : (N, 3) ndarray
        Coordinates (noise along z).
    intensity : (N,) ndarray
        Intensity (one material: uniform around 100).
    ground : (N,) ndarray of bool
        True when the surface hit is terrain.
    name : str
    meta : dict
        The scene's parameters.
    attributes : dict
        Further per-point arrays where the scene has them (:func:`make_garden_scene`:
        ``number_of_returns``, ``return_number``, ``classification``, ``part``).
    """

    xyz: np.ndarray
    intensity: np.ndarray
    ground: np.ndarray
    name: str
    meta: dict = field(default_factory=dict)
    attributes: dict = field(default_factory=dict)


def _boxes(x, y, boxes):
    """Roof height of flat-roofed boxes ``(x0, x1, y0, y1, height)`` (-inf outside)."""
    h = np.full_like(x, -np.inf)
    for x0, x1, y0, y1, top in boxes:
        inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        h[inside] = np.maximum(h[inside], top)
    return h


def _ramp(x, y):
    upper = 4.0 * (x > 60)
    on_ramp = (np.abs(y - 40) <= 5) & (x > 35) & (x <= 60)
    t = 0.15 * (x - 35)
    ground = np.where(on_ramp, np.minimum(t, 4.0), upper)
    return ground, _boxes(x, y, [(10, 25, 60, 75, 7.0), (75, 90, 5, 20, 10.0)])


def _embankment(x, y):
    d = np.abs(y - 40)
    ground = np.clip(5.0 - (d - 6.0) / 1.5, 0.0, 5.0)
    return ground, _boxes(x, y, [(10, 24, 62, 74, 6.0), (70, 85, 4, 16, 7.0)])


def _bridge(x, y):
    d = np.abs(y - 40)
    emb = np.clip(6.0 - (d - 5.0) / 1.5, 0.0, 6.0)
    road = (np.abs(x - 50) <= 15)
    ground = np.where(road, 0.0, emb)
    deck = road & (d <= 5)
    obj = np.where(deck, 6.0, -np.inf)
    return ground, obj


def _quarry(x, y):
    r = np.hypot(x - 50, y - 40)
    depth = np.zeros_like(r)
    rim = 30.0
    for k in range(3):  # benches: 4 m faces of slope 2 (1:0.5), 4 m wide treads
        face0 = rim - k * 6.0
        depth += np.clip((face0 - r) * 2.0, 0.0, 4.0)
    return -depth, _boxes(x, y, [(2, 10, 2, 10, 5.0)])


def _flat_roof(x, y):
    ground = 0.02 * x
    return ground, _boxes(x, y, [(20, 80, 20, 60, 8.0)])


def _platform(x, y):
    ground = np.where(np.hypot(x - 35, y - 40) <= 11.0, 0.8, 0.0)
    return ground, _boxes(x, y, [(62, 80, 25, 37, 2.5), (65, 67, 55, 59.5, 1.5),
                                 (70, 72, 55, 59.5, 1.5)])


def _low_objects(x, y):
    ground = 0.02 * x + 0.01 * y
    boxes = [(8, 20, 10, 11, 0.3), (30, 31.5, 30, 34, 0.4), (50, 51, 5, 45, 0.25),
             (62, 70, 52, 53.5, 0.45), (75, 90, 20, 21, 0.35), (15, 16, 55, 70, 0.3)]
    top = _boxes(x, y, [(x0, x1, y0, y1, 0.0) for x0, x1, y0, y1, _ in boxes])
    for x0, x1, y0, y1, h in boxes:  # each box's height above the sloping terrain
        inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        top[inside] = ground[inside] + h
    return ground, top


_MAKERS = {"ramp": _ramp, "embankment": _embankment, "bridge": _bridge,
           "quarry": _quarry, "flat_roof": _flat_roof, "platform": _platform,
           "low_objects": _low_objects}


def make_terrain_scene(name: str, *, extent=(100.0, 80.0), density=3.0, sigma=0.05,
                       rng=None) -> TerrainScene:
    """One of :data:`TERRAIN_SCENES`, scanned from above with exact ground truth.

    Parameters
    ----------
    name : str
        Scene name (:data:`TERRAIN_SCENES`).
    extent : (float, float)
        Size of the area in x and y (m), origin at (0, 0).
    density : float
        Points per square metre.
    sigma : float
        Noise std along z (m).
    rng : numpy.random.Generator or int or None
        Random source (positions, noise, intensity).

    Returns
    -------
    TerrainScene

    Examples
    --------
    >>> s = make_terrain_scene("bridge", rng=0)
    >>> bool(0.8 < s.ground.mean() < 0.99)
    True
    """
    if name not in _MAKERS:
        raise ValueError(f"unknown terrain scene {name!r}; expected one of {TERRAIN_SCENES}")
    g = np.random.default_rng(rng)
    n = round(extent[0] * extent[1] * density)
    x = g.uniform(0, extent[0], n)
    y = g.uniform(0, extent[1], n)
    terrain, top = _MAKERS[name](x, y)
    obj = top > terrain
    z = np.where(obj, np.maximum(top, terrain), terrain) + g.normal(0, sigma, n)
    xyz = np.c_[x, y, z + 100.0]
    inten = g.normal(100.0, 8.0, n)
    return TerrainScene(xyz=xyz, intensity=inten, ground=~obj, name=name,
                        meta={"extent": tuple(extent), "density": density, "sigma": sigma})


#: Parts of :func:`make_garden_scene` (``attributes["part"]``) and their ASPRS class.
GARDEN_PARTS = {"terrain": (0, 2), "roof": (1, 6), "wall": (2, 6), "crown": (3, 5),
                "trunk": (4, 5), "hedge": (5, 5), "garden_wall": (6, 1)}
_HOUSES = [(8.0, 20.0, 8.0, 18.0, 6.0), (30.0, 44.0, 26.0, 36.0, 4.5),
           (48.0, 52.0, 6.0, 9.0, 2.6)]  # x0, x1, y0, y1, roof height: two houses, a shed
#: trees: x, y, crown radius, crown base and top heights (beside house 1, over a corner
#: of house 2, free-standing)
_TREES = [(23.2, 13.0, 3.0, 2.5, 7.5), (29.0, 25.0, 2.5, 2.0, 6.5),
          (40.0, 12.0, 3.5, 3.0, 9.0), (12.0, 32.0, 2.5, 2.0, 6.0)]
_HEDGE = (5.0, 40.0, 44.4, 45.6, 2.6)  # x0, x1, y0, y1, top: as high as the shed
_GARDEN_WALL = (5.0, 40.0, 47.0, 47.3, 1.2)


def _crown_top(x, y, tree):
    """Height of the crown's upper surface (a half ellipsoid) and where it lies over."""
    cx, cy, r, base, top = tree
    d2 = ((x - cx) ** 2 + (y - cy) ** 2) / r**2
    inside = d2 < 1.0
    return np.where(inside, base + (top - base) * np.sqrt(np.clip(1.0 - d2, 0, 1)),
                    -np.inf), inside


def make_garden_scene(*, extent=(60.0, 50.0), density=8.0, sigma=0.03,
                      rng=None) -> TerrainScene:
    """Houses, trees on trunks and a hedge: the hard case of building classification.

    One echo per pulse on terrain, roofs and the garden wall (flat tops, Gaussian noise
    ``sigma`` along z); a pulse that hits a crown is returned from inside the foliage
    (depth exponential, mean 0.4 m) and half of them give a last echo lower down (on the
    ground or on a lower branch); a pulse that hits the hedge is returned from its
    clipped surface (depth exponential, mean 0.08 m: leaves, not a plane), a fifth of
    them with a last echo on the ground. Walls and trunks are seen at a slant: points on
    the houses' walls (a quarter of the density per square metre of wall) and along each
    trunk. The truth is ``attributes["classification"]`` (ground 2, building 6: roofs and
    walls; vegetation 5: crowns, trunks, the hedge; 1: the garden wall, 1.2 m) and
    ``attributes["part"]`` (:data:`GARDEN_PARTS`).

    Parameters
    ----------
    extent : (float, float)
        Size of the area in x and y (m), origin at (0, 0); the layout needs 60 x 50 m.
    density : float
        Pulses per square metre.
    sigma : float
        Noise std along z (m).
    rng : numpy.random.Generator or int or None
        Random source.

    Returns
    -------
    TerrainScene

    Examples
    --------
    >>> s = make_garden_scene(rng=0)
    >>> bool((s.attributes["classification"] == 6).mean() > 0.1)
    True
    """
    g = np.random.default_rng(rng)
    n = round(extent[0] * extent[1] * density)
    x, y = g.uniform(0, extent[0], n), g.uniform(0, extent[1], n)
    terrain = 0.01 * x + 0.005 * y
    part = np.zeros(n, np.int8)
    z = terrain.copy()
    # level roofs on the sloping terrain: each at its height above its lowest corner
    roof = _boxes(x, y, [(x0, x1, y0, y1, top + 0.01 * x0 + 0.005 * y0)
                         for x0, x1, y0, y1, top in _HOUSES])
    for box, name in ((_GARDEN_WALL, "garden_wall"), (_HEDGE, "hedge")):
        inside = (x >= box[0]) & (x <= box[1]) & (y >= box[2]) & (y <= box[3])
        part[inside] = GARDEN_PARTS[name][0]
        z[inside] = terrain[inside] + box[4]
    on_roof = np.isfinite(roof)
    part[on_roof] = GARDEN_PARTS["roof"][0]
    z[on_roof] = roof[on_roof]
    crown_z = np.full(n, -np.inf)
    for tree in _TREES:
        cz, inside = _crown_top(x, y, tree)
        over = inside & (cz > np.maximum(z, crown_z))
        crown_z[over] = cz[over] + terrain[over]
    crown = crown_z > z
    part[crown] = GARDEN_PARTS["crown"][0]
    z[crown] = crown_z[crown] - g.exponential(0.4, crown.sum())
    hedge = part == GARDEN_PARTS["hedge"][0]
    z[hedge] -= g.exponential(0.08, hedge.sum())
    z += g.normal(0, sigma, n)
    nret = np.ones(n, np.uint8)
    # last echoes under the foliage: half of the crown pulses, a fifth of the hedge's
    second = (crown & (g.uniform(size=n) < 0.5)) | (hedge & (g.uniform(size=n) < 0.2))
    nret[second] = 2
    s_idx = np.flatnonzero(second)
    low = g.uniform(size=s_idx.size) < 0.6
    z2 = np.where(low, terrain[s_idx],
                  terrain[s_idx] + g.uniform(0.5, 1.0, s_idx.size)
                  * (z[s_idx] - terrain[s_idx] - 0.5))
    z2 = z2 + g.normal(0, sigma, s_idx.size)
    part2 = np.where(low, GARDEN_PARTS["terrain"][0], part[s_idx])
    walls = [_wall_points(g, box, density, sigma) for box in _HOUSES]
    trunks = [_trunk_points(g, tree, sigma) for tree in _TREES]
    wx = np.concatenate(walls + trunks)
    wpart = np.r_[np.full(sum(len(w) for w in walls), GARDEN_PARTS["wall"][0]),
                  np.full(sum(len(t) for t in trunks), GARDEN_PARTS["trunk"][0])]
    wx[:, 2] += 0.01 * wx[:, 0] + 0.005 * wx[:, 1]
    xyz = np.r_[np.c_[x, y, z], np.c_[x[s_idx], y[s_idx], z2], wx]
    part = np.r_[part, part2, wpart].astype(np.int8)
    nret = np.r_[nret, np.full(s_idx.size, 2, np.uint8), np.ones(len(wx), np.uint8)]
    rnum = np.r_[np.ones(n, np.uint8), np.full(s_idx.size, 2, np.uint8),
                 np.ones(len(wx), np.uint8)]
    classes = np.zeros(len(part), np.uint8)
    for code, cls in GARDEN_PARTS.values():
        classes[part == code] = cls
    xyz[:, 2] += 100.0
    inten = g.normal(100.0, 8.0, len(part))
    return TerrainScene(xyz=xyz, intensity=inten, ground=part == 0, name="garden",
                        meta={"extent": tuple(extent), "density": density, "sigma": sigma,
                              "houses": list(_HOUSES), "trees": list(_TREES),
                              "hedge": _HEDGE, "garden_wall": _GARDEN_WALL},
                        attributes={"number_of_returns": nret, "return_number": rnum,
                                    "classification": classes, "part": part})


def _wall_points(g, box, density, sigma):
    """Points on the four walls of a box (seen at a slant: a quarter of the density per
    square metre of wall), the height field's terrain added by the caller."""
    x0, x1, y0, y1, top = box
    sides = [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)),
             ((x0, y1), (x0, y0))]
    out = []
    for (ax, ay), (bx, by) in sides:
        length = float(np.hypot(bx - ax, by - ay))
        m = g.poisson(0.25 * density * length * top)
        t, h = g.uniform(0, 1, m), g.uniform(0, top, m)
        out.append(np.c_[ax + t * (bx - ax), ay + t * (by - ay), h + g.normal(0, sigma, m)])
    return np.concatenate(out)


def _trunk_points(g, tree, sigma, per_metre=6.0):
    """Points around a trunk (radius 0.15 m) from the ground to the crown's base."""
    cx, cy, _, base, _ = tree
    m = g.poisson(per_metre * base)
    a, h = g.uniform(0, 2 * np.pi, m), g.uniform(0, base, m)
    return np.c_[cx + 0.15 * np.cos(a), cy + 0.15 * np.sin(a), h + g.normal(0, sigma, m)]
