"""The generic per-point drivers (neighbors/_drivers.py) and their disk cache."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from lidarstat._shared._jit import njit
from lidarstat.neighbors import CellIndex, radius_neighbors
from lidarstat.neighbors._drivers import make_drivers

SRC = str(Path(__file__).resolve().parents[2] / "src")

_KEYS = """
import json
from lidarstat.features import _jet_kernels as jk, _quadric_cells as qc, _quadric_kernels as qk
drivers = (jk.fit_jets_block, jk.fit_jets_cells, qk.fit_quadrics_block, qc.fit_quadrics_cells)
cg = drivers[0].targetctx.codegen()
print(json.dumps([str(d._cache._index_key((), cg)) for d in drivers]))
"""


def test_driver_cache_keys_are_stable_across_processes():
    """Numba keys a cached closure by its pickled cells (random per process); the drivers'
    keys must be the same in two fresh interpreters (so `cache=True` loads them) and
    differ between the jet and the quadric drivers (no wrong code loaded)."""
    runs = [subprocess.run([sys.executable, "-c", _KEYS], capture_output=True, text=True,
                           env={"PYTHONPATH": SRC, "PATH": ""}, check=True) for _ in range(2)]
    keys = [json.loads(r.stdout) for r in runs]
    assert keys[0] == keys[1]
    assert len(set(keys[0])) == 4


@njit
def _ws(params):
    return (np.zeros(1),)


@njit
def _count_point(i, pts, idx, dist, s, e, r, params, ws, buf, outs):
    """Toy fit: the number of neighbours and the sum of their indices."""
    count, total = outs
    count[r] = e - s
    acc = 0
    for t in range(s, e):
        acc += idx[t]
    total[r] = acc + params[0]


@njit
def _skip(r, outs):
    count, total = outs
    count[r] = -1
    total[r] = -1


def test_generic_drivers_visit_every_neighbourhood(rng):
    """A toy fit through both drivers sees exactly the CSR neighbourhoods (cells: the fused
    search, in sorted order; inactive points skipped)."""
    block, cells = make_drivers(_count_point, _ws, _skip)
    pts = rng.uniform(0, 1, (800, 3))
    nb = radius_neighbors(pts, 0.15)
    count = np.zeros(800, np.int64)
    total = np.zeros(800, np.int64)
    block(pts, np.arange(800), nb.indptr, nb.indices, nb.distances, (5,), (count, total))
    assert np.array_equal(count, nb.counts)
    sums = np.add.reduceat(nb.indices, nb.indptr[:-1]) + 5
    assert np.array_equal(total, sums)
    index = CellIndex(pts, 0.15)
    active = np.ones(800, np.uint8)
    active[::7] = 0
    c2 = np.zeros(800, np.int64)
    t2 = np.zeros(800, np.int64)
    for c0, c1 in index.cell_blocks(100):
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start, index.dims,
              0.15, active, (5,), (c2[s0:s1], t2[s0:s1]))
    # row i is sorted position i = point order[i]; neighbour ids are sorted positions
    order = index.order
    inv = np.empty_like(order)
    inv[order] = np.arange(800)
    on = active == 1
    assert np.all(c2[~on] == -1) and np.all(t2[~on] == -1)
    assert np.array_equal(c2[on], nb.counts[order][on])
    want = np.add.reduceat(inv[nb.indices], nb.indptr[:-1])[order] + 5
    assert np.array_equal(t2[on], want[on])
