"""Result containers of segmentation: per-point labels, a segment table, polylines."""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path
from ..errors import InvalidParameterError, UnknownFormatError


def _column(values, n, name, what):
    arr = np.asarray(values)
    if arr.shape[:1] != (n,):
        raise InvalidParameterError(f"{what} column '{name}' has {arr.shape[:1]} rows, not {n}")
    return arr


def _scalar(v):
    """A JSON/CSV-friendly Python scalar (NaN -> None)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _write_records(path: Path, columns: dict[str, np.ndarray], what: str):
    """Write a column table as CSV (one row per entry) or JSON (list of records)."""
    suffix = path.suffix.lower()
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    flat = {}
    for name in names:
        arr = np.asarray(columns[name])
        if arr.ndim == 1:
            flat[name] = arr
        else:  # vector columns (normals, centroids) become name_0, name_1, ...
            for j in range(arr.shape[1]):
                flat[f"{name}_{j}"] = arr[:, j]
    if suffix == ".csv":
        with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(list(flat))
            cols = [flat[k].tolist() for k in flat]
            for i in range(n):
                w.writerow(["" if _scalar(c[i]) is None else
                            (repr(c[i]) if isinstance(c[i], float) else c[i]) for c in cols])
    elif suffix == ".json":
        records = [{k: _scalar(np.asarray(columns[k])[i]) if np.asarray(columns[k]).ndim == 1
                    else [_scalar(x) for x in np.asarray(columns[k])[i]] for k in names}
                   for i in range(n)]
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(records, indent=1))
    else:
        raise UnknownFormatError(f"{path}: unknown {what} format '{path.suffix}'; "
                                 "use .csv or .json")
    return path


@dataclass
class Polylines:
    """3-D polylines (intersection lines, ridge lines) with attributes per line.

    Attributes
    ----------
    vertices : list of (m_i, 3) ndarray
        Vertices of each line, in the cloud's coordinates.
    attributes : dict of str to (n_lines,) ndarray
        Per-line values (segments joined, strength, RMS, ...).
    """

    vertices: list
    attributes: dict = field(default_factory=dict)

    def __post_init__(self):
        self.vertices = [np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in self.vertices]
        n = len(self.vertices)
        self.attributes = {k: _column(v, n, k, "line") for k, v in self.attributes.items()}

    def __len__(self) -> int:
        return len(self.vertices)

    @classmethod
    def from_segments(cls, start, end, attributes=None) -> "Polylines":
        """Straight lines from `start` (n, 3) to `end` (n, 3)."""
        start = np.asarray(start, dtype=np.float64).reshape(-1, 3)
        end = np.asarray(end, dtype=np.float64).reshape(-1, 3)
        if start.shape != end.shape:
            raise InvalidParameterError("start and end must have the same shape")
        return cls([np.stack([a, b]) for a, b in zip(start, end)], dict(attributes or {}))

    def lengths(self) -> np.ndarray:
        """Length of each line."""
        return np.array([np.linalg.norm(np.diff(v, axis=0), axis=1).sum() for v in self.vertices])

    def sample(self, spacing: float | None = None):
        """Points along the lines: the vertices, or every `spacing` along each line.

        Returns
        -------
        xyz : (M, 3) ndarray
        line_id : (M,) ndarray of int32
            1-based line number of each point.
        """
        pts, ids = [], []
        for i, v in enumerate(self.vertices):
            if spacing is not None and len(v) > 1:
                seg = np.linalg.norm(np.diff(v, axis=0), axis=1)
                t = np.r_[0.0, np.cumsum(seg)]
                s = np.r_[np.arange(0.0, t[-1], float(spacing)), t[-1]]
                v = np.c_[[np.interp(s, t, v[:, j]) for j in range(3)]].T
            pts.append(v)
            ids.append(np.full(len(v), i + 1, dtype=np.int32))
        if not pts:
            return np.empty((0, 3)), np.empty(0, dtype=np.int32)
        return np.concatenate(pts), np.concatenate(ids)

    def write(self, path: str | os.PathLike, *, spacing: float | None = None, crs=None) -> Path:
        """Write the lines atomically; the format follows the suffix.

        ``.geojson``: a FeatureCollection of 3-D LineStrings with the attributes as
        properties. ``.csv``: one row per vertex (``line_id, vertex, x, y, z`` and the
        line's attributes). Point-cloud suffixes (``.las``, ``.laz``, ``.ply``, ``.npz``,
        ``.txt``): points along the lines (every `spacing`, or the vertices) with
        ``line_id`` and the attributes as fields, so CloudCompare shows them over the cloud.
        """
        path = Path(path)
        suffix = path.suffix.lower()
        n = len(self)
        if suffix in (".geojson", ".json"):
            feats = []
            for i, v in enumerate(self.vertices):
                props = {"line_id": i + 1}
                props.update({k: _scalar(a[i]) for k, a in self.attributes.items()
                              if np.ndim(a[i]) == 0})
                feats.append({"type": "Feature", "properties": props,
                              "geometry": {"type": "LineString", "coordinates": v.tolist()}})
            doc = {"type": "FeatureCollection", "features": feats}
            with atomic_path(path) as tmp:
                tmp.write_text(json.dumps(doc))
            return path
        if suffix == ".csv":
            xyz, line_id = self.sample(None)
            vertex = np.concatenate([np.arange(len(v)) for v in self.vertices]) if n else \
                np.empty(0, int)
            cols = {"line_id": line_id, "vertex": vertex, "x": xyz[:, 0], "y": xyz[:, 1],
                    "z": xyz[:, 2]}
            cols.update({k: np.asarray(a)[line_id - 1] for k, a in self.attributes.items()})
            return _write_records(path, cols, "line")
        from ..io import PointCloud, write

        xyz, line_id = self.sample(spacing)
        fields = {"line_id": line_id}
        fields.update({k: np.asarray(a)[line_id - 1] for k, a in self.attributes.items()
                       if np.asarray(a).ndim == 1 and np.asarray(a).dtype.kind in "biuf"})
        return write(path, PointCloud(xyz=xyz, attributes={}, crs=crs), fields=fields)


def segment_table(labels, xyz) -> dict[str, np.ndarray]:
    """Basic per-segment columns: ``segment_id``, ``n_points`` and the centroid.

    Parameters
    ----------
    labels : (N,) array of int
        Segment ids 1..n, 0 = none.
    xyz : (N, 3) array

    Returns
    -------
    dict of str to ndarray
        ``segment_id`` (1..n), ``n_points``, ``centroid_x``, ``centroid_y``, ``centroid_z``.
    """
    labels = np.asarray(labels)
    xyz = np.asarray(xyz, dtype=np.float64)
    n = int(labels.max()) if labels.size else 0
    counts = np.bincount(labels, minlength=n + 1)[1:]
    table = {"segment_id": np.arange(1, n + 1, dtype=np.int32), "n_points": counts}
    safe = np.maximum(counts, 1)
    for j, c in enumerate("xyz"):
        # Centre first so that UTM-sized coordinates keep their precision in the sums.
        o = xyz[:, j].mean() if len(xyz) else 0.0
        s = np.bincount(labels, weights=xyz[:, j] - o, minlength=n + 1)[1:]
        table[f"centroid_{c}"] = np.where(counts > 0, s / safe + o, np.nan)
    return table


@dataclass
class Segmentation:
    """Result of a segmentation method.

    Attributes
    ----------
    labels : (N,) ndarray of int32
        Segment id per point, 1..n; 0 = in no segment.
    table : dict of str to ndarray
        One row per segment; the first column is ``segment_id``. Methods add the fitted
        surface, its parameters with standard errors, test results, sizes, RMS.
    lines : Polylines or None
        Intersection (or ridge) lines between segments.
    fields : dict of str to (N,) ndarray
        Further per-point outputs of the method (written beside ``segment_id``).
    method : str
    params : dict
        Parameters actually used (after automatic choices), for the report.
    """

    labels: np.ndarray
    table: dict
    lines: Polylines | None = None
    fields: dict = field(default_factory=dict)
    method: str = ""
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        self.labels = np.ascontiguousarray(self.labels, dtype=np.int32)
        n = self.n_segments
        if "segment_id" not in self.table:
            raise InvalidParameterError("the segment table needs a 'segment_id' column")
        rows = len(self.table["segment_id"])
        self.table = {k: _column(v, rows, k, "segment") for k, v in self.table.items()}
        if rows != n:
            raise InvalidParameterError(
                f"the segment table has {rows} rows but the labels have {n} segments")
        self.fields = {k: _column(v, self.labels.size, k, "point") for k, v in
                       self.fields.items()}

    @property
    def n_segments(self) -> int:
        """Number of segments (ids 1..n)."""
        return int(self.labels.max()) if self.labels.size else 0

    def to_fields(self) -> dict[str, np.ndarray]:
        """Per-point fields to write: ``segment_id`` (uint32, 0 = none) and the method's."""
        return {"segment_id": self.labels.astype(np.uint32), **self.fields}

    def write_table(self, path: str | os.PathLike) -> Path:
        """Write the segment table atomically as ``.csv`` or ``.json``."""
        return _write_records(Path(path), self.table, "segment table")

    def summary(self) -> str:
        """A few lines: segments, points in segments, the largest sizes."""
        n = self.labels.size
        inside = int(np.count_nonzero(self.labels))
        sizes = np.bincount(self.labels)[1:]
        top = ", ".join(str(s) for s in np.sort(sizes)[::-1][:5])
        lines = [f"{self.method or 'segmentation'}: {self.n_segments} segments, "
                 f"{inside}/{n} points ({100.0 * inside / max(n, 1):.1f}%) in a segment",
                 f"  largest: {top}" if sizes.size else "  no segment"]
        if self.lines is not None:
            lines.append(f"  {len(self.lines)} lines")
        return "\n".join(lines)
