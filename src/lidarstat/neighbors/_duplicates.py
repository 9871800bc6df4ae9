"""Points that share a location: found once, by a sort, and handled by one policy.

A laser scanner can return the same coordinates more than once (overlapping strips
quantised to the same millimetre, a merged file holding a tile twice, a point cloud
padded with copies). Copies carry no new geometric information, yet a local model would
count every copy as an independent observation: its tests would gain degrees of freedom
they do not have, and an exact neighbour search around a location with ``m`` copies does
``m**2`` work (100,000 copies: 10**10 pairs).

The policy of the local models (curvature quadrics, jets and ridges) is therefore: every
location enters the model **once** (the unique cloud), and the result of a location is
written to every point at it, so every input point keeps its row and a cloud with copies
gives exactly the result of its unique cloud. Methods that cannot work on the unique cloud
refuse a cloud dominated by copies with :class:`~lidarstat.errors.DuplicatePointsError`,
naming the counts (:func:`refuse_dominated`).

Only exact copies (equal float64 coordinates) are merged: coordinates read from LAS/LAZ
are integers times a scale, so copies are exact, and any tolerance would change the
result on clouds that have none.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from .._shared._jit import kernel_array
from .._shared.validation import check_points
from ..errors import DuplicatePointsError, LidarstatError
from . import _kernels
from ._csr import Neighborhoods

logger = logging.getLogger("lidarstat")


@dataclass(frozen=True)
class Duplicates:
    """The distinct locations of a cloud and how often each occurs.

    Attributes
    ----------
    first : (U,) ndarray of int64
        Index of the first point at each distinct location, ascending (so
        ``points[first]`` is the unique cloud in input order).
    inverse : (N,) ndarray of int64
        Location of every input point: ``points == points[first][inverse]``.
    counts : (U,) ndarray of int64
        Number of points at each location.
    """

    first: np.ndarray
    inverse: np.ndarray
    counts: np.ndarray

    @property
    def n_points(self) -> int:
        """Number of input points N."""
        return int(self.inverse.size)

    @property
    def n_unique(self) -> int:
        """Number of distinct locations U."""
        return int(self.first.size)

    @property
    def n_copies(self) -> int:
        """Points beyond the first at their location, ``N - U``."""
        return self.n_points - self.n_unique

    @property
    def any(self) -> bool:
        """True when at least two points share a location."""
        return self.n_copies > 0

    @property
    def largest(self) -> int:
        """Most points at one location (0 for an empty cloud)."""
        return int(self.counts.max()) if self.counts.size else 0

    def broadcast(self, values):
        """Per-location `values` (first axis U) as per-point values (first axis N)."""
        return np.take(np.asarray(values), self.inverse, axis=0)

    def describe(self) -> str:
        """One clause for messages, e.g. ``100,000 points share 1 location``."""
        loc = "location" if self.n_unique == 1 else "locations"
        text = f"{self.n_points:,} points share {self.n_unique:,} {loc}"
        if self.n_unique > 1 and self.any:
            text += f" (up to {self.largest:,} at one)"
        return text


def find_duplicates(points) -> Duplicates:
    """Group the points by exact coordinates (one hashed pass, no per-point Python loop).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (any magnitude).

    Returns
    -------
    Duplicates

    Examples
    --------
    >>> d = find_duplicates([[0., 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 0]])
    >>> d.first.tolist(), d.inverse.tolist(), d.counts.tolist()
    ([0, 1], [0, 1, 0, 0], [3, 1])
    >>> d.describe()
    '4 points share 2 locations (up to 3 at one)'
    """
    pts = check_points(points, min_points=0)
    n = pts.shape[0]
    if n == 0:
        empty = np.zeros(0, dtype=np.int64)
        return Duplicates(empty, empty, empty)
    h = _row_hash(pts)
    s = np.sort(h)
    if not (s[1:] == s[:-1]).any():  # equal rows hash equally: every row is distinct
        every = np.arange(n, dtype=np.int64)
        return Duplicates(every, every.copy(), np.ones(n, dtype=np.int64))
    return Duplicates(*_kernels.unique_rows(pts, h))


def _row_hash(pts):
    """A 64-bit hash (as int64) of each row's coordinate bits; -0.0 hashes as 0.0."""
    pts = kernel_array(pts)
    return location_hash(pts[:, 0], pts[:, 1], pts[:, 2]).view(np.int64)


#: Rows hashed at a time: the strided columns are copied this many at a time.
_HASH_BLOCK = 1 << 18


