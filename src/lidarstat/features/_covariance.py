"""Per-point covariance (eigen) features over kNN or radius neighbourhoods (seed 003)."""

from __future__ import annotations

import logging

import numpy as np

from .._shared import _memory as _mem
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import CellIndex, Neighborhoods, knn_cell_size
from . import _covariance_kernels as _ck
from . import _scan_kernels as _sk
from ._covariance_result import EIGEN_MODES, CovarianceResult, EigenMode, add_sensor_fields

logger = logging.getLogger(__name__)



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
        _check_neighborhoods(neighborhoods, n, func)
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
        if order is not None:
            scan_in = np.empty_like(scan)
            scan_in[order] = scan
            scan = scan_in
        add_sensor_fields(res, pts, sensor, scan)
    return res


def covariance_frames(points, neighborhoods, *, sensor=None, block_size=262144):
    """Normal, centroid and principal direction of the normals of every point's given
    neighbourhood, without the other covariance features.

    The same values, bit for bit, as ``normals``, ``centroid`` and ``PrincipalDirX/Y/Z``
    of :func:`covariance_features` with these `neighborhoods` and `sensor`: the first
    pass of the covariance kernel and the normal spread over the rows, without the
    variance of the surface variation, the scan geometry and the eigen features, the
    kernel's rows a block at a time (a segmentation that needs the planes of its rows
    holds 72 bytes a point instead of the whole result's 250 and more).

    Parameters
    ----------
    points : (N, 3) array_like
    neighborhoods : Neighborhoods
        One row per point, indexing the `N` points.
    sensor : (3,) array_like, optional
        Scanner position: normals point to it (else up).
    block_size : int
        Rows of the covariance kernel's output held at a time.

    Returns
    -------
    normals, centroids, principal_dirs : (N, 3) ndarray of float64
        Unit normals, neighbourhood centroids (file coordinates) and the direction of
        largest variation of the neighbours' normals.

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.features import covariance_features, covariance_frames
    >>> from lidarstat.neighbors import knn_neighbors
    >>> rng = np.random.default_rng(0)
    >>> pts = np.c_[rng.uniform(0, 10, (500, 2)), rng.normal(0, 0.01, 500)]
    >>> nbh = knn_neighbors(pts, 12)
    >>> normals, centroids, dirs = covariance_frames(pts, nbh)
    >>> bool((normals == covariance_features(pts, neighborhoods=nbh).normals).all())
    True
    """
    func = "covariance_frames"
    pts = check_points(points)
    n = pts.shape[0]
    sensor = _check_sensor(sensor, func)
    block_size = check_scalar(block_size, "block_size", func=func, low=1, closed="left",
                              integer=True)
    _check_neighborhoods(neighborhoods, n, func)
    origin = pts.mean(axis=0)
    local = pts - origin
    sens = None if sensor is None else sensor - origin
    indptr, indices = neighborhoods.indptr, neighborhoods.indices
    normals = np.empty((n, 3))
    centroids = np.empty((n, 3))
    for r0 in range(0, n, block_size):  # the kernel's output rows a block at a time
        r1 = min(n, r0 + block_size)
        raw = _rows(local, np.arange(r0, r1), indptr[r0:r1 + 1], indices, sens)
        normals[r0:r1] = raw[:, _ck.C_NX:_ck.C_NZ + 1]
        centroids[r0:r1] = raw[:, _ck.C_CX:_ck.C_CZ + 1] + origin
    del local
    spread = np.empty((n, 4))
    _ck.normal_spread_rows_offset(normals, 0, neighborhoods.indptr, neighborhoods.indices,
                                  spread)
    return normals, centroids, np.ascontiguousarray(spread[:, :3])


def _check_neighborhoods(neighborhoods, n, func):
    if not isinstance(neighborhoods, Neighborhoods):
        raise InvalidParameterError(f"{func}: `neighborhoods` must be a Neighborhoods instance")
    if neighborhoods.n_points != n or len(neighborhoods) != n:
        raise InvalidParameterError(
            f"{func}: `neighborhoods` must have one row per point and index the {n} points "
            f"(got {len(neighborhoods)} rows over {neighborhoods.n_points} points)"
        )


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
