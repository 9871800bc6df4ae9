"""Large inputs: tiles with halos, tile catalogues with buffers, run one by one, in threads
or with Dask (local or a ``distributed`` cluster)."""

from .._shared._tiles import Tile, TileGrid, map_tiles, tile_grid
from ._catalogue import (DEFAULT_TEMPLATE, BufferedTile, Catalogue, TileRun,
                         process_catalogue)
from ._methods import METHODS, SEGMENTATIONS, method_function, segmentation
from ._stream import process_file
from ._terrain import GROUND_CODES_DTM, terrain_model

__all__ = ["Tile", "TileGrid", "tile_grid", "map_tiles", "process_file", "Catalogue",
           "BufferedTile", "TileRun", "process_catalogue", "DEFAULT_TEMPLATE",
           "terrain_model", "GROUND_CODES_DTM",
           "METHODS", "SEGMENTATIONS", "method_function", "segmentation"]
