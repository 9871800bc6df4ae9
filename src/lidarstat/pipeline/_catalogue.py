"""Catalogues of tiles: many LAS/LAZ/COPC files processed as one area.

A :class:`Catalogue` is a folder, a glob or a list of files, indexed by their headers
alone (bounds, point counts, CRS), as lidR's ``LAScatalog`` and PDAL's ``tindex`` do. Each
file is a tile: :func:`process_catalogue` runs a method on every tile together with a
*buffer*, the points of the neighbouring tiles within a given distance of the tile's
extent, and writes the tile's own points (every original field kept) with the results to
one output per input. The buffer is removed on output, so a method whose answer depends
only on points within the buffer distance gives every point the result it gets on the
whole area.

Outputs appear atomically, one per tile as it completes (with label fields joined
across the tiles, when every tile has run: ``_catalogue_join``); a rerun skips the tiles
whose output exists (``resume=True``), so a stopped run goes on where it stopped. Tiles run one
after the other, in threads, or as Dask tasks on the local machine or on a
``distributed`` cluster (``address``); each task reads and writes its own tile, so memory
holds the tiles in progress, not the area, and nothing large travels between workers.
"""

from __future__ import annotations

import glob as _glob
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._shared.validation import check_scalar
from ..errors import InvalidParameterError, PointCloudReadError, PointCloudWriteError
from ..io import FileExtent, PointCloud, file_extent, read, read_window, write

__all__ = ["DEFAULT_TEMPLATE", "BufferedTile", "Catalogue", "write_tiles"]

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
    buffer_ids : (M,) ndarray of int64, optional
        Each buffer point's number over the catalogue (the points of the files before
        its file plus its place in its file), when read with ``ids=True``.
    """

    core: PointCloud
    buffer: PointCloud
    extent: FileExtent | None = None
    buffer_ids: np.ndarray | None = None

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

    def tile_xyz(self, i: int) -> np.ndarray:
        """The (M, 3) points of tile `i` (read whole)."""
        return read(self.files[i].path).xyz

    def window(self, i: int, buffer: float) -> tuple[float, float, float, float]:
        """Tile `i`'s extent grown by `buffer` on every side."""
        f = self.files[i]
        return (f.xmin - buffer, f.ymin - buffer, f.xmax + buffer, f.ymax + buffer)

    def neighbours(self, i: int, buffer: float) -> list[int]:
        """Tiles other than `i` whose extent meets `i`'s extent grown by `buffer`."""
        w = self.window(i, buffer)
        return [j for j, f in enumerate(self.files) if j != i and f.intersects(w)]

    def read_tile(self, i: int, buffer: float, *, points_per_chunk: int = 1_000_000,
                  ids: bool = False) -> BufferedTile:
        """Tile `i` whole, and the points of its neighbours within `buffer` of its extent;
        with `ids`, the buffer points' numbers over the catalogue
        (:attr:`BufferedTile.buffer_ids`)."""
        core = read(self.files[i].path)
        offsets = self.point_offsets() if ids else None
        parts, numbers = [], []
        for j in (self.neighbours(i, buffer) if buffer > 0 else []):
            got = read_window(self.files[j].path, self.window(i, buffer),
                              points_per_chunk=points_per_chunk, copc=self.files[j].copc,
                              index=ids)
            if ids:
                got, places = got
                numbers.append(places + offsets[j])
            parts.append(got)
        keep = [k for k, p in enumerate(parts) if len(p.xyz)]
        parts = [parts[k] for k in keep]
        buffer_ids = (np.concatenate([numbers[k] for k in keep]) if keep else
                      np.empty(0, np.int64)) if ids else None
        if not parts:
            return BufferedTile(core, PointCloud(np.empty((0, 3))), self.files[i],
                                buffer_ids)
        names = set.intersection(*(set(p.attributes) for p in parts))
        xyz = np.concatenate([p.xyz for p in parts])
        attrs = {n: np.concatenate([np.asarray(p.attributes[n]) for p in parts])
                 for n in names}
        return BufferedTile(core, PointCloud(xyz, attrs), self.files[i], buffer_ids)

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
