"""Read and write LAS/LAZ, PLY, CSV/TXT and NPZ point clouds (atomic, lossless for LAS); read E57."""

from __future__ import annotations

from ._cloud import SUPPORTED_SUFFIXES, PointCloud, iter_chunks, read, rewrite, write
from ._extent import FileExtent, file_extent, read_window
from ._raster import Raster, read_geotiff, write_geotiff, write_vrt
from ._descriptions import field_description, register_field_descriptions
from ._info import describe, format_description
from ._sensor import SENSOR_SIDECAR_SUFFIX, read_sensor, sensor_sidecar, write_sensor
from ._units import UNIT_NAMES, LinearUnits, linear_units

__all__ = ["PointCloud", "read", "write", "describe", "format_description", "iter_chunks", "rewrite",
           "SUPPORTED_SUFFIXES", "read_sensor", "write_sensor", "sensor_sidecar",
           "SENSOR_SIDECAR_SUFFIX", "LinearUnits", "linear_units", "UNIT_NAMES",
           "register_field_descriptions", "field_description", "FileExtent", "file_extent",
           "read_window", "Raster", "write_geotiff", "read_geotiff", "write_vrt"]
