"""Covariance segmentation: region growing on classes, intersection lines, scores on TLS truth."""

import numpy as np
import pytest

from lidarstat.classify import covariance
from lidarstat.segment import (hoover, local_intersections, segment_covariance,
                               segment_planes)
from lidarstat.synth import distance_to_creases, make_tls_building


def _gable(rng, n=30000, sigma=0.003):
    xy = rng.uniform(0, 10, (n, 2))
    z = 5 - np.tan(np.radians(30)) * np.abs(xy[:, 0] - 5) + rng.normal(0, sigma, n)
    return np.c_[xy, z] + [600_000.0, 5_200_000.0, 0.0], (xy[:, 0] > 5).astype(int) + 1


def test_gable_roof_two_planes_and_the_ridge(rng):
    pts, truth = _gable(rng)
    seg = segment_covariance(pts, covariance(pts, k=30, keep_neighbors=True), min_points=100)
    assert seg.n_segments == 2
    h = hoover(seg.labels, truth, 0.8)
    assert h.correct == 2
    # plane table: the roof slopes and an RMS of the noise
    t = seg.table
    assert np.allclose(np.sort(np.abs(t["normal_x"])), np.sin(np.radians(30)), atol=5e-3)
    assert np.all(t["rms"] < 0.01)
    # one line, on the ridge (x = 5, z = 5) within a few noise sigmas, spanning it
    lines = seg.lines
    assert len(lines) == 1
    v = lines.vertices[0] - [600_000.0, 5_200_000.0, 0.0]
    assert np.all(np.abs(v[:, 0] - 5) < 0.01) and np.all(np.abs(v[:, 2] - 5) < 0.01)
    assert np.ptp(v[:, 1]) > 8.0


def test_partition_does_not_depend_on_seed_order(rng):
    pts, _ = _gable(rng, n=8000)
    a = segment_covariance(pts, covariance(pts, k=20, keep_neighbors=True), seeds="curvature",
                           min_points=20)
    b = segment_covariance(pts, covariance(pts, k=20, keep_neighbors=True), seeds="index",
                           min_points=20)
    assert np.array_equal(a.labels, b.labels)


def test_vocabulary_min_points_seeds_enum_and_the_deprecated_min_size(rng):
    """``min_points`` is the smallest segment kept (``min_size`` still works and warns);
    ``seeds`` takes the enum or its string; the result's params say what was used."""
    from lidarstat.errors import InvalidParameterError, LidarstatDeprecationWarning
    from lidarstat.segment import SeedOrder

    pts, _ = _gable(rng, n=6000)
    res = covariance(pts, k=20, keep_neighbors=True)
    a = segment_covariance(pts, res, min_points=20, seeds=SeedOrder.INDEX)
    with pytest.warns(LidarstatDeprecationWarning, match="min_size is deprecated"):
        b = segment_covariance(pts, res, min_size=20, seeds="index")
    assert np.array_equal(a.labels, b.labels)
    assert a.params["min_points"] == 20 and a.params["seeds"] == "index"
    with pytest.raises(InvalidParameterError, match="'seeds' parameter"):
        segment_covariance(pts, res, seeds="random")
    for gone in ("refine", "adaptive_scale"):
        with pytest.raises(TypeError, match=gone):
            segment_covariance(pts, res, **{gone: False})


def test_local_intersection_is_eq17_closest_point():
    # planes z = 0 and x = 0 meet on the y axis; p1, p2 either side: closest point (0, y, 0)
    pts = np.array([[0.3, 1.0, 0.0], [0.0, 1.2, 0.4]])
    labels = np.array([1, 2])
    normals = np.array([[0.0, 0, 1], [1.0, 0, 0]])
    from lidarstat.neighbors import Neighborhoods

    nbh = Neighborhoods(np.array([0, 2, 4]), np.array([0, 1, 1, 0]), np.zeros(4), 2)
    x0, seg = local_intersections(pts, labels, normals, pts, nbh, max_distance=1.0)
    np.testing.assert_allclose(x0, [[0.0, 1.1, 0.0]], atol=1e-12)
    assert seg.tolist() == [[1, 2]]
    x0, _ = local_intersections(pts, labels, normals, pts, nbh, max_distance=0.2)
    assert len(x0) == 0  # rejected: too far from the points


