"""Per-point classes: HK surface types (seed 000)."""

from ._hk import SurfaceType, hk_surface_types

__all__ = ["SurfaceType", "hk_surface_types"]
