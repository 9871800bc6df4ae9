"""Segmentation: region growing over CSR neighbourhoods, result containers and scores.

Methods (covariance, SAR + Forward Search, curvature classes, ridges) compute per-edge
criteria and call the shared graph kernels here; every method returns a
:class:`Segmentation`.
"""

from ._grow import adjacency, components, grow_regions, relabel
from ._metrics import CreaseCoverage, HooverScore, binary_scores, crease_coverage, hoover
from ._result import Polylines, Segmentation, segment_table
from ._forward_search import ForwardSearchResult, StopRule, forward_search
from ._search_area import SearchAreas, delaunay_graph, search_areas
from ._raw_clusters import RawClusters, plane_edges, raw_clusters
from ._sar_unit import SurfaceUnit
from ._sar_refine import refine_cluster
from ._intersect import intersection_lines
from ._sar import segment_sar
from ._sar_units import refine_raw_clusters
from ._curvature_units import curvature_units, segment_curvature
from ._covariance_lines import fit_lines, local_intersections
from ._covariance_segments import SeedOrder, reintegrate, segment_covariance, segment_planes
from ._ridges import RIDGE_FIELDS, RidgeResult, ridges
from ._ridge_segments import ridge_segments

__all__ = ["Segmentation", "Polylines", "segment_table", "components", "grow_regions",
           "relabel", "adjacency", "hoover", "HooverScore", "binary_scores",
           "crease_coverage", "CreaseCoverage",
           "ForwardSearchResult", "StopRule", "forward_search", "SearchAreas", "delaunay_graph",
           "search_areas", "RawClusters", "plane_edges", "raw_clusters", "SurfaceUnit",
           "refine_cluster", "intersection_lines", "refine_raw_clusters", "segment_sar",
           "curvature_units", "segment_curvature", "segment_covariance", "SeedOrder", "segment_planes",
           "local_intersections", "fit_lines", "reintegrate", "ridges", "ridge_segments",
           "RidgeResult", "RIDGE_FIELDS"]
