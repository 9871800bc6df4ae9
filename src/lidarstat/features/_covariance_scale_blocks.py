"""The covariance features at per-point automatic sizes, block by block.

An automatic scale chooses, per point, a prefix of its ``k_max`` nearest neighbours
sorted by distance (:mod:`._covariance_scale`). Held for the whole cloud, those rows cost
12 ``k_max`` bytes a point (int32 index and float64 distance, 600 bytes at
``k_max = 50``), plus the prefixes gathered from them. Here the query points are taken a
block of grid cells at a time (:meth:`lidarstat.neighbors.CellIndex.cell_blocks`, about
`block_size` points): the block's kNN rows, the size rule, the covariance of the chosen
prefixes, then the rows are dropped. Only per-point results live for the whole cloud
(the kernel output row, the size and its radius), so the working set is that of one
block whatever the number of points.

The features need two passes: the variance of the surface variation over a
neighbourhood (eq. 5) and the spread of the normals read every neighbour's result of
the first pass. The second pass searches each block's rows again (the search is exact
and deterministic, so the rows are the same) instead of keeping them.

Every kernel sees what the whole-cloud computation gives it (the same coordinates, the
same rows in the same order, the same per-row noise), in the grid's sorted order instead
of the input order, so the results are the same, bit for bit; :func:`_assemble` puts
them back in input order.
"""

from __future__ import annotations

import numpy as np

from .._shared import _memory as _mem
from ..neighbors import CellIndex, Neighborhoods, knn_cell_size
from . import _covariance_kernels as _ck
from . import _scan_kernels as _sk
from ._covariance_result import add_sensor_fields


def blocked_prefix_features(points, k_max, choose, *, sensor=None, eigen_mode="raw",
                            keep_neighbors=False, block_size=262144, progress=None,
                            rule="given", k_min=None):
    """Covariance features on a per-point prefix of the `k_max` nearest neighbours.

    Parameters
    ----------
    points : (N, 3) float64 ndarray
    k_max : int
        Row length (at most N).
    choose : callable(local, indptr, idx, rows) -> (M,) int array
        The size rule of one block: `local` the (N, 3) coordinates in the grid's sorted
        order, ``indptr, idx`` the block's rows (sorted positions, by distance, the
        point itself first), `rows` the input indices of the block's points.
    sensor, eigen_mode, keep_neighbors, block_size, progress, rule, k_min
        As :func:`lidarstat.features.prefix_features`.

    Returns
    -------
    CovarianceResult
        As :func:`lidarstat.features.prefix_features` on the full rows.
    """
    from ._covariance import _assemble, _scan_rows, _surface_variation

    pts = points
    n = pts.shape[0]
    cell, tau0 = knn_cell_size(pts, k_max, rng=0)
    index = CellIndex(pts, cell)
    order = index.order
    origin = pts.mean(axis=0)
    local = np.ascontiguousarray((pts - origin)[order])  # sorted order, the rows' origin
    sens = None if sensor is None else np.asarray(sensor, float) - origin
    blocks = index.cell_blocks(block_size)
    search = _Search(index, k_max, tau0, keep_neighbors)
    raw = np.empty((n, _ck.NCOL))
    kopt = np.empty(n, dtype=np.int64)
    reach = np.empty(n)
    for c0, c1 in blocks:
        s0, s1 = int(index.cell_start[c0]), int(index.cell_start[c1])
        table, dist = search.rows(c0, c1)
        m = s1 - s0
        indptr_full = np.arange(m + 1, dtype=np.int64) * k_max
        sizes = np.minimum(np.asarray(choose(local, indptr_full, table.reshape(-1),
                                             order[s0:s1]), dtype=np.int64), k_max)
        indptr, idx, last = _prefix(table, sizes)
        _ck.covariance_rows(local, np.arange(s0, s1, dtype=np.int64), indptr, idx,
                            np.zeros(3) if sens is None else sens, sens is not None,
                            raw[s0:s1])
        kopt[s0:s1] = sizes
        reach[s0:s1] = dist.reshape(-1)[last]
        if progress is not None:
            progress(s1, 2 * n)
    sv = _surface_variation(raw)
    nrm = np.ascontiguousarray(raw[:, _ck.C_NX:_ck.C_NZ + 1])
    mean_sv = np.empty(n)
    var_sv = np.empty(n)
    spread = np.empty((n, 4))
    scan = None if sens is None else np.empty((n, _sk.NSCAN))
    angles = None
    if sens is not None:
        angles = _sk.scan_angles(local, sens)
    for c0, c1 in blocks:
        s0, s1 = int(index.cell_start[c0]), int(index.cell_start[c1])
        table, _ = search.rows(c0, c1)
        indptr, idx, _ = _prefix(table, kopt[s0:s1])
        _ck.neighbourhood_variance(sv, indptr, idx, mean_sv[s0:s1], var_sv[s0:s1])
        _ck.normal_spread_rows_offset(nrm, s0, indptr, idx, spread[s0:s1])
        if scan is not None:
            scan[s0:s1] = _scan_rows(local, np.arange(s0, s1), indptr, idx, raw[s0:s1],
                                     sens, angles)
        if progress is not None:
            progress(n + s1, 2 * n)
    del sv, nrm
    res = _assemble(raw, mean_sv, var_sv, spread, origin, order, k=None, radius=None,
                    eigen_mode=eigen_mode, neighborhoods=search.kept())
    source = np.empty_like(order)
    source[order] = np.arange(n)
    res.fields["OptimalKNN"] = kopt[source].astype(np.int32)
    res.fields["OptimalRadius"] = reach[source]
    res.meta.update(scale="optimal", rule=rule, k_min=k_min, k_max=k_max if n else 0)
    if sensor is not None:
        add_sensor_fields(res, pts, np.asarray(sensor, float), scan[source])
    return res




