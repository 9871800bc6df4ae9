"""Structural checks of a LAS/LAZ file, from its own bytes, before laspy or lazrs allocate.

laspy trusts the header: a point count, a VLR count or a LAZ chunk table that does not match
the file makes it hang, allocate tens of gigabytes or (through lazrs) abort the interpreter.
:func:`check_las` reads the public header block (LAS 1.0-1.4), walks the VLR and EVLR headers
and, for LAZ, the chunk table pointer, the chunk table (decoded only once its count is known
to fit the file) and the layer sizes at the start of each layered chunk (point formats
6-10), and compares every offset, count and length with the size of the file or chunk.
:func:`read_ceiling` is the most one read may allocate (``max_bytes``, else the environment
variable ``LIDARSTAT_MAX_READ_BYTES``, else half of the physical memory).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import struct
from pathlib import Path

from .._shared.validation import MAX_COORDINATE
from ..errors import InvalidParameterError, MalformedFileError

#: Environment variable holding the default read ceiling, in bytes.
MAX_READ_ENV = "LIDARSTAT_MAX_READ_BYTES"
#: Largest accepted |scale| of a LAS coordinate.
MAX_SCALE = 1e6

_HEADER_SIZE = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
_POINT_SIZE = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
_VLR_HEADER, _EVLR_HEADER = 54, 60
_LASZIP = (b"laszip encoded", 22204)
_LASZIP_FIXED = 34  # bytes of the LasZip VLR before its item list
_CHUNK_TABLE_HEADER = 8  # u32 version, u32 number of chunks
_VARIABLE = 0xFFFFFFFF  # chunk_size of LAZ files with variable-size chunks
_LAYERED = 3  # LasZip compressor of point formats 6-10
_BYTE14 = 14  # extra bytes, one layer per byte
_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}  # layers of POINT14, RGB14, RGBNIR14, WAVEPACKET14
# Bytes one point costs in memory while read: laspy's packed record and its copy, the
# unpacked attribute arrays (about one more record) and the float64 coordinates; measured
# 95-101 bytes a point for 38-41-byte records (tracemalloc peak of a whole read).
_RECORDS_PER_POINT, _PER_POINT_OVERHEAD = 3, 32


@dataclasses.dataclass(frozen=True)
class LasLayout:
    """What :func:`check_las` found: the header fields the readers rely on."""

    version: tuple[int, int]
    point_format: int
    record_length: int
    point_count: int
    offset_to_point_data: int
    compressed: bool
    file_size: int

    def bytes_for(self, n_points: int) -> int:
        """Estimated peak bytes to read `n_points` points of this file."""
        return n_points * (_RECORDS_PER_POINT * self.record_length + _PER_POINT_OVERHEAD)


def read_ceiling(max_bytes=None) -> int:
    """Most bytes one read may allocate.

    Parameters
    ----------
    max_bytes : int, optional
        Explicit ceiling. Default: the integer in the environment variable
        ``LIDARSTAT_MAX_READ_BYTES``, else half of the physical memory (16 GiB when it
        cannot be determined).

    Raises
    ------
    InvalidParameterError
        If `max_bytes` or the environment variable is not a positive integer.
    """
    if max_bytes is None:
        env = os.environ.get(MAX_READ_ENV, "").strip()
        if env:
            try:
                max_bytes = int(float(env))
            except (ValueError, OverflowError):
                raise InvalidParameterError(
                    f"{MAX_READ_ENV}={env!r} is not a number of bytes") from None
            if max_bytes <= 0:
                raise InvalidParameterError(f"{MAX_READ_ENV}={env!r} must be positive")
            return max_bytes
        try:
            return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
        except (ValueError, OSError, AttributeError):
            return 16 * 2**30
    if (isinstance(max_bytes, bool) or not isinstance(max_bytes, numbers.Integral)
            or max_bytes <= 0):
        raise InvalidParameterError(f"The 'max_bytes' parameter must be a positive int. "
                                    f"Got {max_bytes!r} instead.")
    return int(max_bytes)


def check_ceiling(path: Path, what: str, need: int, max_bytes=None) -> None:
    """Raise :class:`MalformedFileError` if reading needs more than the read ceiling."""
    limit = read_ceiling(max_bytes)
    if need > limit:
        raise MalformedFileError(
            f"{path}: reading {what} needs about {_size(need)}, more than the read ceiling "
            f"of {_size(limit)} (max_bytes or {MAX_READ_ENV})")


def _size(n: int) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} bytes"


class _Fields:
    """Little-endian field reader over the file's bytes with one error format."""

    def __init__(self, path: Path, kind: str, fh, size: int) -> None:
        self.path, self.kind, self.fh, self.size = path, kind, fh, size

    def fail(self, what: str, msg: str) -> MalformedFileError:
        return MalformedFileError(f"{self.path}: unreadable {self.kind} file (malformed "
                                  f"{what}: {msg})")

    def read(self, offset: int, fmt: str, what: str, field: str):
        n = struct.calcsize("<" + fmt)
        if offset < 0 or offset + n > self.size:
            raise self.fail(what, f"{field} at byte {offset} lies beyond the end of the file "
                                  f"({self.size} bytes)")
        self.fh.seek(offset)
        data = self.fh.read(n)
        if len(data) != n:
            raise self.fail(what, f"{field} at byte {offset} cannot be read (file shrank?)")
        return struct.unpack("<" + fmt, data)


