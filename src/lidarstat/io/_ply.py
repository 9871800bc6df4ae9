"""PLY reading and writing through plyfile (binary little endian), in CloudCompare's conventions.

Writing names the ``vertex`` properties as CloudCompare's PLY filter maps them: the normal
``NormalX/NormalY/NormalZ`` as ``nx ny nz``, the colour ``red green blue`` as ``uchar``
(16-bit LAS colours scaled to 8 bits, ``round(v / 257)``) and every other field ``name`` as
``scalar_name``, which CloudCompare loads as a scalar field called ``name``. Reading accepts
both spellings (``nx`` -> ``NormalX``, ``scalar_K`` -> ``K``), so the field names of a cloud
lidarstat wrote come back exactly. A CRS, if any, is stored in a ``comment crs ...`` line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile

from .._shared._atomic import atomic_path
from ..errors import (
    InvalidParameterError,
    MalformedFileError,
    PointCloudReadError,
    PointCloudWriteError,
)
from ._cloud import PointCloud

_CRS_COMMENT = "crs "
#: Prefix CloudCompare gives (and recognises on) the properties it loads as scalar fields.
SCALAR_PREFIX = "scalar_"
#: lidarstat field -> PLY property, for the fields CloudCompare maps to normals and colours.
NORMALS = {"NormalX": "nx", "NormalY": "ny", "NormalZ": "nz"}
COLOURS = ("red", "green", "blue")
# numpy dtype.str (without byte order) -> PLY-representable dtype
_PLY_TYPES = {"i1": "i1", "u1": "u1", "i2": "i2", "u2": "u2", "i4": "i4", "u4": "u4",
              "f4": "f4", "f8": "f8", "b1": "u1", "f2": "f4"}


def _short(exc: BaseException) -> str:
    from ._las import short_cause

    return short_cause(exc)


_HEADER_LIMIT = 1 << 20  # a PLY header longer than 1 MiB is not a point cloud's
_SIZES = {"int8": 1, "char": 1, "uint8": 1, "uchar": 1, "int16": 2, "short": 2, "uint16": 2,
          "ushort": 2, "int32": 4, "int": 4, "uint32": 4, "uint": 4, "float32": 4,
          "float": 4, "float64": 8, "double": 8}


def check_header(path: Path, max_bytes=None) -> None:
    """Compare the element counts of a PLY header with the bytes after it.

    A binary row needs at least the sum of its scalar property sizes (plus the length
    field of each list), an ASCII row at least two characters per property. Headers the
    check cannot parse are left to plyfile, whose errors the reader converts.

    Raises
    ------
    MalformedFileError
        If an element announces more rows than the file can hold, or reading would exceed
        the read ceiling.
    """
    from ._las_checks import check_ceiling

    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(_HEADER_LIMIT)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return
    body_start = head.find(b"\n", end)
    room = size - (body_start + 1 if body_start >= 0 else size)
    lines = head[:end].decode("ascii", "replace").splitlines()
    ascii_ = any(ln.split()[:2] == ["format", "ascii"] for ln in lines)
    elements: list[list] = []  # [name, count, min row bytes, properties]
    for ln in lines:
        tok = ln.split()
        if len(tok) == 3 and tok[0] == "element" and tok[2].isdigit():
            elements.append([tok[1], int(tok[2]), 0, 0])
        elif elements and tok and tok[0] == "property":
            row = elements[-1]
            row[3] += 1
            if len(tok) >= 5 and tok[1] == "list":
                row[2] += _SIZES.get(tok[2], 1)
            elif len(tok) >= 3:
                row[2] += _SIZES.get(tok[1], 1)
    need_file = need_mem = 0
    for name, count, row_bytes, n_props in elements:
        per_row = 2 * n_props if ascii_ else row_bytes
        need_file += count * per_row
        need_mem += count * (max(row_bytes, 8 * n_props) + 24)
        if need_file > room:
            raise MalformedFileError(
                f"{path}: unreadable PLY file (malformed header: element {name!r} announces {count} rows of "
                f"at least {per_row} bytes, but {room} bytes follow the header)")
    check_ceiling(path, f"{sum(e[1] for e in elements)} PLY rows", need_mem, max_bytes)


def read_file(path: Path, fmt: str = "ply", max_bytes=None) -> PointCloud:
    """Read the ``vertex`` element of a PLY file; x/y/z (any case) are the coordinates.

    Property names become field names through :func:`field_names` (``nx`` -> ``NormalX``,
    ``scalar_K`` -> ``K``); list properties are skipped.
    """
    check_header(path, max_bytes)
    try:
        ply = plyfile.PlyData.read(str(path))
        vertex = ply["vertex"]
        data = vertex.data
    except KeyError:
        raise PointCloudReadError(f"{path}: unreadable PLY file (no 'vertex' element)") from None
    except Exception as exc:
        raise PointCloudReadError(f"{path}: unreadable PLY file ({_short(exc)})") from exc
    names = list(data.dtype.names or ())
    lower = {n.lower(): n for n in names}
    missing = [c for c in "xyz" if c not in lower]
    if missing:
        raise PointCloudReadError(
            f"{path}: PLY vertex element has no {'/'.join(missing)} property; found: "
            f"{', '.join(names)}")
    bad = [lower[c] for c in "xyz" if data.dtype[lower[c]].kind not in "iuf"]
    if bad:
        raise MalformedFileError(f"{path}: unreadable PLY file (malformed header: coordinate "
                                 f"property {bad[0]!r} is a list, not a number)")
    xyz = np.column_stack([np.asarray(data[lower[c]], dtype=np.float64) for c in "xyz"])
    coords = {lower[c] for c in "xyz"}
    kept = [n for n in names if n not in coords and data.dtype[n].kind != "O"]  # no lists
    attrs = {field: np.array(data[prop]) for prop, field in field_names(kept).items()}
    crs = None
    for comment in ply.comments:
        if comment.startswith(_CRS_COMMENT):
            crs = comment[len(_CRS_COMMENT):].strip() or None
    return PointCloud(xyz, attrs, crs=crs, source_path=path, source_format="ply")


def field_names(properties: list[str]) -> dict[str, str]:
    """Map PLY property names to lidarstat field names.

    ``nx``/``ny``/``nz`` become ``NormalX``/``NormalY``/``NormalZ`` and ``scalar_<name>``
    becomes ``<name>``; every other property keeps its name. A property keeps its own name
    when the new one would collide with another property's field or with a coordinate.

    Parameters
    ----------
    properties : list of str
        Property names of the ``vertex`` element, coordinates excluded, in file order.

    Returns
    -------
    dict of str to str
        Property name -> field name, in file order.
    """
    renamed = {}
    for prop in properties:
        if prop in NORMALS.values():
            renamed[prop] = {v: k for k, v in NORMALS.items()}[prop]
        elif prop.startswith(SCALAR_PREFIX) and len(prop) > len(SCALAR_PREFIX):
            renamed[prop] = prop[len(SCALAR_PREFIX):]
    used = {p for p in properties if p not in renamed} | set("xyzXYZ")
    out = {}
    for prop in properties:
        new = renamed.get(prop, prop)
        if prop in renamed and (new in used or new.lower() in ("x", "y", "z")):
            new = prop
        used.add(new)
        out[prop] = new
    return out


def property_names(columns: dict[str, np.ndarray]) -> dict[str, str]:
    """Map lidarstat field names to PLY property names (the inverse of :func:`field_names`).

    The three normal components become ``nx ny nz`` and the three colours keep ``red green
    blue`` (when all three of either are present, one-dimensional); every other field
    ``name`` becomes ``scalar_<name>``.

    Parameters
    ----------
    columns : dict of str to ndarray
        The one-dimensional per-point fields to write.

    Returns
    -------
    dict of str to str
        Field name -> property name; normals, then colours, then the rest in input order
        (CloudCompare fills its normal and colour slots from the first matching names).
    """
    normals = all(n in columns for n in NORMALS)
    colours = all(c in columns for c in COLOURS)
    out = {n: NORMALS[n] for n in NORMALS if normals}
    out.update({c: c for c in COLOURS if colours})
    for name in columns:
        if name not in out:
            out[name] = SCALAR_PREFIX + name
    return out


def _colour(path: Path, name: str, values: np.ndarray) -> np.ndarray:
    """`values` as PLY ``uchar``: 8-bit values as they are, 16-bit ones scaled by 1/257."""
    v = np.asarray(values)
    if v.size and (v.dtype.kind not in "biuf" or not np.all(np.isfinite(v))
                   or v.min() < 0 or v.max() > 65535 or not np.all(v == np.round(v))):
        raise InvalidParameterError(f"{path}: colour {name!r} must hold integers in 0..65535 "
                                    "(8-bit or 16-bit colour) to be written as PLY uchar")
    if v.size and v.max() > 255:
        v = np.round(v / 257.0)
    return v.astype(np.uint8)


def _ply_dtype(path: Path, name: str, values: np.ndarray) -> np.dtype:
    code = _PLY_TYPES.get(values.dtype.str.lstrip("<>|="))
    if code is not None:
        return np.dtype("<" + code) if code not in ("i1", "u1") else np.dtype(code)
    if values.dtype.kind in "iu":
        if values.size == 0:
            return np.dtype("<i4")
        lo, hi = values.min(), values.max()
        if lo >= np.iinfo(np.int32).min and hi <= np.iinfo(np.int32).max:
            return np.dtype("<i4")
        if lo >= 0 and hi <= np.iinfo(np.uint32).max:
            return np.dtype("<u4")
        return np.dtype("<f8")  # PLY has no 64-bit integers
    raise InvalidParameterError(f"{path}: field {name!r} has dtype {values.dtype}, which "
                                "PLY cannot store")


def _columns(cloud: PointCloud, new: dict) -> dict[str, np.ndarray]:
    """Flatten attributes (N, k) into ``name_0 .. name_{k-1}``; new fields override."""
    cols = {}
    for name, values in {**cloud.attributes, **new}.items():
        values = np.asarray(values)
        if values.ndim == 1:
            cols[name] = values
        else:
            flat = values.reshape(len(values), -1)
            for j in range(flat.shape[1]):
                cols[f"{name}_{j}"] = flat[:, j]
    return cols


def _dump(ply: plyfile.PlyData, tmp: Path) -> None:
    """Low-level writer: serialise `ply` to `tmp`."""
    ply.write(str(tmp))


def _xyz_dtype(xyz: np.ndarray) -> str:
    """``f4`` when float32 holds every coordinate exactly, else ``f8`` (both read by clients)."""
    return "<f4" if np.array_equal(xyz.astype(np.float32).astype(np.float64), xyz) else "<f8"


def write_file(path: Path, cloud: PointCloud, new: dict, fmt: str = "ply") -> None:
    """Write a binary little-endian PLY in CloudCompare's conventions.

    ``x y z`` are ``float`` when float32 holds every coordinate exactly and ``double``
    otherwise (large, e.g. projected, coordinates), so no coordinate is rounded. Normals are
    written as ``nx ny nz``, colours as ``red green blue`` (``uchar``) and every other field
    as ``scalar_<name>`` (see :func:`property_names`).

    Raises
    ------
    InvalidParameterError
        If a field name contains white space, a field's dtype has no PLY type, or a colour
        is not an 8-bit or 16-bit integer colour.
    PointCloudWriteError
        If plyfile fails to write the file.
    """
    cols = _columns(cloud, new)
    bad = [n for n in cols if not n or any(ch.isspace() for ch in n)]
    if bad:
        raise InvalidParameterError(f"{path}: PLY property names cannot contain spaces: "
                                    f"{bad[0]!r}")
    names = property_names(cols)
    values = {n: (_colour(path, n, v) if names[n] in COLOURS else v) for n, v in cols.items()}
    coord = _xyz_dtype(cloud.xyz)
    dtypes = [("x", coord), ("y", coord), ("z", coord)]
    dtypes += [(names[n], _ply_dtype(path, n, values[n])) for n in names]
    arr = np.empty(len(cloud), dtype=dtypes)
    for j, c in enumerate("xyz"):
        arr[c] = cloud.xyz[:, j]
    for n in names:
        arr[names[n]] = values[n]
    comments = ["written by lidarstat"]
    if cloud.crs:
        comments.append(_CRS_COMMENT + " ".join(cloud.crs.split()))
    ply = plyfile.PlyData([plyfile.PlyElement.describe(arr, "vertex")], text=False,
                          byte_order="<", comments=comments)
    try:
        with atomic_path(path) as tmp:
            _dump(ply, tmp)
    except OSError:
        raise
    except Exception as exc:
        raise PointCloudWriteError(f"{path}: cannot write PLY file ({_short(exc)})") from exc
