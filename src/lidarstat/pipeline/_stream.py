"""Out-of-core processing of a point-cloud file, tile by tile with halos.

Memory holds one input chunk, or the tiles being processed, at a time; it does not grow
with the file. The steps:

1. stream the file once for its planimetric bounds;
2. stream it again, appending each point (index, x, y, z) of every tile whose core or
   halo contains it to a scratch file, as one run of records per tile and input chunk;
3. run the method on each tile (one after the other, in threads, or as Dask tasks) and
   append its core points' results, with their point numbers, to a second scratch file,
   one run per output chunk and field (the points of a tile are spread over the whole
   file, so results written into file-sized arrays would touch every page of them for
   every tile: memory would grow with the file);
4. stream the input a third time, writing every original field plus the results chunk by
   chunk to a temporary output linked into place when complete; each chunk's results are
   read back from its own runs.

The scratch files have no name (:func:`lidarstat._shared._atomic.unnamed_file`): the
kernel frees them however the process ends, SIGKILL included. In memory there is only
an index of the runs, ``(offset, count)`` per tile and input chunk, and per output chunk
and field.
"""

from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .._shared._atomic import unnamed_file
from .._shared._tiles import Tile, TileGrid, _fields_of
from .._shared.validation import check_option, check_scalar
from ..errors import InvalidPointsError
from ..io import iter_chunks, rewrite
from ._stream_labels import LINK, Labels

