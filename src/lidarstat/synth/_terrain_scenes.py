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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["TERRAIN_SCENES", "TerrainScene", "make_terrain_scene"]

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
    """

    xyz: np.ndarray
    intensity: np.ndarray
    ground: np.ndarray
    name: str
    meta: dict = field(default_factory=dict)


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
