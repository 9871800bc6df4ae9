"""Per-point covariance (eigen) features over kNN or radius neighbourhoods (seed 003)."""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from .._shared import _memory as _mem
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..io import register_field_descriptions
from ..neighbors import CellIndex, Neighborhoods, knn_cell_size
from . import _covariance_kernels as _ck
from . import _scan_kernels as _sk

logger = logging.getLogger(__name__)



class EigenMode(str, enum.Enum):
    """What the eigen features' ratios are computed from (PDAL's ``mode``,
    ``--eigen-mode``)."""

    #: The eigenvalues (jakteristics, CloudCompare).
    RAW = "raw"
    #: Their square roots (PDAL's default, pgeof).
    SQRT = "sqrt"
    #: The eigenvalues divided by their sum.
    NORMALIZED = "normalized"

    def __str__(self):
        return self.value


EIGEN_MODES = tuple(m.value for m in EigenMode)

#: Per-point output fields, name -> (dtype, description). Names follow PDAL's
#: ``filters.covariancefeatures`` / ``filters.normal`` / ``filters.eigenvalues``.
FIELDS = {
    "NormalX": ("float64", "unit normal x (toward the sensor, else up)"),
    "NormalY": ("float64", "unit normal y"),
    "NormalZ": ("float64", "unit normal z"),
    "Eigenvalue0": ("float64", "smallest covariance eigenvalue"),
    "Eigenvalue1": ("float64", "middle covariance eigenvalue"),
    "Eigenvalue2": ("float64", "largest covariance eigenvalue"),
    "SurfaceVariation": ("float64", "lambda0/(lambda0+lambda1+lambda2), eq. 4"),
    "CurvatureVariance": ("float64", "variance of SurfaceVariation over nbhd, eq. 5"),
    "Linearity": ("float64", "(l2-l1)/l2"),
    "Planarity": ("float64", "(l1-l0)/l2"),
    "Scattering": ("float64", "l0/l2"),
    "Verticality": ("float64", "z of the eigenvalue-weighted |e| (PDAL)"),
    "Omnivariance": ("float64", "cbrt(l0 l1 l2)"),
    "Anisotropy": ("float64", "(l2-l0)/l2"),
    "Eigenentropy": ("float64", "-sum l ln l"),
    "EigenvalueSum": ("float64", "l0+l1+l2"),
    "DemantkeVerticality": ("float64", "1-|NormalZ|"),
    "PrincipalDirX": ("float64", "max-curvature direction x (normals)"),
    "PrincipalDirY": ("float64", "max-curvature direction y"),
    "PrincipalDirZ": ("float64", "max-curvature direction z"),
    "NormalVariation": ("float64", "variance of normals along PrincipalDir"),
    "neighbors": ("int32", "points in the neighbourhood"),
}
#: Fields of the automatic scale (PDAL's ``filters.optimalneighborhood`` names).
SCALE_FIELDS = {
    "OptimalKNN": ("int32", "neighbourhood size of minimum eigenentropy"),
    "OptimalRadius": ("float64", "distance to the OptimalKNN-th nearest point"),
}
FIELDS.update(SCALE_FIELDS)
register_field_descriptions(FIELDS)


class PointClass(IntEnum):
    """Codes of ``point_class`` (:func:`lidarstat.classify.covariance`; a contract)."""

    UNDETERMINED = 0
    SURFACE = 1
    EDGE = 2
    BOUNDARY = 3


