"""NPZ reading and writing: an ``xyz`` (N, 3) array (or ``x``, ``y``, ``z``) plus attributes.

Reading also accepts the column layout of the E57-derived ``pump_scan.npz`` (``x``, ``y``,
``z``, ``intensity``, ``red``, ``green``, ``blue``, ``row``, ``col``). Every other array with
N rows becomes an attribute; a 0-d string array ``crs`` is the CRS.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path
from .._shared.validation import check_points
from ..errors import InvalidParameterError, PointCloudReadError
from ._cloud import PointCloud


def read_file(path: Path, fmt: str = "npz") -> PointCloud:
    """Read an ``.npz`` archive written by :func:`write_file` or with x/y/z columns."""
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
