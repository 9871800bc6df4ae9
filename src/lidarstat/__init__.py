"""lidarstat: statistically tested geometry for laser-scanning point clouds.

Subpackages (imported lazily, so ``import lidarstat`` stays cheap):

io         read and write LAS/LAZ, PLY, CSV/TXT and NPZ point clouds
neighbors  CSR neighbourhoods from radius (3-D sphere, 2-D disc) and kNN queries
features   local models per point (weighted quadric / Taylor fit, curvature)
stats      hypothesis tests on per-point estimates (chi-square, F, z, Bonferroni)
classify   surface types and other per-point classes
segment    region growing, segment tables, intersection lines, Hoover scores
pipeline   tiles with halos, streamed files, threads or Dask
synth      synthetic scenes with exact ground truth
cli        the ``lidarstat`` command
"""

from __future__ import annotations

import importlib
import logging

__version__ = "0.1.0"

_SUBPACKAGES = ("io", "neighbors", "features", "stats", "classify", "segment", "pipeline", "synth", "cli")
__all__ = [*_SUBPACKAGES, "read", "write", "curvature", "__version__"]

logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in ("read", "write"):
        return getattr(importlib.import_module(f"{__name__}.io"), name)
    if name == "curvature":
        return importlib.import_module(f"{__name__}.features").curvature
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
