"""Read and write LAS/LAZ, PLY, CSV/TXT and NPZ point clouds (atomic, lossless for LAS)."""

from __future__ import annotations

from ._cloud import SUPPORTED_SUFFIXES, PointCloud, iter_chunks, read, rewrite, write
from ._info import describe, format_description
from ._units import UNIT_NAMES, LinearUnits, linear_units

__all__ = ["PointCloud", "read", "write", "describe", "format_description", "iter_chunks", "rewrite",
           "SUPPORTED_SUFFIXES", "LinearUnits", "linear_units", "UNIT_NAMES"]
