"""Moments classification: the fast kernels equal their plain references, so speed-ups
change no label (TIN evaluation, cell medians, curve smoothing, tiling)."""

import numpy as np
import pytest
from classify.test_moments_classify import _scene

from lidarstat.classify import (_cycle, _moments_ground, _moments_windows, _surface,
                                _surface_kernels, moments)


def _scipy_surface(xy_ground, z_ground, *, cell, which="median", rank=None, where=None,
                   frame=None):
    """The scipy surface: LinearNDInterpolator, the nearest vertices' plane outside (in
    the `frame` without the empty bands, as the TIN)."""
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import Delaunay, cKDTree

    if where is not None:  # the ground as copies: the subset the caller names
        xy_ground, z_ground = xy_ground[where], z_ground[where]
        rank = None if rank is None else rank[where]
    sel = _surface._cell_pick(xy_ground, z_ground, cell, which, rank)
    P, V = xy_ground[sel], z_ground[sel]
    P = P if frame is None else frame(P)
    lin, tree = LinearNDInterpolator(Delaunay(P), V), cKDTree(P)

    def f(q):
        q = q if frame is None else frame(q)
        v = lin(q)
        bad = np.isnan(v)
        v[bad] = _surface._extrapolate(P, V, tree, q[bad])
        return v

    f.frame = frame
    return f


def _convolve_smooth(y, w):
    ok = np.isfinite(y)
    k = np.ones(w)
    num = np.convolve(np.where(ok, y, 0.0), k, mode="same")
    den = np.convolve(ok.astype(float), k, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def test_tin_matches_scipy_inside_outside_any_order(rng):
    P = rng.uniform(0, 200, (3000, 2))
    V = rng.normal(size=3000)
    q = np.r_[rng.uniform(-20, 220, (40000, 2)), P, P[:50] + 1e-13]  # vertices, near-hull
    ref = _scipy_surface(P, V, cell=1e-9)(q)  # cell tiny: every point is a vertex
    got = _surface.TinSurface(P, V, cell=4.0)(q)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[40000:43000], V, rtol=0, atol=1e-12)


def _box_bins(P, simp, ox, oy, g, nx, ny):
    """The bins of every triangle's bounding box (NumPy reference of the CSR the TIN
    kernel reads, each bin's triangles ascending)."""
    lo = np.floor((P[simp].min(axis=1) - [ox, oy]) / g).astype(np.int64)
    hi = np.floor((P[simp].max(axis=1) - [ox, oy]) / g).astype(np.int64)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, [nx - 1, ny - 1])
    lists = [[] for _ in range(nx * ny)]
    for t in range(len(simp)):
        for i in range(lo[t, 0], hi[t, 0] + 1):
            for j in range(lo[t, 1], hi[t, 1] + 1):
                lists[i * ny + j].append(t)
    return (np.r_[0, np.cumsum([len(c) for c in lists])].astype(np.int64),
            np.array([t for c in lists for t in c], np.int64))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("bin_side", [None, 0.25, 1.0])
def test_tin_bins_of_the_triangles_give_the_bounding_boxes_values(seed, bin_side):
    """The bins hold only the triangles that meet them: every value (vertices, edge
    midpoints, points just outside the hull, slivers of a grid of vertices) is the one
    the bins of the bounding boxes give, bit for bit, and fewer triangles are tried."""
    g = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), -1).reshape(-1, 2)
    P = np.r_[g.uniform(0, 30, (400, 2)), grid * 0.5 + 31, [[45.0, 45.0], [45.0, 10.0]]]
    P = np.unique(np.round(P, 3), axis=0)
    V = g.normal(size=len(P))
    f = _surface.TinSurface(P, V, cell=2.0, bin_side=bin_side)
    ox, oy, side, nx, ny, indptr, tri, simp, tf = f._tri
    mid = (P[simp] + P[np.roll(simp, 1, axis=1)]) / 2
    q = np.r_[P, mid.reshape(-1, 2), g.uniform(-1, 47, (20000, 2)),
              P[g.choice(len(P), 100)] + g.normal(0, 1e-9, (100, 2))]
    ref_ptr, ref_tri = _box_bins(P, simp, ox, oy, side, nx, ny)
    for blocks in (1, 3):  # the same lists whatever the blocks of triangles
        other = _surface_kernels.bin_triangles(P, simp, ox, oy, side, nx, ny, blocks)
        np.testing.assert_array_equal(other[0], indptr)
        np.testing.assert_array_equal(other[1], tri)
    assert tri.size < 0.8 * ref_tri.size
    for c in range(nx * ny):  # each bin's list: a subset of its boxes', in their order
        got = tri[indptr[c]:indptr[c + 1]]
        assert np.isin(got, ref_tri[ref_ptr[c]:ref_ptr[c + 1]]).all()
        assert (np.diff(got) > 0).all()
    ref, got = np.empty(len(q)), np.empty(len(q))
    _surface._tin_eval(q, ox, oy, side, nx, ny, ref_ptr, ref_tri, simp, tf, f.V,
                       _surface._EPS, _surface._EPS_BROAD, ref)
    _surface._tin_eval(q, ox, oy, side, nx, ny, indptr, tri, simp, tf, f.V,
                       _surface._EPS, _surface._EPS_BROAD, got)
    assert np.isfinite(ref[:len(P)]).all()
    np.testing.assert_array_equal(got, ref)  # NaN (outside) where NaN