def test_segment_planes_exact():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 1, (200, 2))
    pts = np.c_[xy, 2 * xy[:, 0] + 1]
    t = segment_planes(pts, np.ones(200, dtype=int))
    n = np.array([-2.0, 0, 1]) / np.sqrt(5)
    np.testing.assert_allclose([t["normal_x"][0], t["normal_y"][0], t["normal_z"][0]], n,
                               atol=1e-9)
    assert t["rms"][0] < 1e-7 and t["n_points"][0] == 200


def _face_plane(sc, f):
    """Least-squares plane (unit normal, point) of the scan points of true face f."""
    p = sc.xyz[sc.face == f]
    c = p.mean(axis=0)
    return np.linalg.svd(p - c, full_matrices=False)[2][2], c


def _dominant_faces(sc, labels, a, b):
    return (int(np.bincount(sc.face[labels == a]).argmax()),
            int(np.bincount(sc.face[labels == b]).argmax()))


@pytest.mark.slow
def test_tls_building_hoover_and_lines():
    """Synthetic terrestrial scan: every face > 200 points found (Hoover T = 0.8), with the
    fascia (3 scan rows, its border points given back by the segment-level planes) and the
    soffit (1-2 rows: a strip segment).

    Lines with support lie within 2 sigma of both true faces' planes and of the nearest
    listed true crease (``meta['edges']``, which holds the roof-fascia creases).
    """
    sc = make_tls_building(rng=0)
    # the defaults: the automatic (tested) scale
    seg = segment_covariance(sc.xyz, covariance(sc.xyz, sensor=sc.scanner,
                                                keep_neighbors=True))
    h = hoover(seg.labels, sc.face + 1, 0.8, min_points=200)
    assert h.correct == h.n_truth == 14 and h.noise == 0
    assert seg.fields["scale_k"].max() == 50 and (seg.fields["scale_k"] < 50).any()
    assert (seg.fields["reintegrated"] == 2).any() and (seg.fields["reintegrated"] == 3).any()
    two_sigma = 2 * (0.002 + 5e-5 * 30)  # range noise at 30 m
    t = np.array([0.2, 0.5, 0.8])[:, None]
    names = sc.meta["face_names"]
    pairs = set()
    for v, a, b, n in zip(seg.lines.vertices, seg.lines.attributes["segment_a"],
                          seg.lines.attributes["segment_b"], seg.lines.attributes["n_points"]):
        if n < 50 or np.linalg.norm(v[-1] - v[0]) <= 1.0:
            continue
        fa, fb = _dominant_faces(sc, seg.labels, a, b)
        (na, ca), (nb, cb) = _face_plane(sc, fa), _face_plane(sc, fb)
        q = v[0] + t * (v[-1] - v[0])
        assert np.abs((q - ca) @ na).max() < two_sigma, (names[fa], names[fb])
        assert np.abs((q - cb) @ nb).max() < two_sigma, (names[fa], names[fb])
        assert distance_to_creases(q, sc.meta["edges"]).max() < two_sigma, (names[fa],
                                                                             names[fb])
        pairs.add(frozenset((names[fa], names[fb])))
    assert {frozenset(("house_roof_south", "house_roof_fascia_south")),
            frozenset(("house_roof_fascia_south", "house_roof_soffit")),
            frozenset(("ground_+z", "house_wall_-y"))} <= pairs
    # no supported line between faces that do not meet (roof and soffit, wall and roof)
    assert frozenset(("house_roof_south", "house_roof_soffit")) not in pairs
    assert frozenset(("house_wall_-y", "house_roof_south")) not in pairs


