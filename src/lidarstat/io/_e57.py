"""E57 reading (ASTM E2807) through pye57: points in the file's global frame, scanner poses.

Every scan (``data3D`` entry) is read with its pose applied (rotation quaternion and
translation), so the coordinates of all scans share one frame, and the scans are
concatenated. Attributes: ``intensity``, ``red``/``green``/``blue`` (from
``colorRed``...), ``row``/``col`` (``rowIndex``/``columnIndex``) when the file has them,
and ``scan_index`` when it holds more than one scan. The scanner position of a scan is its
pose translation (the origin of the scanner's own frame), :func:`scan_positions`.
Writing E57 is not supported.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PointCloudReadError, PointCloudWriteError
from ._cloud import PointCloud

_RENAME = {"intensity": "intensity", "colorRed": "red", "colorGreen": "green",
           "colorBlue": "blue", "rowIndex": "row", "columnIndex": "col"}


def _open(path: Path):
    try:
        import pye57
    except ImportError as exc:  # pragma: no cover - pye57 is a test dependency
        raise PointCloudReadError(
            f"{path}: reading E57 needs the pye57 package (pip install 'lidarstat[e57]')"
        ) from exc
    try:
        return pye57.E57(str(path))
    except Exception as exc:  # libE57 raises its own exception types
        from ._las import short_cause

        raise PointCloudReadError(f"{path}: unreadable E57 file ({short_cause(exc)})") from exc


def scan_positions(path) -> np.ndarray:
    """Scanner position of every scan of an E57 file, shape (S, 3), in the file's frame.

    The position is the scan's pose translation (identity pose: the origin).
    """
    path = Path(path)
    e57 = _open(path)
    try:
        out = np.zeros((e57.scan_count, 3))
        for i in range(e57.scan_count):
            header = e57.get_header(i)
            if header.has_pose():
                out[i] = np.asarray(header.translation, dtype=np.float64)
        return out
    finally:
        e57.close()


#: Bytes per point while reading: float64 x/y/z, the attribute buffers and the copies.
_BYTES_PER_POINT = 112
_CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")


def _read_scan(e57, i: int, path: Path) -> dict:
    """Scan `i` as pye57's ``read_scan`` gives it, refusing a scan that holds fewer records
    than it announces (pye57 would return uninitialised values for the missing ones)."""
    from pye57.utils import convert_spherical_to_cartesian

    header = e57.get_header(i)
    n = int(header.point_count)
    present = set(header.point_fields)
    if all(f in present for f in _CARTESIAN):
        coords, invalid = _CARTESIAN, "cartesianInvalidState"
    elif all(f in present for f in _SPHERICAL):
        coords, invalid = _SPHERICAL, "sphericalInvalidState"
    else:
        raise PointCloudReadError(f"{path}: scan {i} of the E57 file has neither cartesian nor "
                                  "spherical coordinates")
    fields = [*coords, *(f for f in (*_RENAME, invalid) if f in present)]
    data, buffers = e57.make_buffers(fields, n)
    reader = header.points.reader(buffers)
    try:
        got = reader.read() if n else 0
    finally:
        reader.close()
    if got != n:
        raise PointCloudReadError(f"{path}: unreadable E57 file (scan {i} announces {n} points "
                                  f"in recordCount, {got} found)")
    if invalid in data:
        keep = ~data.pop(invalid).astype(bool)
        data = {k: v[keep] for k, v in data.items()}
    xyz = np.column_stack([data.pop(c) for c in coords]).astype(np.float64)
    if coords == _SPHERICAL:
        xyz = convert_spherical_to_cartesian(xyz)
    if header.has_pose():
        xyz = e57.to_global(xyz, header.rotation, header.translation)
    data["xyz"] = xyz
    return data


def read_file(path: Path, fmt: str = "e57", max_bytes=None) -> PointCloud:
    """Read every scan of an E57 file, poses applied, as one :class:`PointCloud`."""
    from ._las import NOT_FOREIGN, short_cause
    from ._las_checks import check_ceiling

    e57 = _open(path)
    try:
        try:
            total = sum(int(e57.get_header(i).point_count) for i in range(e57.scan_count))
        except NOT_FOREIGN:
            raise
        except BaseException as exc:
            raise PointCloudReadError(
                f"{path}: unreadable E57 file ({short_cause(exc)})") from exc
        check_ceiling(path, f"{total} E57 points", total * _BYTES_PER_POINT, max_bytes)
        xyz, attrs = [], {}
        for i in range(e57.scan_count):
            try:
                data = _read_scan(e57, i, path)
            except (PointCloudReadError, *NOT_FOREIGN):
                raise
            except BaseException as exc:
                raise PointCloudReadError(
                    f"{path}: cannot read scan {i} of the E57 file ({short_cause(exc)})"
                ) from exc
            xyz.append(data.pop("xyz"))
            for key, name in _RENAME.items():
                if key in data:
                    attrs.setdefault(name, []).append(data[key])
        n = [len(a) for a in xyz]
        attrs = {k: np.concatenate(v) for k, v in attrs.items() if len(v) == len(xyz)}
        if len(xyz) > 1:
            attrs["scan_index"] = np.repeat(np.arange(len(xyz), dtype=np.uint16), n)
        pts = np.concatenate(xyz) if xyz else np.empty((0, 3))
    finally:
        e57.close()
    return PointCloud(pts, attrs, source_path=path, source_format="e57")


def write_file(path: Path, cloud, fields, fmt):
    raise PointCloudWriteError(f"{path}: writing E57 is not supported; write .las or .laz")
