"""LAS/LAZ reading and writing through laspy (LAZ via the lazrs backend).

Reading keeps the laspy header on the :class:`PointCloud` so that writing back preserves
version, point format, scales, offsets, VLRs, EVLRs, CRS, standard dimensions and existing
extra bytes; new per-point results become LAS extra bytes.

Every extra-bytes field lidarstat adds is recorded as PDAL's ``writers.las`` records its
own: a 32-byte description (the field's documented meaning, see
:func:`lidarstat.io.field_description`), no no-data value and no min/max. Floating-point
fields mark "no value" with NaN, which PDAL, laspy and CloudCompare all read as NaN; a
``no_data`` of NaN would add nothing (PDAL ignores ``no_data`` when reading, laspy only uses
it to skip values in its min/max, by an equality NaN never meets) and a finite sentinel
would change the values. The min/max laspy computes are left out because they are not
reliable (wrong once a NaN is among the values, and wrong for integers in laspy 2.7's LAZ
and LAS writes alike), and a streamed write fixes the header before it has seen every chunk.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Iterator
from pathlib import Path

import laspy
import numpy as np
from laspy.point.dims import DimensionKind
from laspy.vlrs.known import GeoKeyDirectoryVlr, LasZipVlr, WktCoordinateSystemVlr

from .._shared._atomic import atomic_path
from ..errors import (
    InvalidParameterError,
    InvalidPointsError,
    LidarstatWarning,
    PointCloudReadError,
    PointCloudWriteError,
)
from . import _las_checks
from ._cloud import PointCloud
from ._descriptions import field_description

_BACKEND = laspy.LazBackend.Lazrs
_MAX_EB_NAME = 32
_EB_TYPES = {"b": "u1", "u1": "u1", "u2": "u2", "u4": "u4", "u8": "u8", "i1": "i1",
             "i2": "i2", "i4": "i4", "i8": "i8", "f2": "f4", "f4": "f4", "f8": "f8"}


#: Exceptions a reader lets through; every other one (including the PanicException lazrs
#: raises, a BaseException) becomes a PointCloudReadError naming the file.
NOT_FOREIGN = (KeyboardInterrupt, SystemExit, GeneratorExit)


def short_cause(exc: BaseException, limit: int = 120) -> str:
    """One-line, length-limited description of an exception."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def crs_of(header) -> str | None:
    """CRS of a LAS header as WKT (or ``"EPSG:<code>"`` from GeoTIFF keys), else None.

    Uses ``header.parse_crs()`` when pyproj is importable; otherwise reads the WKT VLR/EVLR
    text or the GeoTIFF projected/geographic EPSG key directly.
    """
    try:
        import pyproj  # noqa: F401
    except ImportError:
        pass
    else:
        try:
            crs = header.parse_crs()
            if crs is not None:
                return crs.to_wkt()
        except Exception:  # a malformed CRS must not make the points unreadable
            pass
    records = list(header.vlrs) + list(getattr(header, "evlrs", None) or [])
    for vlr in records:
        if isinstance(vlr, WktCoordinateSystemVlr) and vlr.string.strip("\0 \n"):
            return vlr.string.rstrip("\0")
    for vlr in records:
        if isinstance(vlr, GeoKeyDirectoryVlr):
            for key in vlr.geo_keys:
                if (key.id in (3072, 2048) and key.tiff_tag_location == 0
                        and key.value_offset not in (0, 32767)):
                    return f"EPSG:{key.value_offset}"
    return None


def _format_only(record) -> bool:
    """True for a VLR describing the file's encoding (LASzip, COPC), not its content."""
    return isinstance(record, LasZipVlr) or getattr(record, "user_id", "") == "copc"


def _strip_laszip(header):
    """A copy of `header` without the records of the input's encoding.

    The LASzip VLR is rewritten by the writer; the COPC info VLR and hierarchy EVLR
    describe an octree layout that a plain LAS/LAZ output does not have.
    """
    header = copy.deepcopy(header)
    header.vlrs = type(header.vlrs)([v for v in header.vlrs if not _format_only(v)])
    if getattr(header, "evlrs", None):
        header.evlrs = type(header.evlrs)([v for v in header.evlrs if not _format_only(v)])
    return header


