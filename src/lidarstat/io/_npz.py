"""NPZ reading and writing: an ``xyz`` (N, 3) array (or ``x``, ``y``, ``z``) plus attributes.

Reading also accepts the column layout of the E57-derived ``pump_scan.npz`` (``x``, ``y``,
``z``, ``intensity``, ``red``, ``green``, ``blue``, ``row``, ``col``). Every other array with
N rows becomes an attribute; a 0-d string array ``crs`` is the CRS.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path
from .._shared.validation import check_points
from ..errors import InvalidParameterError, MalformedFileError, PointCloudReadError
from ._cloud import PointCloud


def check_members(path: Path, max_bytes=None) -> None:
    """Compare each array's announced shape with its archive member, before loading.

    Raises
    ------
    MalformedFileError
        If an array's header announces more bytes than its member holds, or the arrays
        together exceed the read ceiling.
    """
    from ._las import short_cause
    from ._las_checks import check_ceiling

    total = 0
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as fh:
                    fmt = np.lib.format
                    version = fmt.read_magic(fh)
                    read_header = (fmt.read_array_header_1_0 if version == (1, 0)
                                   else fmt.read_array_header_2_0)
                    shape, _, dtype = read_header(fh)
                nbytes = math.prod(shape) * dtype.itemsize
                if dtype.hasobject:
                    raise MalformedFileError(f"{path}: array {info.filename[:-4]!r} holds "
                                             "Python objects, which need pickle; refused")
                if nbytes > info.file_size:
                    raise MalformedFileError(
                        f"{path}: unreadable NPZ file (malformed array header: "
                        f"{info.filename[:-4]!r} announces shape {shape} ({nbytes} bytes), but "
                        f"its member holds {info.file_size} bytes)")
                total += nbytes
    except MalformedFileError:
        raise
    except Exception as exc:  # zipfile, bad .npy header ...
        raise PointCloudReadError(f"{path}: unreadable NPZ file ({short_cause(exc)})") from exc
    check_ceiling(path, f"{total} bytes of arrays", 2 * total, max_bytes)


def read_file(path: Path, fmt: str = "npz", max_bytes=None) -> PointCloud:
    """Read an ``.npz`` archive written by :func:`write_file` or with x/y/z columns."""
    check_members(path, max_bytes)
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {k: archive[k] for k in archive.files}
    except Exception as exc:  # zipfile, pickle refusal, truncation ...
        from ._las import short_cause

        raise PointCloudReadError(f"{path}: unreadable NPZ file ({short_cause(exc)})") from exc
    lower = {k.lower(): k for k in arrays}
    crs = None
    if "crs" in arrays and arrays["crs"].ndim == 0:
        crs = str(arrays.pop("crs")) or None
    if "xyz" in lower:
        key = lower["xyz"]
        xyz = arrays.pop(key)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise PointCloudReadError(f"{path}: array {key!r} has shape {xyz.shape}; "
                                      "expected (N, 3)")
    elif all(c in lower for c in "xyz"):
        cols = [arrays.pop(lower[c]) for c in "xyz"]
        if any(c.ndim != 1 or c.shape != cols[0].shape for c in cols):
            raise PointCloudReadError(f"{path}: arrays x, y, z must be 1-D of equal length; "
                                      f"got shapes {[c.shape for c in cols]}")
        xyz = np.column_stack(cols) if cols[0].size else np.empty((0, 3))
    else:
        raise PointCloudReadError(f"{path}: no 'xyz' array nor 'x', 'y', 'z' arrays; found: "
                                  f"{', '.join(arrays) or 'nothing'}")
    if xyz.dtype.kind not in "biuf":
        raise MalformedFileError(f"{path}: the coordinates hold {xyz.dtype} values, not "
                                 "numbers")
    xyz = check_points(xyz, name="xyz", min_points=0, source=str(path))
    attrs = {}
    for name, values in arrays.items():
        if values.ndim >= 1 and values.shape[0] == len(xyz):
            attrs[name] = values
    return PointCloud(xyz, attrs, crs=crs, source_path=path, source_format="npz")


def _dump(tmp: Path, arrays: dict) -> None:
    """Low-level writer: save `arrays` (compressed) to `tmp`."""
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def write_file(path: Path, cloud: PointCloud, new: dict, fmt: str = "npz") -> None:
    """Write ``xyz``, every attribute, the new fields and ``crs`` (if any)."""
    arrays = {"xyz": cloud.xyz}
    for name, values in {**cloud.attributes, **new}.items():
        values = np.asarray(values)
        if name in ("xyz", "crs"):
            raise InvalidParameterError(f"{path}: field name {name!r} is reserved in NPZ files")
        if values.dtype.kind == "O":
            raise InvalidParameterError(f"{path}: field {name!r} has dtype object, which NPZ "
                                        "files store only with pickle")
        arrays[name] = values
    if cloud.crs:
        arrays["crs"] = np.array(cloud.crs)
    with atomic_path(path) as tmp:
        _dump(tmp, arrays)