def test_tin_degenerate_vertices_fall_back_to_nearest():
    P = np.c_[np.arange(5.0), np.arange(5.0)]  # collinear: no triangle
    f = _surface.TinSurface(P, np.arange(5.0), cell=1.0)
    assert f(np.array([[0.1, 0.0], [3.9, 4.2]])).tolist() == [0.0, 4.0]
    f = _surface.TinSurface(P[:2], np.arange(2.0), cell=1.0)
    assert f(np.array([[0.9, 0.8]])).tolist() == [1.0]


@pytest.mark.parametrize("which", ["min", "median"])
def test_cell_pick_equals_lexsort(rng, which):
    xy = rng.uniform(0, 60, (20000, 2))
    z = np.round(rng.normal(size=20000), 1)  # many ties: broken by input order
    key = _surface.cell_keys(xy, 4.0)
    o = np.lexsort((z, key))
    ks = key[o]
    b = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True])
    ref = o[b[:-1]] if which == "min" else o[(b[:-1] + b[1:] - 1) // 2]
    assert np.array_equal(_surface._cell_pick(xy, z, 4.0, which), ref)
    # on a reordered cloud, ties go to the lower rank (input index): the same points
    perm = rng.permutation(z.size)
    got = _surface._cell_pick(xy[perm], z[perm], 4.0, which, rank=perm)
    assert np.array_equal(np.sort(perm[got]), np.sort(ref))
    far = xy * [1, 1e4]  # sparse cells over a huge box: the argsort path
    key = _surface.cell_keys(far, 4.0)
    assert _surface._cell_pick(far, z, 4.0, which).size == np.unique(key).size


@pytest.mark.parametrize("which", ["min", "median"])
def test_cell_pick_of_rows_equals_pick_of_their_copy(rng, which, monkeypatch):
    """The pick among the rows `where` (keys, counting sort and cells in parallel blocks)
    is the serial pick of the copy ``xy[where]``, whatever the blocks."""
    from lidarstat.classify import _surface_kernels as k

    n = 30000
    xy = rng.uniform(0, 80, (n, 2))
    z = np.round(rng.normal(size=n), 1)  # many ties: broken by rank
    rank = rng.permutation(n)
    where = np.flatnonzero(rng.uniform(size=n) < 0.7)
    ref = where[_surface._cell_pick(xy[where], z[where], 4.0, which, rank[where])]
    assert np.array_equal(_surface._cell_pick(xy, z, 4.0, which, rank, where), ref)
    monkeypatch.setattr(_surface, "_PARALLEL_PICK", 0)  # the parallel path at any size
    assert np.array_equal(_surface._cell_pick(xy, z, 4.0, which, rank, where), ref)
    key = _surface.cell_keys(xy[where], 4.0)
    order, starts = _surface.cell_order(key)
    for blocks in (1, 3, 7):  # uneven blocks, more than the threads
        got = np.empty(where.size, np.int64)
        nkeys = k.cell_keys_where(xy, where, 4.0, blocks, got)
        assert np.array_equal(got, key) and nkeys == key.max() + 1
        rows, st = k.order_where(key, nkeys, where, blocks)
        assert np.array_equal(rows, where[order]) and np.array_equal(st, starts)
        assert np.array_equal(k.pick_cells(rows, z, st, which == "median", rank, blocks), ref)
    far = xy * [1, 1e4]  # sparse cells over a huge box: the argsort path
    ref = where[_surface._cell_pick(far[where], z[where], 4.0, which, rank[where])]
    assert np.array_equal(_surface._cell_pick(far, z, 4.0, which, rank, where), ref)
    assert _surface._cell_pick(xy, z, 4.0, which, rank, where[:0]).size == 0


@pytest.mark.parametrize("n, w", [(10, 3), (11, 5), (3000, 31), (40000, 401)])
def test_smoothing_equals_convolution(rng, n, w):
    y = np.cumsum(rng.normal(size=n)) + 50.0
    y[rng.uniform(size=n) < 0.05] = np.nan
    np.testing.assert_allclose(_cycle._smooth(y, w), _convolve_smooth(y, w), rtol=1e-12,
                               atol=1e-12, equal_nan=True)


def test_classification_identical_to_scipy_surface(rng, monkeypatch):
    xyz, inten, nret, rnum, _ = _scene(rng)
    kw = dict(number_of_returns=nret, return_number=rnum, window=50)
    fast = moments(xyz, inten, **kw)
    monkeypatch.setattr(_moments_ground, "ground_surface", _scipy_surface)
    monkeypatch.setattr(_cycle, "_smooth", _convolve_smooth)
    ref = moments(xyz, inten, **kw)
    assert np.array_equal(fast.classification, ref.classification)
    assert np.array_equal(fast.cluster_id, ref.cluster_id)
    assert np.array_equal(fast.height, ref.height)
    assert [s.to_dict() for s in fast.steps] == [s.to_dict() for s in ref.steps]


def test_schedulers_give_identical_results(rng):
    pytest.importorskip("dask", reason="the dask scheduler needs dask")
    xyz, inten, nret, rnum, _ = _scene(rng, 6000)
    kw = dict(number_of_returns=nret, return_number=rnum, window=30, min_window=10)
    runs = [moments(xyz, inten, scheduler=s, workers=2, **kw)
            for s in ("sync", "threads", "dask")]
    for r in runs[1:]:
        assert np.array_equal(r.classification, runs[0].classification)
        assert np.array_equal(r.cluster_id, runs[0].cluster_id)
        assert [s.to_dict() for s in r.steps] == [s.to_dict() for s in runs[0].steps]
        assert r.windows == runs[0].windows
    # cluster ids are unique per window: no id spans two root windows (the windows lie on
    # multiples of their side in the file's coordinates)
    key = np.floor(xyz[:, :2] / 30).astype(int) @ [100000, 1]
    for c in np.unique(runs[0].cluster_id):
        assert np.unique(key[runs[0].cluster_id == c]).size == 1
    assert len({t["window"] for t in runs[0].windows}) == len(runs[0].windows)


@pytest.mark.parametrize("seed", range(2))
def test_steps_beside_each_other_equal_the_steps_in_turn(seed):
    # workers > 1 builds the raised patches' graph beside the window passes and finds the
    # roads beside the building tests; workers=1 runs them in turn
    xyz, inten, nret, rnum, _ = _scene(np.random.default_rng(seed), 12000)
    kw = dict(number_of_returns=nret, return_number=rnum, window=30, min_window=10)
    one, two = (moments(xyz, inten, workers=w, **kw) for w in (1, 2))
    assert (one.classification == 11).any()  # a road step ran
    for k, v in one.to_fields().items():
        assert np.array_equal(v, two.to_fields()[k], equal_nan=v.dtype.kind == "f"), k
    for k, v in one.building_fields.items():
        assert np.array_equal(v, two.building_fields[k], equal_nan=v.dtype.kind == "f"), k
    assert [s.to_dict() for s in one.steps] == [s.to_dict() for s in two.steps]


def test_lengths_in_metres_whatever_the_file_unit(rng):
    """The same scene in feet with units=0.3048 gets the labels of the metre scene."""
    xyz, inten, nret, rnum, _ = _scene(rng, 8000)
    kw = dict(number_of_returns=nret, return_number=rnum, window=50)
    ref = moments(xyz, inten, **kw)
    ft = moments(xyz / 0.3048, inten, units=0.3048, **kw)
    assert (ft.classification == ref.classification).mean() > 0.998
    np.testing.assert_allclose(ft.height * 0.3048, ref.height, atol=1e-5)
    naive = moments(xyz / 0.3048, inten, **kw)  # windows 3.3 x too small
    assert (naive.classification != ref.classification).sum() > \
        5 * (ft.classification != ref.classification).sum()
    with pytest.raises(Exception, match="units"):
        moments(xyz, inten, units=0, window=50)


def test_low_outlier_and_road_cell_kernels_equal_lexsort(rng):
    from lidarstat.classify import _outliers, _roads

    ij = rng.integers(0, 30, (20000, 2))
    z = np.round(rng.normal(size=20000), 1)  # ties: the first in input order wins
    key = ij[:, 0] * 30 + ij[:, 1]
    o = np.lexsort((z, key))
    ks = key[o]
    first = o[np.r_[True, ks[1:] != ks[:-1]]]
    none = np.zeros(z.size, bool)
    z1, arg = _outliers._lowest_live(key, z, none, 900)
    assert np.array_equal(arg[key[first]], first)
    assert np.array_equal(z1[key[first]], z[first])
    assert (arg >= 0).sum() == first.size
    flagged = np.zeros(z.size, bool)  # flagged points are left out: the next lowest wins
    flagged[first] = True
    _, arg2 = _outliers._lowest_live(key, z, flagged, 900)
    live = np.flatnonzero(~flagged)
    o = live[np.lexsort((z[live], key[live]))]
    ks = key[o]
    assert np.array_equal(arg2[ks[np.r_[True, ks[1:] != ks[:-1]]]],
                          o[np.r_[True, ks[1:] != ks[:-1]]])
    xy = rng.uniform(0, 50, (20000, 2))
    v = np.round(rng.normal(100, 20, 20000))
    span = np.ptp(xy, axis=0)
    key = _surface.cell_keys(xy, np.sqrt(8 * span[0] * span[1] / 20000))
    o = np.lexsort((v, key))
    ks, vs = key[o], v[o]
    b = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1], True])
    ref = np.empty(v.size)
    ref[o] = np.repeat(0.5 * (vs[(b[:-1] + b[1:] - 1) // 2] + vs[(b[:-1] + b[1:]) // 2]),
                       np.diff(b))
    assert np.array_equal(_roads.cell_median(xy, v, points_per_cell=8), ref)


def test_window_order_changes_no_label(rng, monkeypatch):
    """Working in root-window order (contiguous windows) gives exactly the labels, heights,
    ids, windows and report steps of working in input order, on a cloud in random order
    with ties everywhere: centimetre coordinates, duplicated positions, low echoes."""
    xyz, inten, nret, rnum, _ = _scene(rng, 16000)
    xyz = np.round(xyz, 2)
    dup = rng.choice(len(xyz), 800, replace=False)  # same x, y, another z (two echoes)
    xyz = np.r_[xyz, xyz[dup] + [0, 0, 0.5]]
    inten, nret, rnum = (np.r_[a, a[dup]] for a in (inten, nret, rnum))
    xyz[rng.choice(len(xyz), 10, replace=False), 2] -= 4.0
    o = rng.permutation(len(xyz))
    xyz, inten, nret, rnum = xyz[o], inten[o], nret[o], rnum[o]
    kw = dict(number_of_returns=nret, return_number=rnum, window=42, min_window=10)
    fast = moments(xyz, inten, **kw)
    monkeypatch.setattr(_moments_windows, "window_order",
                        lambda roots: (np.arange(sum(t.points.size for t in roots)), roots))
    ref = moments(xyz, inten, **kw)
    assert fast.params["n_low_noise"] > 0
    for name in ("classification", "cluster_id", "height", "ground"):
        assert np.array_equal(getattr(fast, name), getattr(ref, name), equal_nan=True), name
    assert [s.to_dict() for s in fast.steps] == [s.to_dict() for s in ref.steps]
    assert fast.windows == ref.windows


def test_cell_keys_equal_the_numpy_expression(rng):
    """The compiled cell keys equal NumPy's ``floor((xy - origin) / cell)`` expression,
    with the default origin and a given one (UTM-sized and quantised coordinates)."""
    def ref(xy, cell, origin=None):
        o = xy.min(axis=0) if origin is None else np.asarray(origin, dtype=float)
        ij = np.floor((xy - o) / cell).astype(np.int64)
        return ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]

    for xy in (rng.uniform(0, 100, (20000, 2)), rng.uniform(4.5e5, 4.6e5, (20000, 2)),
               np.round(rng.uniform(0, 50, (20000, 2)), 1)):
        for cell in (0.1, 1.0, 3.7):
            assert np.array_equal(_surface.cell_keys(xy, cell), ref(xy, cell))
            o = xy.min(axis=0) + 3.3  # some points below the origin: negative indices
            assert np.array_equal(_surface.cell_keys(xy, cell, o), ref(xy, cell, o))


@pytest.mark.parametrize("seed", range(6))
def test_canonical_order_equals_lexsort(seed):
    from lidarstat.classify._moments_kernels import canonical_order

    g = np.random.default_rng(seed)
    n = int(g.integers(2, 6000))
    step = (1.0, 0.1, 0.001, 0.5, 2.0, 0.01)[seed]  # quantised: runs of equal x
    x = np.round(g.uniform(0, 20, n) / step) * step
    if seed == 4:
        x[: n // 2] = 7.0  # one long run: the merge path
    if seed == 1:  # negative values: the comparison sort instead of the radix sort of the bits
        x -= 10.0
    if seed == 5:  # -0.0 and 0.0 are one key (the bits of -0.0 are negative)
        x[: n // 3] = 0.0
        x[n // 3: n // 2] = -0.0
    y, z, w = (np.round(g.uniform(0, 3, n)) for _ in range(3))
    z[z == 0] = -0.0  # -0.0 and 0.0 are equal keys
    for inten in (w, None):
        keys = tuple(c for c in (inten, z, y, x) if c is not None)
        assert np.array_equal(canonical_order(x, y, z, inten), np.lexsort(keys))


@pytest.mark.parametrize("seed", range(3))
def test_canonical_order_in_blocks_of_runs_equals_lexsort(seed):
    # above _TIE_BLOCK points the runs of equal x are sorted in blocks of whole runs in
    # parallel: runs longer than a block, runs across the even split, one-point runs
    from lidarstat.classify._moments_kernels import _TIE_BLOCK, canonical_order

    g = np.random.default_rng(seed)
    n = 4 * _TIE_BLOCK + int(g.integers(1, _TIE_BLOCK))
    x = np.round(g.uniform(0, (3, 40, 5000)[seed], n))
    if seed == 0:
        x[: 2 * _TIE_BLOCK] = 1.0  # one run over two blocks' worth of points
    y, z = (np.round(g.uniform(0, 4, n)) for _ in range(2))
    w = g.integers(0, 3, n).astype(np.uint16)
    assert np.array_equal(canonical_order(x, y, z, w), np.lexsort((w, z, y, x)))
    assert np.array_equal(canonical_order(x, y, z), np.lexsort((z, y, x)))


def _low_outliers_reference(xy, z, *, points_per_cell=4.0, k=5.0, min_depth=0.5,
                            iterations=3):
    """The low-noise rule in plain NumPy: lexsort for the cell minima, np.partition for
    the second-lowest neighbour."""
    n = z.size
    out = np.zeros(n, bool)
    lo = xy.min(axis=0)
    span = np.maximum(xy.max(axis=0) - lo, 1e-9)
    cell = float(np.sqrt(points_per_cell * span[0] * span[1] / n))
    ij = np.floor((xy - lo) / cell).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    for _ in range(iterations):
        live = np.flatnonzero(~out)
        key = ij[live, 0] * shape[1] + ij[live, 1]
        o = np.lexsort((live, z[live], key))
        first = np.r_[True, key[o][1:] != key[o][:-1]]
        z1 = np.full(shape[0] * shape[1], np.inf)
        arg = np.full(shape[0] * shape[1], -1)
        z1[key[o][first]] = z[live][o][first]
        arg[key[o][first]] = live[o][first]
        z1, arg = z1.reshape(shape), arg.reshape(shape)
        p = np.pad(z1, 1, constant_values=np.inf)
        stack = np.stack([p[1 + dx:1 + dx + shape[0], 1 + dy:1 + dy + shape[1]]
                          for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy])
        ref = np.partition(stack, 1, axis=0)[1]
        ok = np.isfinite(z1) & np.isfinite(ref)
        if ok.sum() < 8:
            break
        gap = ref[ok] - z1[ok]
        med = np.median(gap)
        fence = max(med + k * 1.4826 * np.median(np.abs(gap - med)), min_depth)
        bad = gap > fence
        if not bad.any():
            break
        out[arg[ok][bad]] = True
    return out


@pytest.mark.parametrize("seed", range(6))
def test_low_outliers_equal_reference(seed):
    from lidarstat.classify import low_outliers

    g = np.random.default_rng(seed)
    n = int(g.integers(500, 8000))
    xy = g.uniform(0, g.uniform(20, 80), (n, 2))
    z = np.round(0.1 * xy[:, 0] + g.normal(0, 0.05, n), 2)  # ties among the lows
    low = g.choice(n, size=int(g.integers(1, 30)), replace=False)
    z[low] -= g.uniform(1, 8, low.size)
    z[low[: low.size // 2]] = z[low[0]]  # equal lows in one cell: the first index wins
    got = low_outliers(xy, z)
    assert np.array_equal(got, _low_outliers_reference(xy, z))
    assert got[low].mean() > 0.5
    pts = np.c_[xy, z]  # the first two columns of a cloud's coordinates, read in place
    assert np.array_equal(low_outliers(pts, pts[:, 2]), got)
    assert np.array_equal(low_outliers(pts[:, :2], z), got)


@pytest.mark.parametrize("seed", range(4))
def test_root_windows_equal_tile_grid(seed):
    """The root windows (compiled keys, counting sort) are the tiles of ``tile_grid`` with
    the grid anchored at 0: same order, keys, bounds, points and cores."""
    from lidarstat._shared._tiles import tile_grid

    g = np.random.default_rng(seed)
    n = int(g.integers(1, 30000))
    xy = np.round(g.uniform(0, g.uniform(1, 400), (n, 2)) + g.uniform(0, 100, 2), 2)
    size = (64.0, 10.0, 7.3, 1000.0)[seed]
    xyh = np.zeros((n, 3))
    xyh[:, :2] = xy
    perm_ref, ref = _moments_windows.window_order(tile_grid(xyh, size, anchor=(0.0, 0.0)))
    perm, got = _moments_windows.root_windows(xy, size)
    assert np.array_equal(perm, perm_ref) and len(got) == len(ref)
    for a, b in zip(got, ref):
        assert (a.key, a.bounds) == (b.key, b.bounds)
        assert np.array_equal(a.points, b.points) and np.array_equal(a.core, b.core)


@pytest.mark.parametrize("seed", range(3))
def test_ground_surface_on_rows_equals_the_copied_ground(seed):
    """`where` gives the surface of the ground's copies (ties in z included)."""
    g = np.random.default_rng(seed)
    xy = g.uniform(0, 40, (3000, 2))
    z = np.round(0.1 * xy[:, 0] + g.normal(0, 0.05, 3000), 2)  # many tied heights
    rank = g.permutation(3000)
    rows = np.flatnonzero(g.random(3000) < 0.7)
    for which in ("median", "min"):
        for r in (rank, None):
            a = _surface.ground_surface(xy, z, cell=4.0, which=which, rank=r, where=rows)
            b = _surface.ground_surface(xy[rows], z[rows], cell=4.0, which=which,
                                        rank=None if r is None else r[rows])
            q = g.uniform(-5, 45, (500, 2))
            assert np.array_equal(a(q), b(q))


@pytest.mark.parametrize("seed", range(4))
def test_in_place_row_kernels_equal_numpy_gathers(seed):
    from lidarstat.classify._moments import _permute_columns
    from lidarstat.classify._moments_kernels import compact_rows

    g = np.random.default_rng(seed)
    n = int(g.integers(1, 3000))
    a = g.normal(size=(n, 3))
    order = g.permutation(n)
    b = a.copy()
    _permute_columns(b, order)
    assert np.array_equal(b, a[order])
    keep = g.uniform(size=n) < 0.7
    c = a.copy()
    m = compact_rows(c, keep)
    assert m == keep.sum() and np.array_equal(c[:m], a[keep])


def test_overwrite_xyz_gives_the_same_fields(rng):
    """The work arrays in the caller's memory (and in the own copy of non-float input)
    change no field; low noise makes the in-place removal of rows run too."""
    xyz, inten, nret, rnum, _ = _scene(rng, 6000)
    xyz[:3, 2] -= 30.0  # three low-noise points
    kw = dict(number_of_returns=nret, return_number=rnum, window=50)
    ref = moments(xyz, inten, **kw)
    assert ref.params["n_low_noise"] >= 1
    own = xyz.copy()
    for got in (moments(own, inten, overwrite_xyz=True, **kw),
                moments(xyz.tolist(), inten, **kw)):
        for name, v in ref.to_fields().items():
            assert np.array_equal(got.to_fields()[name], v, equal_nan=True), name
    assert not np.array_equal(own, xyz)  # the memory was used


@pytest.mark.parametrize("seed", range(3))
def test_noise_fence_equals_the_sorted_key_reference(seed):
    from lidarstat.classify._terrain import noise_fence
    from lidarstat.classify._terrain_kernels import block_spread

    g = np.random.default_rng(seed)
    n = 5000
    xy = g.uniform(0, 60, (n, 2))
    h = np.round(g.normal(0, 0.05, n), 3)  # zeros: vertices, left out
    ground = g.uniform(size=n) < 0.8
    cell, fence, nx, ny = 2.0, 7.0, 30, 30
    key = np.floor(xy[:, 0] / cell).astype(np.int64) * ny + np.floor(xy[:, 1] / cell).astype(
        np.int64)
    src = ground & (h != 0)
    values = h[src][np.argsort(key[src], kind="stable")]
    offsets = np.r_[0, np.cumsum(np.bincount(key[src], minlength=nx * ny))]
    centre, spread = np.full(nx * ny, np.nan), np.full(nx * ny, np.nan)
    block_spread(offsets, values, nx, ny, np.unique(key[ground]), 64, 8, centre, spread)
    ref = centre[key] + fence * spread[key]
    ref[~np.isfinite(ref)] = np.inf
    got = noise_fence(xy, h, ground, cell=cell, fence=fence, min_points=64, max_radius=8)
    assert np.array_equal(got, ref)


@pytest.mark.parametrize("seed", range(4))
def test_raised_patch_copy_check_finds_every_copy(seed):
    from lidarstat.classify._continuity import _Grid2D
    from lidarstat.neighbors import find_duplicates

    g = np.random.default_rng(seed)
    n = 2000
    xy, z = np.round(g.uniform(0, 30, (n, 2)), 1), np.round(g.normal(size=n), 1)
    if seed % 2:
        xy[:3], z[:3] = xy[-3:], z[-3:]
    if seed == 2:  # -0.0 and 0.0 are one location
        xy[0], xy[1], z[1] = (-0.0, 5.0), (0.0, 5.0), z[0]
    ref = find_duplicates(np.c_[xy, z]).any
    rank = g.permutation(n)  # any order of the points inside a cell
    for cell in (0.7, 3.0):
        grid = _Grid2D(xy, cell, xy.min(axis=0), rank)
        assert grid.may_have_copies(z[grid.pos]) == ref  # cells of about 20 points
        assert not grid.points[:, 2].any()  # the 2-D kNN's z = 0 restored


@pytest.mark.parametrize("seed", range(4))
def test_cluster_bound_from_sorted_heights_equals_numpy_medians(seed):
    # the median read from the sorted kept heights (odd and even counts, ties) is
    # np.median's, so the bound is the same number
    from lidarstat.classify._moments_analysis import _cluster_bound

    g = np.random.default_rng(seed)
    for n in (7, 8, 9, 10, 101, 1000):
        v = np.round(g.normal(0, 0.05, n), 3 if seed % 2 else 6)
        med = np.median(v)
        ref = float(med + 3.0 * 1.4826 * np.median(np.abs(v - med))) if n >= 8 else -np.inf
        assert _cluster_bound(np.sort(v), 3.0) == ref


@pytest.mark.parametrize("seed", range(3))
def test_without_evidence_every_field_cut_and_deciding_test_is_the_same(seed):
    # evidence=False (the CLI without a report) leaves out the densities and the dip
    # test of each window's heights before its cut, which the report alone reads
    xyz, inten, nret, rnum, _ = _scene(np.random.default_rng(seed), 16000)
    kw = dict(number_of_returns=nret, return_number=rnum, window=50.0, min_window=12.5)
    a = moments(xyz, inten, **kw)
    b = moments(xyz, inten, evidence=False, **kw)
    for name, v in a.to_fields().items():
        assert np.array_equal(v, b.to_fields()[name], equal_nan=True), name
    assert a.windows == b.windows and a.params == b.params
    assert [s.choice.threshold for s in a.steps] == [s.choice.threshold for s in b.steps]
    assert all(s.density is not None for s in a.steps)
    # the road step's density decides its cut (the antimode): kept
    assert all((s.density is None) != (s.window == -1) for s in b.steps)
    window_dips = [s.dip for s in a.steps if s.population.startswith("heights")]
    assert window_dips and all(window_dips)
    assert not any(s.dip for s in b.steps if s.population.startswith("heights"))
    assert ([s.dip for s in a.steps if not s.population.startswith("heights")]
            == [s.dip for s in b.steps if not s.population.startswith("heights")])


@pytest.mark.parametrize("seed", range(4))
def test_block_spread_equals_numpy_medians_of_each_block(seed):
    # np.median and the median of the absolute deviations of each block: odd and even
    # counts, ties, borders, blocks widened to several cells' radius where the cells
    # are sparse
    from lidarstat.classify._terrain_kernels import block_spread

    g = np.random.default_rng(seed)
    nx, ny, min_points, max_radius = 23, 17, 40, 4
    n = 3000
    ij = np.c_[g.integers(0, nx, n), g.integers(0, ny, n)]
    dense = ij[:, 0] < nx // 2  # about 15 values a cell on one side, sparse on the other
    keep = dense | (g.uniform(size=n) < 0.15)
    ij = ij[keep]
    v = np.round(g.standard_t(3, ij.shape[0]), 2 if seed % 2 else 6)
    key = ij[:, 0] * ny + ij[:, 1]
    order = np.argsort(key, kind="stable")
    values = v[order]
    offsets = np.r_[0, np.cumsum(np.bincount(key, minlength=nx * ny))]
    cells = np.arange(nx * ny)
    centre, spread = np.full(nx * ny, -1.0), np.full(nx * ny, -1.0)
    block_spread(offsets, values, nx, ny, cells, min_points, max_radius, centre, spread)
    grid = [[v[key == a * ny + b] for b in range(ny)] for a in range(nx)]
    widened = 0
    for c in cells:
        i, j = divmod(int(c), ny)
        for w in range(1, max_radius + 1):
            blk = np.concatenate([grid[a][b] for a in range(max(0, i - w), min(nx, i + w + 1))
                                  for b in range(max(0, j - w), min(ny, j + w + 1))])
            if blk.size >= min_points:
                break
        widened += w > 1
        if blk.size < 3:
            assert np.isnan(centre[c]) and np.isnan(spread[c])
            continue
        m = np.median(blk)
        assert centre[c] == m
        assert spread[c] == 1.4826 * np.median(np.abs(blk - m))
    assert widened > 50


def _same_step(a, b):
    """Two MomentsStep records hold the same numbers (curves and density element-wise)."""
    assert (a.window, a.step, a.population, a.category, a.n, a.dip) == (
        b.window, b.step, b.population, b.category, b.n, b.dip)
    assert a.choice == b.choice
    assert a.curves.keys() == b.curves.keys()
    for k in a.curves:
        assert np.array_equal(a.curves[k], b.curves[k], equal_nan=True), k
    assert (a.density is None) == (b.density is None)
    if a.density is not None:
        assert np.array_equal(a.density.grid, b.density.grid)
        assert np.array_equal(a.density.density, b.density.density)
        assert a.density.bandwidth == b.density.bandwidth


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("evidence", [True, False])
def test_clusters_from_the_cuts_first_analysis_equal_their_own(seed, evidence):
    # the paper's first step on a window's heights repeats the window cut's analysis of
    # the same heights: taken from the cut, its dip test, cycle and record are the ones
    # the step computes itself, and so are every later step and every label
    from lidarstat.classify._cycle import ElevationRule
    from lidarstat.classify._moments_analysis import paper_clusters, progressive_cut
    from lidarstat.classify._moments_options import MomentsMethod, MomentsOptions

    g = np.random.default_rng(seed)
    n = 6000 + 3000 * seed
    xy = g.uniform(0, 64, (n, 2))
    obj = g.uniform(size=n) < 0.3
    h = np.round(np.where(obj, g.uniform(2, 15, n), g.normal(0, 0.1, n)), 3)
    inten = np.round(np.where(g.uniform(size=n) < 0.4, g.normal(40, 5, n),
                              g.normal(120, 10, n)))
    p = MomentsOptions(alpha=0.05, min_points=10, smoothing=0.01, cycle=None,
                       bandwidth="silverman", method=MomentsMethod.MOMENTS,
                       elevation_rule=ElevationRule.SYMMETRY, window=64.0, min_window=16.0,
                       ground_spread=3.0, evidence=evidence)
    reused = 0
    for cats in ({"elevation": h, "intensity": inten}, {"elevation": h}):
        own = []
        lab_a, next_a = paper_clusters(cats, p, -1, own, 1)
        first = {}
        progressive_cut(xy, h, np.arange(n), p.window, np.inf, p, "", [], [], True, first)
        taken = []
        lab_b, next_b = paper_clusters(cats, p, -1, taken, 1, first)
        assert np.array_equal(lab_a, lab_b) and next_a == next_b
        assert len(own) == len(taken)
        for a, b in zip(own, taken):
            _same_step(a, b)
        reused += taken[0].choice is first["choice"]
    assert reused >= 1  # the elevation analysis was taken, not recomputed


def _symmetry_reference(xs, *, min_points, smoothing, curve_step):
    """The symmetry rule from every cycle's curves (choose_cycle, thin_curves)."""
    from lidarstat.classify._moments_result import thin_curves
    from lidarstat.stats import sequential_moments

    sm = sequential_moments(xs, min_points=max(2, min(4, xs.size)), sorted_values=xs)
    ch = _cycle.choose_cycle(sm, "elevation", min_points=min_points, smoothing=smoothing,
                             elevation_rule="symmetry")
    return ch, (thin_curves(sm) if curve_step else None)


@pytest.mark.parametrize("seed", range(6))
def test_symmetry_cycle_equals_the_rule_on_every_cycles_curves(seed):
    # the cut and the thinned curves from the prefix sums are the choice and the curves
    # of the whole sequential analysis, number for number (ties, constant values, a
    # symmetric cloud, too few values, the cut at the last cycle tested)
    from lidarstat.classify._moments_result import curve_step

    g = np.random.default_rng(seed)
    for n in (2, 5, 24, 25, 300, 5000):
        for kind in ("bimodal", "ties", "constant", "normal", "skewed"):
            x = {"bimodal": lambda: np.r_[g.normal(0, 0.2, n), g.normal(6, 0.5, n // 4)],
                 "ties": lambda: np.round(g.normal(0, 0.3, n), 1),
                 "constant": lambda: np.full(n, 1.5),
                 "normal": lambda: g.normal(3, 1, n),
                 "skewed": lambda: g.exponential(1, n)}[kind]()
            xs = np.sort(x)
            m = xs.size - max(2, min(4, xs.size)) + 1
            for step in (0, curve_step(m)):
                a, ca = _cycle.symmetry_cycle(xs, min_points=10, smoothing=0.01,
                                              curve_step=step)
                b, cb = _symmetry_reference(xs, min_points=10, smoothing=0.01,
                                            curve_step=step)
                assert repr(a) == repr(b), (n, kind)  # NaN evidence compares by repr
                if step:
                    for k in cb:
                        assert ca[k].dtype == cb[k].dtype, k
                        assert np.array_equal(ca[k], cb[k], equal_nan=True), (n, kind, k)


@pytest.mark.parametrize("seed", range(3))
def test_classification_identical_with_the_rule_on_every_cycles_curves(seed, monkeypatch):
    # moments with the cuts from the prefix sums equals moments with every cycle's curves:
    # fields, cuts, windows, recorded choices and curves
    from lidarstat.classify import _moments_analysis

    xyz, inten, nret, rnum, _ = _scene(np.random.default_rng(seed), 16000)
    kw = dict(number_of_returns=nret, return_number=rnum, window=50.0, min_window=12.5)
    a = moments(xyz, inten, **kw)
    monkeypatch.setattr(_moments_analysis, "symmetry_cycle", _symmetry_reference)
    b = moments(xyz, inten, **kw)
    for name, v in a.to_fields().items():
        assert np.array_equal(v, b.to_fields()[name], equal_nan=True), name
    assert a.windows == b.windows
    assert len(a.steps) == len(b.steps)
    for s, t in zip(a.steps, b.steps):
        assert repr(s.choice) == repr(t.choice)
        for k in s.curves:
            assert np.array_equal(s.curves[k], t.curves[k], equal_nan=True), k


@pytest.mark.parametrize("seed", range(4))
def test_sorted_mad_equals_numpy_median_of_distances(seed):
    # the merge of the two runs of distances reads np.median's middle one or two
    from lidarstat.classify._moments_kernels import sorted_mad

    g = np.random.default_rng(seed)
    for n in (1, 2, 3, 8, 9, 100, 1001):
        for decimals in (0, 2, 6):
            xs = np.sort(np.round(g.normal(g.uniform(-3, 3), 1.0, n), decimals))
            middle = np.mean(xs[(n - 1) // 2: n // 2 + 1])
            for med in (middle, xs[0] - 1.0, xs[-1] + 0.5, float(g.uniform(xs[0], xs[-1]))):
                ref = np.median(np.abs(xs - med))
                assert np.float64(sorted_mad(xs, float(med))).tobytes() == ref.tobytes()
