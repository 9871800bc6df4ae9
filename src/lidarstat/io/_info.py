"""``describe`` / ``format_description``: what ``lidarstat info FILE`` prints.

For LAS/LAZ the counts, bounds, scales, offsets and VLRs come from the header; the field
ranges and the classification histogram are accumulated chunk by chunk so that large files
are never held in memory at once. Other formats are read whole.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import LidarstatError, PointCloudReadError
from ._cloud import _format_of, read

_CHUNK = 2_000_000
_EPSG_RE = re.compile(r'(?:AUTHORITY|ID)\[\s*"EPSG"\s*,\s*"?(\d+)"?\s*\]', re.IGNORECASE)


def _crs_summary(crs: str | None) -> tuple[str | None, int | None]:
    if not crs:
        return None, None
    if crs.upper().startswith("EPSG:"):
        code = crs.split(":", 1)[1]
        return crs, int(code) if code.isdigit() else None
    epsg = None
    for match in _EPSG_RE.finditer(crs):  # only the identifier of the outermost CRS counts
        head = crs[: match.start()]
        if head.count("[") - head.count("]") == 1:
            epsg = int(match.group(1))
    return " ".join(crs.split())[:80], epsg


class _Ranges:
    """Running min/max per field and a classification histogram."""

    def __init__(self) -> None:
        self.lo: dict[str, float] = {}
        self.hi: dict[str, float] = {}
        self.dtype: dict[str, str] = {}
        self.classes: dict[int, int] = {}

    def add(self, name: str, values: np.ndarray) -> None:
        values = np.asarray(values)
        self.dtype.setdefault(name, str(values.dtype))
        if values.size == 0 or values.dtype.kind not in "biuf":
            return
        if values.dtype.kind == "f":
            finite = values[np.isfinite(values)]
            if finite.size == 0:
                return
            lo, hi = finite.min().item(), finite.max().item()
        else:
            lo, hi = values.min().item(), values.max().item()
        self.lo[name] = min(self.lo.get(name, lo), lo)
        self.hi[name] = max(self.hi.get(name, hi), hi)
        if name == "classification":
            vals, counts = np.unique(values, return_counts=True)
            for v, c in zip(vals.tolist(), counts.tolist()):
                self.classes[int(v)] = self.classes.get(int(v), 0) + int(c)

    def fields(self) -> list[dict]:
        return [{"name": n, "dtype": d, "min": self.lo.get(n), "max": self.hi.get(n)}
                for n, d in self.dtype.items()]


def _densities(count: int, lo, hi) -> tuple[float | None, float | None]:
    if count == 0 or lo is None:
        return None, None
    ext = np.asarray(hi, float) - np.asarray(lo, float)
    area = float(ext[0] * ext[1])
    volume = float(area * ext[2])
    return (count / area if area > 0 else None), (count / volume if volume > 0 else None)


def _describe_las(path: Path, fmt: str, max_bytes) -> dict:
    import laspy
    from laspy.vlrs.known import LasZipVlr

    from ._las import _BACKEND, NOT_FOREIGN, _checked, _unreadable, crs_of, read_chunks

    _checked(path, fmt, _CHUNK, max_bytes, allow_empty=True)
    ranges = _Ranges()
    try:
        with laspy.open(path, laz_backend=_BACKEND) as reader:
            h = reader.header
            crs, epsg = _crs_summary(crs_of(h))
            for points in read_chunks(reader, path, fmt, _CHUNK):
                for name in h.point_format.dimension_names:
                    if name not in ("X", "Y", "Z"):
                        ranges.add(name, points[name])
    except (LidarstatError, *NOT_FOREIGN):
        raise
    except BaseException as exc:  # lazrs panics are BaseExceptions
        raise _unreadable(path, fmt, exc) from exc
    count = int(h.point_count)
    lo = [float(v) for v in h.mins] if count else None
    hi = [float(v) for v in h.maxs] if count else None
    return {
        "las_version": f"{h.version.major}.{h.version.minor}",
        "point_format": int(h.point_format.id),
        "point_count": count,
        "bounds": {"min": lo, "max": hi},
        "scales": [float(v) for v in h.scales],
        "offsets": [float(v) for v in h.offsets],
        "crs": crs,
        "epsg": epsg,
        "fields": ranges.fields(),
        "classification": dict(sorted(ranges.classes.items())) or None,
        "vlr_count": sum(not isinstance(v, LasZipVlr) for v in h.vlrs),
        "evlr_count": len(getattr(h, "evlrs", None) or []),
        "extra_dimensions": list(h.point_format.extra_dimension_names),
    }


def _describe_other(path: Path, max_bytes) -> dict:
    cloud = read(path, max_bytes=max_bytes)
    ranges = _Ranges()
    for name, values in cloud.attributes.items():
        ranges.add(name, values)
    crs, epsg = _crs_summary(cloud.crs)
    return {
        "las_version": None,
        "point_format": None,
        "point_count": len(cloud),
        "bounds": {"min": cloud.xyz.min(axis=0).tolist(), "max": cloud.xyz.max(axis=0).tolist()},
        "scales": None,
        "offsets": None,
        "crs": crs,
        "epsg": epsg,
        "fields": ranges.fields(),
        "classification": dict(sorted(ranges.classes.items())) or None,
        "vlr_count": None,
        "evlr_count": None,
        "extra_dimensions": None,
    }


def describe(path: str | os.PathLike, *, max_bytes: int | None = None) -> dict:
    """Summarise a point-cloud file.

    LAS/LAZ files get the structure checks of :func:`lidarstat.io.read` and are read in
    chunks; an empty LAS/LAZ file is described (0 points), not refused.

    Parameters
    ----------
    path : path-like
        Any file :func:`lidarstat.io.read` understands.
    max_bytes : int, optional
        Read ceiling, as in :func:`lidarstat.io.read` (for LAS/LAZ: per chunk).

    Returns
    -------
    dict
        Keys: ``path``, ``format``, ``file_size``, ``las_version``, ``point_format``,
        ``point_count``, ``bounds`` (``{"min": [x, y, z], "max": [...]}``), ``scales``,
        ``offsets``, ``crs`` (first 80 characters of the WKT, or ``"EPSG:<code>"``),
        ``epsg``, ``fields`` (list of ``{"name", "dtype", "min", "max"}``),
        ``classification`` (``{class: count}`` or None), ``vlr_count``, ``evlr_count``,
        ``extra_dimensions``, ``density_2d`` (points per square unit of the XY bounding
        box) and ``density_3d`` (points per cubic unit of the bounding box). Entries that
        do not apply to the format are None.

    Raises
    ------
    MalformedFileError, PointCloudReadError, UnknownFormatError, InvalidPointsError
        As :func:`lidarstat.io.read`.
    """
    path = Path(path)
    fmt = _format_of(path)
    if not path.is_file():
        raise PointCloudReadError(f"{path}: no such file")
    info = (_describe_las(path, fmt, max_bytes) if fmt in ("las", "laz")
            else _describe_other(path, max_bytes))
    d2, d3 = _densities(info["point_count"], info["bounds"]["min"], info["bounds"]["max"])
    return {"path": str(path), "format": fmt, "file_size": path.stat().st_size, **info,
            "density_2d": d2, "density_3d": d3}


def _num(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.10g}"
    return str(v)


def format_description(d: dict) -> str:
    """Render the dict of :func:`describe` as human-readable text (no trailing newline)."""
    lines = [f"file:         {d['path']} ({d['file_size']:,} bytes)"]
    fmt = d["format"].upper()
    if d.get("las_version"):
        fmt += f" {d['las_version']}, point format {d['point_format']}"
    lines.append(f"format:       {fmt}")
    lines.append(f"points:       {d['point_count']:,}")
    lo, hi = d["bounds"]["min"], d["bounds"]["max"]
    if lo is not None:
        for j, axis in enumerate("xyz"):
            lines.append(f"{axis} range:      {_num(lo[j])} .. {_num(hi[j])}")
    if d.get("scales"):
        lines.append("scales:       " + " ".join(_num(v) for v in d["scales"]))
        lines.append("offsets:      " + " ".join(_num(v) for v in d["offsets"]))
    crs = d.get("crs") or "none"
    if d.get("epsg") and not crs.upper().startswith("EPSG"):
        crs = f"EPSG:{d['epsg']}  {crs}"
    lines.append(f"CRS:          {crs}")
    if d.get("vlr_count") is not None:
        lines.append(f"VLRs/EVLRs:   {d['vlr_count']} / {d['evlr_count']}")
    if d.get("density_2d") is not None:
        lines.append(f"density:      {d['density_2d']:.4g} points per square unit (XY box)")
    if d.get("density_3d") is not None:
        lines.append(f"              {d['density_3d']:.4g} points per cubic unit (XYZ box)")
    if d["fields"]:
        width = max(len(f["name"]) for f in d["fields"])
        lines.append("fields:")
        for f in d["fields"]:
            lines.append(f"  {f['name']:<{width}}  {f['dtype']:<8} "
                         f"{_num(f['min'])} .. {_num(f['max'])}")
    if d.get("classification"):
        lines.append("classification:")
        for cls, n in d["classification"].items():
            lines.append(f"  {cls:>3}: {n:,}")
    return "\n".join(lines)