def _cloud_from_points(points, header, path: Path, fmt: str, crs, keep=None) -> PointCloud:
    """The decoded cloud of `points`: coordinates and the attributes named in `keep`
    (default all; every one when `keep` names one the records lack, so that the caller's
    check of the names sees them all)."""
    names = [n for n in header.point_format.dimension_names if n not in ("X", "Y", "Z")]
    if keep is not None and set(keep) <= set(names):
        names = [n for n in names if n in keep]
    try:
        xyz = np.empty((len(points), 3), dtype=np.float64)
        for j, dim in enumerate("XYZ"):
            np.multiply(points[dim], header.scales[j], out=xyz[:, j])
            xyz[:, j] += header.offsets[j]
        attrs = {name: np.array(points[name]) for name in names}
    except NOT_FOREIGN:
        raise
    except BaseException as exc:  # e.g. extra-bytes VLR describing fields the records lack
        raise _unreadable(path, fmt, exc) from exc
    return PointCloud(xyz, attrs, crs=crs, source_path=path, source_format=fmt,
                      las_header=header)


def _unreadable(path: Path, fmt: str, exc: BaseException) -> PointCloudReadError:
    return PointCloudReadError(f"{path}: unreadable {fmt.upper()} file ({short_cause(exc)})")


def _checked(path: Path, fmt: str, chunk: int | None, max_bytes, allow_empty: bool = False
             ) -> _las_checks.LasLayout:
    """Structural checks shared by :func:`read_file`, :func:`iter_file` and ``describe``."""
    try:
        layout = _las_checks.check_las(path, fmt)
    except OSError as exc:
        if isinstance(exc, PointCloudReadError):
            raise
        raise PointCloudReadError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if layout.point_count == 0 and not allow_empty:
        raise InvalidPointsError(f"{path}: empty point cloud (0 points)")
    n = layout.point_count if chunk is None else min(chunk, layout.point_count)
    _las_checks.check_ceiling(path, f"{n} points of {layout.record_length} bytes",
                              layout.bytes_for(n), max_bytes)
    return layout


def read_file(path: Path, fmt: str, max_bytes=None, keep=None) -> PointCloud:
    """Read a whole LAS/LAZ file into a :class:`PointCloud` (structure checked first);
    only the attributes named in `keep` are decoded (default all)."""
    _checked(path, fmt, None, max_bytes)
    try:
        las = laspy.read(path, laz_backend=_BACKEND)
        points = las.points
        n_header = las.header.point_count
        header = _strip_laszip(las.header)
        crs = crs_of(header)
    except NOT_FOREIGN:
        raise
    except BaseException as exc:  # ZeroDivisionError, MemoryError, lazrs panics ...
        raise _unreadable(path, fmt, exc) from exc
    if len(points) != n_header:
        raise PointCloudReadError(f"{path}: unreadable {fmt.upper()} file (header announces "
                                  f"{n_header} points, {len(points)} found)")
    return _cloud_from_points(points, header, path, fmt, crs, keep)


def _open_reader(path: Path, fmt: str):
    """``laspy.open`` of `path` for reading; its failure as one line naming the file."""
    try:
        return laspy.open(path, laz_backend=_BACKEND)
    except NOT_FOREIGN:
        raise
    except BaseException as exc:
        raise _unreadable(path, fmt, exc) from exc


def iter_file(path: Path, fmt: str, points_per_chunk: int, max_bytes=None
              ) -> Iterator[PointCloud]:
    """Stream a LAS/LAZ file as clouds of at most `points_per_chunk` points.

    The file gets the checks of :func:`read_file`, and every chunk must hold the points the
    header promises: a short file raises :class:`PointCloudReadError` instead of ending early.
    """
    _checked(path, fmt, points_per_chunk, max_bytes)
    reader = _open_reader(path, fmt)
    with reader:
        try:
            header = _strip_laszip(reader.header)
            crs = crs_of(header)
        except NOT_FOREIGN:
            raise
        except BaseException as exc:
            raise _unreadable(path, fmt, exc) from exc
        for points in read_chunks(reader, path, fmt, points_per_chunk):
            yield _cloud_from_points(points, header, path, fmt, crs)