@dataclass(frozen=True)
class CovarianceResult:
    """Per-point covariance features and what the classification needs beside them.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        The per-point output fields (``FIELDS``), in input order.
    centroid : (N, 3) ndarray
        Neighbourhood centroids (file coordinates).
    major : (N, 3) ndarray
        Eigenvector of the largest eigenvalue.
    offset_uv : (N, 2) ndarray
        Index point minus centroid along the largest and the middle eigenvector (eq. 7, 8).
    mean_variation : (N,) ndarray
        Mean of SurfaceVariation over each neighbourhood (beside its variance, eq. 5).
    k, radius : int or None, float or None
        The neighbourhood definition.
    neighborhoods : Neighborhoods or None
        The neighbourhoods (original indices, rows sorted by distance for kNN), when
        ``keep_neighbors`` was asked.
    sensor : (3,) ndarray or None
        Scanner position, when given.
    ray_range, ray_cos : (N,) ndarray or None
        With a sensor: distance from it and |cos| of the angle between the ray and the
        normal (the share of range noise that falls across the surface).
    scan_boundary : (N, 4) ndarray or None
        With a sensor: Hotelling T2 of the complete-disc centroid in linearised scan
        coordinates, the disc's point count m, its radius over the neighbourhood's and the
        neighbourhood's reach (:mod:`lidarstat.features._scan_kernels`; the reach is the
        scale of the ``'grid'`` boundary test).
    """

    fields: dict
    centroid: np.ndarray
    major: np.ndarray
    offset_uv: np.ndarray
    mean_variation: np.ndarray
    k: int | None
    radius: float | None
    eigen_mode: str = "raw"
    neighborhoods: Neighborhoods | None = None
    sensor: np.ndarray | None = None
    ray_range: np.ndarray | None = None
    ray_cos: np.ndarray | None = None
    scan_boundary: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    def __len__(self):
        return self.fields["SurfaceVariation"].size

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) unit normals."""
        f = self.fields
        return np.stack([f["NormalX"], f["NormalY"], f["NormalZ"]], axis=1)

    @property
    def eigenvalues(self) -> np.ndarray:
        """(N, 3) eigenvalues, ascending."""
        f = self.fields
        return np.stack([f["Eigenvalue0"], f["Eigenvalue1"], f["Eigenvalue2"]], axis=1)

    @property
    def counts(self) -> np.ndarray:
        """Neighbours per point."""
        return self.fields["neighbors"]

    def to_fields(self):
        """The per-point arrays with their file dtypes, for :func:`lidarstat.io.write`."""
        return {k: np.asarray(v, dtype=FIELDS[k][0]) for k, v in self.fields.items()}


def eigen_features(evals, normal, major, *, mode="raw"):
    """The eigenvalue features of PDAL's ``filters.covariancefeatures`` from eigenvalues.

    Parameters
    ----------
    evals : (N, 3) ndarray
        Eigenvalues in ascending order ``l0 <= l1 <= l2`` (``l0`` is the paper's lambda0).
    normal, major : (N, 3) ndarray
        Eigenvectors of ``l0`` and ``l2`` (the middle one is their cross product).
    mode : EigenMode or {'raw', 'sqrt', 'normalized'}
        What the ratios are computed from, as PDAL's ``mode`` option: the eigenvalues
        (jakteristics, CloudCompare), their square roots (PDAL's default, pgeof,
        Guinard and Landrieu 2017) or the eigenvalues divided by their sum.
        ``SurfaceVariation`` and ``EigenvalueSum`` always use the raw eigenvalues (eq. 4).

    Returns
    -------
    dict of str -> (N,) ndarray
    """
    mode = EigenMode(check_option(mode, "mode", EIGEN_MODES, func="eigen_features")).value
    raw = np.asarray(evals, dtype=np.float64)
    total = raw.sum(axis=1)
    if mode == "sqrt":
        lam = np.sqrt(raw)
    elif mode == "normalized":
        with np.errstate(invalid="ignore", divide="ignore"):
            lam = raw / total[:, None]
    else:
        lam = raw
    l0, l1, l2 = lam[:, 0], lam[:, 1], lam[:, 2]
    middle = np.cross(normal, major)
    unary = (l2[:, None] * np.abs(major) + l1[:, None] * np.abs(middle)
             + l0[:, None] * np.abs(normal))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {
            "Linearity": (l2 - l1) / l2,
            "Planarity": (l1 - l0) / l2,
            "Scattering": l0 / l2,
            "Verticality": unary[:, 2] / np.linalg.norm(unary, axis=1),
            "Omnivariance": np.cbrt(l0 * l1 * l2),
            "Anisotropy": (l2 - l0) / l2,
            "Eigenentropy": -(_xlogx(l0) + _xlogx(l1) + _xlogx(l2)),
            "EigenvalueSum": total,
            "SurfaceVariation": raw[:, 0] / total,
            "DemantkeVerticality": 1.0 - np.abs(normal[:, 2]),
        }
    return out


def _xlogx(x):
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(x > 0, x * np.log(np.where(x > 0, x, 1.0)), 0.0)


def _knn_table(points, k, *, block_size, sort=True, sensor=None, progress=None, rng=0):
    """Exact kNN of every point with the grid kernel, in the grid's sorted order.

    Returns ``(index, table, nbh, raw)``: ``table[r]`` lists the sorted positions of the k
    nearest neighbours of sorted position r (in ascending distance if `sort`), int32 when
    the cloud allows (4 k bytes per point); with `sort`, ``nbh`` holds the same
    neighbourhoods as :class:`Neighborhoods` in input order (original indices, distances),
    written by the kernel directly, else None. ``raw`` holds the covariance kernel's
    output per sorted position (computed in the same pass); `sensor` in file coordinates.
    """
    cell, tau0 = knn_cell_size(points, k, rng=rng)
    index = CellIndex(points, cell)
    n = index.n_points
    dtype = np.int32 if n < 2**31 - 1 else np.int64
    # written once by the kernel, then streamed: ordinary pages (_memory's module doc)
    table = _mem.empty((n, k), dtype=dtype)
    nbr_idx = _mem.empty(n * k if sort else 0, dtype=dtype)  # int32: 4 k bytes per point less
    nbr_dist = _mem.empty(n * k if sort else 0)
    raw = _mem.empty((n, _ck.NCOL))
    sens = np.zeros(3) if sensor is None else np.asarray(sensor, float) - index.origin
    for c0, c1 in index.cell_blocks(block_size):
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        _ck.knn_cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start,
                      index.dims, float(index.cell), int(k), tau0, sort, table[s0:s1],
                      index.order, nbr_idx, nbr_dist, sens, sensor is not None, raw[s0:s1])
        if progress is not None:
            progress(int(s1), 2 * n)
    nbh = None
    if sort:
        # rows visited in the grid order by the row-wise kernels that read them
        nbh = Neighborhoods(np.arange(n + 1, dtype=np.int64) * k, nbr_idx, nbr_dist, n,
                            kind="knn", k=k, row_order=index.order)
    return index, table, nbh, raw


def _check_sensor(sensor, func):
    if sensor is None:
        return None
    s = np.asarray(sensor, dtype=np.float64)
    if s.shape != (3,) or not np.isfinite(s).all():
        raise InvalidParameterError(
            f"The 'sensor' parameter of {func} must be 3 finite coordinates. Got {sensor!r} instead."
        )
    return s


#: The range of neighbourhood sizes of the automatic scale (``k`` and ``radius`` None):
#: Weinmann et al.'s lower bound, and the paper's fixed k = 50 as the upper one (the plane
#: and cylinder tests keep their power; the kNN search is that of the fixed scale).
OPTIMAL_K_MIN, OPTIMAL_K_MAX = 20, 50
#: A prefix whose middle eigenvalue is below this share of the largest is no candidate: it
#: is a piece of a scan line, not of a surface (its entropy is low, its normal undetermined).
OPTIMAL_MIN_SPREAD = 0.1


def covariance_features(points, *, k=None, radius=None, neighborhoods=None, sensor=None,
                        eigen_mode="raw", keep_neighbors=False, block_size=262144,
                        progress=None) -> CovarianceResult:
    """Covariance features of every point (Bae, Lichti et al.; Pauly et al. 2002).

    For each point the covariance of its neighbourhood is computed centred on the
    neighbourhood mean (two passes, divided by n - 1), and eigen-decomposed:
    eigenvalues ``l0 <= l1 <= l2``, the normal (eigenvector of ``l0``, oriented toward
    `sensor` or else up), the surface variation ``l0 / (l0 + l1 + l2)`` (eq. 4), its
    variance over the neighbourhood (eq. 5), PDAL's eigen features and the principal
    curvature direction from the covariance of the neighbours' normals (section 5).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (any magnitude: local origins are subtracted).
    k : int, optional
        Neighbours per point, the point itself included (the paper: 50). Ignored when
        `radius` or `neighborhoods` is given. When neither `k` nor `radius` is given,
        every point gets its own optimal neighbourhood size: the prefix of its
        ``OPTIMAL_K_MAX`` (50) nearest neighbours, at least ``OPTIMAL_K_MIN`` (20), whose
        normalised eigenvalues have the smallest entropy (Weinmann et al. 2015, as PDAL's
        ``filters.optimalneighborhood``), among the prefixes that span a surface (middle
        eigenvalue at least ``OPTIMAL_MIN_SPREAD`` of the largest; else all 50); fields
        ``OptimalKNN`` and ``OptimalRadius``.
    radius : float, optional
        Use the points within a 3-D sphere of this radius instead of the k nearest.
    neighborhoods : Neighborhoods, optional
        Precomputed neighbourhoods (one row per point) instead of either.
    sensor : (3,) array_like, optional
        Scanner position; normals point toward it. Default: normals point up (+z).
    eigen_mode : EigenMode or {'raw', 'sqrt', 'normalized'}
        See :func:`eigen_features`.
    keep_neighbors : bool
        Keep the neighbourhoods in the result (for segmentation); kNN rows are sorted by
        distance.
    block_size : int
        Points per processing block (bounds the scratch memory).
    progress : callable(done, total), optional

    Returns
    -------
    CovarianceResult

    Notes
    -----
    Rows with fewer than 3 neighbours get NaN features. The kNN search is exact; it runs
    on a uniform grid (cell = 0.9 quantile of the k-th neighbour distance of a sample)
    in the grid's sorted order, which is much faster than KD-tree queries for k = 50.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.features import covariance_features
    >>> rng = np.random.default_rng(0)
    >>> pts = np.c_[rng.uniform(0, 10, (2000, 2)), np.zeros(2000)] + [5e5, 5e6, 100.0]
    >>> res = covariance_features(pts, k=20)
    >>> bool(np.abs(res["NormalZ"] - 1).max() < 1e-9), float(res["SurfaceVariation"].max())
    (True, 0.0)
    """
    func = "covariance_features"
    pts = check_points(points)
    n = pts.shape[0]
    sensor = _check_sensor(sensor, func)
    eigen_mode = EigenMode(check_option(eigen_mode, "eigen_mode", EIGEN_MODES,
                                        func=func)).value
    block_size = check_scalar(block_size, "block_size", func=func, low=1, closed="left",
                              integer=True)
    if neighborhoods is not None:
        if not isinstance(neighborhoods, Neighborhoods):
            raise InvalidParameterError(f"{func}: `neighborhoods` must be a Neighborhoods instance")
        if neighborhoods.n_points != n or len(neighborhoods) != n:
            raise InvalidParameterError(
                f"{func}: `neighborhoods` must have one row per point and index the {n} points "
                f"(got {len(neighborhoods)} rows over {neighborhoods.n_points} points)"
            )
        kind = "given"
    elif radius is not None:
        radius = check_scalar(radius, "radius", func=func, low=0.0)
        kind = "radius"
    elif k is None:
        from ._covariance_scale import optimal_scale

        return optimal_scale(pts, sensor=sensor, eigen_mode=eigen_mode,
                             keep_neighbors=keep_neighbors, block_size=block_size,
                             progress=progress)
    else:
        k = check_scalar(k, "k", func=func, low=3, closed="left", integer=True)
        if k > n:
            raise InvalidParameterError(
                f"The 'k' parameter of {func} must be at most the number of points: the "
                f"cloud has {n:,} (distinct locations), fewer than k = {k}; lower k (at "
                "least 3)")
        kind = "knn"

    keep = None
    if kind == "given":
        origin = pts.mean(axis=0)
        local = pts - origin
        sens = None if sensor is None else sensor - origin
        raw = _rows(local, np.arange(n), neighborhoods.indptr, neighborhoods.indices, sens)
        mean_sv, var_sv = _variance_csr(raw, neighborhoods.indptr, neighborhoods.indices)
        spread = np.empty((n, 4))
        _ck.normal_spread_rows_offset(np.ascontiguousarray(raw[:, _ck.C_NX:_ck.C_NZ + 1]), 0,
                                      neighborhoods.indptr, neighborhoods.indices, spread)
        order = None
        keep = neighborhoods if keep_neighbors else None
        k, radius = neighborhoods.k, neighborhoods.radius
        scan = None if sens is None else _scan_rows(local, np.arange(n), neighborhoods.indptr,
                                                    neighborhoods.indices, raw, sens)
    elif kind == "radius":
        index = CellIndex(pts, radius)
        origin = index.origin
        sens = None if sensor is None else sensor - origin
        raw = np.empty((n, _ck.NCOL))
        blocks = index.cell_blocks(block_size)
        for c0, c1 in blocks:
            s0, s1 = index.cell_start[c0], index.cell_start[c1]
            indptr, idx, _ = index.query_cells(c0, c1)
            raw[s0:s1] = _rows(index.sorted_points, np.arange(s0, s1), indptr, idx, sens)
            if progress is not None:
                progress(int(s1), 2 * n)
        sv = _surface_variation(raw)
        mean_sv = np.empty(n)
        var_sv = np.empty(n)
        spread = np.empty((n, 4))
        nrm = np.ascontiguousarray(raw[:, _ck.C_NX:_ck.C_NZ + 1])
        scan = None if sens is None else np.empty((n, _sk.NSCAN))
        angles = None if sens is None else _sk.scan_angles(index.sorted_points, sens)
        for c0, c1 in blocks:
            s0, s1 = index.cell_start[c0], index.cell_start[c1]
            indptr, idx, _ = index.query_cells(c0, c1)
            _ck.neighbourhood_variance(sv, indptr, idx, mean_sv[s0:s1], var_sv[s0:s1])
            _spread_block(nrm, s0, s1, indptr, idx, spread)
            if scan is not None:
                scan[s0:s1] = _scan_rows(index.sorted_points, np.arange(s0, s1), indptr, idx,
                                         raw[s0:s1], sens, angles)
            if progress is not None:
                progress(int(n + s1), 2 * n)
        order = index.order
        if keep_neighbors:
            from ..neighbors import radius_neighbors

            keep = radius_neighbors(pts, radius)
        k = None
    else:
        index, table, keep, raw = _knn_table(pts, k, block_size=block_size,
                                             sort=keep_neighbors, sensor=sensor,
                                             progress=progress)
        origin = index.origin
        mean_sv = _mem.empty(n)
        var_sv = _mem.empty(n)
        spread = _mem.empty((n, 4))
        # eq. 5 variance and normal spread in one pass over the table, from a compact
        # copy of the normals (the strided view into `raw` is slower: measured)
        _ck.table_second_pass(raw, table, _mem.empty(n), _mem.empty((n, 3)), mean_sv,
                              var_sv, spread)
        scan = None
        if sensor is not None:
            scan = _scan_rows(index.sorted_points, np.arange(n),
                              np.arange(n + 1, dtype=np.int64) * k, table.reshape(-1), raw,
                              np.asarray(sensor, float) - origin)
        if progress is not None:
            progress(2 * n, 2 * n)
        order = index.order
        del table

    res = _assemble(raw, mean_sv, var_sv, spread, origin, order, k=k, radius=radius,
                    eigen_mode=eigen_mode, neighborhoods=keep)
    if sensor is not None:
        ray = pts - sensor
        rng_ = np.linalg.norm(ray, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = np.abs(np.einsum("ij,ij->i", ray, res.normals)) / rng_
        object.__setattr__(res, "sensor", sensor)
        object.__setattr__(res, "ray_range", rng_)
        object.__setattr__(res, "ray_cos", cos)
        if order is not None:
            scan_in = np.empty_like(scan)
            scan_in[order] = scan
            scan = scan_in
        object.__setattr__(res, "scan_boundary", scan)
    return res


def _rows(local, query, indptr, idx, sens):
    out = np.empty((query.size, _ck.NCOL))
    _ck.covariance_rows(local, np.ascontiguousarray(query, dtype=np.int64), indptr, idx,
                        np.zeros(3) if sens is None else sens, sens is not None, out)
    return out


def _scan_rows(pts, rowpoint, indptr, idx, raw, sens, angles=None):
    """:func:`._scan_kernels.scan_centroid_rows` of CSR rows whose kernel output is `raw`."""
    out = np.empty((rowpoint.size, _sk.NSCAN))
    if angles is None:
        angles = _sk.scan_angles(pts, sens)
    _sk.scan_centroid_rows(pts, angles, np.ascontiguousarray(rowpoint, dtype=np.int64),
                           np.ascontiguousarray(indptr, dtype=np.int64), idx,
                           np.ascontiguousarray(raw[:, _ck.C_NX:_ck.C_NZ + 1]),
                           np.ascontiguousarray(raw[:, _ck.C_AX:_ck.C_AZ + 1]),
                           np.asarray(sens, dtype=np.float64), out)
    return out


def _surface_variation(raw):
    with np.errstate(invalid="ignore", divide="ignore"):
        return raw[:, _ck.C_L0] / (raw[:, _ck.C_L0] + raw[:, _ck.C_L1] + raw[:, _ck.C_L2])


def _variance_csr(raw, indptr, idx):
    sv = _surface_variation(raw)
    mean_sv = np.empty(sv.size)
    var_sv = np.empty(sv.size)
    _ck.neighbourhood_variance(sv, indptr, idx, mean_sv, var_sv)
    return mean_sv, var_sv


def _spread_block(nrm, s0, s1, indptr, idx, spread):
    """Normal spread of rows s0..s1 (sorted positions) from a block's CSR (row r = s0 + r)."""
    _ck.normal_spread_rows_offset(nrm, s0, indptr, idx, spread[s0:s1])


def _assemble(raw, mean_sv, var_sv, spread, origin, order, *, k, radius, eigen_mode,
              neighborhoods):
    """The result in input order (`order`: sorted position -> input index, or None)."""
    n = raw.shape[0]
    if order is None:
        source = np.arange(n)
    else:
        source = np.empty_like(order)
        source[order] = np.arange(n)
    block = _mem.empty((len(_ck.FIELD_ROWS), n))
    centroid = _mem.empty((n, 3))
    major = _mem.empty((n, 3))
    offset_uv = _mem.empty((n, 2))
    mean_out = _mem.empty(n)
    counts = _mem.empty(n, dtype=np.int32)
    mode = {"raw": _ck.MODE_RAW, "sqrt": _ck.MODE_SQRT, "normalized": _ck.MODE_NORMALIZED}
    with np.errstate(invalid="ignore", divide="ignore"):
        _ck.assemble(raw, mean_sv, var_sv, np.ascontiguousarray(spread), source,
                     np.asarray(origin, dtype=np.float64), mode[eigen_mode], block, centroid,
                     major, offset_uv, mean_out, counts)
    fields = dict(zip(_ck.FIELD_ROWS, block))
    fields["neighbors"] = counts
    return CovarianceResult(
        fields=fields, centroid=centroid, major=major, offset_uv=offset_uv,
        mean_variation=mean_out, k=k, radius=radius, eigen_mode=eigen_mode,
        neighborhoods=neighborhoods,
    )
