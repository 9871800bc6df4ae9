"""Generic Numba drivers that run a per-point local fit over CSR rows or over grid cells.

A local-fit kernel (the quadric of ``features/_quadric_kernels.py``, the jet of
``features/_jet_kernels.py``) provides three jitted functions:

* ``workspace(params)``: the per-thread scratch arrays (a tuple), allocated once per
  chunk of points or cells, never per point;
* ``fit_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs)``: fit point ``i`` of
  ``pts`` from its neighbours ``idx[s:e]`` at distances ``dist[s:e]`` and write output
  row ``r`` of every array of the tuple ``outs`` (status included, failures too); ``buf``
  has at least ``e - s`` rows of 4 columns of scratch for the neighbours;
* ``skip(r, outs)``: mark output row ``r`` as not fitted (status SKIPPED).

:func:`make_drivers` builds from them the two loops every such kernel needs, once:

* ``block(pts, query, indptr, idx, dist, params, outs)``: the neighbourhoods are CSR rows
  (row r is the neighbourhood of ``pts[query[r]]``), parallel over chunks of rows;
* ``cells(c0, c1, pts, cell_keys, cell_start, dims, radius, active, params, outs)``: the
  fused neighbour search of a :class:`lidarstat.neighbors.CellIndex` (3-D sphere of
  `radius`, the 27 cells around each occupied cell gathered into a per-chunk buffer) and
  fit of the points of cells ``c0..c1-1``, so no global CSR arrays are written and read
  back; output row r is sorted position ``cell_start[c0] + r``; points with
  ``active[i] == 0`` are skipped.

The drivers are closures over the kernel's functions; Numba keys the on-disk cache of a
closure by the pickled cell contents, which include each dispatcher's UUID, random per
process (numba issue 6264), so :func:`make_drivers` keys the drivers' caches instead by
the kernel functions' module, name and source file contents
(:func:`lidarstat._shared._jit.closure_cache`): ``cache=True`` then loads the drivers in
every new process, and an edit of the kernel's file compiles them again.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import prange

from .._shared._jit import closure_cache, njit_parallel
from ._kernels import STORE_ALL, _cell_ranges, _scan

_CHUNK = 64
_CELL_CHUNK = 64

Drivers = namedtuple("Drivers", ["block", "cells"])


def make_drivers(fit_point, workspace, skip) -> Drivers:
    """The CSR-block and fused-cell drivers of one per-point fit.

    Parameters
    ----------
    fit_point : numba dispatcher
        ``fit_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs)``: fits point ``i``
        from its neighbours ``idx[s:e]`` and writes output row ``r`` of `outs`.
    workspace : numba dispatcher
        ``workspace(params)``: the per-thread scratch arrays (a tuple).
    skip : numba dispatcher
        ``skip(r, outs)``: marks output row ``r`` as not fitted.

    Returns
    -------
    Drivers
        ``(block, cells)``: the loop over CSR rows and the fused grid search and fit over
        the cells of a :class:`CellIndex` (signatures in the module docstring).
    """
    @njit_parallel
    def block(pts, query, indptr, idx, dist, params, outs):
        mq = query.size
        nchunks = (mq + _CHUNK - 1) // _CHUNK
        longest = 1
        for r in range(mq):
            longest = max(longest, indptr[r + 1] - indptr[r])
        for ch in prange(nchunks):
            ws = workspace(params)
            buf = np.empty((longest, 4))
            for r in range(ch * _CHUNK, min(mq, (ch + 1) * _CHUNK)):
                fit_point(query[r], pts, idx, dist, indptr[r], indptr[r + 1], r, params, ws,
                          buf, outs)

    @njit_parallel
    def cells(c0, c1, pts, cell_keys, cell_start, dims, radius, active, params, outs):
        base = cell_start[c0]
        r2 = radius * radius
        ncell = c1 - c0
        nchunks = (ncell + _CELL_CHUNK - 1) // _CELL_CHUNK
        for ch in prange(nchunks):
            ws = workspace(params)
            ranges = np.empty((9, 2), dtype=np.int64)
            cap = 256
            idx_buf = np.empty(cap, dtype=np.int32)
            dist_buf = np.empty(cap)
            buf = np.empty((cap, 4))
            for c in range(c0 + ch * _CELL_CHUNK, min(c1, c0 + (ch + 1) * _CELL_CHUNK)):
                nr = _cell_ranges(c, cell_keys, cell_start, dims, 3, ranges)
                need = 0
                for t in range(nr):
                    need += ranges[t, 1] - ranges[t, 0]
                if need > cap:
                    cap = max(need, 2 * cap)
                    idx_buf = np.empty(cap, dtype=np.int32)
                    dist_buf = np.empty(cap)
                    buf = np.empty((cap, 4))
                for i in range(cell_start[c], cell_start[c + 1]):
                    r = i - base
                    if active[i] == 0:
                        skip(r, outs)
                        continue
                    n = _scan(pts[i, 0], pts[i, 1], pts[i, 2], pts, ranges, nr, r2, 3,
                              idx_buf, dist_buf, 0, STORE_ALL)
                    fit_point(i, pts, idx_buf, dist_buf, 0, n, r, params, ws, buf, outs)

    kernels = (fit_point, workspace, skip)
    return Drivers(closure_cache(block, kernels), closure_cache(cells, kernels))