_REC = np.dtype([("i", "<i8"), ("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("core", "u1")])


def _bounds(src, points_per_chunk):
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    n = 0
    for chunk in iter_chunks(src, points_per_chunk):
        xy = chunk.xyz[:, :2]
        if not np.all(np.isfinite(chunk.xyz)):
            raise InvalidPointsError(f"{src}: NaN or infinite coordinates")
        if len(xy):
            lo = np.minimum(lo, xy.min(axis=0))
            hi = np.maximum(hi, xy.max(axis=0))
        n += len(xy)
    if n == 0:
        raise InvalidPointsError(f"{src}: the file holds no points")
    return lo, hi, n


class _Scratch:
    """Runs of records appended to one unnamed file, indexed by key in memory.

    Appends come from one thread; reads (``os.pread``) may come from several.
    """

    def __init__(self, directory):
        self._fh = unnamed_file(directory)
        self._fd = self._fh.fileno()
        self._end = 0
        self.runs: dict = defaultdict(list)  # key -> [(offset, count), ...]

    def append(self, key, rec: np.ndarray) -> None:
        """Append the records `rec` to the runs of `key`."""
        view = memoryview(np.ascontiguousarray(rec)).cast("B")
        start = self._end
        while view:
            n = os.pwrite(self._fd, view, self._end)
            view = view[n:]
            self._end += n
        self.runs[key].append((start, len(rec)))

    def read(self, key, dtype: np.dtype) -> np.ndarray:
        """Every record of `key`, in the order appended (empty when none)."""
        parts = [np.frombuffer(self._pread(off, cnt * dtype.itemsize), dtype=dtype)
                 for off, cnt in self.runs.get(key, ())]
        return np.concatenate(parts) if parts else np.empty(0, dtype)

    def _pread(self, offset: int, size: int) -> bytes:
        parts = []
        while size > 0:
            block = os.pread(self._fd, size, offset)
            if not block:
                raise EOFError("scratch file shorter than its index")
            parts.append(block)
            offset, size = offset + len(block), size - len(block)
        return b"".join(parts) if len(parts) != 1 else parts[0]

    def close(self) -> None:
        self._fh.close()


def _bucket(src, grid, scratch, points_per_chunk):
    """Append every point to its tiles' runs in `scratch`; return the tile numbers used."""
    start = 0
    for chunk in iter_chunks(src, points_per_chunk):
        pid, key, core = grid.memberships(chunk.xyz[:, :2], first_index=start)
        order = np.argsort(key, kind="stable")
        pid, key, core = pid[order], key[order], core[order]
        cuts = np.flatnonzero(np.r_[True, key[1:] != key[:-1], True])
        for s, e in zip(cuts[:-1], cuts[1:]):
            rec = np.empty(e - s, _REC)
            rows = pid[s:e] - start
            rec["i"] = pid[s:e]
            rec["x"], rec["y"], rec["z"] = chunk.xyz[rows].T
            rec["core"] = core[s:e]
            scratch.append(int(key[s]), rec)
        start += len(chunk)
    return sorted(scratch.runs)


def process_file(func: Callable, src, dst, *, size: float, halo: float,
                 scheduler: str = "sync", workers: int | None = None,
                 points_per_chunk: int = 1_000_000, workdir=None, progress=None,
                 with_tile: bool = False, labels: dict | None = None,
                 collect: Callable | None = None, finish: Callable | None = None) -> Path:
    """Run a per-point method on a file tile by tile and write its results beside the input's.

    Parameters
    ----------
    func : callable
        ``func(points) -> dict`` of per-point arrays (or an object with ``to_fields()``)
        for the (M, 3) points of one tile with its halo. Fix any whole-cloud estimate
        (noise level, thresholds) beforehand. It may return ``(fields, info)``: `info`
        goes to `collect`.
    src, dst : path-like
        Input (never modified) and output point-cloud files. LAS/LAZ to LAS/LAZ streams;
        other formats are read and written whole (the tiles still bound the method's
        working memory).
    size : float
        Core tile side (planimetric, in the file's units).
    halo : float
        At least the method's neighbourhood radius: the result then equals the untiled
        one.
    scheduler : {'sync', 'threads', 'dask'}
        How tiles run (see :func:`map_tiles`).
    workers : int, optional
        Threads for 'threads' (default: the CPU count).
    points_per_chunk : int
        Points per streamed chunk of the input.
    workdir : path-like, optional
        Folder (file system) of the two unnamed scratch files (tile buckets, results);
        default `dst`'s folder. Nothing named is created there.
    progress : callable, optional
        ``progress(done_points, total_points)``.
    with_tile : bool
        Call ``func(points, tile)``, `tile` a :class:`Tile` (its key, core square, point
        numbers and core flags; `points` in the file's order).
    labels : dict of str to bool, optional
        Label fields of `func`'s result (integers, 0 = none, numbered from 1 per tile):
        written with ids unique over the file; a field mapped to True is also *joined*
        across tiles, two tiles' labels becoming one id where they hold the same points
        of the tiles' overlap (see ``lidarstat.pipeline._stream_labels``; a surface
        crossing a tile border keeps one id).
    collect : callable, optional
        ``collect(tile, info, bases)`` in the calling thread for every tile, in order:
        `info` as `func` returned it, `bases` the number added to the tile's labels of
        each field of `labels` (its *nodes*).
    finish : callable, optional
        ``finish(maps)`` once every tile has run, before the output is written: `maps`
        maps each field of `labels` to a :class:`LabelMap` (node -> id written, core
        points per node), for outputs beside the points (tables, lines).

    Returns
    -------
    Path
        `dst`.
    """
    src, dst = Path(src), Path(dst)
    check_option(scheduler, "scheduler", ("sync", "threads", "dask"), func="process_file")
    size = check_scalar(size, "size", func="process_file", low=0, closed="neither")
    halo = check_scalar(halo, "halo", func="process_file", low=0, high=size, closed="left")
    if workers is not None:
        workers = check_scalar(workers, "workers", func="process_file", low=1, closed="left",
                               integer=True)
    points_per_chunk = check_scalar(points_per_chunk, "points_per_chunk", func="process_file",
                                    low=1, closed="left", integer=True)
    lo, hi, n = _bounds(src, points_per_chunk)
    grid = TileGrid.covering(lo, hi, size, halo)
    parent = Path(workdir) if workdir is not None else dst.parent
    buckets = _Scratch(parent)
    results = _Scratch(parent)
    try:
        _run_tiles(func, src, dst, grid, n, buckets, results, scheduler=scheduler,
                   workers=workers, points_per_chunk=points_per_chunk, progress=progress,
                   with_tile=with_tile, labels=labels or {}, collect=collect,
                   finish=finish)
    finally:
        buckets.close()
        results.close()
    return dst


def _shared_rows(xyz, core, bounds, halo):
    """Rows of a tile that another tile also holds: its halo, and its core points within
    `halo` of its border (a little wider: an extra row pairs with nothing)."""
    x0, y0, x1, y1 = bounds
    h = halo * (1 + 1e-9) + 1e-9 * (x1 - x0)
    x, y = xyz[:, 0], xyz[:, 1]
    near = (x - x0 < h) | (x1 - x < h) | (y - y0 < h) | (y1 - y < h)
    return ~core | near


def _run_tiles(func, src, dst, grid, n, buckets, results, *, scheduler, workers,
               points_per_chunk, progress, with_tile=False, labels=None, collect=None,
               finish=None):
    """Steps 2-4 of :func:`process_file`, with its scratch files `buckets` and `results`."""
    keys = _bucket(src, grid, buckets, points_per_chunk)
    # name -> (number, dtype, trailing shape) of every result field, first come
    registry: dict[str, tuple] = {}
    state = {name: Labels(name, bool(join)) for name, join in (labels or {}).items()}
    written: dict[str, np.dtype] = {}  # dtype of each label field (stored as nodes)
    done = 0
    tiles_run = 0

    def compute(key):
        rec = buckets.read(key, _REC)
        core = rec["core"].astype(bool)
        if not core.any():
            return None
        xyz = np.c_[rec["x"], rec["y"], rec["z"]]
        tile = Tile(grid.key_of(key), grid.bounds(key), rec["i"], core)
        out = func(xyz, tile) if with_tile else func(xyz)
        info = None
        if isinstance(out, tuple):
            out, info = out
        fields = _fields_of(out, len(rec), grid.key_of(key))
        shared = _shared_rows(xyz, core, tile.bounds, grid.halo) if state else None
        links = {}
        for name in state:
            if name not in fields:
                raise InvalidPointsError(f"tile {tile.key}: no label field {name!r}")
            lab = fields[name].astype(np.int64)
            links[name] = (lab.max(initial=0), rec["i"][shared], lab[shared], core[shared])
        return tile, {name: arr[core] for name, arr in fields.items()}, info, links

    def put(result):
        """Append the results of a tile's core rows to the runs of their chunk and field."""
        nonlocal done, tiles_run
        if result is None:
            return
        tile, fields, info, links = result
        rows = tile.points[tile.core]
        bases = {}
        for name, (top, i, lab, core) in links.items():
            lab_state = state[name]
            written.setdefault(name, fields[name].dtype)
            local = fields[name].astype(np.int64)
            base = lab_state.add_tile(top, np.bincount(np.maximum(local, 0),
                                                       minlength=int(top) + 1))
            bases[name] = base
            fields[name] = np.where(local > 0, local + base, 0)
            if lab_state.join:
                rec = np.empty(i.size, LINK)
                rec["i"], rec["node"], rec["tile"] = i, np.where(lab > 0, lab + base, 0), \
                    tiles_run
                rec["core"] = core
                results.append(("links", name), rec)
        tiles_run += 1
        if collect is not None:
            collect(tile, info, bases)
        chunk = rows // points_per_chunk
        order = np.argsort(chunk, kind="stable")
        chunk = chunk[order]
        cuts = np.flatnonzero(np.r_[True, chunk[1:] != chunk[:-1], True]) \
            if rows.size else np.zeros(1, dtype=np.int64)
        for name, arr in fields.items():
            if name not in registry:
                registry[name] = (len(registry), arr.dtype, arr.shape[1:])
            j, dtype, shape = registry[name]
            rec = np.empty(rows.size, [("row", "<i8"), ("v", dtype, shape)])
            rec["row"] = rows[order]
            rec["v"] = arr[order]
            for s, e in zip(cuts[:-1], cuts[1:]):
                results.append((int(chunk[s]), j), rec[s:e])
        done += rows.size
        if progress is not None:
            progress(done, n)

    # Tiles go in batches, so that finished results never pile up in memory.
    nworkers = workers if workers is not None else (os.cpu_count() or 1)
    batch = 1 if scheduler == "sync" else 2 * nworkers
    pool = ThreadPoolExecutor(max_workers=nworkers) if scheduler == "threads" else None
    try:
        for b in range(0, len(keys), batch):
            part = keys[b:b + batch]
            if scheduler == "sync":
                out = [compute(k) for k in part]
            elif scheduler == "threads":
                out = pool.map(compute, part)  # each put as soon as it is done
            else:
                import dask

                out = dask.compute(*[dask.delayed(compute)(k) for k in part])
            for result in out:
                put(result)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)

    maps = {name: lab.finish(results.read(("links", name), LINK) if lab.join else None)
            for name, lab in state.items()}
    if finish is not None:
        finish(maps)

    def fields_of(start, chunk):
        """The results of points ``start .. start + len(chunk)`` (zeros where none)."""
        m = len(chunk)
        out = {}
        for name, (j, dtype, shape) in registry.items():
            arr = np.zeros((m,) + shape, dtype=dtype)
            rec_type = np.dtype([("row", "<i8"), ("v", dtype, shape)])
            for c in range(start // points_per_chunk,
                           (start + max(m, 1) - 1) // points_per_chunk + 1):
                rec = results.read((c, j), rec_type)
                inside = (rec["row"] >= start) & (rec["row"] < start + m)
                arr[rec["row"][inside] - start] = rec["v"][inside]
            out[name] = maps[name](arr).astype(written[name]) if name in maps else arr
        return out

    rewrite(src, dst, fields_of, points_per_chunk=points_per_chunk)
