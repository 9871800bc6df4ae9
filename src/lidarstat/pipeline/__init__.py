"""Large inputs: planimetric tiles with halos, run one by one, in threads or with Dask."""

from .._shared._tiles import Tile, TileGrid, map_tiles, tile_grid
from ._stream import process_file

__all__ = ["Tile", "TileGrid", "tile_grid", "map_tiles", "process_file"]
