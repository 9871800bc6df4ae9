"""CSR neighbourhoods from fixed-radius (3-D sphere, 2-D disc) and kNN queries.

Every neighbour search of the package lives here: the radius and kNN queries returning
:class:`Neighborhoods`, and the Numba kernels of the exact grid kNN search
(``grid_knn_point`` and its helpers, cell size :func:`knn_cell_size`) that the drivers
of the covariance features and of the moments classification's patch graph call inside
their own kernels, fused with the per-point model.

Every query is sized before it allocates (:func:`max_pairs`); points sharing a location
are found by :func:`find_duplicates` (the policy of the local models is in
``lidarstat.neighbors._duplicates``).
"""

from ._budget import max_pairs
from ._csr import Neighborhoods
from ._drivers import Drivers, make_drivers
from ._duplicates import (Duplicates, check_copies, copies_degenerate, find_duplicates,
                          location_hash, map_rows, refuse_dominated, run_on_unique)
from ._query import CellIndex, KnnIndex, knn_neighbors, radius_neighbors
from ._grid_knn import knn_cell_size
from ._knn_indices import knn_indices
from ._delaunay import delaunay_triangles
from ._grid_kernels import _CELL_CHUNK as GRID_CELL_CHUNK
from ._grid_kernels import _block_ranges as grid_block_ranges
from ._grid_kernels import _count as grid_candidate_count
from ._grid_kernels import _knn_point as grid_knn_point
from ._grid_kernels import cell_block as grid_cell_block
from ._grid_kernels import knn_found as grid_knn_found
from ._grid_kernels import _scratch as grid_knn_scratch
from ._grid_kernels import _guaranteed as grid_guaranteed
from ._grid_kernels import block_2d as grid_block_2d
from ._grid_kernels import select_2d as grid_select_2d
from ._grid_kernels import walk_block_2d as grid_walk_block_2d
from ._kernels import _cell_ranges as grid_cell_ranges
from ._kernels import cells_may_share as grid_cells_may_share
from ._kernels import radix_order

__all__ = ["Neighborhoods", "CellIndex", "KnnIndex", "radius_neighbors", "knn_neighbors",
           "knn_indices", "delaunay_triangles",
           "Duplicates", "find_duplicates", "location_hash", "check_copies",
           "copies_degenerate", "map_rows",
           "refuse_dominated", "run_on_unique", "max_pairs", "Drivers", "make_drivers",
           "knn_cell_size", "GRID_CELL_CHUNK", "grid_block_ranges", "grid_candidate_count",
           "grid_knn_point", "grid_knn_scratch", "grid_guaranteed", "grid_block_2d",
           "grid_select_2d", "grid_walk_block_2d", "grid_cell_ranges", "grid_cell_block",
           "grid_knn_found", "grid_cells_may_share",
           "radix_order"]
