"""lidarstat: statistically tested geometry for laser-scanning point clouds.

Subpackages (imported lazily, so ``import lidarstat`` stays cheap):

io         read and write LAS/LAZ, PLY, CSV/TXT and NPZ point clouds
neighbors  CSR neighbourhoods from radius (3-D sphere, 2-D disc) and kNN queries
features   local models per point (weighted quadric / Taylor fit, curvature)
stats      hypothesis tests on per-point estimates (chi-square, F, z, Bonferroni)
classify   surface types and other per-point classes
segment    region growing, segment tables, intersection lines, Hoover scores
pipeline   tiles with halos, catalogues of tiles, threads or Dask; terrain models;
           the methods layer (one entry per method, ``lidarstat.segmentation``)
report     maps and the HTML report of a run
synth      synthetic scenes with exact ground truth
cli        the ``lidarstat`` command
"""

from __future__ import annotations

import importlib
import logging

__version__ = "0.1.0"

_SUBPACKAGES = ("io", "neighbors", "features", "stats", "classify", "segment", "pipeline",
                "report", "synth", "cli")
#: The methods, one end-to-end function each (lidarstat.pipeline.METHODS), and the
#: segmentation by method name.
_METHODS = ("curvature", "jets", "ridges", "covariance", "moments")
__all__ = [*_SUBPACKAGES, "read", "write", *_METHODS, "segmentation", "__version__"]

logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in ("read", "write"):
        return getattr(importlib.import_module(f"{__name__}.io"), name)
    if name in _METHODS:
        return importlib.import_module(f"{__name__}.pipeline").method_function(name)
    if name == "segmentation":
        return importlib.import_module(f"{__name__}.pipeline").segmentation
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
