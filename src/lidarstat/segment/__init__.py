"""Segmentation: region growing over CSR neighbourhoods, result containers and scores.

Methods (covariance, SAR + Forward Search, curvature classes, ridges) compute per-edge
criteria and call the shared graph kernels here; every method returns a
:class:`Segmentation`.
"""

from ._grow import adjacency, components, grow_regions, relabel
from ._metrics import HooverScore, binary_scores, hoover
from ._result import Polylines, Segmentation, segment_table
from ._forward_search import ForwardSearchResult, forward_search
from ._search_area import SearchAreas, delaunay_graph, search_areas

__all__ = ["Segmentation", "Polylines", "segment_table", "components", "grow_regions",
           "relabel", "adjacency", "hoover", "HooverScore", "binary_scores",
           "ForwardSearchResult", "forward_search", "SearchAreas", "delaunay_graph",
           "search_areas"]
