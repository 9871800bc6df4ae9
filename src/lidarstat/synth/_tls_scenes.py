"""Terrestrial scenes with exact truth: a building with a gable house and a process plant.

Both are CSG solids (:mod:`lidarstat.synth._csg`) scanned from one or several stations by
:func:`lidarstat.synth.scan_spherical`, with range noise ``sigma(r) = a + b r``.
"""

from __future__ import annotations

import numpy as np

from .._shared.validation import check_scalar
from ._csg import Box, Cylinder, FaceRegistry, Polyhedron, difference, union
from ._tls import scan_spherical
from ._truth import SyntheticCloud

__all__ = ["make_tls_building", "make_tls_plant"]


def _scene_args(func, stations, sigma, range_sigma):
    """Validated station count and noise model of a TLS scene (`sigma` overrides)."""
    stations = check_scalar(stations, "stations", func=func, low=1, high=2, closed="both",
                            integer=True)
    if sigma is not None:
        range_sigma = (check_scalar(sigma, "sigma", func=func, low=0.0, closed="left"), 0.0)
    return stations, range_sigma


def _ground(reg, half=80.0):
    return Box(reg, "ground", (0.0, 0.0, -0.5), np.eye(3), (half, half, 0.5))


def _abox(reg, name, lo, hi):
    """Axis-aligned box from its corners."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return Box(reg, name, (lo + hi) / 2, np.eye(3), (hi - lo) / 2)


def _gable_house(reg, name, x0, x1, y0, y1, wall_h, ridge_h, *, wall=0.3, overhang=0.4,
                 fascia=0.2, openings=()):
    """Hollow house: walls of thickness `wall`, void floor 0.2 above ground, a gable roof
    (ridge along x, at mid-y) with eaves overhang and fascia, and `openings` = list of
    (name, lo, hi) boxes subtracted from the shell (recesses or through-holes)."""
    shell = difference(_abox(reg, f"{name}_wall", (x0, y0, -0.5), (x1, y1, wall_h)),
                       _abox(reg, f"{name}_room", (x0 + wall, y0 + wall, 0.2),
                             (x1 - wall, y1 - wall, wall_h - wall)))
    for oname, lo, hi in openings:
        shell = difference(shell, _abox(reg, f"{name}_{oname}", lo, hi))
    ym = 0.5 * (y0 + y1)
    ey0, ey1 = y0 - overhang, y1 + overhang
    zb, ze = wall_h - 0.2, wall_h - 0.2 + fascia  # soffit and eave line heights
    run, rise = ym - ey0, ridge_h - ze
    n_s = np.array([0.0, -rise, run])
    n_n = np.array([0.0, rise, run])
    roof = Polyhedron(
        reg, f"{name}_roof",
        normals=[n_s, n_n, (1, 0, 0), (-1, 0, 0), (0, 0, -1), (0, -1, 0), (0, 1, 0)],
        offsets=[n_s @ (0, ey0, ze), n_n @ (0, ey1, ze), x1 + overhang, -(x0 - overhang),
                 -zb, -ey0, ey1],
        face_names=("south", "north", "gable_east", "gable_west", "soffit", "fascia_south",
                    "fascia_north"))
    return union(shell, roof)


def make_tls_building(*, step=0.0025, stations=1, range_sigma=(0.002, 5e-5), sigma=None,
                      max_range=80.0, rng=None) -> SyntheticCloud:
    """Terrestrial scan of a hollow gable-roofed house and a flat-roofed garage.

    Metres; ground plane z = 0 (faces ``ground_+z``).  The house (walls 0.3 m thick,
    12 x 8 m, eaves 6 m, ridge 9.2 m along x, roof overhang 0.4 m with soffit and fascia)
    has on its south facade (y = 10) two ground-floor windows recessed 0.15 m, two
    upper windows cut *through* the wall (the room behind is seen through them, faces
    ``house_room_*``), and a door recessed 0.2 m; on its west facade (x = -6) one
    recessed and one through window.  The garage (box 4 x 5 x 3 m) east of the house
    occludes part of the scene.  Station 0 stands at (-9, -14, 1.6) looking north-east;
    with ``stations=2`` a second at (14, -10, 1.6) looks north-west.  About 58,000
    points with one station and the default step (0.0025 rad = 2.5 cm at 10 m), in about
    4 s.

    Parameters
    ----------
    step : float
        Angular step (radians); the number of points scales as ``1 / step**2``.
    stations : {1, 2}
        Number of scanner stations.
    range_sigma : (float, float)
        Range noise std ``a + b * range`` (metres).
    sigma : float, optional
        If given, overrides `range_sigma` with ``(sigma, 0)`` (used by
        ``lidarstat synth --sigma``).
    max_range : float
        Maximum range (metres).
    rng : numpy.random.Generator or int or None
        Random source of the noise.

    Returns
    -------
    SyntheticCloud
        See :func:`scan_spherical`.  Face names: ``ground_+z``, ``house_wall_-y``
        (south facade), ``house_wall_-x`` (west facade), ``house_roof_south``,
        ``house_roof_gable_west``, ``house_win1_+y`` (back of a recess), ...

    Examples
    --------
    >>> c = make_tls_building(step=0.03)
    >>> "house_roof_south" in {c.meta["face_names"][f] for f in c.face}
    True
    """
    stations, range_sigma = _scene_args("make_tls_building", stations, sigma, range_sigma)
    reg = FaceRegistry()
    x0, x1, y0, y1 = -6.0, 6.0, 10.0, 18.0
    ops = [("win1", (-4.5, y0 - 0.1, 1.0), (-3.3, y0 + 0.15, 2.4)),
           ("win2", (3.3, y0 - 0.1, 1.0), (4.5, y0 + 0.15, 2.4)),
           ("win3", (-4.5, y0 - 0.1, 3.4), (-3.3, y0 + 0.5, 4.8)),
           ("win4", (3.3, y0 - 0.1, 3.4), (4.5, y0 + 0.5, 4.8)),
           ("door", (-0.5, y0 - 0.1, 0.05), (0.5, y0 + 0.2, 2.2)),
           ("win5", (x0 - 0.1, 12.0, 1.2), (x0 + 0.12, 13.2, 2.5)),
           ("win6", (x0 - 0.1, 14.8, 3.4), (x0 + 0.5, 16.0, 4.8))]
    house = _gable_house(reg, "house", x0, x1, y0, y1, 6.0, 9.2, openings=ops)
    garage = _abox(reg, "garage", (8.0, 4.0, -0.5), (12.0, 9.0, 3.0))
    solid = union(_ground(reg), union(house, garage))
    sc = [(-9.0, -14.0, 1.6), (14.0, -10.0, 1.6)][:stations]
    az = [(0.55, 1.65), (1.45, 2.55)][:stations]
    el = [(-0.22, 0.5), (-0.22, 0.5)][:stations]
    meta = {"scene": "tls_building", "house": {"x": (x0, x1), "y": (y0, y1), "eaves": 6.0,
                                               "ridge": 9.2, "wall": 0.3},
            "openings": {o[0]: (o[1], o[2]) for o in ops}}
    refl = {"ground": 0.25, "house_wall": 0.55, "house_room": 0.6, "house_roof": 0.2,
            "house_door": 0.35, "garage": 0.45, **{f"house_win{k}": 0.1 for k in range(1, 7)}}
    return scan_spherical(solid, sensor=sc, azimuth=az, elevation=el, step=step,
                          range_sigma=range_sigma, max_range=max_range, rng=rng,
                          reflectance=refl, name="tls_building", meta=meta)


def make_tls_plant(*, step=0.0025, stations=1, range_sigma=(0.002, 5e-5), sigma=None,
                   max_range=80.0, rng=None) -> SyntheticCloud:
    """Terrestrial scan of a small process plant: tanks, pipes, a pump housing.

    Metres; ground z = 0.  Two vertical tanks with flat tops (``tank1``: radius 3 m,
    6 m high at (0, 16); ``tank2``: radius 2 m, 4 m high at (9, 17)); a pump housing
    box (``pump``, 3 x 2 x 1.5 m) with a horizontal pipe of radius 0.3 m leaving it
    westward (``pipe_a``, open end with a cap); a pipe rack: two pipes along x of radii
    0.15 and 0.5 m at heights 3 and 3.2 m (``pipe_b``, ``pipe_c``) passing through two
    box supports (``support1``, ``support2``), and a small pipe of radius 0.1 m along y
    (``pipe_d``) resting 0.4 m above the ground between the pump and tank 2.  Cylinder
    faces carry K = 0, H = -1/(2R) (convex).  Creases include the circles where pipes
    enter boxes and where the tanks meet the ground.  Station 0 stands on the ground at
    (-6, -8, 1.6); the optional second is on a platform at (14, -4, 8.0) and looks down
    on the flat tank tops (``tank1_cap_top``, ``tank2_cap_top``).  About 70,000 points
    with one station and the default step, 141,000 with two.

    Parameters
    ----------
    step, stations, range_sigma, sigma, max_range, rng
        As for :func:`make_tls_building`.

    Returns
    -------
    SyntheticCloud

    Examples
    --------
    >>> c = make_tls_plant(step=0.03)
    >>> "tank1_side" in {c.meta["face_names"][f] for f in c.face}
    True
    """
    stations, range_sigma = _scene_args("make_tls_plant", stations, sigma, range_sigma)
    reg = FaceRegistry()
    ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    ez = np.array([0, 0, 1.0])
    tank1 = Cylinder(reg, "tank1", (0.0, 16.0, 2.75), ez, 3.0, 6.5)
    tank2 = Cylinder(reg, "tank2", (9.0, 17.0, 1.75), ez, 2.0, 4.5)
    pump = _abox(reg, "pump", (3.0, 8.0, -0.5), (6.0, 10.0, 1.5))
    pipe_a = Cylinder(reg, "pipe_a", (-1.0, 9.0, 0.8), ex, 0.3, 8.2)  # x from -5.1 to 3.1
    sup1 = _abox(reg, "support1", (-6.5, 4.4, -0.5), (-5.5, 6.3, 4.0))
    sup2 = _abox(reg, "support2", (7.5, 4.4, -0.5), (8.5, 6.3, 4.0))
    pipe_b = Cylinder(reg, "pipe_b", (1.0, 4.8, 3.0), ex, 0.15, 20.0)
    pipe_c = Cylinder(reg, "pipe_c", (1.0, 5.6, 3.2), ex, 0.5, 18.0)
    pipe_d = Cylinder(reg, "pipe_d", (5.5, 12.45, 0.5), ey, 0.1, 5.3)  # y 9.8 .. 15.1
    solid = _ground(reg)
    for prim in (tank1, tank2, pump, pipe_a, sup1, sup2, pipe_b, pipe_c, pipe_d):
        solid = union(solid, prim)
    sc = [(-6.0, -8.0, 1.6), (14.0, -4.0, 8.0)][:stations]
    az = [(0.45, 1.75), (1.3, 2.75)][:stations]
    el = [(-0.25, 0.45), (-0.4, 0.1)][:stations]
    meta = {"scene": "tls_plant",
            "cylinders": {c.name: {"center": c.center.tolist(), "axis": c.axis.tolist(),
                                   "radius": c.radius, "length": c.length}
                          for c in (tank1, tank2, pipe_a, pipe_b, pipe_c, pipe_d)}}
    refl = {"ground": 0.25, "tank": 0.65, "pipe": 0.5, "pump": 0.3, "support": 0.35}
    return scan_spherical(solid, sensor=sc, azimuth=az, elevation=el, step=step,
                          range_sigma=range_sigma, max_range=max_range, rng=rng,
                          reflectance=refl, name="tls_plant", meta=meta)
