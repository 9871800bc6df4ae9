"""Large inputs: tiles with halos, tile catalogues with buffers, run one by one, in threads
or with Dask (local or a ``distributed`` cluster)."""

from .._shared._tiles import Tile, TileGrid, map_tiles, tile_grid
from ._catalogue import DEFAULT_TEMPLATE, BufferedTile, Catalogue, write_tiles
from ._catalogue_run import TileRun, process_catalogue
from ._methods import METHODS, SEGMENTATIONS, method_function, segmentation
from ._stream import process_file
from ._stream_labels import LabelMap
from ._stream_sample import FileSample, sample_file
from ._terrain import GROUND_CODES_DTM, terrain_model

__all__ = [
                         "DEFAULT_TEMPLATE",
                         "GROUND_CODES_DTM",
                         "METHODS",
                         "SEGMENTATIONS",
                         "BufferedTile",
                         "Catalogue",
                         "FileSample",
                         "LabelMap",
                         "Tile",
                         "TileGrid",
                         "TileRun",
                         "map_tiles",
                         "method_function",
                         "process_catalogue",
                         "process_file",
                         "sample_file",
                         "segmentation",
                         "terrain_model",
                         "tile_grid",
                         "write_tiles",
]
