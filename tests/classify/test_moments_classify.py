"""Moments classification: cycle choice, synthetic scene against truth, bad input, ISPRS."""

import numpy as np
import pytest
from conftest import shared_file

from lidarstat.classify import (ASPRS, BUILDING_FIELDS, choose_cycle, filter_errors, low_outliers,
                                moments)
from lidarstat.errors import InvalidParameterError, InvalidPointsError, LidarstatWarning
from lidarstat.stats import sequential_moments


def _scene(rng, n=12000):
    """Sloped terrain, a dark road, two flat roofs, a tree with several returns."""
    xy = rng.uniform(0, 100, (n, 2))
    z = 4.5e6 + 0.08 * xy[:, 0] - 0.03 * xy[:, 1] + rng.normal(0, 0.05, n)
    truth = np.full(n, ASPRS["ground"])
    inten = rng.normal(160, 12, n)
    road = np.abs(xy[:, 1] - 20) < 4
    truth[road] = ASPRS["road"]
    inten[road] = rng.normal(60, 8, road.sum())
    nret = np.ones(n, int)
    rnum = np.ones(n, int)
    for cx, cy, h in [(30, 60, 7.0), (70, 70, 10.0)]:
        b = (np.abs(xy[:, 0] - cx) < 9) & (np.abs(xy[:, 1] - cy) < 7)
        z[b] += h
        truth[b] = ASPRS["building"]
        inten[b] = rng.normal(110, 10, b.sum())
    tree = np.hypot(xy[:, 0] - 80, xy[:, 1] - 35) < 5
    first = tree & (rng.uniform(size=n) < 0.6)
    z[first] += rng.uniform(3, 9, first.sum())
    truth[first] = ASPRS["high_vegetation"]
    nret[tree] = 2
    rnum[first] = 1
    rnum[tree & ~first] = 2
    return np.c_[xy, z], inten, nret, rnum, truth


def test_cycle_choice_finds_the_cluster_boundary(rng):
    z = np.r_[rng.normal(0, 0.2, 3000), rng.normal(8, 0.5, 600)]
    for rule in ("plateau", "symmetry"):
        ch = choose_cycle(sequential_moments(z), "elevation", elevation_rule=rule)
        assert 560 <= ch.cycle <= 720, rule
    i = np.r_[rng.normal(50, 5, 3000), rng.normal(120, 10, 1500)]
    ch = choose_cycle(sequential_moments(i), "intensity")
    assert 70 < ch.threshold < 110
    assert choose_cycle(sequential_moments(i), "intensity", cycle=5).cycle == 5


def test_synthetic_scene_against_truth(rng):
    xyz, inten, nret, rnum, truth = _scene(rng)
    res = moments(xyz, inten, number_of_returns=nret, return_number=rnum, window=50)
    tg = np.isin(truth, (2, 11))
    e = filter_errors(res.ground, tg)
    assert e.total < 0.005 and e.kappa > 0.95  # measured 0.0001 / 0.999
    bld = truth == ASPRS["building"]
    assert (res.classification[bld] == ASPRS["building"]).mean() > 0.9
    road = truth == ASPRS["road"]
    assert (res.classification[road] == ASPRS["road"]).mean() > 0.8
    assert (res.classification[truth == 2] == ASPRS["road"]).mean() < 0.05
    veg = truth == ASPRS["high_vegetation"]
    assert np.isin(res.classification[veg], (3, 4, 5)).mean() > 0.8
    assert res.cluster_id.min() >= 1 and len(res.steps) > 0


def test_skewness_balancing_baseline_runs(rng):
    xyz, inten, *_ , truth = _scene(rng, 6000)
    res = moments(xyz, inten, method="skewness-balancing", window=50)
    e = filter_errors(res.ground, np.isin(truth, (2, 11)))
    assert e.total < 0.1


def test_no_intensity_warns_and_runs(rng):
    xyz, *_ = _scene(rng, 3000)
    with pytest.warns(LidarstatWarning, match="intensity"):
        res = moments(xyz, None, window=50)
    assert ASPRS["road"] not in res.classification


