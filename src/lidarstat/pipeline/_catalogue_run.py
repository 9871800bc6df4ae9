"""Running a method over a :class:`Catalogue`: every tile with its buffer, one after the
other, in threads or as Dask tasks (local or a ``distributed`` cluster), each output
written atomically as its tile completes (see ``_catalogue``), or, with label fields
joined across the tiles, when every tile has run (see ``_catalogue_join``)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._shared._atomic import output_group
from .._shared.validation import check_option, check_scalar
from ..errors import InvalidParameterError
from ..io import write
from . import _catalogue_join as _join
from ._catalogue import DEFAULT_TEMPLATE, BufferedTile, Catalogue

__all__ = ["TileRun", "process_catalogue"]


@dataclass
class TileRun:
    """What happened to one tile: ``status`` is ``"done"``, ``"skipped"`` (its output
    exists) or ``"resumed"`` (joined labels: its run kept from a stopped run)."""

    index: int
    input: Path
    output: Path
    status: str
    n_points: int = 0
    n_buffer: int = 0
    seconds: float = 0.0
    summary: dict = field(default_factory=dict)


def _release_memory() -> None:
    """Hand the heap's free pages back to the system (glibc's ``malloc_trim``).

    A tile's arrays are freed when it is written, but glibc keeps the free pages of its
    heaps (one heap per thread) for later allocations, so the resident memory of a run
    of many tiles would grow towards the largest set of tiles ever in progress at once,
    heap by heap. No-op where the C library has no ``malloc_trim``.
    """
    global _TRIM
    if _TRIM is None:
        import ctypes
        import ctypes.util

        try:
            _TRIM = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _TRIM = False
    if _TRIM:
        _TRIM(0)


_TRIM = None


def _run_one(func, cat: Catalogue, i: int, out: Path, buffer: float, points_per_chunk: int,
             join: tuple | None = None) -> TileRun:
    try:
        return _run_tile(func, cat, i, out, buffer, points_per_chunk, join)
    finally:  # the tile's arrays are gone: their pages go back to the system
        _release_memory()


def _run_tile(func, cat: Catalogue, i: int, out: Path, buffer: float, points_per_chunk: int,
              join: tuple | None = None) -> TileRun:
    """Run tile `i`; write its output, or with `join` ``(labels, outdir)`` its pending
    run (``_catalogue_join``)."""
    t0 = time.perf_counter()
    tile = cat.read_tile(i, buffer, points_per_chunk=points_per_chunk, ids=join is not None)
    with output_group(defer=False):  # what the method writes of a tile appears at once
        fields = func(tile)
    info = {}
    if isinstance(fields, tuple):
        fields, info = fields
    n = tile.n_core
    core_fields = {}
    for name, values in fields.items():
        values = np.asarray(values)
        if values.shape[0] != len(tile.xyz):
            raise InvalidParameterError(f"{cat.files[i].path}: the method returned {name!r} "
                                        f"with {values.shape[0]} values for "
                                        f"{len(tile.xyz)} points")
        core_fields[name] = values[:n]
    if join is not None:
        labels, outdir, key = join
        fields = {name: np.asarray(values) for name, values in fields.items()}
        _join.put_pending(cat, i, out, outdir, tile, fields, dict(info), labels, buffer, key)
        return TileRun(i, cat.files[i].path, out, "done", n, len(tile.buffer.xyz),
                       time.perf_counter() - t0, _scalars(info))
    with output_group(defer=False):  # each tile appears when complete (resume)
        write(out, tile.core, fields=core_fields)
    return TileRun(i, cat.files[i].path, out, "done", n, len(tile.buffer.xyz),
                   time.perf_counter() - t0, dict(info))


def _scalars(info) -> dict:
    """The entries of a tile's `info` that are numbers or words (its summary)."""
    return {k: v for k, v in dict(info).items() if isinstance(v, (int, float, str, bool))
            or (isinstance(v, np.generic) and v.ndim == 0)}


