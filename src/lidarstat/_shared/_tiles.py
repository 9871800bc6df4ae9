"""Planimetric tiles with halos, and running a per-point method tile by tile.

Published as :mod:`lidarstat.pipeline`; the tile driver lives below every method so that a
method that is tiled by construction (the moments classification) can use it.

Every lidarstat method is a function of each point's neighbourhood, so a tile extended
by a halo at least as wide as the neighbourhood gives its core points exactly the answer
the whole cloud gives. Tiles run one after the other, in threads (the Numba kernels
release the GIL) or as Dask tasks (local or distributed), and only the core points'
results are kept.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .._shared._columns import column_max, column_min
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError


@dataclass(frozen=True)
class Tile:
    """One tile: its core square and the points of core plus halo.

    Attributes
    ----------
    key : tuple of int
        (column, row) of the tile in the grid.
    bounds : tuple of float
        Core square ``(xmin, ymin, xmax, ymax)``.
    points : (M,) ndarray of int64
        Indices of the core and halo points, increasing.
    core : (M,) ndarray of bool
        Which of `points` lie in the core (each point is core in exactly one tile).
    """

    key: tuple
    bounds: tuple
    points: np.ndarray
    core: np.ndarray

    @property
    def n_core(self) -> int:
        """Number of core points."""
        return int(np.count_nonzero(self.core))


@dataclass(frozen=True)
class TileGrid:
    """A grid of square tiles of side `size` from `origin`, `ncol` x `nrow`, with a halo."""

    origin: tuple
    size: float
    halo: float
    ncol: int
    nrow: int

    @classmethod
    def covering(cls, lo, hi, size, halo) -> "TileGrid":
        """The grid whose tiles cover the planimetric box ``lo``..``hi``."""
        n = np.floor((np.asarray(hi, float) - np.asarray(lo, float)) / size).astype(int) + 1
        return cls((float(lo[0]), float(lo[1])), float(size), float(halo), int(n[0]),
                   int(n[1]))

    def key_of(self, flat: int) -> tuple:
        """(column, row) of a flat tile number."""
        return divmod(int(flat), self.nrow)

    def bounds(self, flat: int) -> tuple:
        """Core square ``(xmin, ymin, xmax, ymax)`` of a flat tile number."""
        cx, cy = self.key_of(flat)
        x0 = self.origin[0] + cx * self.size
        y0 = self.origin[1] + cy * self.size
        return (x0, y0, x0 + self.size, y0 + self.size)

    def memberships(self, xy, first_index: int = 0):
        """Every (point, tile) pair of core or halo membership.

        Returns
        -------
        pid : (P,) int64
            Point index (plus `first_index`, for chunks of a file).
        key : (P,) int64
            Flat tile number, ``column * nrow + row``.
        is_core : (P,) bool
        """
        size, halo = self.size, self.halo
        rel = (np.asarray(xy, float) - self.origin) / size
        cell = np.floor(rel).astype(np.int64)
        if cell.size and (cell.min() < 0 or cell[:, 0].max() >= self.ncol
                          or cell[:, 1].max() >= self.nrow):
            raise InvalidParameterError("points lie outside the tile grid (stale bounds?)")
        n = len(cell)
        idx = np.arange(n, dtype=np.int64) + first_index
        if halo == 0:  # core memberships only
            return idx, cell[:, 0] * self.nrow + cell[:, 1], np.ones(n, bool)
        off = (rel - cell) * size  # position inside the core square
        lo = off < halo
        hi = (size - off) <= halo
        every = np.ones(n, bool)
        pid, key, is_core = [], [], []
        for dx in (-1, 0, 1):
            # dx = 1: the point is near the low border of its cell, so the tile at
            # cell - 1 gets it as halo; dx = -1: near the high border, tile cell + 1.
            sx = every if dx == 0 else (lo[:, 0] if dx == 1 else hi[:, 0])
            for dy in (-1, 0, 1):
                sy = every if dy == 0 else (lo[:, 1] if dy == 1 else hi[:, 1])
                sel = sx & sy
                cx = cell[sel, 0] - dx
                cy = cell[sel, 1] - dy
                ok = (cx >= 0) & (cx < self.ncol) & (cy >= 0) & (cy < self.nrow)
                pid.append(idx[sel][ok])
                key.append(cx[ok] * self.nrow + cy[ok])
                is_core.append(np.full(int(ok.sum()), dx == 0 and dy == 0))
        return np.concatenate(pid), np.concatenate(key), np.concatenate(is_core)


def tile_grid(xyz, size: float, halo: float = 0.0, *, anchor=None) -> list[Tile]:
    """Cut a cloud into square planimetric tiles of side `size` with a `halo` around each.

    Parameters
    ----------
    xyz : (N, 3) array
    size : float
        Side of the core squares (same unit as the coordinates).
    halo : float, default 0
        Width of the band around a core square whose points are added to the tile as
        context; must be smaller than `size`.
    anchor : (x, y), optional
        A corner of the grid (tiles at ``anchor + size * k``); default the points' lower
        corner. A fixed anchor gives every part of an area the same grid.

    Returns
    -------
    list of Tile
        Tiles with at least one core point, in (column, row) order.

    Examples
    --------
    >>> xyz = np.c_[[0.0, 0.9, 1.5, 2.2], np.zeros(4), np.zeros(4)]
    >>> for t in tile_grid(xyz, 1.0, 0.3):
    ...     print(t.key, t.points.tolist(), t.core.tolist())
    (0, 0) [0, 1] [True, True]
    (1, 0) [1, 2, 3] [False, True, False]
    (2, 0) [3] [True]
    """
    xyz = check_points(xyz, name="xyz", min_points=1)
    size = check_scalar(size, "size", func="tile_grid", low=0, closed="neither")
    halo = check_scalar(halo, "halo", func="tile_grid", low=0, high=size, closed="left")
    xy = xyz[:, :2]
    lo = column_min(xy)
    if anchor is not None:
        lo = np.asarray(anchor, float) + size * np.floor((lo - np.asarray(anchor, float)) / size)
    grid = TileGrid.covering(lo, column_max(xy), size, halo)
    pid, key, is_core = grid.memberships(xy)
    if halo > 0:
        order = np.lexsort((pid, key))
    else:  # only core memberships, pid already increasing: a stable sort of the keys
        order = np.argsort(key, kind="stable")
    pid, key, is_core = pid[order], key[order], is_core[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ends = np.r_[starts[1:], key.size]
    tiles = []
    for s, e in zip(starts, ends):
        if not is_core[s:e].any():
            continue
        tiles.append(Tile(key=grid.key_of(int(key[s])), bounds=grid.bounds(int(key[s])),
                          points=pid[s:e], core=is_core[s:e]))
    return tiles


def _fields_of(result, n, key):
    fields = result.to_fields() if hasattr(result, "to_fields") else result
    if not isinstance(fields, dict):
        raise InvalidParameterError(
            f"tile {key}: the function must return a dict of per-point arrays or an object "
            f"with to_fields(), got {type(result).__name__}")
    out = {}
    for name, arr in fields.items():
        arr = np.asarray(arr)
        if arr.shape[:1] != (n,):
            raise InvalidParameterError(
                f"tile {key}: field '{name}' has {arr.shape[:1]} rows for {n} points")
        out[name] = arr
    return out


def _block(points):
    """The slice of a tile's points when they are a block of consecutive rows, else None.

    A tile's points are increasing and distinct, so they are consecutive exactly when the
    last is ``size - 1`` past the first."""
    m = points.size
    if m and int(points[-1]) - int(points[0]) == m - 1:
        return slice(int(points[0]), int(points[0]) + m)
    return None


def _read_only(view):
    view.flags.writeable = False
    return view


def map_tiles(func: Callable, xyz, *, size: float | None = None, halo: float = 0.0,
              scheduler: str = "sync", workers: int | None = None, progress=None,
              tiles: list | None = None, attributes: dict | None = None,
              collect: Callable | None = None, views: bool = False) -> dict[str, np.ndarray]:
    """Run ``func(xyz_of_tile)`` on every tile and assemble the core points' results.

    Parameters
    ----------
    func : callable
        ``func(points) -> dict`` of per-point arrays (or an object with ``to_fields()``,
        such as :class:`~lidarstat.features.CurvatureResult`) for the (M, 3) points of a
        tile, core and halo. Anything estimated from the whole cloud (a noise level, say)
        must be fixed in `func` beforehand, or tiles would estimate it each on their own.
        With `attributes`, it is called as ``func(points, attributes_of_tile)``.
    xyz : (N, 3) array or None
        None: the points are their `attributes` alone (given `tiles`), and `func` is
        called as ``func(attributes_of_tile)`` (a caller holding its columns apart
        makes no (N, 3) array for them).
    size : float
        Core tile side (not needed when `tiles` is given).
    halo : float
        At least the neighbourhood radius of `func` (planimetric), so that every core
        point sees its whole neighbourhood; then the result equals the untiled one.
    scheduler : {'sync', 'threads', 'dask'}, default 'sync'
        'threads' runs tiles in a thread pool of `workers`; 'dask' builds one
        ``dask.delayed`` task per tile and computes them with Dask's current scheduler
        (a ``distributed.Client`` if one is active, for clusters).
    workers : int, optional
        Threads for 'threads'.
    progress : callable, optional
        ``progress(done_points, total_points)`` after each tile.
    tiles : list of Tile, optional
        Tiles from :func:`tile_grid` on the same points, reused instead of cutting the
        cloud again (a method that runs several passes over the same tiles).
    attributes : dict of str to (N,) ndarray, optional
        Per-point arrays handed to `func` cut to each tile's points (intensity, ...).
    collect : callable, optional
        ``collect(tile, result)``, called in the calling thread for every tile in tile
        order, to gather what a result holds beyond its per-point fields (reports).
    views : bool, default False
        Hand `func` read-only views of `xyz` and `attributes` for a tile whose points
        are consecutive rows (a cloud sorted tile by tile) instead of copies; `func` must
        then not write into its inputs.

    Returns
    -------
    dict of str to (N,) ndarray
        Each field of `func`'s result for every point of `xyz`.

    Examples
    --------
    >>> xyz = np.c_[np.arange(6.0), np.zeros(6), np.arange(6.0)]
    >>> seen = []
    >>> out = map_tiles(lambda p, a: {"z2": p[:, 2] * a["w"]}, xyz, size=2.0,
    ...                 attributes={"w": np.full(6, 2.0)},
    ...                 collect=lambda t, r: seen.append(t.key))
    >>> out["z2"].tolist(), seen
    ([0.0, 2.0, 4.0, 6.0, 8.0, 10.0], [(0, 0), (1, 0), (2, 0)])
    """
    if xyz is None:  # the points are their attributes alone: ``func(attributes)``
        if tiles is None or not attributes:
            raise InvalidParameterError("map_tiles without `xyz` needs `tiles` and "
                                        "`attributes`")
        n = len(next(iter(attributes.values())))
    else:
        xyz = check_points(xyz, name="xyz", min_points=1)
        n = len(xyz)
    check_option(scheduler, "scheduler", ("sync", "threads", "dask"), func="map_tiles")
    if workers is not None:
        workers = check_scalar(workers, "workers", func="map_tiles", low=1, closed="left",
                               integer=True)
    if tiles is None:
        if size is None:
            raise InvalidParameterError("map_tiles needs `size` or precomputed `tiles`")
        tiles = tile_grid(xyz, size, halo)
    if attributes is not None:
        attributes = {name: np.asarray(a) for name, a in attributes.items()}
        for name, a in attributes.items():
            if a.shape[:1] != (n,):
                raise InvalidParameterError(
                    f"map_tiles: attribute '{name}' has {a.shape[:1]} rows for "
                    f"{n} points")
    out: dict[str, np.ndarray] = {}
    done = 0

    def put(tile, result):
        nonlocal done
        if collect is not None:
            collect(tile, result)
        fields = _fields_of(result, tile.points.size, tile.key)
        block = _block(tile.points)
        whole = block is not None and bool(tile.core.all())
        rows = block if whole else tile.points[tile.core]
        for name, arr in fields.items():
            if name not in out:
                out[name] = np.zeros((n,) + arr.shape[1:], dtype=arr.dtype)
            out[name][rows] = arr if whole else arr[tile.core]
        done += tile.points.size if whole else rows.size
        if progress is not None:
            progress(done, n)

    def args(tile):
        rows = _block(tile.points) if views else None
        if xyz is None:
            if rows is None:
                return ({name: a[tile.points] for name, a in attributes.items()},)
            return ({name: _read_only(a[rows]) for name, a in attributes.items()},)
        if rows is None:
            if attributes is None:
                return (xyz[tile.points],)
            return xyz[tile.points], {name: a[tile.points] for name, a in attributes.items()}
        if attributes is None:
            return (_read_only(xyz[rows]),)
        return _read_only(xyz[rows]), {name: _read_only(a[rows])
                                       for name, a in attributes.items()}

    def one(tile):
        return func(*args(tile))

    if scheduler == "sync":
        for t in tiles:
            put(t, one(t))
    elif scheduler == "threads":
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for t, res in zip(tiles, pool.map(one, tiles)):
                put(t, res)
    else:
        try:
            import dask
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise InvalidParameterError(
                "scheduler='dask' needs Dask: pip install 'lidarstat[dask]'") from exc
        tasks = [dask.delayed(func)(*args(t)) for t in tiles]
        for t, res in zip(tiles, dask.compute(*tasks)):
            put(t, res)
    return out