def location_hash(x, y, z) -> np.ndarray:
    """A 64-bit hash (uint64) of the bits of every location ``(x[i], y[i], z[i])``, -0.0
    taken as 0.0: equal locations hash equally (the hash of :func:`find_duplicates`).

    The three float64 columns may be views of other arrays (the columns of an (N, 3) or
    (N, 2) array): one compiled pass (:func:`~._kernels.column_hash`) over blocks of
    rows, each column handed to it contiguous and writable (one compiled variant), so no
    copy of the cloud's size is made.

    Examples
    --------
    >>> import numpy as np
    >>> h = location_hash(np.array([0.0, -0.0, 1.0]), np.zeros(3), np.zeros(3))
    >>> bool(h[0] == h[1]), bool(h[0] == h[2])
    (True, False)
    """
    cols = [np.asarray(c) for c in (x, y, z)]
    n = cols[0].shape[0]
    out = np.empty(n, np.uint64)
    for a in range(0, n, _HASH_BLOCK):
        b = min(a + _HASH_BLOCK, n)
        bits = [kernel_array(c[a:b]).view(np.uint64) for c in cols]
        _kernels.column_hash(*bits, out[a:b])
    return out


def refuse_dominated(dup: Duplicates, *, what: str, max_share: float = 0.5,
                     max_copies: int | None = None) -> None:
    """Raise :class:`DuplicatePointsError` when copies dominate a cloud.

    A cloud is refused when more than `max_share` of its points are copies of another
    point, or when one location holds more than `max_copies` points (the exact
    neighbour searches of the method would do ``m**2`` work there).

    Parameters
    ----------
    dup : Duplicates
    what : str
        The method, named in the message (e.g. ``"segment --method covariance"``).
    max_share : float
        Largest acceptable share of copies.
    max_copies : int, optional
        Largest acceptable number of points at one location.
    """
    if not dup.any:
        return
    share = dup.n_copies / dup.n_points
    if share > max_share:
        why = f"{share:.0%} of them are copies"
    elif max_copies is not None and dup.largest > max_copies:
        why = f"more than {max_copies:,} at one location"
    else:
        return
    raise DuplicatePointsError(
        f"{dup.describe()} ({why}); {what} needs distinct locations: remove the duplicate "
        "points first")


def check_copies(points, *, what: str) -> Duplicates:
    """:func:`refuse_dominated` with the defaults of the segmentation methods.

    Refused: more than half of the points are copies, or one location holds more points
    than the square root of :func:`~lidarstat.neighbors.max_pairs` (its copies alone
    would make more neighbour pairs than the ceiling). Returns the :class:`Duplicates`.
    """
    from ._budget import max_pairs

    dup = find_duplicates(points)
    refuse_dominated(dup, what=what, max_copies=math.isqrt(max_pairs()))
    return dup


def run_on_unique(dup: Duplicates, run, *, what: str):
    """Call ``run()`` (a model on the unique cloud), adding the counts to its refusals.

    Logs one warning naming the counts. A refusal of the model (any
    :class:`~lidarstat.errors.LidarstatError`, e.g. too few neighbours everywhere) is
    raised again after :meth:`Duplicates.describe`, so a cloud of copies is refused for
    what it is.
    """
    logger.warning("%s: %s; each location enters the model once and its result is "
                   "written to every point at it", what, dup.describe())
    try:
        return run()
    except LidarstatError as exc:
        raise type(exc)(f"{dup.describe()} and each location counts once: {exc}") from None


def map_rows(obj, n_rows: int, rows):
    """`obj` with every per-point array (first axis `n_rows`) replaced by ``arr[rows]``.

    `obj` is an array, a dict of them, or a dataclass whose attributes are mapped
    recursively (other values, and :class:`Neighborhoods`, are kept). With
    ``rows = dup.inverse`` a result of the unique cloud becomes the result of every
    input point; with ``rows = dup.first`` a result given for the input cloud becomes
    one of its unique cloud.
    """
    if isinstance(obj, np.ndarray):
        return np.take(obj, rows, axis=0) if obj.ndim and obj.shape[0] == n_rows else obj
    if isinstance(obj, dict):
        return {k: map_rows(v, n_rows, rows) for k, v in obj.items()}
    if (dataclasses.is_dataclass(obj) and not isinstance(obj, type)
            and not isinstance(obj, Neighborhoods)):  # CSR rows are not per-point arrays
        changes = {f.name: map_rows(getattr(obj, f.name), n_rows, rows)
                   for f in dataclasses.fields(obj) if f.init}
        return dataclasses.replace(obj, **changes)
    return obj


def copies_degenerate(dup: Duplicates, status, *, too_few, degenerate, min_neighbors):
    """Statuses of the unique cloud, with "too few" turned into "degenerate" at clumps.

    A location that by itself holds at least `min_neighbors` points (copies) has enough
    points and no geometry: its status becomes `degenerate`, as the singular fit of all
    its copies gave, not `too_few`. Elsewhere the statuses are those of the unique cloud
    (a doubled cloud gives exactly its unique cloud's).

    Returns
    -------
    (U,) ndarray
        A copy of `status`.
    """
    status = np.array(status, copy=True)
    status[(status == too_few) & (dup.counts >= min_neighbors)] = degenerate
    return status
