"""Catalogues of tiles: many LAS/LAZ/COPC files processed as one area.

A :class:`Catalogue` is a folder, a glob or a list of files, indexed by their headers
alone (bounds, point counts, CRS), as lidR's ``LAScatalog`` and PDAL's ``tindex`` do. Each
file is a tile: :func:`process_catalogue` runs a method on every tile together with a
*buffer*, the points of the neighbouring tiles within a given distance of the tile's
extent, and writes the tile's own points (every original field kept) with the results to
one output per input. The buffer is removed on output, so a method whose answer depends
only on points within the buffer distance gives every point the result it gets on the
whole area.

Outputs appear atomically, one per tile as it completes; a rerun skips the tiles whose
output exists (``resume=True``), so a stopped run goes on where it stopped. Tiles run one
after the other, in threads, or as Dask tasks on the local machine or on a
``distributed`` cluster (``address``); each task reads and writes its own tile, so memory
holds the tiles in progress, not the area, and nothing large travels between workers.
"""

from __future__ import annotations

import glob as _glob
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._shared._atomic import output_group
from .._shared.validation import check_option, check_scalar
from ..errors import InvalidParameterError, PointCloudReadError, PointCloudWriteError
from ..io import FileExtent, PointCloud, file_extent, read, read_window, write

__all__ = ["DEFAULT_TEMPLATE", "BufferedTile", "Catalogue", "TileRun", "process_catalogue"]

#: Output name of a tile: ``{stem}`` (the input's name without ``.las``, ``.laz`` or
#: ``.copc.laz``), ``{name}`` (with them), ``{index}`` (its place in the catalogue).
DEFAULT_TEMPLATE = "{stem}.laz"
_SUFFIXES = (".copc.laz", ".laz", ".las")


def _stem(path: Path) -> str:
    name = path.name
    for suffix in _SUFFIXES:
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


def _expand(inputs) -> list[Path]:
    """Files named by a folder, a glob, a file, or an iterable of those."""
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    found: list[Path] = []
    for item in inputs:
        text = os.fspath(item)
        path = Path(text)
        if path.is_dir():
            hits = sorted(p for p in path.iterdir()
                          if p.is_file() and p.name.lower().endswith((".las", ".laz")))
            if not hits:
                raise PointCloudReadError(f"{text}: the folder holds no .las or .laz file")
            found += hits
        elif any(c in text for c in "*?["):
            hits = sorted(Path(p) for p in _glob.glob(text) if Path(p).is_file())
            if not hits:
                raise PointCloudReadError(f"{text}: no file matches")
            found += hits
        elif path.is_file():
            found.append(path)
        else:
            raise PointCloudReadError(f"{text}: no such file or folder")
    resolved = [p.resolve() for p in found]
    if len(set(resolved)) != len(resolved):
        seen, dup = set(), None
        for p, r in zip(found, resolved):
            if r in seen:
                dup = p
                break
            seen.add(r)
        raise PointCloudReadError(f"{dup}: named twice in the catalogue")
    return found


@dataclass(frozen=True)
class BufferedTile:
    """One tile's points and its buffer from the neighbouring tiles.

    Attributes
    ----------
    core : PointCloud
        The tile's own points, every field of its file.
    buffer : PointCloud
        Points of the neighbouring tiles within the buffer distance of the tile's extent.
    extent : FileExtent, optional
        The tile's file: its path and header bounds.
    """

    core: PointCloud
    buffer: PointCloud
    extent: FileExtent | None = None

    @property
    def n_core(self) -> int:
        """Points of the tile itself (the first rows of :attr:`xyz`)."""
        return len(self.core.xyz)

    @property
    def xyz(self) -> np.ndarray:
        """Core points first, then the buffer."""
        return np.concatenate([self.core.xyz, self.buffer.xyz])

    def attribute(self, name: str) -> np.ndarray | None:
        """A field over core and buffer points, or None when a tile lacks it."""
        a, b = self.core.attributes.get(name), self.buffer.attributes.get(name)
        if a is None or (b is None and len(self.buffer.xyz)):
            return None
        return np.concatenate([np.asarray(a), np.asarray(b)]) if b is not None else np.asarray(a)