def read_chunks(reader, path: Path, fmt: str, points_per_chunk: int):
    """Yield the point records of an open laspy reader, each chunk as long as promised."""
    total, done = int(reader.header.point_count), 0
    while done < total:
        want = min(points_per_chunk, total - done)
        try:
            points = reader.read_points(want)
        except NOT_FOREIGN:
            raise
        except BaseException as exc:
            raise _unreadable(path, fmt, exc) from exc
        if len(points) != want:
            raise PointCloudReadError(
                f"{path}: unreadable {fmt.upper()} file (header announces {total} "
                f"points, {done + len(points)} found)")
        done += want
        yield points


# ---------------------------------------------------------------------- writing
def _fits(values: np.ndarray, info) -> bool:
    """Whether `values` can be stored losslessly in the laspy dimension `info`."""
    if values.ndim != (1 if info.num_elements == 1 else 2):
        return False
    if values.dtype.kind not in "biuf":
        return False
    if info.kind == DimensionKind.FloatingPoint or info.scales is not None:
        return True
    if values.size == 0:
        return True
    v = values
    if v.dtype.kind == "f":
        if not np.all(np.isfinite(v)) or not np.all(v == np.round(v)):
            return False
    if info.kind == DimensionKind.BitField or info.kind == DimensionKind.UnsignedInteger:
        lo, hi = 0, 2 ** info.num_bits - 1
    else:
        lo, hi = -(2 ** (info.num_bits - 1)), 2 ** (info.num_bits - 1) - 1
    return bool(v.min() >= lo and v.max() <= hi)


def _extra_bytes_param(path: Path, name: str, values: np.ndarray) -> laspy.ExtraBytesParams:
    if len(name) > _MAX_EB_NAME:
        raise InvalidParameterError(f"{path}: field name {name!r} is longer than the "
                                    f"{_MAX_EB_NAME} characters LAS extra bytes allow")
    code = _EB_TYPES.get(values.dtype.str.lstrip("<>|=")) or _EB_TYPES.get(values.dtype.kind)
    if code is None:
        raise InvalidParameterError(f"{path}: field {name!r} has dtype {values.dtype}, which "
                                    "cannot be stored as LAS extra bytes")
    if values.ndim == 2 and values.shape[1] in (2, 3):
        code = f"{values.shape[1]}{code}"
    elif values.ndim != 1:
        raise InvalidParameterError(f"{path}: field {name!r} has shape {values.shape}; LAS "
                                    "extra bytes need (N,) or (N, 2|3)")
    return laspy.ExtraBytesParams(name=name, type=code, description=field_description(name))


_EB_STATS = 0b110  # min and max bits of an extra-bytes record's options


def _drop_statistics(header) -> None:
    """Clear the min/max bits of every extra-bytes record (see the module docstring).

    laspy rebuilds the records of a header's extra bytes, those of the input included, and
    would write its own min/max for each.
    """
    for vlr in header.vlrs.get("ExtraBytesVlr"):
        for record in vlr.extra_bytes_structs:
            record.options &= ~_EB_STATS