@pytest.mark.parametrize("bad, err", [
    (np.zeros((0, 3)), InvalidPointsError),
    (np.array([[0, 0, np.nan]] * 20), InvalidPointsError),
])
def test_bad_points(bad, err):
    with pytest.raises(err):
        moments(bad)


def test_bad_parameters(rng):
    xyz = rng.normal(size=(100, 3))
    with pytest.raises(InvalidParameterError):
        moments(xyz, method="nope")
    with pytest.raises(InvalidParameterError):
        moments(xyz, np.ones(5))


def test_input_not_modified(rng):
    xyz, inten, *_ = _scene(rng, 3000)
    a, b = xyz.copy(), inten.copy()
    moments(xyz, inten, window=50)
    assert np.array_equal(a, xyz) and np.array_equal(b, inten)


@pytest.mark.parametrize("sample, bound", [("samp21", 0.075), ("samp31", 0.03)])
def test_isprs_sample_error_bound(sample, bound):
    """Default parameters (no tuning per sample) against the manual ISPRS reference.

    Measured: samp21 6.69 %, samp31 1.95 % total error
    (benchmarks/results_isprs_moments.json).
    """
    from lidarstat.io import read

    c = read(shared_file(f"isprs_filtertest/joined/{sample}_ref_intensity.laz"))
    res = moments(c.xyz, c["intensity"])
    e = filter_errors(res.ground, np.asarray(c["classification"]) == 2)
    assert e.total < bound


def test_low_outliers_flags_isolated_low_points_only(rng):
    """Single and paired echoes 1.5-8 m under a sloped, undulating terrain with a walled
    block: every one is flagged, no terrain or roof point is (the fence is k = 5 MADs)."""
    n = 20000
    xy = rng.uniform(0, 120, (n, 2))
    z = (50 + 0.06 * xy[:, 0] + 0.6 * np.sin(xy[:, 1] / 9) + rng.normal(0, 0.05, n))
    block = (np.abs(xy[:, 0] - 60) < 10) & (np.abs(xy[:, 1] - 60) < 15)
    z[block] += 8
    idx = rng.choice(np.flatnonzero(~block), 40, replace=False)
    z[idx] -= rng.uniform(1.5, 8, idx.size)
    pair = idx[:10]  # a second echo beside each of ten outliers
    xy2 = xy[pair] + rng.normal(0, 0.2, (10, 2))
    z2 = z[pair] + rng.normal(0, 0.1, 10)
    xy, z = np.r_[xy, xy2], np.r_[z, z2]
    truth = np.zeros(z.size, bool)
    truth[idx] = True
    truth[n:] = True
    before = z.copy()
    flagged = low_outliers(xy, z)
    assert np.array_equal(flagged, truth)
    assert np.array_equal(z, before)


def test_als_town_against_truth():
    """The synthetic town (sloped terrain, asphalt roads with their own reflectance,
    gable/hip/flat roofs, trees with several returns, cars, noise) scored against its
    exact ASPRS classes. Measured on this scene (100 x 80 m, 4 pulses/m2, rng 0):
    ground/object total 0.83 %, kappa 0.950; road precision 0.928 / recall 0.971;
    building 0.968 / 0.982; low noise 164 of 164 flagged."""
    from lidarstat.segment import binary_scores
    from lidarstat.synth import make_als_town

    c = make_als_town(extent=(100, 80), density=4, rng=0)
    a = c.attributes
    truth = a["classification"].astype(int)
    res = moments(c.xyz, a["intensity"], number_of_returns=a["number_of_returns"],
                           return_number=a["return_number"])
    cls = res.classification.astype(int)
    scored = truth != 7
    e = filter_errors(res.ground[scored], np.isin(truth[scored], (2, 11)))
    assert e.total < 0.012 and e.kappa > 0.93
    road = binary_scores(cls == 11, truth == 11)
    assert road["precision"] > 0.9 and road["recall"] > 0.93
    bld = binary_scores(cls == 6, truth == 6)
    assert bld["precision"] > 0.93 and bld["recall"] > 0.95
    veg = np.isin(truth, (3, 4, 5))
    assert np.isin(cls[veg], (3, 4, 5)).mean() > 0.85
    low = (truth == 7) & (c.fields["height_above_ground"] < 0)
    assert (cls[low] == ASPRS["low_noise"]).all()
    assert (cls[~low] != ASPRS["low_noise"]).mean() > 0.999


