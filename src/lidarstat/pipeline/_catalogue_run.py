"""Running a method over a :class:`Catalogue`: every tile with its buffer, one after the
other, in threads or as Dask tasks (local or a ``distributed`` cluster), each output
written atomically as its tile completes (see ``_catalogue``)."""

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
from ._catalogue import DEFAULT_TEMPLATE, BufferedTile, Catalogue

__all__ = ["TileRun", "process_catalogue"]


@dataclass
class TileRun:
    """What happened to one tile: ``status`` is ``"done"`` or ``"skipped"`` (resumed)."""

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


def _run_one(func, cat: Catalogue, i: int, out: Path, buffer: float, points_per_chunk: int
             ) -> TileRun:
    try:
        return _run_tile(func, cat, i, out, buffer, points_per_chunk)
    finally:  # the tile's arrays are gone: their pages go back to the system
        _release_memory()


def _run_tile(func, cat: Catalogue, i: int, out: Path, buffer: float, points_per_chunk: int
              ) -> TileRun:
    t0 = time.perf_counter()
    tile = cat.read_tile(i, buffer, points_per_chunk=points_per_chunk)
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
    with output_group(defer=False):  # each tile appears when complete (resume)
        write(out, tile.core, fields=core_fields)
    return TileRun(i, cat.files[i].path, out, "done", n, len(tile.buffer.xyz),
                   time.perf_counter() - t0, dict(info))


def process_catalogue(func: Callable[[BufferedTile], dict], catalogue, outdir, *,
                      buffer: float, template: str = DEFAULT_TEMPLATE, resume: bool = True,
                      scheduler: str = "threads", workers: int | None = None,
                      address: str | None = None, points_per_chunk: int = 1_000_000,
                      progress: Callable | None = None) -> list[TileRun]:
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

    Returns
    -------
    list of TileRun
        In catalogue order.
    """
    cat = catalogue if isinstance(catalogue, Catalogue) else Catalogue(catalogue)
    buffer = check_scalar(buffer, "buffer", func="process_catalogue", low=0, closed="left")
    check_option(scheduler, "scheduler", ("threads", "sync", "dask"), func="process_catalogue")
    if address is not None and scheduler != "dask":
        raise InvalidParameterError("process_catalogue: address needs scheduler='dask'")
    paths = cat.outputs(outdir, template)
    Path(outdir).mkdir(parents=True, exist_ok=True)
    runs: list[TileRun | None] = [None] * len(cat)
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
                        address):
        runs[run.index] = run
        done += 1
        if progress is not None:
            progress(done, len(cat))
    return [r for r in runs if r is not None]


def _execute(func, cat, paths, todo: Iterable[int], buffer, points_per_chunk, scheduler,
             workers, address):
    todo = list(todo)
    if scheduler == "sync" or not todo:
        for i in todo:
            yield _run_one(func, cat, i, paths[i], buffer, points_per_chunk)
        return
    if scheduler == "threads":
        from concurrent.futures import ThreadPoolExecutor, as_completed

        with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
            futures = [pool.submit(_run_one, func, cat, i, paths[i], buffer, points_per_chunk)
                       for i in todo]
            for fut in as_completed(futures):
                yield fut.result()
        return
    yield from _execute_dask(func, cat, paths, todo, buffer, points_per_chunk, workers, address)


def _execute_dask(func, cat, paths, todo, buffer, points_per_chunk, workers, address):
    try:
        import dask
    except ImportError:  # pragma: no cover - dask is an optional dependency
        raise InvalidParameterError("scheduler 'dask' needs dask: pip install "
                                    "'lidarstat[dask]'") from None
    if address is None:
        tasks = [dask.delayed(_run_one)(func, cat, i, paths[i], buffer, points_per_chunk)
                 for i in todo]
        yield from dask.compute(*tasks, scheduler="threads", num_workers=workers)
        return
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover
        raise InvalidParameterError("a cluster address needs distributed: pip install "
                                    "'lidarstat[dask]'") from None
    with Client(address) as client:
        futures = [client.submit(_run_one, func, cat, i, paths[i], buffer, points_per_chunk,
                                 pure=False) for i in todo]
        for fut in as_completed(futures):
            yield fut.result()
