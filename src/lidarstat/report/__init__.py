"""Pictures and reports a person can open (PNG views of per-point fields)."""

from ._demo import DEMO_FILES, run_demo
from ._fs_plots import plot_forward_search, plot_forward_search_units
from ._moments import write_moments_report
from ._views import plot_field, plot_surface_types

__all__ = ["plot_field", "plot_surface_types", "plot_forward_search", "plot_forward_search_units",
           "write_moments_report", "run_demo", "DEMO_FILES"]
