"""Pictures and reports a person can open: PNG views and maps, and one HTML page per run."""

from ._demo import DEMO_FILES, run_demo
from ._fs_plots import plot_forward_search, plot_forward_search_units
from ._maps import (
           ASPRS_COLOURS,
           class_grid,
           hillshade,
           plot_class_map,
           plot_flag_map,
           plot_hillshade,
    plot_segment_map,
    plot_value_map,
)
from ._moments import write_moments_report
from ._page import ReportPage
from ._run import map_resolution, write_run_report
from ._views import plot_field, plot_surface_types

__all__ = [
           "ASPRS_COLOURS",
           "DEMO_FILES",
           "ReportPage",
           "class_grid",
           "hillshade",
           "map_resolution",
           "plot_class_map",
           "plot_field",
           "plot_flag_map",
           "plot_forward_search",
           "plot_forward_search_units",
           "plot_hillshade",
           "plot_segment_map",
           "plot_surface_types",
           "plot_value_map",
           "run_demo",
           "write_moments_report",
           "write_run_report",
]