def test_road_cut_between_the_modes_and_none_when_unimodal(rng):
    """Darker cluster 30 % of the ground: the cut lies between the modes and splits the
    clusters with under 2 % error; a unimodal ground gives no road; the paper's
    kurtosis-peak rule is available as an option."""
    from lidarstat.classify._roads import road_cut

    road = rng.normal(30, 3, 3000)
    land = rng.normal(60, 6, 7000)
    v = np.r_[road, land]
    ch, sm, de, dip = road_cut(v)
    assert ch.rule == "antimode" and dip["multimodal"]
    err = ((road > ch.threshold).sum() + (land <= ch.threshold).sum()) / v.size
    assert err < 0.02
    assert ch.cycle == (v > ch.threshold).sum()
    ch2, *_ = road_cut(v, rule="kurtosis-peak")
    assert ch2.rule in ("kurtosis-peak", "none")
    ch3, *_ = road_cut(rng.normal(60, 6, 10000))
    assert ch3.cycle is None
    ch4, *_ = road_cut(np.r_[rng.normal(30, 3, 100), rng.normal(60, 6, 9900)])
    assert ch4.cycle is None  # 1 % darker: below min_fraction, no road cluster


def test_raised_patches_roof_wider_than_the_opening_but_not_a_terrace(rng):
    """A 40 x 40 m flat roof (twice the 20 m opening window) is a raised patch and comes
    out as building; a 3 m terrace joined to the terrain below by a ramp is not raised
    and stays ground."""
    from lidarstat.classify._continuity import raised_patches

    n = 16000
    xy = rng.uniform(0, 120, (n, 2))
    x, y = xy[:, 0], xy[:, 1]
    step = np.where(y < 15, np.clip((x - 74) / 8, 0, 1), (x > 80).astype(float))  # ramp
    z = 20 + 0.03 * y + 3.0 * step + rng.normal(0, 0.04, n)
    roof = (np.abs(xy[:, 0] - 35) < 20) & (np.abs(xy[:, 1] - 60) < 20)
    z[roof] += 6
    r = raised_patches(xy, z)
    assert r[roof].mean() > 0.98 and r[~roof].mean() < 0.002
    xyz = np.c_[xy, z]
    on = moments(xyz, rng.normal(100, 10, n), window=60)
    assert (on.classification[roof] == ASPRS["building"]).mean() > 0.95
    assert on.ground[~roof].mean() > 0.97