def test_tls_plant_pipes_and_tanks_one_cylinder_segment_each():
    """Synthetic plant (coarse step): every face > 200 points correctly detected (Hoover
    T = 0.8), pieces of one pipe or tank cut by shadows merged by the cylinder fit of
    their union, and the table's cylinder radii equal the true ones within 2 %. With the
    default 'grid' boundary test's classes the thin pipe_b (r = 0.15 m, about four scan
    columns across at this step) is still a correct segment but modelled as a plane: most
    of its points are within 0.5 r_k of its silhouettes, boundaries, and the cylinder
    merge seeds its axes from surface points only (at the default step it is a cylinder
    of the right radius: docs/methods/covariance.md)."""
    from lidarstat.classify import covariance
    from lidarstat.synth import make_tls_plant

    sc = make_tls_plant(step=0.004, rng=0)
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True)
    seg = segment_covariance(sc.xyz, res)
    h = hoover(seg.labels, sc.face + 1, 0.8, min_points=200)
    assert h.correct == h.n_truth >= 10
    names = sc.meta["face_names"]
    t = seg.table
    found = 0
    for s in np.flatnonzero(t["model"] == 2):
        face = names[np.bincount(sc.face[seg.labels == s + 1]).argmax()]
        cyl = sc.meta["cylinders"].get(face.replace("_side", ""))
        assert cyl is not None, f"segment on {face} modelled as a cylinder"
        assert abs(t["radius"][s] / cyl["radius"] - 1) < 0.02
        assert abs(abs(np.dot([t["axis_x"][s], t["axis_y"][s], t["axis_z"][s]],
                              cyl["axis"])) - 1) < 1e-3
        found += 1
    assert found >= 3  # of tank1, tank2, pipe_a, pipe_b, pipe_c


@pytest.mark.slow
def test_curved_creases_are_polylines_on_the_true_circles():
    """tls_plant at the default step: every face > 200 points found; pipe-support, pipe-pump and
    tank-ground creases are circles, and their polylines lie within 2 sigma of the true
    arcs of their two faces."""
    from lidarstat.synth import make_tls_plant

    sc = make_tls_plant(rng=0)
    seg = segment_covariance(sc.xyz, covariance(sc.xyz, sensor=sc.scanner, keep_neighbors=True))
    h = hoover(seg.labels, sc.face + 1, 0.8, min_points=200)
    assert h.correct == h.n_truth == 11
    cyl = seg.table["model"] == 2
    two_sigma = 2 * (0.002 + 5e-5 * 25)
    names = sc.meta["face_names"]
    found = set()
    for v, a, b in zip(seg.lines.vertices, seg.lines.attributes["segment_a"],
                       seg.lines.attributes["segment_b"]):
        if not (cyl[a - 1] or cyl[b - 1]):
            continue
        fa, fb = _dominant_faces(sc, seg.labels, a, b)
        arcs = [c for c in sc.meta["edges"] if set(c["faces"]) == {fa, fb}]
        assert arcs and all(c["kind"] == "arc" for c in arcs)
        q = np.concatenate([v[:-1] + s * (v[1:] - v[:-1]) for s in (0.0, 0.5)] + [v[-1:]])
        assert distance_to_creases(q, arcs).max() < two_sigma
        if len(v) >= 5:
            found.add(frozenset((names[fa], names[fb])))
    assert {frozenset(("ground_+z", "tank1_side")), frozenset(("pipe_b_side", "support2_-x")),
            frozenset(("pipe_c_side", "support2_-x")), frozenset(("pipe_a_side", "pump_-x"))} \
        <= found


def test_cylinder_refit_recovers_a_tilted_axis(rng):
    """fit_cylinder: all five parameters from a noisy half cylinder, started 2 degrees and
    2 cm off; the start the normals give is what it corrects."""
    from lidarstat.segment._cylinders import fit_cylinder

    n, r = 4000, 0.3
    ax = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])
    u = np.cross(ax, [0, 0, 1.0])
    u /= np.linalg.norm(u)
    w = np.cross(ax, u)
    h, phi = rng.uniform(-2, 2, n), rng.uniform(0, np.pi, n)
    c0 = np.array([5.0, -3.0, 1.0])
    p = c0 + np.outer(h, ax) + r * (np.outer(np.cos(phi), u) + np.outer(np.sin(phi), w))
    p += rng.normal(0, 0.002, (n, 3))
    start = ax + np.radians(2) * u
    a, c, rr, rms = fit_cylinder(p, np.arange(n), start / np.linalg.norm(start),
                                 c0 + 0.02 * w, 0.28, 0.002)
    assert abs(abs(a @ ax) - 1) < 1e-5
    off = (c - c0) - ((c - c0) @ ax) * ax
    assert np.linalg.norm(off) < 1e-3 and abs(rr - r) < 1e-3
    assert 0.5 < rms < 1.5  # isotropic noise: about 1 in noise units (3-D noise, radial part)


