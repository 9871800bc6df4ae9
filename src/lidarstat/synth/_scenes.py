"""Range-image scenes of CSG solids (OSU-like) and the ``SCENES`` registry.

Both scenes are orthographic scans along -z on a regular XY grid (like the OSU / MSU
range images used by Crosilla et al. 2009); the grid nodes whose ray hits the object give
one sample each, noise is added to z.  Truth conventions are those of
:mod:`lidarstat.synth._csg` (normals toward the viewer, H < 0 on convex faces, H > 0 on the
inside of subtracted cylinders).
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError
from ._als import make_als_town, make_hip_roof_scene
from ._csg import Box, Cylinder, FaceRegistry, difference, union
from ._edges import crease_lines
from ._orthographic import scan_orthographic
from ._surface_kinds import SURFACE_KINDS, make_surface
from ._tls_scenes import make_tls_building, make_tls_plant
from ._truth import SyntheticCloud, _build

__all__ = ["make_agpart", "make_column", "SCENES"]


def _spacing(spacing, func):
    sp = np.asarray(spacing, dtype=np.float64).ravel()
    if sp.size == 1:
        sp = np.repeat(sp, 2)
    if sp.size != 2 or not np.all(np.isfinite(sp)) or np.any(sp <= 0):
        raise InvalidParameterError(
            f"The 'spacing' parameter of {func} must be a positive float or a pair of "
            f"positive floats. Got {spacing!r} instead."
        )
    if sp.min() < 0.002:
        raise InvalidParameterError(
            f"The 'spacing' parameter of {func} must be at least 0.002 (grid too large). "
            f"Got {spacing!r} instead."
        )
    return float(sp[0]), float(sp[1])


def _rodrigues(k, angle):
    k = np.asarray(k, float) / np.linalg.norm(k)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * (Kx @ Kx)


def _tilt_rotation(tilt_deg, azimuth_deg):
    """Rotation taking +z to (sin t cos a, sin t sin a, cos t) about a horizontal axis."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    k = np.array([-math.sin(a), math.cos(a), 0.0])
    return _rodrigues(k, t)


def _cyl_min_z(c, a, R, L):
    return c[2] - L / 2 * abs(a[2]) - R * math.sqrt(max(1 - a[2] ** 2, 0.0))


def _finish_scan(name, solid, faces, spacing, sigma, rng, meta, jump_factor=3.0):
    scan = scan_orthographic(solid, faces, spacing=spacing, jump_factor=jump_factor)
    meta = dict(meta)
    counts = np.bincount(scan["face"], minlength=len(faces.faces))
    face_info = []
    for i, f in enumerate(faces.faces):
        info = dict(f)
        info["id"] = i
        info["n_points"] = int(counts[i])
        flips = scan["flipped"][scan["face"] == i]
        info["flipped"] = bool(flips.any()) if flips.size else None
        face_info.append(info)
    meta.update({
        "faces": face_info,
        "face_names": [f["name"] for f in faces.faces],
        "spacing": spacing,
        "view_direction": (0.0, 0.0, -1.0),
        "ij": scan["ij"],
        "grid_origin": scan["grid_origin"],
        "grid_shape": scan["grid_shape"],
        "jump_factor": jump_factor,
        "creases": crease_lines(solid),
        "edge_distance": (
            "3-D distance to the nearest boundary sample: samples next to a miss "
            "(silhouette) or across a depth jump > jump_factor * XY separation between "
            "different faces, and midpoints of 8-neighbour pairs on different faces "
            "(creases); accurate to about one grid step"
        ),
    })
    return _build(xyz_true=scan["xyz"], normal=scan["normal"], K=scan["K"], H=scan["H"],
                  kmin=scan["kmin"], kmax=scan["kmax"], face=scan["face"],
                  edge_distance=scan["edge_distance"], sigma=sigma, rng=rng, name=name,
                  meta=meta)