def _new_header(cloud: PointCloud, attrs: dict) -> laspy.LasHeader:
    rgb = all(c in attrs for c in ("red", "green", "blue"))
    pf = 8 if rgb and "nir" in attrs else 7 if rgb else 6
    header = laspy.LasHeader(version="1.4", point_format=pf)
    if len(cloud):
        lo, hi = cloud.xyz.min(axis=0), cloud.xyz.max(axis=0)
        offsets = np.floor(lo)
        extent = float(np.max(hi - offsets))
    else:
        offsets, extent = np.zeros(3), 0.0
    scale = 1e-4
    while extent / scale > 2**31 - 2:
        scale *= 10.0
    header.scales = np.full(3, scale)
    header.offsets = offsets
    if cloud.crs:
        if "[" in cloud.crs:
            header.vlrs.append(WktCoordinateSystemVlr(cloud.crs))
            header.global_encoding.wkt = True
        else:
            try:
                import pyproj

                header.add_crs(pyproj.CRS.from_user_input(cloud.crs))
            except Exception as exc:  # no pyproj or unparsable: points are still worth writing
                warnings.warn(f"CRS {cloud.crs[:40]!r} not written to the LAS file "
                              f"({short_cause(exc, 60)}); pyproj converts it to WKT",
                              LidarstatWarning, stacklevel=4)
    return header


def _plan(path: Path, cloud: PointCloud, new: dict, header) -> tuple[dict, list]:
    """Split values into standard/existing dimensions and new extra bytes."""
    fmt = header.point_format
    existing = {n for n in fmt.dimension_names if n not in ("X", "Y", "Z")}
    attrs = dict(cloud.attributes)
    if cloud.las_header is None and "scan_angle" in existing and "scan_angle" not in attrs \
            and "scan_angle_rank" in attrs:
        attrs["scan_angle"] = np.round(attrs.pop("scan_angle_rank") / 0.006).astype(np.int16)
    assign, params = {}, []
    for source, values_by_name in (("attribute", attrs), ("field", new)):
        for name, values in values_by_name.items():
            values = np.asarray(values)
            if name in existing:
                if _fits(values, fmt.dimension_by_name(name)):
                    assign[name] = values
                    continue
                if source == "attribute" and cloud.las_header is None and values.dtype.kind == "f":
                    name = f"{name}_f"  # e.g. float intensity from PLY/NPZ: keep it exactly
                else:
                    info = fmt.dimension_by_name(name)
                    raise InvalidParameterError(
                        f"{path}: {source} {name!r} ({values.dtype}) does not fit the LAS "
                        f"dimension {name!r} ({info.kind.name}, {info.num_bits} bits)")
            if values.dtype == bool:
                values = values.astype(np.uint8)
            if name in assign:
                assign.pop(name)
                params = [p for p in params if p.name != name]
            params.append(_extra_bytes_param(path, name, values))
            assign[name] = values
    return assign, params


def _dump(records, tmp: Path, compress: bool) -> None:
    """Low-level writer: a LAS/LAZ file at `tmp` of ``records.header`` and the point
    records ``records.chunks()`` yields, then the header's EVLRs (as ``laspy.LasData.write``
    writes them)."""
    header = records.header
    with open(tmp, "wb") as fh, laspy.LasWriter(fh, header, do_compress=compress,
                                                 closefd=False, laz_backend=_BACKEND) as writer:
        for rec in records.chunks():
            writer.write_points(rec)
        if header.version.minor >= 4 and header.evlrs is not None:
            writer.write_evlrs(header.evlrs)


def _record(path: Path, header, cloud: PointCloud, assign: dict, start: int = 0,
            stop: int | None = None):
    """LAS point record of points ``start:stop`` of `cloud` with the `assign` values, for
    `header`."""
    stop = len(cloud) if stop is None else stop
    ints = np.round((cloud.xyz[start:stop] - header.offsets) / header.scales)
    if ints.size and (ints.min() < -(2**31) or ints.max() > 2**31 - 1):
        raise InvalidParameterError(
            f"{path}: coordinates do not fit the LAS scale {list(header.scales)} and offset "
            f"{list(header.offsets)} (32-bit overflow)")
    try:
        # A bare record: building a LasData would reset the shared header's point count,
        # which the streaming writer keeps.
        rec = laspy.ScaleAwarePointRecord.zeros(stop - start, header=header)
        for j, dim in enumerate("XYZ"):
            rec[dim] = ints[:, j].astype(np.int32)
        for name, values in assign.items():
            rec[name] = values[start:stop]
    except (ValueError, OverflowError, TypeError) as exc:
        raise InvalidParameterError(f"{path}: cannot build LAS points ({short_cause(exc)})"
                                    ) from exc
    return rec


