"""Private helpers shared by every subpackage (validation, atomic writes, JIT defaults).

Also what more than one layer needs and none of them owns: the shared Numba kernels
(3x3 eigen-solver, grid kNN), scan geometry and point spacing, and the tile driver that
:mod:`lidarstat.pipeline` publishes.  Imports only :mod:`lidarstat.errors`.
"""