def test_strip_segment_of_one_curved_scan_row(rng):
    """A narrow face seen on one scan row only: the row is a circle arc on a horizontal
    plane, so the strip identifies its plane and becomes a segment; a straight row (a line:
    any plane through it fits) does not."""
    from lidarstat.neighbors import knn_neighbors
    from lidarstat.segment._refine import strip_segments

    sensor = np.zeros(3)
    az = np.linspace(0.2, 0.8, 400)
    rho = 4.2 / np.tan(np.radians(9.5))  # a soffit 4.2 m above the scanner
    arc = np.c_[rho * np.cos(az), rho * np.sin(az), np.full(az.size, 4.2)]
    line = np.c_[np.linspace(0, 12, 400), np.full(400, 25.0), np.full(400, 4.2)]
    for pts, expect in ((arc, True), (line, False)):
        ray = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        p = pts + ray * rng.normal(0, 0.003, (len(pts), 1))
        nbh = knn_neighbors(p, 20)
        lab = strip_segments(p, np.zeros(len(p), dtype=np.int32), nbh, 0.003,
                             candidates=np.ones(len(p), bool), sensor=sensor)
        assert (lab.max() == 1) == expect
        if expect:
            assert (lab == 1).mean() > 0.95


def test_refine_borders_moves_a_misassigned_row(rng):
    """Two planes meeting at 90 degrees; the first row of plane B was grown into A. The
    border refinement gives it back (it is an outlier of A's plane and an inlier of B's)."""
    from lidarstat.neighbors import knn_neighbors
    from lidarstat.segment._refine import refine_borders

    g = np.arange(0, 2, 0.02)
    u, v = np.meshgrid(g, g)
    a = np.c_[u.ravel(), v.ravel(), np.zeros(u.size)]          # z = 0, x >= 0
    b = np.c_[np.zeros(u.size), v.ravel(), u.ravel() + 0.02]   # x = 0, z > 0
    p = np.r_[a, b] + rng.normal(0, 0.001, (2 * u.size, 3))
    lab = np.r_[np.ones(u.size), np.full(u.size, 2)].astype(np.int32)
    row = np.flatnonzero(np.r_[np.zeros(u.size, bool), b[:, 2] < 0.05])
    lab[row] = 1  # two rows of B given to A
    new, moved, _ = refine_borders(p, lab, knn_neighbors(p, 20), 0.001)
    assert (new[row] == 2).all() and moved[row].all()
    # anything else that moved is a point of A's first column (on the crease within the
    # noise) that happened to lie beyond 3 sigma of A's plane
    other = np.flatnonzero(moved & ~np.isin(np.arange(len(p)), row))
    assert other.size <= 5 and (np.abs(p[other, 0]) < 0.004).all()


@pytest.mark.parametrize("seed", range(6))
def test_strip_links_are_the_pairs_within_the_larger_radius(seed):
    """Each point is searched with its own radius (in blocks of near radii), never with
    the largest: the pairs are exactly those within the larger of the two radii, each
    once, with exact copies, radius-0 points and one isolated point of a huge radius."""
    from lidarstat.segment._refine import _link_pairs

    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 1500))
    p = rng.random((n, 3)) * [10.0, 10.0, 1.0]
    p[rng.integers(0, n, 15)] = p[rng.integers(0, n, 15)]  # exact copies
    r = rng.gamma(2.0, 0.15, n)
    r[rng.random(n) < 0.05] = 0.0
    r[0] = 4.0  # an isolated point's reach: the old global radius
    a, b = _link_pairs(p, r, block=int(rng.integers(1, 400)))
    got = np.stack([a, b], axis=1)
    assert (a < b).all() and len(np.unique(got, axis=0)) == len(got)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    i, j = np.nonzero(np.triu(d <= np.maximum(r[:, None], r[None, :]), k=1))
    want = np.stack([i, j], axis=1)
    assert np.array_equal(got[np.lexsort(got.T[::-1])], want)