#: Points per record a write fills and writes at a time: a few megabytes, so that the
#: record being filled stays in the processor's cache while every field is copied into it
#: (a whole-cloud record is filled one field at a time, each pass over all its memory).
WRITE_CHUNK = 1 << 15


def _header_for(path: Path, cloud: PointCloud, new: dict):
    if cloud.las_header is not None:
        header = _strip_laszip(cloud.las_header)
    else:
        header = _new_header(cloud, {**cloud.attributes, **new})
    assign, params = _plan(path, cloud, new, header)
    if params:
        header.add_extra_dims(params)
    _drop_statistics(header)
    return header, assign


class _Records:
    """The point records of a whole cloud, :data:`WRITE_CHUNK` points at a time."""

    def __init__(self, path: Path, header, cloud: PointCloud, assign: dict):
        self.path, self.header, self.cloud = path, header, cloud
        self.assign = {k: np.asarray(v) for k, v in assign.items()}

    def chunks(self):
        n = len(self.cloud)
        for start in range(0, n, WRITE_CHUNK):
            yield _record(self.path, self.header, self.cloud, self.assign, start,
                          min(start + WRITE_CHUNK, n))


def write_file(path: Path, cloud: PointCloud, new: dict, fmt: str) -> None:
    """Write `cloud` plus `new` fields to a LAS/LAZ file atomically.

    The points are packed and written :data:`WRITE_CHUNK` at a time; the file is the one
    ``laspy.LasData.write`` writes.
    """
    header, assign = _header_for(path, cloud, new)
    header.point_count = len(cloud)
    try:
        with atomic_path(path) as tmp:
            _dump(_Records(path, header, cloud, assign), tmp, fmt == "laz")
    except (OSError, InvalidParameterError):
        raise
    except Exception as exc:  # laspy / lazrs errors
        raise PointCloudWriteError(f"{path}: cannot write {fmt.upper()} file "
                                   f"({short_cause(exc)})") from exc


def _copy_records(points, header, into=None):
    """A point record for `header` holding the records of `points` byte for byte.

    `header` is the input's header with new extra bytes appended (see
    :func:`rewrite_file`): every field of the input keeps its raw bytes (coordinates as
    the stored integers, bit fields packed as read), so nothing is decoded and encoded
    again. `into`: a record for `header` of as many points to fill (default a new,
    zeroed one).
    """
    rec = laspy.ScaleAwarePointRecord.zeros(len(points), header=header) if into is None else into
    src, dst = points.array, rec.array
    size = src.dtype.itemsize
    if all(dst.dtype.fields.get(name) == field for name, field in src.dtype.fields.items()):
        # the input's fields lead the output's records at the same offsets: one copy of
        # each record's first `size` bytes
        rows = dst.view(np.uint8).reshape(len(dst), dst.dtype.itemsize)
        rows[:, :size] = np.ascontiguousarray(src).view(np.uint8).reshape(len(src), size)
    else:
        for name in src.dtype.names:
            dst[name] = src[name]
    return rec


