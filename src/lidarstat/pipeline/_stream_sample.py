"""A sample of the tiles of one large file, on which what the area decides once is decided.

A tiled run (:func:`lidarstat.pipeline.process_file`) must fix before the tiles run what
the method would otherwise estimate from each tile's points (the noise sigma, the ladder
of an automatic scale, a bandwidth), as a catalogue of tile files does on a sample of its
tiles. :func:`sample_file` streams the file twice (the points per tile, then the points
of the chosen tiles) and holds only the sampled tiles: up to ``count`` non-empty tiles of
the grid of side ``size``, spread evenly over them. The result has the shape of a
:class:`~lidarstat.pipeline.Catalogue` that the area's decisions read: ``len``, ``files``
(each with ``path`` and ``n_points``) and ``tile_xyz(i)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._shared._tiles import TileGrid
from .._shared.validation import check_scalar
from ..io import iter_chunks
from ._stream import _bounds

__all__ = ["FileSample", "SampleTile", "sample_file"]


@dataclass(frozen=True)
class SampleTile:
    """One sampled tile: a name for messages (``path``), its points and core square."""

    path: Path
    n_points: int
    bounds: tuple


class FileSample:
    """Sampled tiles of one file, read by the area's decisions like a catalogue's tiles.

    Attributes
    ----------
    files : list of SampleTile
    n_points : int
        Points of the whole file.
    """

    def __init__(self, files: list[SampleTile], xyz: list[np.ndarray], n_points: int):
        self.files = files
        self._xyz = xyz
        self.n_points = n_points

    def __len__(self) -> int:
        return len(self.files)

    def tile_xyz(self, i: int) -> np.ndarray:
        """The (M, 3) points of sampled tile `i`."""
        return self._xyz[i]


def sample_file(src, size: float, *, count: int = 9, points_per_chunk: int = 1_000_000
                ) -> FileSample:
    """Up to `count` non-empty tiles of side `size` of the file `src`, spread evenly over
    its tiles (in column, row order), each with its points (no halo)."""
    size = check_scalar(size, "size", func="sample_file", low=0, closed="neither")
    src = Path(src)
    lo, hi, n = _bounds(src, points_per_chunk)
    grid = TileGrid.covering(lo, hi, size, 0.0)
    counts = np.zeros(grid.ncol * grid.nrow, np.int64)
    for chunk in iter_chunks(src, points_per_chunk):
        _, key, _ = grid.memberships(chunk.xyz[:, :2])
        counts += np.bincount(key, minlength=counts.size)
    full = np.flatnonzero(counts)
    picks = full[np.unique(np.linspace(0, full.size - 1, min(full.size, count)).round()
                           .astype(np.int64))]
    parts: dict[int, list] = {int(k): [] for k in picks}
    for chunk in iter_chunks(src, points_per_chunk):
        _, key, _ = grid.memberships(chunk.xyz[:, :2])
        for k, part in parts.items():
            sel = key == k
            if sel.any():
                part.append(chunk.xyz[sel])
    files, xyz = [], []
    for k in sorted(parts):
        col, row = grid.key_of(k)
        xyz.append(np.concatenate(parts[k]))
        files.append(SampleTile(Path(f"{src.name}[tile {col},{row}]"), int(counts[k]),
                                grid.bounds(k)))
    return FileSample(files, xyz, n)
