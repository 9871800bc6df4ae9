"""The ``lidarstat`` command: one subcommand per job, each a thin shell over the library."""

from ._app import build_parser, main, run

__all__ = ["main", "build_parser", "run"]