def rewrite_file(src: Path, dst: Path, fin: str, fout: str, fields_of, points_per_chunk: int,
                 check_fields, decode: bool = True) -> int:
    """Copy the LAS/LAZ file `src` to `dst` with new fields, chunk by chunk.

    Each chunk's records are copied as read (:func:`_copy_records`) and the new fields
    written over them; ``fields_of(start, chunk)`` sees the chunk decoded as a
    :class:`PointCloud` (`decode` False: the ``range`` of its positions, nothing
    decoded). `check_fields(fields, n)` checks the fields of a chunk of `n`
    points. The file is the one :func:`write_stream` writes from the decoded chunks.
    Returns the number of points written.
    """
    _checked(src, fin, points_per_chunk, None)
    reader = _open_reader(src, fin)
    reused = {}  # the first chunk's record, filled again for the next ones

    def parts():
        try:
            in_header = _strip_laszip(reader.header)
            crs = crs_of(in_header) if decode else None
        except NOT_FOREIGN:
            raise
        except BaseException as exc:
            raise _unreadable(src, fin, exc) from exc
        bare = PointCloud(np.empty((0, 3)), las_header=in_header)
        start = 0
        for points in read_chunks(reader, src, fin, points_per_chunk):
            m = len(points)
            chunk = (_cloud_from_points(points, in_header, src, fin, crs) if decode
                     else range(start, start + m))
            new = check_fields(fields_of(start, chunk), m)
            start += m
            # packed and written WRITE_CHUNK points at a time: the record being filled
            # stays in the processor's cache through the copy, the fields, laspy's
            # header statistics and the file write
            for a in range(0, m, WRITE_CHUNK):
                b = min(a + WRITE_CHUNK, m)
                part = new if (a, b) == (0, m) else {k: v[a:b] for k, v in new.items()}
                yield bare, part, lambda header, assign, points=points[a:b]: _copied_record(
                    dst, header, points, assign, reused)

    with reader:
        return _write_parts(dst, parts(), fout)


def _copied_record(path, header, points, assign, reused=None):
    """The records of `points` copied as read (:func:`_copy_records`) with the new
    fields of `assign` written over them.

    `reused` (a dict kept over the chunks of one copy, which writes each record before
    it makes the next): the first chunk's record is filled again for the next chunks
    of the same header and fields. Every chunk writes the same bytes of it (the input's
    records, then the same fields), so the bytes none writes stay zero as in a new
    record, and its memory is paged in (zeroed by the system) once, not once a chunk.
    """
    key = (id(header), tuple(assign))
    into = None
    if reused is not None and reused.get("key") == key and len(reused["rec"]) >= len(points):
        into = reused["rec"][:len(points)]
    rec = _copy_records(points, header, into)
    if reused is not None and into is None:
        reused.update(key=key, rec=rec)
    try:
        for name, values in assign.items():
            rec[name] = values
    except (ValueError, OverflowError, TypeError) as exc:
        raise InvalidParameterError(
            f"{path}: cannot build LAS points ({short_cause(exc)})") from exc
    return rec


def write_stream(path: Path, chunks, fmt: str) -> int:
    """Write ``(cloud, new_fields)`` chunks one after the other to a LAS/LAZ file.

    The first chunk fixes the header (its source header, or a new one) and the extra
    bytes; memory holds one chunk at a time. The file appears only when complete.
    Returns the number of points written.
    """
    return _write_parts(path, ((cloud, new, lambda header, assign, cloud=cloud: _record(
        path, header, cloud, assign)) for cloud, new in chunks), fmt)


def _write_parts(path: Path, parts, fmt: str) -> int:
    """Write ``(cloud, new_fields, make_record)`` parts to a LAS/LAZ file, atomically.

    The first part's cloud (its source header, or none) and new fields fix the header;
    ``make_record(header, assign)`` builds each part's points. Returns the number of
    points written.
    """
    total = 0
    try:
        with atomic_path(path) as tmp:
            writer = None
            try:
                for cloud, new, make_record in parts:
                    if writer is None:
                        header, _ = _header_for(path, cloud, new)
                        writer = laspy.open(tmp, mode="w", header=header,
                                            do_compress=fmt == "laz", laz_backend=_BACKEND)
                    assign, _ = _plan(path, cloud, new, writer.header)
                    rec = make_record(writer.header, assign)
                    writer.write_points(rec)
                    total += len(rec)
                if writer is None:
                    raise InvalidParameterError(f"{path}: nothing to write (no points)")
            finally:
                if writer is not None:
                    writer.close()
    except (OSError, InvalidParameterError, PointCloudReadError):
        raise
    except Exception as exc:  # laspy / lazrs errors
        raise PointCloudWriteError(f"{path}: cannot write {fmt.upper()} file "
                                   f"({short_cause(exc)})") from exc
    return total