def make_agpart(*, spacing=(0.02, 0.0168), sigma=0.0, rng=None, tilt=40.0,
                azimuth=100.0) -> SyntheticCloud:
    """Range scan of an agpart-2-like part (OSU range image; Crosilla et al. 2009).

    Units are decimetres.  The solid is ``(shaft U disk) - bore``, all coaxial, axis
    ``a = (sin(tilt) cos(azimuth), sin(tilt) sin(azimuth), cos(tilt))`` (tilted from the
    vertical so the grid sees the part obliquely):

    * shaft: cylinder of radius 1.1 and length 3.35, from -1.9 to +1.45 along the axis
      (measured from the disk centre);
    * disk: coaxial cylinder of radius 2.0, thickness 0.5 (-0.25 .. +0.25), so the shaft
      sticks out 1.2 above and 1.65 below it;
    * bore: coaxial cylinder of radius 0.28 through the whole shaft, subtracted.

    The disk centre lies on the z axis at a height putting the lowest point of the solid
    at z = 0.  Seen from above: the annular top cap of the shaft with the bore opening
    (planar), the shaft side above the disk and a crescent of it below the disk rim
    (convex, R = 1.1), the annular top face of the disk (planar), the disk rim (convex,
    R = 2.0) and the inside of the bore (concave, R = 0.28, H = +1/0.56) through its
    opening.  With the defaults there are about 34,500 samples over 4.0 x 3.8 dm
    (shaft side 6840, shaft top cap 8109, disk rim 3832, disk top 15148, bore 563).
    The paper's image is about 4 x 3 dm with ~30,000 points; with these dimensions the
    disk alone projects to at least 4 x 3.7 dm for any tilt between 35 and 45 degrees.

    Parameters
    ----------
    spacing : float or (float, float)
        Grid steps (dx, dy) in dm; the default is the paper's 0.02 x 0.0168.
    sigma : float
        Standard deviation of the range noise added to z (dm).
    rng : numpy.random.Generator or int or None
        Random source for the noise.
    tilt : float
        Angle of the axis from the vertical, degrees in [0, 70].
    azimuth : float
        Direction of the tilted axis in the XY plane, degrees from +x.

    Returns
    -------
    SyntheticCloud
        ``face`` indexes ``meta["faces"]`` (names ``shaft_side``, ``shaft_cap_top``,
        ``disk_side``, ``disk_cap_top``, ``bore_side``, ...; each with ``n_points``);
        ``meta["creases"]`` holds the solid's true creases (:func:`crease_lines`).

    Examples
    --------
    >>> c = make_agpart(spacing=0.1)
    >>> c.meta["face_names"][c.face[0]] in c.meta["face_names"]
    True
    """
    func = "make_agpart"
    rng = np.random.default_rng(rng)
    sp = _spacing(spacing, func)
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0, closed="left")
    tilt = check_scalar(tilt, "tilt", func=func, low=0.0, high=70.0, closed="both")
    azimuth = check_scalar(azimuth, "azimuth", func=func)
    a = _tilt_rotation(tilt, azimuth)[:, 2]
    shaft_r, shaft_len, above, below = 1.1, 3.35, 1.2, 1.65
    disk_r, disk_t, bore_r = 2.0, 0.5, 0.28
    s_center = (disk_t / 2 + above - (disk_t / 2 + below)) / 2  # shaft centre along axis
    o = np.zeros(3)
    zmin = min(_cyl_min_z(o + s_center * a, a, shaft_r, shaft_len),
               _cyl_min_z(o, a, disk_r, disk_t))
    o[2] = -zmin
    faces = FaceRegistry()
    shaft = Cylinder(faces, "shaft", o + s_center * a, a, shaft_r, shaft_len)
    disk = Cylinder(faces, "disk", o, a, disk_r, disk_t)
    bore = Cylinder(faces, "bore", o + s_center * a, a, bore_r, shaft_len + 0.4)
    solid = difference(union(shaft, disk), bore)
    meta = {"scene": "agpart", "units": "dm", "axis": a.tolist(), "tilt": tilt,
            "azimuth": azimuth, "disk_center": o.tolist(),
            "shaft": {"radius": shaft_r, "length": shaft_len,
                      "center": (o + s_center * a).tolist()},
            "disk": {"radius": disk_r, "thickness": disk_t, "center": o.tolist()},
            "bore": {"radius": bore_r, "length": shaft_len + 0.4}}
    return _finish_scan("agpart", solid, faces, sp, sigma, rng, meta)


