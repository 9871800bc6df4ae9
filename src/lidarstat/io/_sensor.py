"""The scanner position a point-cloud file carries: an E57 scan pose or a JSON sidecar.

Terrestrial scans are oriented toward their scanner: normals point to it and the range
noise a + b r grows with the distance from it. A file gives the position in one of two
ways, looked up in this order:

1. a sidecar ``<file name>.sensor.json`` beside the file (``scan.laz.sensor.json`` for
   ``scan.laz``), holding ``{"sensor": [x, y, z]}`` in the file's coordinates (the format
   for LAS/LAZ, PLY, CSV and NPZ, which have no standard place for it);
2. an E57 file's scan pose: the translation of its scan (every scan of one file must share
   it: several stations need per-station processing or an explicit position).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..errors import LidarstatWarning, PointCloudReadError

#: Suffix appended to a point-cloud file name to form its sensor sidecar.
SENSOR_SIDECAR_SUFFIX = ".sensor.json"


def sensor_sidecar(path) -> Path:
    """Path of the sensor sidecar of a point-cloud file (``<name>.sensor.json``)."""
    path = Path(path)
    return path.with_name(path.name + SENSOR_SIDECAR_SUFFIX)


def write_sensor(path, sensor) -> Path:
    """Write the sensor sidecar of `path` (atomically). Returns the sidecar's path."""
    from .._shared._atomic import atomic_path

    s = _as_position(sensor, sensor_sidecar(path))
    side = sensor_sidecar(path)
    with atomic_path(side) as tmp:
        tmp.write_text(json.dumps({"sensor": [float(v) for v in s]}, indent=1) + "\n")
    return side


def _as_position(value, source):
    try:
        s = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        s = np.empty(0)
    if s.shape != (3,) or not np.isfinite(s).all():
        raise PointCloudReadError(f"{source}: the sensor position must be 3 finite numbers "
                                  f"[x, y, z]; got {value!r}")
    return s


def read_sensor(path):
    """The scanner position `path` carries, or None (see the module notes for where from).

    Parameters
    ----------
    path : path-like
        A point-cloud file.

    Returns
    -------
    sensor : (3,) ndarray or None
        Scanner position in the file's coordinates.
    source : str or None
        Where it came from (the sidecar's path or ``"E57 pose"``).

    Raises
    ------
    PointCloudReadError
        If the sidecar exists but is not JSON with a ``sensor`` of three finite numbers.

    Warns
    -----
    LidarstatWarning
        If an E57 file holds scans from different positions (None is returned).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_sensor(d / "scan.laz", [1.0, 2.0, 1.5])
    >>> read_sensor(d / "scan.laz")[0].tolist()
    [1.0, 2.0, 1.5]
    """
    path = Path(path)
    side = sensor_sidecar(path)
    if side.is_file():
        try:
            doc = json.loads(side.read_text())
        except (OSError, ValueError) as exc:
            raise PointCloudReadError(f"{side}: unreadable sensor sidecar ({exc})") from exc
        if not isinstance(doc, dict) or "sensor" not in doc:
            raise PointCloudReadError(f"{side}: a sensor sidecar must be a JSON object with a "
                                      "'sensor' entry [x, y, z]")
        return _as_position(doc["sensor"], side), str(side)
    if path.suffix.lower() == ".e57" and path.is_file():
        from ._e57 import scan_positions

        pos = scan_positions(path)
        if not len(pos):
            return None, None
        if np.ptp(pos, axis=0).max() > 0:
            warnings.warn(f"{path}: {len(pos)} scans from different positions; no single "
                          "sensor position (pass one, or process the stations separately)",
                          LidarstatWarning, stacklevel=2)
            return None, None
        return pos[0].copy(), "E57 pose"
    return None, None
