"""The one place where Numba compilation defaults are set.

Every kernel uses ``@njit`` or ``@njit_parallel`` from here: ``cache=True`` so tests and the
CLI load compiled code from ``__pycache__`` instead of recompiling at every start,
``nogil=True`` so kernels can run in threads (Dask), ``fastmath=False`` because the
statistics rely on IEEE semantics (NaN propagation, no reassociation of the moment sums).
"""

from __future__ import annotations

import numba

_DEFAULTS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


def njit(*args, **kwargs):
    """``numba.njit`` with lidarstat's defaults."""
    opts = {**_DEFAULTS, **kwargs}
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


def njit_parallel(func):
    """``numba.njit(parallel=True)`` with lidarstat's defaults."""
    return numba.njit(parallel=True, **_DEFAULTS)(func)
