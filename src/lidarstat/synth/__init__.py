"""Synthetic point clouds with exact ground truth (NumPy only).

Height fields (``make_plane``, ``make_cylinder``, ``make_sphere_cap``,
``make_paraboloid``, ``make_scherk``, ``make_surface``) and orthographic range scans of
CSG solids (``make_agpart``, ``make_column``) return a :class:`SyntheticCloud` carrying
the true normals, curvatures (K, H, kmin, kmax), surface type codes, face ids and the
distance of every point to the nearest edge.

Sign convention: normals point up (+z) / toward the viewer and H < 0 on convex surfaces
(the top of a horizontal cylinder of radius R has K = 0, H = -1/(2R)).  Surface type
codes: 0 unclassified, 1 planar, 2 parabolic ridge, 3 parabolic valley, 4 elliptic peak,
5 elliptic pit, 6 saddle ridge, 7 saddle valley, 8 minimal saddle.
"""

from __future__ import annotations

from ._als import ASPRS_CLASSES, MATERIALS, make_als_town, make_hip_roof_scene
from ._csg import (
    Box,
    Cylinder,
    FaceRegistry,
    Polyhedron,
    difference,
    union,
)
from ._edges import crease_lines, distance_to_creases
from ._orthographic import scan_orthographic
from ._roof_scenes import ROOF_SCENE_KINDS, make_roof_scene
from ._scenes import SCENES, make_agpart, make_column
from ._surface_kinds import SURFACE_KINDS, make_surface
from ._surfaces import (
    make_cylinder,
    make_paraboloid,
    make_plane,
    make_scherk,
    make_sphere_cap,
)
from ._terrain_scenes import (GARDEN_PARTS, TERRAIN_SCENES, TerrainScene, make_garden_scene,
                              make_terrain_scene)
from ._tls import scan_spherical
from ._tls_scenes import make_tls_building, make_tls_plant
from ._truth import (
    SURFACE_TYPE_NAMES,
    SyntheticCloud,
    neighborhood_class_truth,
    point_class_truth,
    principal_curvatures,
    surface_type_from_curvature,
)

__all__ = [
    "SyntheticCloud",
    "point_class_truth",
    "neighborhood_class_truth",
    "SURFACE_TYPE_NAMES",
    "SURFACE_KINDS",
    "SCENES",
    "surface_type_from_curvature",
    "principal_curvatures",
    "make_plane",
    "make_cylinder",
    "make_sphere_cap",
    "make_paraboloid",
    "make_scherk",
    "make_surface",
    "make_agpart",
    "make_column",
    "make_als_town",
    "make_hip_roof_scene",
    "make_roof_scene",
    "ROOF_SCENE_KINDS",
    "MATERIALS",
    "ASPRS_CLASSES",
    "make_tls_building",
    "TERRAIN_SCENES",
    "TerrainScene",
    "make_terrain_scene",
    "make_garden_scene",
    "GARDEN_PARTS",
    "make_tls_plant",
    "scan_spherical",
    "crease_lines",
    "distance_to_creases",
    "Cylinder",
    "Box",
    "Polyhedron",
    "FaceRegistry",
    "union",
    "difference",
    "scan_orthographic",
]
