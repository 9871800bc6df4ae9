"""Pictures and reports a person can open (PNG views of per-point fields)."""

from ._views import plot_field, plot_surface_types

__all__ = ["plot_field", "plot_surface_types"]
