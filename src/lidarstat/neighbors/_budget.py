"""The neighbour-pair ceiling: a neighbourhood query is sized before anything is allocated.

Memory and time of a fixed-radius query grow with the number of neighbour pairs, which
no option bounds: 100,000 points within one radius make 10**10 pairs (160 GB of CSR
arrays, and as many distance computations). Every query of
:class:`~lidarstat.neighbors.CellIndex` therefore bounds the pairs of the points it is
about to search, in three steps of increasing cost, before it allocates:

1. an upper bound from the cell populations (the points of the 27 or 9 cells around
   each query point, O(cells)): below the ceiling, the query runs as before;
2. a lower bound from a grid of half-radius cells, whose points are all within the
   radius of each other (O(N log N), only when step 1 exceeds the ceiling): above the
   ceiling, the query is refused at once (a cloud of copies is refused here, in
   milliseconds);
3. the exact count of the search's counting pass, checked before the CSR is allocated.

The ceiling is :func:`max_pairs`: the environment variable ``LIDARSTAT_MAX_PAIRS`` when
set, else as many pairs as a quarter of the physical memory holds (16 bytes a pair: an
int64 index and a float64 distance).
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InvalidParameterError, TooManyNeighborsError
from .._shared._memory import physical_memory

#: Bytes of one neighbour pair in a CSR neighbourhood (int64 index + float64 distance).
PAIR_BYTES = 16

#: Fallback ceiling when the physical memory is unknown.
_DEFAULT_PAIRS = 1 << 28


def max_pairs() -> int:
    """The largest number of neighbour pairs one query may produce.

    ``LIDARSTAT_MAX_PAIRS`` (a positive integer) when set, else a quarter of the physical
    memory divided by :data:`PAIR_BYTES` (at least 2**26).

    Examples
    --------
    >>> max_pairs() > 0
    True
    """
    env = os.environ.get("LIDARSTAT_MAX_PAIRS")
    if env:
        try:
            value = int(float(env))
        except ValueError:
            value = 0
        if value <= 0:
            raise InvalidParameterError(
                f"LIDARSTAT_MAX_PAIRS must be a positive integer; got {env!r}")
        return value
    mem = physical_memory()
    if not mem:
        return _DEFAULT_PAIRS
    return max(1 << 26, mem // 4 // PAIR_BYTES)


def _size(nbytes: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if nbytes < 1000 or unit == "TB":
            return f"{nbytes:.0f} {unit}" if unit == "bytes" else f"{nbytes:.1f} {unit}"
        nbytes /= 1000
    return ""  # pragma: no cover


def refuse_pairs(pairs: int, *, radius: float, exact: bool, ceiling: int,
                 n_query: int | None = None) -> None:
    """Raise :class:`TooManyNeighborsError` for a query of `pairs` neighbour pairs."""
    amount = f"{pairs:,}" if exact else f"at least {pairs:,}"
    per = "" if not n_query else f", {pairs / n_query:,.0f} per point"
    raise TooManyNeighborsError(
        f"radius {radius:g} gives {amount} neighbour pairs ({_size(pairs * PAIR_BYTES)}"
        f"{per}), above the ceiling of {ceiling:,} (LIDARSTAT_MAX_PAIRS); lower the radius "
        "or thin the cloud")


def half_radius_population(points_local, queries_local, radius, dim):
    """Points of `points_local` in the half-radius cell of each query point.

    Every point of a cell of side ``radius / 2`` lies within `radius` of every other
    (the cell's diagonal is ``radius * sqrt(dim) / 2 < radius``), so the sum over the
    queries is a lower bound of the pairs of a radius query.

    Returns
    -------
    (M,) ndarray of int64
    """
    from ._duplicates import find_duplicates

    h = radius / 2.0
    lim = float(1 << 52)  # integers exact in float64

    def keys(p):
        k = np.zeros((p.shape[0], 3))
        with np.errstate(over="ignore", invalid="ignore"):
            k[:, :dim] = np.floor(p[:, :dim] / h)
        return np.clip(k, -lim, lim, out=k)

    kc = keys(points_local)
    n = kc.shape[0]
    cells = find_duplicates(np.concatenate([kc, keys(queries_local)]))
    counts = np.bincount(cells.inverse[:n], minlength=cells.n_unique)
    return counts[cells.inverse[n:]].astype(np.int64)
