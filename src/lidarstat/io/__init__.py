"""Read and write LAS/LAZ, PLY, CSV/TXT and NPZ point clouds (atomic, lossless for LAS); read E57.

The names are loaded on first use (PEP 562), so that a command imports the readers,
writers and rasters it uses, not all of them.
"""

from __future__ import annotations

from importlib import import_module

#: Public name -> the module of this package that defines it.
_WHERE = {
    **dict.fromkeys(("SUPPORTED_SUFFIXES", "PointCloud", "iter_chunks", "read", "rewrite",
                     "write"), "._cloud"),
    **dict.fromkeys(("FileExtent", "file_extent", "read_window"), "._extent"),
    **dict.fromkeys(("Raster", "read_geotiff", "write_geotiff", "write_vrt"), "._raster"),
    **dict.fromkeys(("field_description", "register_field_descriptions"), "._descriptions"),
    **dict.fromkeys(("describe", "format_description"), "._info"),
    **dict.fromkeys(("SENSOR_SIDECAR_SUFFIX", "read_sensor", "sensor_sidecar", "write_sensor"),
                    "._sensor"),
    **dict.fromkeys(("UNIT_NAMES", "LinearUnits", "linear_units"), "._units"),
}

__all__ = ["PointCloud", "read", "write", "describe", "format_description", "iter_chunks", "rewrite",
           "SUPPORTED_SUFFIXES", "read_sensor", "write_sensor", "sensor_sidecar",
           "SENSOR_SIDECAR_SUFFIX", "LinearUnits", "linear_units", "UNIT_NAMES",
           "register_field_descriptions", "field_description", "FileExtent", "file_extent",
           "read_window", "Raster", "write_geotiff", "read_geotiff", "write_vrt"]


def __getattr__(name: str):
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(where, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