def make_column(*, spacing=(0.02, 0.0168), sigma=0.0, rng=None, tilt=30.0,
                azimuth=60.0) -> SyntheticCloud:
    """Range scan of a column1-like scene (OSU): a round column standing on a square base.

    Units are decimetres.  In the object frame (z up) the base is a box
    3.0 x 3.0 x 0.7 centred on the origin and turned by 45 degrees about z relative to the
    tilt direction; the column is a cylinder of radius 0.65 rising 2.6 above the base top
    (embedded 0.1 into the base), closed on top by its circular cap.  The object is then
    tilted by `tilt` degrees toward `azimuth`, so that its top leans toward that direction
    and the two side faces of the base facing away from it are seen from above: the
    vertex where the base top and these two side faces meet is visible.  The lowest
    point of the solid is at z = 0.  Visible faces: base top (+z), two base sides,
    column side (convex, R = 0.65) and column top cap; about 28,300 samples over
    3.8 x 3.6 dm with the defaults.

    Parameters
    ----------
    spacing : float or (float, float)
        Grid steps (dx, dy), dm.
    sigma : float
        Standard deviation of the range noise added to z.
    rng : numpy.random.Generator or int or None
        Random source for the noise.
    tilt : float
        Tilt of the object's vertical axis, degrees in [0, 60].
    azimuth : float
        Direction toward which the object leans, degrees from +x.

    Returns
    -------
    SyntheticCloud
        ``meta["creases"]`` holds the solid's true creases (:func:`crease_lines`).

    Examples
    --------
    >>> c = make_column(spacing=0.1)
    >>> sorted(n for n, f in zip(c.meta["face_names"], c.meta["faces"]) if f["n_points"])[:2]
    ['base_+x', 'base_+z']
    """
    func = "make_column"
    rng = np.random.default_rng(rng)
    sp = _spacing(spacing, func)
    sigma = check_scalar(sigma, "sigma", func=func, low=0.0, closed="left")
    tilt = check_scalar(tilt, "tilt", func=func, low=0.0, high=60.0, closed="both")
    azimuth = check_scalar(azimuth, "azimuth", func=func)
    Rt = _tilt_rotation(tilt, azimuth)
    # local box frame: turned so that its corner (not a face) points away from the lean
    phi = math.radians(azimuth + 45.0 + 180.0)
    Rz = np.array([[math.cos(phi), -math.sin(phi), 0.0], [math.sin(phi), math.cos(phi), 0.0],
                   [0.0, 0.0, 1.0]])
    Rb = Rt @ Rz
    he = np.array([1.5, 1.5, 0.35])
    col_r, col_h, embed = 0.65, 2.6, 0.1
    up = Rt[:, 2]
    corners = (np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij"))
               .reshape(3, -1).T * he) @ Rb.T
    col_len = col_h + embed
    col_c_rel = (he[2] - embed + col_len / 2) * up
    zmin = min(corners[:, 2].min(), _cyl_min_z(col_c_rel, up, col_r, col_len))
    o = np.array([0.0, 0.0, -zmin])
    faces = FaceRegistry()
    base = Box(faces, "base", o, Rb, he)
    column = Cylinder(faces, "column", o + col_c_rel, up, col_r, col_len)
    solid = union(base, column)
    meta = {"scene": "column", "units": "dm", "tilt": tilt, "azimuth": azimuth,
            "base": {"center": o.tolist(), "rotation": Rb.tolist(), "half_extents": he.tolist()},
            "column": {"radius": col_r, "height": col_h, "axis": up.tolist(),
                       "center": (o + col_c_rel).tolist(), "length": col_len}}
    return _finish_scan("column", solid, faces, sp, sigma, rng, meta)


def _surface_scene(kind):
    def scene(**kwargs):
        return make_surface(kind, **kwargs)

    scene.__name__ = f"make_surface_{kind}"
    scene.__doc__ = f"``make_surface({kind!r}, **kwargs)`` (surface type {SURFACE_KINDS[kind]})."
    return scene


#: Scene name -> callable returning a :class:`SyntheticCloud`; used by
#: ``lidarstat synth SCENE OUT``.  Every scene accepts the keywords ``sigma`` (noise std,
#: overriding the scene's noise model) and ``rng``; the range-image scenes and patches also
#: take ``spacing``, the terrestrial scans ``step``,
#: the airborne scenes ``density``.
SCENES = {"agpart": make_agpart, "column": make_column,
          "tls_building": make_tls_building, "tls_plant": make_tls_plant,
          "als_town": make_als_town, "hip_roof": make_hip_roof_scene,
          **{kind: _surface_scene(kind) for kind in SURFACE_KINDS}}