class Catalogue:
    """LAS/LAZ/COPC files processed as one area, indexed by their headers.

    Parameters
    ----------
    inputs : path-like, glob or iterable of them
        A folder (its ``.las``/``.laz`` files), a glob (``tiles/*.laz``), files, or a
        list mixing them.

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from lidarstat.io import PointCloud, write
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for i in range(3):
    ...     xyz = np.c_[np.arange(10.0) + 10 * i, np.zeros(10), np.zeros(10)]
    ...     _ = write(d / f"t{i}.laz", PointCloud(xyz))
    >>> cat = Catalogue(d)
    >>> len(cat), cat.n_points, cat.neighbours(1, buffer=2.0)
    (3, 30, [0, 2])
    """

    def __init__(self, inputs, *, one_crs: bool = True):
        self.files: list[FileExtent] = [file_extent(p) for p in _expand(inputs)]
        crs = {f.crs for f in self.files if f.crs}
        if len(crs) > 1 and one_crs:
            names = ", ".join(str(f.path) for f in self.files[:2])
            raise PointCloudReadError(f"{names}: the tiles are in different coordinate "
                                      "reference systems; a catalogue needs one")
        #: The CRS of the tiles (WKT; None without one, or when they differ).
        self.crs = crs.pop() if len(crs) == 1 else None
        #: The distinct CRSs of the tiles (one for a usable catalogue).
        self.crs_set = frozenset(crs)

    def __len__(self) -> int:
        return len(self.files)

    def __iter__(self):
        return iter(self.files)

    @property
    def n_points(self) -> int:
        """Points in all tiles."""
        return sum(f.n_points for f in self.files)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the area."""
        return (min(f.xmin for f in self.files), min(f.ymin for f in self.files),
                max(f.xmax for f in self.files), max(f.ymax for f in self.files))

    def point_offsets(self) -> list[int]:
        """Points in the tiles before each tile: offsets that make per-tile ids unique."""
        return np.r_[0, np.cumsum([f.n_points for f in self.files])][:-1].astype(int).tolist()

    def gaps_and_overlaps(self) -> tuple[float, float]:
        """``(uncovered, overlapping)`` shares of the area's bounding box: the area no tile
        covers, and the area more than one tile covers (both 0 for a clean tiling)."""
        # header bounds are the points' bounds: strips between tiles narrower than twice
        # the point spacing (or 1 % of a tile's side) are the spacing, not gaps
        side = float(np.median([max(f.xmax - f.xmin, f.ymax - f.ymin) for f in self.files]))
        spacing = float(np.median([np.sqrt((f.xmax - f.xmin) * (f.ymax - f.ymin)
                                           / max(f.n_points, 1)) for f in self.files]))
        tol = max(0.01 * side, 2.0 * spacing)

        def edges(values):
            v = np.unique(values)
            keep = np.r_[True, np.diff(v) > tol]
            return v[keep] if len(v) else v

        boxes = [(f.xmin, f.ymin, f.xmax, f.ymax) for f in self.files]
        xs = edges([v for b in boxes for v in (b[0], b[2])])
        ys = edges([v for b in boxes for v in (b[1], b[3])])
        snap = lambda v, e: e[np.argmin(np.abs(e - v))]
        boxes = [(snap(a, xs), snap(b, ys), snap(c, xs), snap(d, ys)) for a, b, c, d in boxes]
        cx, cy = (xs[1:] + xs[:-1]) / 2, (ys[1:] + ys[:-1]) / 2
        cover = np.zeros((len(cy), len(cx)), int)
        for x0, y0, x1, y1 in boxes:
            cover += np.outer((cy > y0) & (cy < y1), (cx > x0) & (cx < x1))
        area = np.outer(np.diff(ys), np.diff(xs))
        total = max(float(area.sum()), 1e-300)
        return float(area[cover == 0].sum() / total), float(area[cover > 1].sum() / total)

    def tindex(self) -> dict:
        """The tile index as a GeoJSON FeatureCollection: one rectangle per tile with its
        file, point count, heights and COPC flag (PDAL's ``tindex``)."""
        feats = []
        for i, f in enumerate(self.files):
            ring = [[f.xmin, f.ymin], [f.xmax, f.ymin], [f.xmax, f.ymax], [f.xmin, f.ymax],
                    [f.xmin, f.ymin]]
            feats.append({"type": "Feature", "geometry": {"type": "Polygon",
                                                          "coordinates": [ring]},
                          "properties": {"index": i, "location": str(f.path),
                                         "points": f.n_points, "zmin": f.zmin,
                                         "zmax": f.zmax, "copc": f.copc}})
        return {"type": "FeatureCollection", "features": feats}

    def write_tindex(self, path) -> Path:
        """Write :meth:`tindex` as a GeoJSON file (atomically); QGIS shows the tiling."""
        import json

        from .._shared._atomic import atomic_path

        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.tindex(), indent=1))
        return path

    def describe(self) -> dict:
        """A summary of the catalogue: tiles, points, bounds, CRSs, gaps and overlaps."""
        gaps, overlaps = self.gaps_and_overlaps()
        zmin = min((f.zmin for f in self.files), default=float("nan"))
        zmax = max((f.zmax for f in self.files), default=float("nan"))
        return {"tiles": len(self), "points": self.n_points, "bounds": list(self.bounds),
                "zmin": zmin, "zmax": zmax, "crs_count": len(self.crs_set),
                "crs_consistent": len(self.crs_set) <= 1, "copc_tiles":
                sum(f.copc for f in self.files), "uncovered_share": gaps,
                "overlap_share": overlaps,
                "files": [{"path": str(f.path), "points": f.n_points,
                           "bounds": list(f.bounds2d), "copc": f.copc} for f in self.files]}

    def window(self, i: int, buffer: float) -> tuple[float, float, float, float]:
        """Tile `i`'s extent grown by `buffer` on every side."""
        f = self.files[i]
        return (f.xmin - buffer, f.ymin - buffer, f.xmax + buffer, f.ymax + buffer)

    def neighbours(self, i: int, buffer: float) -> list[int]:
        """Tiles other than `i` whose extent meets `i`'s extent grown by `buffer`."""
        w = self.window(i, buffer)
        return [j for j, f in enumerate(self.files) if j != i and f.intersects(w)]

    def read_tile(self, i: int, buffer: float, *, points_per_chunk: int = 1_000_000
                  ) -> BufferedTile:
        """Tile `i` whole, and the points of its neighbours within `buffer` of its extent."""
        core = read(self.files[i].path)
        parts = [read_window(self.files[j].path, self.window(i, buffer),
                             points_per_chunk=points_per_chunk, copc=self.files[j].copc)
                 for j in self.neighbours(i, buffer)] if buffer > 0 else []
        parts = [p for p in parts if len(p.xyz)]
        if not parts:
            return BufferedTile(core, PointCloud(np.empty((0, 3))), self.files[i])
        names = set.intersection(*(set(p.attributes) for p in parts))
        xyz = np.concatenate([p.xyz for p in parts])
        attrs = {n: np.concatenate([np.asarray(p.attributes[n]) for p in parts])
                 for n in names}
        return BufferedTile(core, PointCloud(xyz, attrs), self.files[i])

    def outputs(self, outdir, template: str = DEFAULT_TEMPLATE) -> list[Path]:
        """The output path of every tile; refused before any work when two tiles get one
        name, an output is an input, or the folder is not a folder."""
        outdir = Path(outdir)
        if outdir.exists() and not outdir.is_dir():
            raise PointCloudWriteError(f"{outdir}: not a folder (a catalogue writes one file "
                                       "per tile into a folder)")
        try:
            paths = [outdir / template.format(stem=_stem(f.path), name=f.path.name, index=i)
                     for i, f in enumerate(self.files)]
        except (KeyError, IndexError, ValueError) as exc:
            raise InvalidParameterError(
                f"output template {template!r}: unknown or malformed field ({exc}); use "
                "{stem}, {name} or {index}") from None
        inputs = {f.path.resolve() for f in self.files}
        seen: dict[Path, int] = {}
        for i, p in enumerate(paths):
            r = p.resolve()
            if r in inputs:
                raise PointCloudWriteError(f"{p}: the output of {self.files[i].path} is an "
                                           "input of the catalogue; write elsewhere")
            if r in seen:
                raise PointCloudWriteError(
                    f"{p}: output of both {self.files[seen[r]].path} and "
                    f"{self.files[i].path}; put {{stem}} or {{index}} in the template")
            seen[r] = i
        return paths


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


def write_tiles(cloud: PointCloud, folder, *, size: float,
                template: str = "tile_{col}_{row}.laz") -> list[Path]:
    """Cut a cloud into square tiles of side `size` on multiples of `size`: a catalogue.

    Every field is kept; tiles without points are not written. The files appear
    atomically. (Cutting a file larger than memory is :func:`process_file`'s work; this
    makes catalogues of clouds that fit.)

    Returns
    -------
    list of Path
        The tiles written, in (column, row) order.
    """
    size = check_scalar(size, "size", func="write_tiles", low=0)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = np.floor(cloud.xyz[:, :2] / size).astype(np.int64)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key = key[order]
    starts = np.flatnonzero(np.r_[True, np.any(key[1:] != key[:-1], axis=1)])
    ends = np.r_[starts[1:], len(order)]
    paths = []
    for s, e in zip(starts, ends):
        rows = np.sort(order[s:e])
        sub = PointCloud(cloud.xyz[rows], {k: np.asarray(v)[rows]
                                           for k, v in cloud.attributes.items()},
                         crs=cloud.crs)
        col, row = (int(v) for v in key[s])
        paths.append(write(folder / template.format(col=col, row=row), sub))
    return paths
