"""What a catalogue needs of a file without reading its points: extent, count, CRS; and
the points of a file inside a planimetric window (COPC: a bounds query of its octree).

>>> import numpy as np, tempfile, pathlib
>>> from lidarstat.io import PointCloud, write
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = write(d / "t.las", PointCloud(np.array([[0., 0, 1], [5, 5, 2], [9, 9, 3]])))
>>> e = file_extent(d / "t.las")
>>> e.n_points, e.xmin, e.ymax, e.copc
(3, 0.0, 9.0, False)
>>> read_window(d / "t.las", (4, 4, 10, 10)).xyz[:, 2].tolist()
[2.0, 3.0]
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np

from ..errors import PointCloudReadError
from ._cloud import PointCloud, _format_of, iter_chunks

__all__ = ["FileExtent", "file_extent", "read_window"]

#: Suffixes a catalogue takes (COPC files are ``.copc.laz``).
CATALOGUE_SUFFIXES = (".las", ".laz")


@dataclass(frozen=True)
class FileExtent:
    """Header facts of one LAS/LAZ/COPC file.

    Attributes
    ----------
    path : Path
    xmin, ymin, zmin, xmax, ymax, zmax : float
        Bounds from the header.
    n_points : int
    crs : str or None
        WKT of the file's CRS, when it has one.
    copc : bool
        True for a Cloud Optimized Point Cloud (bounds queries read only what they need).
    """

    path: Path
    xmin: float
    ymin: float
    zmin: float
    xmax: float
    ymax: float
    zmax: float
    n_points: int
    crs: str | None
    copc: bool

    @property
    def bounds2d(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)``."""
        return (self.xmin, self.ymin, self.xmax, self.ymax)

    def intersects(self, window) -> bool:
        """True when the planimetric box ``(xmin, ymin, xmax, ymax)`` meets this extent."""
        x0, y0, x1, y1 = window
        return not (x1 < self.xmin or x0 > self.xmax or y1 < self.ymin or y0 > self.ymax)


def _is_copc(header) -> bool:
    return any(getattr(v, "user_id", "") == "copc" for v in header.vlrs)


def file_extent(path: str | os.PathLike) -> FileExtent:
    """Read the header of a LAS/LAZ/COPC file: its bounds, point count, CRS, COPC or not.

    Raises
    ------
    PointCloudReadError
        When the file is missing, not LAS/LAZ, or its header is unreadable.
    """
    from ._las import _checked, crs_of

    path = Path(path)
    if not path.is_file():
        raise PointCloudReadError(f"{path}: no such file")
    fmt = _format_of(path)
    if fmt not in ("las", "laz"):
        raise PointCloudReadError(f"{path}: a catalogue takes LAS, LAZ or COPC files, "
                                  f"not {fmt.upper()}")
    _checked(path, fmt, 0, None, allow_empty=True)
    try:
        with laspy.open(path) as reader:
            h = reader.header
            mins, maxs = np.asarray(h.mins, float), np.asarray(h.maxs, float)
            return FileExtent(path, *mins.tolist(), *maxs.tolist(), int(h.point_count),
                              crs_of(h), _is_copc(h))
    except (OSError, ValueError, laspy.errors.LaspyException) as exc:
        raise PointCloudReadError(f"{path}: unreadable header ({exc})") from exc


def _in_window(xyz, window) -> np.ndarray:
    x0, y0, x1, y1 = window
    return (xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1)


def read_window(path: str | os.PathLike, window, *, points_per_chunk: int = 1_000_000,
                copc: bool | None = None, index: bool = False):
    """The points of a file inside the planimetric box ``(xmin, ymin, xmax, ymax)``.

    A COPC file is queried through its octree (:class:`laspy.CopcReader`), reading only the
    nodes that meet the box; a LAS/LAZ file is streamed chunk by chunk and filtered, so
    memory holds one chunk plus the points kept. Every field of the file is kept.

    Parameters
    ----------
    path : path-like
    window : (xmin, ymin, xmax, ymax)
        Closed box.
    points_per_chunk : int
        Chunk size of the streamed read (LAS/LAZ).
    copc : bool, optional
        Whether the file is COPC (read from the header when None).
    index : bool
        Also return each point's place in the file (0-based, int64). A COPC file is
        then streamed as the LAZ file it is (the octree does not number the points).

    Returns
    -------
    PointCloud
        Possibly empty; with `index`, ``(cloud, places)``.
    """
    path = Path(path)
    if copc is None:
        copc = file_extent(path).copc
    if copc and not index:
        return _copc_window(path, window)
    xyz, attrs, header, places, start = [], {}, None, [], 0
    for chunk in iter_chunks(path, points_per_chunk):
        keep = _in_window(chunk.xyz, window)
        header = chunk.las_header
        xyz.append(chunk.xyz[keep])
        places.append(start + np.flatnonzero(keep))
        start += len(chunk.xyz)
        for name, values in chunk.attributes.items():
            attrs.setdefault(name, []).append(np.asarray(values)[keep])
    xyz_all = np.concatenate(xyz) if xyz else np.empty((0, 3))
    cloud = PointCloud(xyz_all, {k: np.concatenate(v) for k, v in attrs.items()},
                       source_path=path, source_format=_format_of(path), las_header=header)
    if not index:
        return cloud
    return cloud, (np.concatenate(places).astype(np.int64) if places
                   else np.empty(0, np.int64))


def _copc_window(path: Path, window) -> PointCloud:
    from ._las import _cloud_from_points, crs_of

    x0, y0, x1, y1 = window
    try:
        with laspy.CopcReader.open(path) as reader:
            h = reader.header
            bounds = laspy.copc.Bounds(mins=np.array([x0, y0, h.mins[2] - 1.0]),
                                       maxs=np.array([x1, y1, h.maxs[2] + 1.0]))
            points = reader.query(bounds=bounds)
            cloud = _cloud_from_points(points, h, path, "laz", crs_of(h))
    except (OSError, ValueError, laspy.errors.LaspyException) as exc:
        raise PointCloudReadError(f"{path}: unreadable COPC file ({exc})") from exc
    keep = _in_window(cloud.xyz, window)  # the octree nodes overlap the box: trim to it
    return PointCloud(cloud.xyz[keep], {k: np.asarray(v)[keep]
                                        for k, v in cloud.attributes.items()},
                      crs=cloud.crs, source_path=path, source_format="laz",
                      las_header=cloud.las_header)