def check_las(path: Path, fmt: str) -> LasLayout:
    """Check the structure of a LAS/LAZ file against its size.

    Parameters
    ----------
    path : Path
        The file.
    fmt : str
        ``"las"`` or ``"laz"`` (only used in messages; compression is read from the header).

    Returns
    -------
    LasLayout

    Raises
    ------
    MalformedFileError
        Naming the file and the field at fault, e.g. ``scan.laz: malformed LAZ header:
        offset_to_point_data 99999999 lies beyond the end of the file (1934 bytes)``.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        f = _Fields(path, fmt.upper(), fh, size)
        return _check(f)


def _check(f: _Fields) -> LasLayout:
    size = f.size
    if size < 227:
        raise f.fail("header", f"the file has {size} bytes, fewer than the smallest LAS "
                               "header (227 bytes)")
    (sig,) = f.read(0, "4s", "header", "signature")
    if sig != b"LASF":
        raise f.fail("header", f"signature {sig!r} is not b'LASF'")
    major, minor = f.read(24, "BB", "header", "version")
    if major != 1 or minor not in _HEADER_SIZE:
        raise f.fail("header", f"version {major}.{minor} is not LAS 1.0-1.4")
    header_size, offset, n_vlrs, pf_raw, rec_len, legacy = f.read(94, "HIIBHI", "header",
                                                                 "header fields")
    if header_size < _HEADER_SIZE[minor]:
        raise f.fail("header", f"header_size {header_size} is smaller than the "
                               f"{_HEADER_SIZE[minor]} bytes of a LAS 1.{minor} header")
    if offset > size:
        raise f.fail("header", f"offset_to_point_data {offset} lies beyond the end of the "
                               f"file ({size} bytes)")
    if offset < header_size:
        raise f.fail("header", f"offset_to_point_data {offset} lies inside the header "
                               f"(header_size {header_size})")
    pf = pf_raw & 0x3F
    compressed = bool(pf_raw & 0x80) and not pf_raw & 0x40  # laspy's (and LASzip's) rule
    if pf not in _POINT_SIZE:
        raise f.fail("header", f"point_format {pf} is not a LAS point format (0-10)")
    if rec_len < _POINT_SIZE[pf]:
        raise f.fail("header", f"point_record_length {rec_len} is smaller than the "
                               f"{_POINT_SIZE[pf]} bytes of point format {pf}")
    scales = f.read(131, "3d", "header", "scales")
    offsets = f.read(155, "3d", "header", "offsets")
    for axis, s, o in zip("xyz", scales, offsets):
        if not math.isfinite(s) or s == 0 or abs(s) > MAX_SCALE:
            raise f.fail("header", f"{axis} scale {s!r} must be finite, non-zero and at most "
                                   f"{MAX_SCALE:g} in magnitude")
        if not math.isfinite(o):
            raise f.fail("header", f"{axis} offset {o!r} is not finite")
        if abs(o) - abs(s) * 2.0**31 > MAX_COORDINATE:
            raise f.fail("header", f"{axis} offset {o!r} puts every coordinate beyond "
                                   f"{MAX_COORDINATE:.0e} in magnitude")
    count = legacy
    evlr_start = n_evlrs = 0
    if minor >= 4:
        evlr_start, n_evlrs, count = f.read(235, "QIQ", "header", "EVLR fields")
    laszip = _walk_vlrs(f, header_size, offset, n_vlrs)
    points_end = size
    if n_evlrs:
        _walk_evlrs(f, evlr_start, n_evlrs, offset)
        points_end = evlr_start
    layout = LasLayout((major, minor), pf, rec_len, count, offset, compressed, size)
    if compressed:
        _check_laz(f, layout, laszip, points_end)
    elif count * rec_len > points_end - offset:
        raise f.fail("header", f"point count {count} x point_record_length {rec_len} = "
                               f"{count * rec_len} bytes, but the point data holds "
                               f"{points_end - offset}")
    return layout


def _walk_vlrs(f: _Fields, header_size: int, offset: int, n_vlrs: int) -> bytes | None:
    """Walk the VLR headers between the header and the point data; LasZip VLR data."""
    room = offset - header_size
    if n_vlrs * _VLR_HEADER > room:
        raise f.fail("header", f"number_of_vlrs {n_vlrs} needs at least "
                               f"{n_vlrs * _VLR_HEADER} bytes, but offset_to_point_data "
                               f"leaves {room} after the header")
    pos, laszip = header_size, None
    for i in range(n_vlrs):
        user, record_id, length = f.read(pos + 2, "16sHH", "VLR", f"VLR {i} header")
        end = pos + _VLR_HEADER + length
        if end > offset:
            raise f.fail("VLR", f"VLR {i} ({_user(user)}, record {record_id}) has "
                                f"record_length {length}, which runs past "
                                f"offset_to_point_data {offset}")
        if (user.rstrip(b"\0"), record_id) == _LASZIP:
            f.fh.seek(pos + _VLR_HEADER)
            laszip = f.fh.read(length)
        pos = end
    return laszip


def _walk_evlrs(f: _Fields, start: int, n_evlrs: int, offset: int) -> None:
    if start < offset or start > f.size:
        raise f.fail("header", f"start_of_first_evlr {start} lies outside the file's data "
                               f"({offset}..{f.size})")
    if n_evlrs * _EVLR_HEADER > f.size - start:
        raise f.fail("header", f"number_of_evlrs {n_evlrs} needs at least "
                               f"{n_evlrs * _EVLR_HEADER} bytes, but only {f.size - start} "
                               "follow start_of_first_evlr")
    pos = start
    for i in range(n_evlrs):
        user, record_id, length = f.read(pos + 2, "16sHQ", "EVLR", f"EVLR {i} header")
        end = pos + _EVLR_HEADER + length
        if end > f.size:
            raise f.fail("EVLR", f"EVLR {i} ({_user(user)}, record {record_id}) has "
                                 f"record_length {length}, which runs past the end of the "
                                 f"file ({f.size} bytes)")
        pos = end


def _user(raw: bytes) -> str:
    return repr(raw.rstrip(b"\0").decode("ascii", "replace"))


def _check_laz(f: _Fields, layout: LasLayout, laszip: bytes | None, points_end: int) -> None:
    if laszip is None:
        raise f.fail("VLRs", "a compressed point format needs a LasZip VLR; there is none")
    if len(laszip) < _LASZIP_FIXED:
        raise f.fail("VLR", f"LasZip VLR has {len(laszip)} bytes, fewer than {_LASZIP_FIXED}")
    compressor, chunk_size = struct.unpack_from("<H10xI", laszip, 0)
    (n_items,) = struct.unpack_from("<H", laszip, 32)
    if len(laszip) < _LASZIP_FIXED + 6 * n_items:
        raise f.fail("VLR", f"LasZip VLR lists {n_items} items but holds {len(laszip)} bytes")
    items = [struct.unpack_from("<HHH", laszip, _LASZIP_FIXED + 6 * i) for i in range(n_items)]
    item_bytes = sum(size for _, size, _ in items)
    if item_bytes != layout.record_length:
        raise f.fail("VLR", f"LasZip items total {item_bytes} bytes per point, but "
                            f"point_record_length is {layout.record_length}")
    if compressor == 0 or layout.point_count == 0:
        return
    data = layout.offset_to_point_data
    (table,) = f.read(data, "q", "chunk table", "the offset")
    if table == -1:  # written to a stream: the offset is the last 8 bytes of the file
        (table,) = f.read(f.size - 8, "q", "chunk table", "the offset at the end")
    first = data + 8
    if not first <= table <= f.size - _CHUNK_TABLE_HEADER:
        raise f.fail("chunk table", f"its offset {table} lies outside the file's point data "
                                    f"({first}..{f.size - _CHUNK_TABLE_HEADER})")
    _, n_chunks = f.read(table, "II", "chunk table", "the header")
    room = table - first  # every chunk holds at least one byte of compressed points
    if n_chunks > room or (n_chunks == 0 and layout.point_count):
        raise f.fail("chunk table", f"{n_chunks} chunks announced for {room} bytes of "
                                    "compressed points")
    if chunk_size != _VARIABLE and n_chunks * chunk_size < layout.point_count:
        raise f.fail("header", f"point count {layout.point_count} exceeds {n_chunks} chunks "
                               f"of {chunk_size} points")
    entries = _chunk_table(f, layout, laszip)
    if chunk_size == _VARIABLE and sum(n for n, _ in entries) != layout.point_count:
        raise f.fail("chunk table", f"its chunks hold {sum(n for n, _ in entries)} points, "
                                    f"the header {layout.point_count}")
    if sum(b for _, b in entries) > room:
        raise f.fail("chunk table", f"its chunks total {sum(b for _, b in entries)} bytes; "
                                    f"the file holds {room}")
    if compressor == _LAYERED:
        _check_layers(f, layout, items, entries, first)


def _chunk_table(f: _Fields, layout: LasLayout, laszip: bytes) -> list[tuple[int, int]]:
    """(points, bytes) of every chunk, decoded by lazrs once its size is known to be bounded."""
    import lazrs

    try:
        f.fh.seek(layout.offset_to_point_data)
        entries = lazrs.read_chunk_table(f.fh, lazrs.LazVlr(laszip))
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # lazrs panics are BaseExceptions
        raise f.fail("chunk table", f"lazrs cannot decode it ({type(exc).__name__})") from exc
    return [(int(n), int(b)) for n, b in entries]


def _check_layers(f: _Fields, layout: LasLayout, items, entries, first: int) -> None:
    """Layered chunks (point formats 6-10): the layer sizes must fit in their chunk.

    Such a chunk starts with its first point raw, the number of points (u32) and one u32
    size per layer (lazrs allocates each layer at its announced size).
    """
    n_layers = sum(_LAYERS.get(kind, size if kind == _BYTE14 else 0)
                   for kind, size, _ in items)
    pos = first
    for i, (_, nbytes) in enumerate(entries):
        head = layout.record_length + 4 + 4 * n_layers
        if nbytes >= head:
            sizes = f.read(pos + layout.record_length + 4, f"{n_layers}I", "chunk",
                           f"layer sizes of chunk {i}")
            if layout.record_length + 4 + 4 * n_layers + sum(sizes) > nbytes:
                raise f.fail("chunk", f"chunk {i} announces {sum(sizes)} bytes of layers, "
                                      f"but the chunk table gives it {nbytes} bytes")
        pos += nbytes
