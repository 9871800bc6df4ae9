"""CSV/TXT reading and writing: one header line of names, one point per line.

Reading detects the separator from the header line (comma, semicolon, else whitespace),
finds the x/y/z columns case-insensitively and keeps every other column as an attribute
(integer-looking columns as int64, the rest as float64). A header-less file of numbers is
read as ``x y z field_3 ...``. Writing uses full precision (``%.17g`` for float64).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path
from ..errors import InvalidParameterError, PointCloudReadError
from ._cloud import PointCloud

_INT_RE = re.compile(r"^[+-]?\d+$")
_NUM_RE = re.compile(r"^[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?|nan|inf|infinity)$",
                     re.IGNORECASE)


def _split(line: str, sep: str | None) -> list[str]:
    parts = line.split(sep) if sep else line.split()
    return [p.strip().strip('"').strip("'") for p in parts]


def _detect(header: str) -> str | None:
    for sep in (",", ";", "\t"):
        if sep in header:
            return sep
    return None


#: Peak bytes of memory per byte of text while parsing (strings, lists, then float64):
#: measured 9 for a CSV of UTM coordinates and an integer column.
TEXT_MEMORY_FACTOR = 10


def read_file(path: Path, fmt: str, max_bytes=None) -> PointCloud:
    """Read a delimited text file whose first line names the columns."""
    from ._las_checks import check_ceiling

    try:
        size = path.stat().st_size
    except OSError as exc:
        raise PointCloudReadError(f"{path}: unreadable {fmt.upper()} file ({exc})") from exc
    check_ceiling(path, f"{size} bytes of text", TEXT_MEMORY_FACTOR * size, max_bytes)
    try:
        with open(path, encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise PointCloudReadError(f"{path}: unreadable {fmt.upper()} file ({exc})") from exc
    lines = [ln for ln in lines if ln.strip()]
    if not lines:
        return PointCloud(np.empty((0, 3)), source_path=path, source_format=fmt)
    first = lines[0].strip()
    for prefix in ("//", "#"):
        if first.startswith(prefix):
            first = first[len(prefix):].strip()
    sep = _detect(first)
    names = _split(first, sep)
    if all(_NUM_RE.match(tok) for tok in names):  # no header line: x y z then extra columns
        names = ["x", "y", "z"] + [f"field_{j}" for j in range(3, len(names))]
        body = lines
    else:
        body = lines[1:]
    lower = [n.lower() for n in names]
    missing = [c for c in "xyz" if c not in lower]
    if missing:
        raise PointCloudReadError(f"{path}: no column named {'/'.join(missing)} in the header "
                                  f"line; found: {', '.join(names)}")
    if len(set(names)) != len(names):
        raise PointCloudReadError(f"{path}: duplicate column names in the header line")
    if not body:
        return PointCloud(np.empty((0, 3)), source_path=path, source_format=fmt)
    rows = [_split(ln, sep) for ln in body]
    for i, row in enumerate(rows):
        if len(row) != len(names):
            lineno = i + 1 + (len(lines) - len(body))
            raise PointCloudReadError(f"{path}: line {lineno} has {len(row)} values; the header "
                                      f"names {len(names)} columns")
    try:
        table = np.array(rows, dtype=np.float64)
    except ValueError as exc:
        raise PointCloudReadError(f"{path}: non-numeric value ({exc})") from exc
    xyz = table[:, [lower.index(c) for c in "xyz"]]
    attrs = {}
    for j, name in enumerate(names):
        if lower[j] in ("x", "y", "z"):
            continue
        col = table[:, j]
        if (all(_INT_RE.match(r[j]) for r in rows[:1000]) and np.all(np.isfinite(col))
                and np.all(np.abs(col) < 2**53) and np.all(col == np.round(col))):
            attrs[name] = col.astype(np.int64)
        else:
            attrs[name] = col
    from .._shared.validation import check_points

    xyz = check_points(xyz, name="xyz", source=str(path))
    return PointCloud(xyz, attrs, source_path=path, source_format=fmt)


def _fmt_of(path: Path, name: str, values: np.ndarray) -> str:
    kind = values.dtype.kind
    if kind in "iub":
        return "%d"
    if kind == "f":
        return "%.9g" if values.dtype.itemsize <= 4 else "%.17g"
    raise InvalidParameterError(f"{path}: field {name!r} has dtype {values.dtype}, which "
                                "cannot be written as a text column")


def _dump(fh, table: np.ndarray, fmts: list[str], sep: str) -> None:
    """Low-level writer: write the rows of the structured `table` to `fh`."""
    np.savetxt(fh, table, fmt=fmts, delimiter=sep)


def write_file(path: Path, cloud: PointCloud, new: dict, fmt: str) -> None:
    """Write a header line and one line per point (comma for .csv, space for .txt)."""
    from ._ply import _columns

    sep = "," if fmt == "csv" else " "
    cols = _columns(cloud, new)
    bad = [n for n in cols if sep in n or "," in n or any(ch.isspace() for ch in n)]
    if bad:
        raise InvalidParameterError(f"{path}: column name {bad[0]!r} contains a separator")
    fmts = ["%.17g"] * 3 + [_fmt_of(path, n, v) for n, v in cols.items()]
    dtypes = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    for n, v in cols.items():
        dtypes.append((n, np.int64 if v.dtype.kind in "iub" and v.dtype != np.uint64
                       else v.dtype))
    table = np.empty(len(cloud), dtype=dtypes)
    for j, c in enumerate("xyz"):
        table[c] = cloud.xyz[:, j]
    for n, v in cols.items():
        table[n] = v
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(sep.join(["x", "y", "z", *cols]) + "\n")
        if len(table):
            _dump(fh, table, fmts, sep)
