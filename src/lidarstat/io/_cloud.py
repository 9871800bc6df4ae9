"""The :class:`PointCloud` container and the suffix-dispatching ``read``/``write``/``iter_chunks``.

The per-format readers and writers live in ``_las``, ``_ply``, ``_text`` and ``_npz``; they
are imported lazily inside the dispatchers so that importing :mod:`lidarstat.io` stays cheap
and the format modules can import :class:`PointCloud` from here without a cycle.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.validation import check_points
from ..errors import (
    InvalidParameterError,
    InvalidPointsError,
    PointCloudReadError,
    PointCloudWriteError,
    UnknownFieldError,
    UnknownFormatError,
)

__all__ = ["PointCloud", "read", "write", "iter_chunks", "SUPPORTED_SUFFIXES"]

#: File suffixes understood by :func:`read` and :func:`write` (compared case-insensitively);
#: ``.e57`` is read only (through pye57).
SUPPORTED_SUFFIXES = (".las", ".laz", ".ply", ".csv", ".txt", ".npz", ".e57")

_XYZ = ("x", "y", "z")


@dataclasses.dataclass(eq=False)
class PointCloud:
    """Coordinates plus named per-point attributes, with enough metadata to write back.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in the file's own (scaled) units; stored as C-contiguous float64.
    attributes : dict of str to ndarray
        Every other per-point field, each an array whose first dimension is N (LAS
        standard dimensions use laspy's names: ``intensity``, ``classification`` ...).
    crs : str, optional
        Coordinate reference system: WKT when the file has one, else ``"EPSG:<code>"``.
    source_path : Path, optional
        File the cloud was read from.
    source_format : str
        One of ``"las"``, ``"laz"``, ``"ply"``, ``"csv"``, ``"txt"``, ``"npz"``, ``"e57"``
        or ``"memory"`` for clouds built in code.
    las_header : laspy.LasHeader, optional
        Header of the LAS/LAZ file the cloud came from, kept so that :func:`write` can
        reproduce version, point format, scales, offsets, VLRs and EVLRs.

    Raises
    ------
    InvalidPointsError
        If `xyz` is not ``(N, 3)`` or holds NaN or infinite values.
    InvalidParameterError
        If an attribute does not have N rows.
    """

    xyz: np.ndarray
    attributes: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    crs: str | None = None
    source_path: Path | None = None
    source_format: str = "memory"
    las_header: Any = None

    def __post_init__(self) -> None:
        if self.source_path is not None:
            self.source_path = Path(self.source_path)
        self.xyz = check_points(self.xyz, name="xyz", min_points=0, source=self._source())
        attrs = {}
        for name, values in dict(self.attributes).items():
            attrs[str(name)] = self._check_field(name, values)
        self.attributes = attrs

    # ------------------------------------------------------------------ helpers
    def _source(self) -> str:
        return str(self.source_path) if self.source_path is not None else "point cloud"

    def _check_field(self, name: str, values) -> np.ndarray:
        if not isinstance(name, str) or not name:
            raise InvalidParameterError(f"{self._source()}: field names must be non-empty "
                                        f"strings; got {name!r}")
        if name.lower() in _XYZ:
            raise InvalidParameterError(f"{self._source()}: {name!r} is a coordinate, not an "
                                        "attribute; change `xyz` instead")
        arr = np.asarray(values)
        if arr.ndim == 0 or arr.shape[0] != len(self.xyz):
            shape = arr.shape if arr.ndim else "a scalar"
            raise InvalidParameterError(
                f"{self._source()}: field {name!r} has {shape} values; expected one per "
                f"point ({len(self.xyz)})"
            )
        return arr

    # ------------------------------------------------------------------ mapping API
    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def __repr__(self) -> str:
        fields = ", ".join(self.attributes) or "no attributes"
        src = f", from {self.source_path}" if self.source_path is not None else ""
        return f"<PointCloud {len(self)} points ({fields}){src}>"

    @property
    def field_names(self) -> list[str]:
        """``["x", "y", "z", *attributes]``."""
        return [*_XYZ, *self.attributes]

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and (name.lower() in _XYZ or name in self.attributes)

    def __getitem__(self, name: str) -> np.ndarray:
        """Return coordinate column ``"x"``/``"y"``/``"z"`` or the attribute `name`.

        Raises
        ------
        UnknownFieldError
            If there is no such field; the message lists the available ones.
        """
        if isinstance(name, str) and name.lower() in _XYZ:
            return self.xyz[:, _XYZ.index(name.lower())]
        try:
            return self.attributes[name]
        except (KeyError, TypeError):
            raise UnknownFieldError(
                f"{self._source()}: unknown field {name!r}; available: "
                f"{', '.join(self.field_names)}"
            ) from None

    def with_fields(self, **arrays) -> PointCloud:
        """Return a new cloud with `arrays` added to (or replacing) the attributes.

        Raises
        ------
        InvalidParameterError
            If an array does not have one value per point.
        """
        attrs = dict(self.attributes)
        for name, values in arrays.items():
            attrs[name] = self._check_field(name, values)
        return dataclasses.replace(self, attributes=attrs)

    def subset(self, index_or_mask) -> PointCloud:
        """Return a new cloud holding the selected points (boolean mask or integer index)."""
        idx = np.asarray(index_or_mask)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise InvalidParameterError(
                    f"{self._source()}: boolean mask has shape {idx.shape}; expected "
                    f"({len(self)},)"
                )
        elif idx.size and not np.issubdtype(idx.dtype, np.integer):
            raise InvalidParameterError(f"{self._source()}: subset needs a boolean mask or "
                                        f"integer indices; got dtype {idx.dtype}")
        else:
            idx = idx.astype(np.intp, copy=False).reshape(-1)
        return dataclasses.replace(
            self,
            xyz=self.xyz[idx],
            attributes={k: v[idx] for k, v in self.attributes.items()},
        )


# ---------------------------------------------------------------------- dispatch
def _format_of(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        shown = path.suffix or "(none)"
        raise UnknownFormatError(
            f"{path}: unknown point-cloud format '{shown}'; supported: "
            f"{', '.join(SUPPORTED_SUFFIXES)}"
        )
    return suffix[1:]


def _module(fmt: str):
    if fmt in ("las", "laz"):
        from . import _las as mod
    elif fmt == "ply":
        from . import _ply as mod
    elif fmt in ("csv", "txt"):
        from . import _text as mod
    elif fmt == "e57":
        from . import _e57 as mod
    else:
        from . import _npz as mod
    return mod


def _select_fields(cloud: PointCloud, fields, path: Path) -> PointCloud:
    if fields is None:
        return cloud
    if isinstance(fields, str):
        fields = [fields]
    wanted = [f for f in fields if f.lower() not in _XYZ]
    missing = [f for f in wanted if f not in cloud.attributes]
    if missing:
        raise UnknownFieldError(
            f"{path}: unknown field {missing[0]!r}; available: {', '.join(cloud.field_names)}"
        )
    cloud.attributes = {k: cloud.attributes[k] for k in wanted}
    return cloud


def _finish(cloud: PointCloud, path: Path, fields) -> PointCloud:
    if len(cloud) == 0:
        raise InvalidPointsError(f"{path}: empty point cloud (0 points)")
    return _select_fields(cloud, fields, path)


def read(path: str | os.PathLike, *, fields=None, max_bytes: int | None = None) -> PointCloud:
    """Read a point cloud, choosing the reader from the file suffix (case-insensitive).

    Parameters
    ----------
    path : path-like
        A ``.las``, ``.laz``, ``.ply``, ``.csv``, ``.txt``, ``.npz`` or ``.e57`` file (E57:
        every scan with its pose applied, through pye57).
    fields : sequence of str, optional
        Attributes to keep (coordinates are always read); default: all.
    max_bytes : int, optional
        Most bytes the read may allocate, estimated from the file's header (LAS/LAZ, PLY),
        its uncompressed array sizes (NPZ) or its size (CSV/TXT, E57) before reading.
        Default: the environment variable ``LIDARSTAT_MAX_READ_BYTES``, else half of the
        physical memory.

    Returns
    -------
    PointCloud

    Raises
    ------
    MalformedFileError
        If the file's structure contradicts itself or its size (a LAS header, VLR or LAZ
        chunk table pointing past the end, a zero or non-finite scale, more points than
        bytes ...) or reading would exceed `max_bytes`; checked before any allocation.
    PointCloudReadError
        If the file is missing, truncated or corrupt (the base class of the above).
    UnknownFormatError
        If the suffix is not supported.
    InvalidPointsError
        If the cloud is empty or has NaN/infinite coordinates.
    UnknownFieldError
        If `fields` names an attribute the file does not have.
    """
    path = Path(path)
    fmt = _format_of(path)
    if not path.exists():
        raise PointCloudReadError(f"{path}: no such file")
    if path.is_dir():
        raise PointCloudReadError(f"{path}: is a directory, not a point-cloud file")
    cloud = _module(fmt).read_file(path, fmt, max_bytes=max_bytes)
    return _finish(cloud, path, fields)


def _check_fields(path: Path, fields, n: int) -> dict:
    new = {}
    for name, values in (fields or {}).items():
        arr = np.asarray(values)
        if arr.ndim != 1 or arr.shape[0] != n:
            raise InvalidParameterError(
                f"{path}: field {name!r} has shape {arr.shape}; expected ({n},), "
                "one value per point"
            )
        if name.lower() in _XYZ:
            raise InvalidParameterError(f"{path}: field {name!r} would overwrite a coordinate")
        new[str(name)] = arr
    return new


def write(path: str | os.PathLike, cloud: PointCloud, *,
          fields: Mapping[str, Any] | None = None) -> Path:
    """Write `cloud` (plus optional new per-point `fields`) atomically to `path`.

    The output goes to a temporary file beside `path` that is renamed onto it only when
    complete, so a failure never leaves a partial file and never alters the input.

    Parameters
    ----------
    path : path-like
        Destination; its suffix selects the format.
    cloud : PointCloud
        Points to write. For LAS/LAZ, ``cloud.las_header`` (if any) is reused so that
        version, point format, scales, offsets, VLRs, EVLRs and extra bytes survive.
    fields : dict of str to 1-D array, optional
        New per-point results (e.g. ``K``, ``H``, ``surface_type``); they become LAS extra
        bytes (described, see :func:`lidarstat.io.field_description`), CSV columns, NPZ arrays
        or PLY properties in CloudCompare's spelling (``NormalX/Y/Z`` as ``nx ny nz``,
        ``red green blue`` as uchar, any other ``name`` as ``scalar_name``; :func:`read`
        returns the lidarstat names).

    Notes
    -----
    A cloud without a LAS header written to ``.las``/``.laz`` gets LAS 1.4 point format 6
    (7 with red/green/blue, 8 with nir too), scale 1e-4 and offsets ``floor(min)``;
    attributes named like standard dimensions fill them when their values fit, float
    attributes that do not fit are kept as extra bytes named ``<name>_f``. Standard
    dimensions missing from ``cloud.attributes`` (e.g. after ``read(..., fields=[...])``)
    are written as zeros.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    PointCloudWriteError
        If `path` is the cloud's own source file or writing fails.
    InvalidParameterError
        If a field has the wrong length or cannot be stored in the format.
    UnknownFormatError
        If the suffix is not supported.
    """
    path = Path(path)
    fmt = _format_of(path)
    if not isinstance(cloud, PointCloud):
        raise InvalidParameterError(f"{path}: `cloud` must be a PointCloud; got "
                                    f"{type(cloud).__name__}")
    src = cloud.source_path
    if src is not None and path.exists() and src.exists() and os.path.samefile(path, src):
        raise PointCloudWriteError(
            f"{path}: refusing to overwrite the cloud's own source file; write elsewhere"
        )
    new = _check_fields(path, fields, len(cloud))
    if not path.parent.is_dir():
        raise PointCloudWriteError(f"{path}: directory {path.parent} does not exist")
    try:
        _module(fmt).write_file(path, cloud, new, fmt)
    except (InvalidParameterError, PointCloudWriteError, UnknownFieldError):
        raise
    except OSError as exc:
        raise PointCloudWriteError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    return path


def iter_chunks(path: str | os.PathLike, points_per_chunk: int = 1_000_000, *,
                max_bytes: int | None = None) -> Iterator[PointCloud]:
    """Yield the file as consecutive :class:`PointCloud` chunks.

    LAS/LAZ files are streamed chunk by chunk; other formats are read whole and yielded as
    one chunk. The file gets the checks of :func:`read`: an empty or malformed file raises,
    and a LAS/LAZ file holding fewer points than its header announces raises
    :class:`PointCloudReadError` at the missing chunk.

    Parameters
    ----------
    path : path-like
        Point-cloud file.
    points_per_chunk : int
        Largest number of points per chunk (LAS/LAZ only).
    max_bytes : int, optional
        Most bytes reading one chunk may allocate; see :func:`read`.
    """
    from .._shared.validation import check_scalar

    points_per_chunk = check_scalar(points_per_chunk, "points_per_chunk", func="iter_chunks",
                                    low=1, closed="left", integer=True)
    path = Path(path)
    fmt = _format_of(path)
    if not path.exists():
        raise PointCloudReadError(f"{path}: no such file")
    if path.is_dir():
        raise PointCloudReadError(f"{path}: is a directory, not a point-cloud file")
    if fmt in ("las", "laz"):
        from . import _las

        yield from _las.iter_file(path, fmt, points_per_chunk, max_bytes)
    else:
        yield read(path, max_bytes=max_bytes)


def rewrite(src: str | os.PathLike, dst: str | os.PathLike, fields_of, *,
            points_per_chunk: int = 1_000_000, decode: bool = True) -> Path:
    """Copy `src` to `dst` with new per-point fields computed chunk by chunk.

    LAS/LAZ to LAS/LAZ is streamed: one chunk of `points_per_chunk` points is in memory
    at a time, every original field, VLR and CRS is kept, and `dst` appears only when
    complete; the records are copied as read, only the new fields are written into
    them. Other formats are read and written whole.

    Parameters
    ----------
    src, dst : path-like
        Input (never modified) and output; formats from the suffixes.
    fields_of : callable
        ``fields_of(start, chunk) -> dict`` of arrays for the points ``start ..
        start + len(chunk)`` of the file (`chunk` is a :class:`PointCloud`).
    points_per_chunk : int
    decode : bool
        False when `fields_of` needs only the chunk's length: `chunk` is then the
        ``range`` of its points' positions in the file and the LAS/LAZ records are not
        decoded into arrays.

    Returns
    -------
    Path
    """
    from .._shared.validation import check_scalar

    points_per_chunk = check_scalar(points_per_chunk, "points_per_chunk", func="rewrite",
                                    low=1, closed="left", integer=True)
    src, dst = Path(src), Path(dst)
    fin, fout = _format_of(src), _format_of(dst)
    if dst.exists() and src.exists() and os.path.samefile(src, dst):
        raise PointCloudWriteError(f"{dst}: refusing to overwrite the input file; "
                                   "write elsewhere")
    if not dst.parent.is_dir():
        raise PointCloudWriteError(f"{dst}: directory {dst.parent} does not exist")
    if fin in ("las", "laz") and fout in ("las", "laz"):
        from . import _las

        if not src.exists():
            raise PointCloudReadError(f"{src}: no such file")
        if src.is_dir():
            raise PointCloudReadError(f"{src}: is a directory, not a point-cloud file")
        _las.rewrite_file(src, dst, fin, fout, fields_of, points_per_chunk,
                          lambda fields, n: _check_fields(dst, fields, n), decode=decode)
        return dst
    cloud = read(src)
    return write(dst, cloud, fields=fields_of(0, cloud if decode else range(len(cloud))))