def process_catalogue(func: Callable[[BufferedTile], dict], catalogue, outdir, *,
                      buffer: float, template: str = DEFAULT_TEMPLATE, resume: bool = True,
                      scheduler: str = "threads", workers: int | None = None,
                      address: str | None = None, points_per_chunk: int = 1_000_000,
                      progress: Callable | None = None, labels: dict | None = None,
                      collect: Callable | None = None, finish: Callable | None = None,
                      run_key: str | None = None) -> list[TileRun]:
    """Run `func` on every tile of a catalogue with a buffer; one output per tile.

    Parameters
    ----------
    func : callable
        ``func(tile: BufferedTile) -> dict`` of per-point arrays over ``tile.xyz`` (core
        points first, then the buffer); the core rows are written. It may return
        ``(fields, info)``, `info` a dict kept as the tile's :attr:`TileRun.summary`.
    catalogue : Catalogue or inputs of :class:`Catalogue`
    outdir : path-like
        Folder of the outputs (created if missing).
    buffer : float
        Distance around each tile from which neighbours' points are read (>= 0); at
        least the method's neighbourhood reach for tiling-independent results.
    template : str
        Output file name, see :data:`DEFAULT_TEMPLATE`.
    resume : bool
        Skip tiles whose output exists.
    scheduler : {"threads", "sync", "dask"}
        How tiles run; ``"dask"`` uses ``distributed`` at `address` when given, else
        Dask's local threads.
    workers : int, optional
        Threads (``"threads"``, local ``"dask"``); default one per core.
    address : str, optional
        Scheduler address of a ``distributed`` cluster (``"tcp://host:8786"``); every
        worker must see the input and output paths.
    points_per_chunk : int
        Chunk size of the streamed buffer reads.
    progress : callable, optional
        ``progress(done, total)`` after each tile.
    labels : dict of str to bool, optional
        Label fields of `func`'s result (integers, 0 = none): written with ids unique
        over the area; a field mapped to True is also *joined* across the tiles, two
        tiles' labels becoming one id where they hold the same points of the tiles'
        overlap (a tile's buffer points are core points of its neighbours), by the rule
        of :func:`process_file` (``lidarstat.pipeline._stream_labels``). The outputs
        then appear only when every tile has run and the labels are joined
        (``lidarstat.pipeline._catalogue_join``: the tiles' runs wait in
        ``OUTDIR/.lidarstat-pending``, which a resumed run goes on from).
    collect : callable, optional
        With `labels`: ``collect(index, info, bases)`` for every tile in catalogue
        order after the join, `info` as `func` returned it, `bases` the number added to
        the tile's labels of each field: its *nodes*.
    finish : callable, optional
        With `labels`: ``finish(maps)`` once, before the outputs are written, `maps`
        mapping each field of `labels` to a :class:`LabelMap` (node -> id written).
    run_key : str, optional
        With `labels`: names the method and its options. A stopped run's pending tile is
        resumed only by a run with the same `run_key` (and input and buffer); a tile
        whose record has another key is run again, so that tiles run with different
        options are never joined.

    Returns
    -------
    list of TileRun
        In catalogue order; with `labels`, a tile whose run was kept from a stopped run
        has status ``"resumed"``, and :attr:`TileRun.summary` holds the scalar entries
        of `info`.
    """
    cat = catalogue if isinstance(catalogue, Catalogue) else Catalogue(catalogue)
    buffer = check_scalar(buffer, "buffer", func="process_catalogue", low=0, closed="left")
    check_option(scheduler, "scheduler", ("threads", "sync", "dask"), func="process_catalogue")
    if address is not None and scheduler != "dask":
        raise InvalidParameterError("process_catalogue: address needs scheduler='dask'")
    paths = cat.outputs(outdir, template)
    Path(outdir).mkdir(parents=True, exist_ok=True)
    runs: list[TileRun | None] = [None] * len(cat)
    join = None
    if labels:
        join = (dict(labels), Path(outdir), run_key)
        todo, resumed, needed = _join.plan(cat, paths, Path(outdir), buffer, resume, run_key)
        for i in range(len(cat)):
            if not needed or i in resumed:
                runs[i] = TileRun(i, cat.files[i].path, paths[i],
                                  "resumed" if needed else "skipped", cat.files[i].n_points)
    else:
        todo = []
        for i, p in enumerate(paths):
            if resume and p.exists():
                runs[i] = TileRun(i, cat.files[i].path, p, "skipped", cat.files[i].n_points)
            else:
                todo.append(i)
    done = len(cat) - len(todo)
    if progress is not None:
        progress(done, len(cat))
    for run in _execute(func, cat, paths, todo, buffer, points_per_chunk, scheduler, workers,
                        address, join):
        runs[run.index] = run
        done += 1
        if progress is not None:
            progress(done, len(cat))
    if join is not None and needed:
        _join.join_outputs(cat, paths, Path(outdir), join[0], resume=resume,
                           collect=collect, finish=finish,
                           points_per_chunk=points_per_chunk)
    return [r for r in runs if r is not None]


def _execute(func, cat, paths, todo: Iterable[int], buffer, points_per_chunk, scheduler,
             workers, address, join=None):
    todo = list(todo)
    if scheduler == "sync" or not todo:
        for i in todo:
            yield _run_one(func, cat, i, paths[i], buffer, points_per_chunk, join)
        return
    if scheduler == "threads":
        from concurrent.futures import ThreadPoolExecutor, as_completed

        with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
            futures = [pool.submit(_run_one, func, cat, i, paths[i], buffer, points_per_chunk,
                                   join) for i in todo]
            for fut in as_completed(futures):
                yield fut.result()
        return
    yield from _execute_dask(func, cat, paths, todo, buffer, points_per_chunk, workers, address,
                             join)


def _execute_dask(func, cat, paths, todo, buffer, points_per_chunk, workers, address,
                  join=None):
    try:
        import dask
    except ImportError:  # pragma: no cover - dask is an optional dependency
        raise InvalidParameterError("scheduler 'dask' needs dask: pip install "
                                    "'lidarstat[dask]'") from None
    if address is None:
        tasks = [dask.delayed(_run_one)(func, cat, i, paths[i], buffer, points_per_chunk,
                                        join) for i in todo]
        yield from dask.compute(*tasks, scheduler="threads", num_workers=workers)
        return
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover
        raise InvalidParameterError("a cluster address needs distributed: pip install "
                                    "'lidarstat[dask]'") from None
    with Client(address) as client:
        futures = [client.submit(_run_one, func, cat, i, paths[i], buffer, points_per_chunk,
                                 join, pure=False) for i in todo]
        for fut in as_completed(futures):
            yield fut.result()
