"""CSR neighbourhoods from fixed-radius (3-D sphere, 2-D disc) and kNN queries.

Every query is sized before it allocates (:func:`max_pairs`); points sharing a location
are found by :func:`find_duplicates` (the policy of the local models is in
``lidarstat.neighbors._duplicates``).
"""

from ._budget import max_pairs
from ._csr import Neighborhoods
from ._drivers import Drivers, make_drivers
from ._duplicates import (Duplicates, check_copies, copies_degenerate, find_duplicates,
                          map_rows, refuse_dominated, run_on_unique)
from ._query import CellIndex, knn_neighbors, radius_neighbors

__all__ = ["Neighborhoods", "CellIndex", "radius_neighbors", "knn_neighbors",
           "Duplicates", "find_duplicates", "check_copies", "copies_degenerate", "map_rows",
           "refuse_dominated", "run_on_unique", "max_pairs", "Drivers", "make_drivers"]