def _raised_patches_scipy(xy, z, k=8, step=0.3, slope=1.0, above_fraction=0.95,
                          min_points=10):
    """Reference: the former scipy implementation (COO graph + connected_components)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = z.size
    kk = min(k + 1, n)
    d, nb = cKDTree(xy).query(xy, k=kk)
    i = np.repeat(np.arange(n), kk - 1)
    j = nb[:, 1:].ravel()
    dz = z[j] - z[i]
    ok = np.abs(dz) <= step + slope * d[:, 1:].ravel()
    g = coo_matrix((np.ones(ok.sum(), np.int8), (i[ok], j[ok])), shape=(n, n))
    ncomp, lab = connected_components(g, directed=False)
    ci, cj, cup = i[~ok], j[~ok], dz[~ok] < 0
    other = lab[ci] != lab[cj]
    li = lab[ci[other]]
    n_above = np.bincount(li[cup[other]], minlength=ncomp)
    n_step = np.bincount(li, minlength=ncomp)
    size = np.bincount(lab, minlength=ncomp)
    raised = (n_step > 0) & (n_above >= above_fraction * n_step) & (size >= min_points)
    raised[np.argmax(size)] = False
    return raised[lab]


@pytest.mark.parametrize("layout", ["uniform", "clustered"])
def test_raised_patches_grid_knn_union_find_equals_scipy_components(rng, layout):
    """The grid kNN + Numba union-find (chunked, in grid order) gives exactly the raised
    points of the former cKDTree query + scipy connected components: on a uniform cloud,
    and on one whose density varies 40-fold with an empty hole (the grid search must
    widen its block of cells there)."""
    from lidarstat.classify._continuity import raised_patches

    n = 30_000
    if layout == "uniform":
        xy = rng.uniform(0, 300, (n, 2))
    else:
        dense = rng.uniform(0, 60, (n // 2, 2)) + [120, 120]
        sparse = rng.uniform(0, 300, (n, 2))
        sparse = sparse[np.hypot(*(sparse - [60, 220]).T) > 40][: n - n // 2]
        xy = np.r_[dense, sparse]
        xy = xy[rng.permutation(len(xy))]
        n = len(xy)
    z = 0.1 * xy[:, 0] + rng.normal(0, 0.05, n)
    cells = np.floor(xy / 30).astype(int)
    roof = ((xy % 30) > 8).all(axis=1) & ((cells.sum(axis=1) % 3) == 0)
    z[roof] += (3 + (7 * cells[:, 0] + 3 * cells[:, 1]) % 9)[roof]  # one height a roof
    z[rng.random(n) < 0.002] -= 5  # isolated low echoes: cut edges everywhere
    ref = _raised_patches_scipy(xy, z)
    got = raised_patches(xy, z, chunk=7_001)
    assert ref.sum() > 0.05 * n
    assert np.array_equal(got, ref)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_patch_graph_is_the_exact_knn_ties_to_the_lower_position(seed):
    """Every point's neighbours in the patch graph are its k + 1 nearest in plan, ordered
    by (distance, sorted position), without itself (else without the farthest), and the
    smooth flags follow: against brute force on a lattice (equal distances everywhere),
    a sparse field beside it (blocks widened) and locations held by 12 points each."""
    from lidarstat.classify._continuity import _knn_smooth, _patch_grid

    g = np.random.default_rng(seed)
    lattice = np.round(g.uniform(0, 12, (1800, 2)) / 0.25) * 0.25
    sparse = g.uniform(0, 300, (150, 2)) + [20, 0]
    stacks = np.repeat(g.uniform(0, 12, (25, 2)), 12, axis=0)
    xy = np.r_[lattice, sparse, stacks]
    n, k, step, slope = len(xy), 8, 0.3, 1.0
    z = 0.05 * xy[:, 0] + g.normal(0, 0.2, n)
    grid, cell = _patch_grid(xy, k, g.permutation(n))
    zs = z[grid.pos]
    nbr = np.empty((n, k), np.int32)
    smooth = np.empty((n, k), np.bool_)
    _knn_smooth(0, grid.cell_keys.size, grid.points, zs, grid.cell_keys, grid.cell_start,
                grid.dims, cell, k, cell, step, slope, nbr, smooth)
    p = grid.points[:, :2]
    d2 = (p[None, :, 0] - p[:, None, 0]) ** 2 + (p[None, :, 1] - p[:, None, 1]) ** 2
    pos = np.arange(n)
    ties = 0
    for i in range(n):
        near = np.lexsort((pos, d2[i]))[:k + 1]
        want = near[near != i] if (near == i).any() else near[:k]
        o = np.argsort(nbr[i])
        assert np.array_equal(nbr[i][o], np.sort(want))
        flags = np.abs(zs[nbr[i]] - zs[i]) <= step + slope * np.sqrt(d2[i, nbr[i]])
        assert np.array_equal(smooth[i], flags)
        ties += d2[i, near[-1]] == np.sort(d2[i])[k + 1]  # the (k+1)-th distance is shared
    assert ties > 0.2 * n  # the tie rule decided many rows


def test_raised_patches_of_a_reordered_cloud_with_ranks(rng):
    """A reordered cloud with its input indices as `rank` gives the raised points of the
    cloud in input order (positions on a half-metre lattice: equal distances everywhere)."""
    from lidarstat.classify._continuity import raised_patches

    n = 20000
    xy = np.round(rng.uniform(0, 100, (n, 2)) / 0.5) * 0.5
    z = 0.1 * xy[:, 0] + rng.normal(0, 0.05, n) + np.where(rng.random(n) < 0.05, 0.6, 0)
    cells = np.floor(xy / 20).astype(int)
    roof = ((xy % 20) > 6).all(axis=1) & ((cells.sum(axis=1) % 2) == 0)
    z[roof] += 3
    ref = raised_patches(xy, z)
    perm = rng.permutation(n)
    got = raised_patches(xy[perm], z[perm], rank=perm)
    assert ref[roof].mean() > 0.9
    assert np.array_equal(got, ref[perm])


def test_deprecated_names_still_work_and_warn(rng):
    """classify_moments, tile_size, min_tile_size and min_cluster are the deprecated
    spellings of moments, window, min_window and min_points: same result, and a
    LidarstatDeprecationWarning."""
    from lidarstat.classify import classify_moments
    from lidarstat.errors import LidarstatDeprecationWarning

    xyz, inten, *_ = _scene(rng, 4000)
    ref = moments(xyz, inten, window=50, min_window=20, min_points=12)
    with pytest.warns(LidarstatDeprecationWarning, match="classify_moments"):
        a = classify_moments(xyz, inten, window=50, min_window=20, min_points=12)
    with pytest.warns(LidarstatDeprecationWarning) as rec:
        b = moments(xyz, inten, tile_size=50, min_tile_size=20, min_cluster=12)
    text = " ".join(str(w.message) for w in rec)
    for old, new in (("tile_size", "window"), ("min_tile_size", "min_window"),
                     ("min_cluster", "min_points")):
        assert f"{old} is deprecated; use {new}" in text
    for r in (a, b):
        assert np.array_equal(r.classification, ref.classification)
        assert np.array_equal(r.cluster_id, ref.cluster_id)
    with pytest.warns(LidarstatDeprecationWarning, match="windows"):
        assert ref.tiles == ref.windows
    with pytest.raises(InvalidParameterError, match="window only"):
        moments(xyz, inten, window=50, tile_size=50)


def test_removed_cut_interpolation_is_refused(rng):
    xyz, inten, *_ = _scene(rng, 2000)
    with pytest.raises(TypeError, match="cut_interpolation"):
        moments(xyz, inten, cut_interpolation=False)


def test_options_take_the_enum_or_its_string(rng):
    from lidarstat.classify import ElevationRule, MomentsMethod, RoadRule

    xyz, inten, *_ = _scene(rng, 4000)
    a = moments(xyz, inten, window=50, method="skewness-balancing", elevation_rule="plateau",
                road_rule="kurtosis-peak")
    b = moments(xyz, inten, window=50, method=MomentsMethod.SKEWNESS_BALANCING,
                elevation_rule=ElevationRule.PLATEAU, road_rule=RoadRule.KURTOSIS_PEAK)
    assert np.array_equal(a.classification, b.classification)
    assert a.params == b.params and a.params["method"] == "skewness-balancing"
    assert type(a.params["road_rule"]) is str  # plain strings in the summary JSON
    for name in ("elevation_rule", "road_rule", "method"):
        with pytest.raises(InvalidParameterError, match=f"'{name}' parameter of moments"):
            moments(xyz, inten, **{name: "nope"})


def test_seed_of_the_dip_tests(rng):
    """rng seeds the dip tests (subsample, dequantisation): the same seed gives the same
    result, a Generator gives one seed for all tests, a negative seed is refused."""
    xyz, inten, *_ = _scene(rng, 4000)
    inten = np.round(inten)  # ties: the dip test dequantises with its generator
    a = moments(xyz, inten, window=50, rng=7)
    b = moments(xyz, inten, window=50, rng=7)
    assert np.array_equal(a.classification, b.classification) and a.params["rng"] == 7
    assert [s.to_dict() for s in a.steps] == [s.to_dict() for s in b.steps]
    d = moments(xyz, inten, window=50, rng=8)
    assert [s.dip for s in a.steps] != [s.dip for s in d.steps]  # the seed reaches the tests
    c = moments(xyz, inten, window=50, rng=np.random.default_rng(1))
    assert isinstance(c.params["rng"], int)
    with pytest.raises(InvalidParameterError, match="rng"):
        moments(xyz, inten, rng=-1)


def test_result_shape(rng):
    """to_fields (written per point), summary (terminal text), params (the values used)."""
    xyz, inten, nret, rnum, _ = _scene(rng, 4000)
    res = moments(xyz, inten, number_of_returns=nret, return_number=rnum, window=50)
    f = res.to_fields()
    assert set(f) == {"classification", "cluster_id", *BUILDING_FIELDS}
    assert all(v.shape == (len(xyz),) for v in f.values())
    text = res.summary()
    assert text.startswith(f"{len(xyz)} points") and "ground" in text
    assert "analysis windows" in text
    p = res.params
    assert p["window"] == 50 and p["min_window"] == 16 and p["min_points"] == 10
    assert p["rng"] == 0 and p["returns"] and p["intensity"]
    assert all("window" in w for w in res.windows)


def test_cycle_and_road_helpers_renamed_min_points(rng):
    """choose_cycle and road_cut take min_points; min_cluster still works and warns."""
    from lidarstat.classify._roads import road_cut
    from lidarstat.errors import LidarstatDeprecationWarning

    sm = sequential_moments(np.r_[rng.normal(0, 0.2, 3000), rng.normal(8, 0.5, 600)])
    ref = choose_cycle(sm, "elevation", min_points=50)
    with pytest.warns(LidarstatDeprecationWarning, match="min_cluster"):
        old = choose_cycle(sm, "elevation", min_cluster=50)
    assert old == ref and ref.evidence["min_points"] == 50
    v = np.r_[rng.normal(30, 3, 3000), rng.normal(60, 6, 7000)]
    with pytest.warns(LidarstatDeprecationWarning, match="min_cluster"):
        assert road_cut(v, min_cluster=20)[0] == road_cut(v, min_points=20)[0]
    with pytest.raises(InvalidParameterError, match="elevation_rule"):
        choose_cycle(sm, "elevation", elevation_rule="flat")


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_classes_do_not_depend_on_the_order_of_the_points(seed):
    """A catalogue's tiles bring the points in another order than the whole file."""
    from lidarstat.classify import moments
    from lidarstat.synth import make_als_town

    town = make_als_town(extent=(90.0, 70.0), density=6.0, rng=seed)
    inten = np.asarray(town.attributes["intensity"])
    xyz = np.round(town.xyz, 1)  # a coarse LAS scale: many points share x, y or z
    a = moments(xyz, inten, window=32.0)
    p = np.random.default_rng(seed).permutation(len(xyz))
    b = moments(xyz[p], inten[p], window=32.0)
    np.testing.assert_array_equal(a.classification[p], b.classification)
    np.testing.assert_array_equal(a.ground[p], b.ground)