def _prefix(table, sizes):
    """CSR of the first ``sizes[r]`` entries of each row of the (M, k) `table`, and the
    flat position in `table` of each row's last kept entry."""
    m, k = table.shape
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(sizes, out=indptr[1:])
    keep = np.arange(k) < sizes[:, None]
    last = np.arange(m, dtype=np.int64) * k + sizes - 1
    return indptr, table[keep], last


class _Search:
    """The sorted kNN rows of a block of cells (sorted positions and distances), from the
    kNN kernel of the fixed-k features (:func:`._covariance._knn_table`, same cell, same
    rows); with `keep`, the whole cloud's rows in input order are also kept (and the
    second pass reads them instead of searching again)."""

    def __init__(self, index, k, tau0, keep):
        self.index, self.k, self.tau0 = index, int(k), tau0
        n = index.n_points
        self.dtype = np.int32 if n < 2**31 - 1 else np.int64
        self.keep = keep
        self.searched = np.zeros(index.n_cells, dtype=bool) if keep else None
        if keep:
            # written once by the kernel, then streamed: ordinary pages (_memory's doc)
            self.nbr_idx = _mem.empty(n * self.k, dtype=self.dtype)
            self.nbr_dist = _mem.empty(n * self.k)
            self.source = None
        else:
            # the kernel writes row i's distances at loc[i] k: loc maps the block's sorted
            # positions to 0..M-1 (the neighbour indices it writes beside are not used)
            self.loc = np.zeros(n, dtype=index.order.dtype)

    def rows(self, c0, c1):
        index, k = self.index, self.k
        s0, s1 = int(index.cell_start[c0]), int(index.cell_start[c1])
        m = s1 - s0
        if self.keep and self.searched[c0]:
            if self.source is None:
                # input index -> sorted position, in the table's dtype (no int64 copy)
                self.source = np.empty(index.n_points, dtype=self.dtype)
                self.source[index.order] = np.arange(index.n_points, dtype=self.dtype)
            rows = index.order[s0:s1]
            return (self.source[self.nbr_idx.reshape(-1, k)[rows]],
                    self.nbr_dist.reshape(-1, k)[rows])
        table = np.empty((m, k), dtype=self.dtype)
        feat = np.empty((m, _ck.NCOL))
        if self.keep:
            order, nbr_idx, nbr_dist = index.order, self.nbr_idx, self.nbr_dist
        else:
            order = self.loc
            order[s0:s1] = np.arange(m)
            nbr_idx = np.empty(m * k, dtype=self.dtype)
            nbr_dist = np.empty(m * k)
        _ck.knn_cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start,
                      index.dims, float(index.cell), k, self.tau0, True, table, order,
                      nbr_idx, nbr_dist, np.zeros(3), False, feat)
        if self.keep:
            self.searched[c0] = True
            return table, self.nbr_dist.reshape(-1, k)[index.order[s0:s1]]
        return table, nbr_dist

    def kept(self):
        if not self.keep:
            return None
        n = self.index.n_points
        return Neighborhoods(np.arange(n + 1, dtype=np.int64) * self.k, self.nbr_idx,
                             self.nbr_dist, n, kind="knn", k=self.k,
                             row_order=self.index.order)
