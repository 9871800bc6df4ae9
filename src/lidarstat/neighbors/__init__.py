"""CSR neighbourhoods from fixed-radius (3-D sphere, 2-D disc) and kNN queries."""

from ._csr import Neighborhoods
from ._drivers import Drivers, make_drivers
from ._query import CellIndex, knn_neighbors, radius_neighbors

__all__ = ["Neighborhoods", "CellIndex", "radius_neighbors", "knn_neighbors", "Drivers",
           "make_drivers"]