def test_classes_of_a_real_tile_do_not_depend_on_the_order(shared_data):
    from lidarstat.io import read

    c = read(shared_data / "ahn3_amsterdam" / "ahn_2386_9702.laz")
    kw = {k: np.asarray(c[k]) for k in ("number_of_returns", "return_number")}
    a = moments(c.xyz, np.asarray(c["intensity"]), **kw)
    p = np.random.default_rng(0).permutation(len(c.xyz))
    b = moments(c.xyz[p], np.asarray(c["intensity"])[p], **{k: v[p] for k, v in kw.items()})
    np.testing.assert_array_equal(a.classification[p], b.classification)


def test_a_given_road_threshold_replaces_the_cut_of_the_cloud(rng):
    """A catalogue decides the road cut once for the area and gives it to every tile:
    the run's own cut given back changes nothing, -inf means no road, another value
    moves the road; params hold the cut used."""
    xyz, inten, nret, rnum, truth = _scene(rng, n=6000)
    kw = dict(number_of_returns=nret, return_number=rnum)
    res = moments(xyz, inten, **kw)
    cut = res.params["road_threshold"]
    assert 60 < cut < 160  # between the road's and the land's intensities
    again = moments(xyz, inten, road_threshold=cut, **kw)
    np.testing.assert_array_equal(again.classification, res.classification)
    assert again.params["road_threshold"] == cut
    none = moments(xyz, inten, road_threshold=float("-inf"), **kw)
    assert ASPRS["road"] not in none.classification
    road = res.classification == ASPRS["road"]
    np.testing.assert_array_equal(none.classification[road], ASPRS["ground"])
    np.testing.assert_array_equal(none.classification[~road], res.classification[~road])
    with pytest.raises(InvalidParameterError, match="road_threshold"):
        moments(xyz, inten, road_threshold=float("nan"), **kw)
