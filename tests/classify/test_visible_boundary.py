"""Range continuity on the scan grid and the 'visible' boundary test: size, power, scenes."""

import numpy as np
import pytest
from test_covariance_classes import _binomial_ok, _f1
from test_scan_boundary import _scans

from lidarstat.classify import PointClass, classify_covariance, covariance
from lidarstat.classify._visible import (
    _GL_W,
    _GL_X,
    edge_jumps,
    edge_resolved,
    grid_adjacency,
    same_sign_p,
)
from lidarstat.errors import InvalidParameterError
from lidarstat.features import covariance_features
from lidarstat.features._scan_kernels import scan_angles
from lidarstat.synth import neighborhood_class_truth, scan_spherical
from lidarstat.synth._csg import Box, FaceRegistry, union


def _edges(sc):
    """Per grid edge: z, p, and the (row, col) offset of the neighbour, true range noise."""
    d = sc.xyz - sc.scanner
    r = np.linalg.norm(d, axis=1)
    dirs = np.ascontiguousarray(d / r[:, None])
    adj, steps = grid_adjacency(scan_angles(sc.xyz, np.asarray(sc.scanner)))
    sig = np.ascontiguousarray(sc.fields["range_sigma"] / r ** 2)
    z = np.empty(adj.shape)
    p = np.empty(adj.shape)
    edge_jumps(dirs, np.ascontiguousarray(1.0 / r), sig, adj, z, p)
    return adj, z, p


def _resolved(sc, adj, alpha=0.05):
    """Per grid edge: both sides linear over three nodes at level `alpha` (true noise)."""
    from scipy.special import ndtri

    d = sc.xyz - sc.scanner
    r = np.linalg.norm(d, axis=1)
    out = np.empty(adj.shape, dtype=np.bool_)
    edge_resolved(np.ascontiguousarray(d / r[:, None]), np.ascontiguousarray(1.0 / r),
                  np.ascontiguousarray(sc.fields["range_sigma"] / r ** 2), adj,
                  float(ndtri(1 - alpha / 2)), out)
    return out


def _corner_scan():
    """Two walls meeting at a convex vertical crease, seen at 45 degrees (no occlusion
    between them), range noise 2 mm + 5e-5 r."""
    reg = FaceRegistry()
    rot = np.array([[np.cos(np.pi / 4), -np.sin(np.pi / 4), 0.0],
                    [np.sin(np.pi / 4), np.cos(np.pi / 4), 0.0], [0.0, 0.0, 1.0]])
    box = Box(reg, "box", (12.0, 0.0, 2.0), rot, (3.0, 3.0, 4.0))
    return scan_spherical(box, scanner=(0.0, 0.0, 1.5), azimuth=(-0.3, 0.3),
                          elevation=(-0.08, 0.15), step=0.004, range_sigma=(0.002, 5e-5),
                          rng=1)


def _horizontal_edges(sc, adj, every=4):
    """Non-overlapping edges (i, i's right neighbour) from every `every`-th row and column,
    with two more nodes on each side of the edge on the same face (the whole grid line is
    one plane)."""
    row, col = sc.fields["row"].astype(np.int64), sc.fields["col"].astype(np.int64)
    key = {(a, b): i for i, (a, b) in enumerate(zip(row.tolist(), col.tolist()))}
    out = []
    for i in np.flatnonzero((row % every == 0) & (col % every == 0)):
        line = [key.get((row[i], col[i] + o)) for o in (-1, 0, 1, 2)]
        if any(j is None for j in line) or len({sc.face[j] for j in line}) != 1:
            continue
        k = np.flatnonzero(adj[i] == line[2])
        if k.size:
            out.append((i, k[0]))
    return np.array(out)


def test_continuity_test_size_on_planes_seen_at_grazing_and_face_on():
    """On one plane the second differences of the inverse range along a grid line are
    pure noise and z = min(|E_a|, |E_b|) (same sign) has the exact tail
    2 P(Z1 > t, Z2 > t), correlation 2/3 for equal noise. Non-overlapping edges of the
    grazing ground and of a wall: the rate of z > t at the t where that tail is 0.05 is
    inside the 99.9 % binomial interval of 0.05; the test's p-value (1 - Phi(z), exact
    at a crease beside an endpoint, the least favourable null) rejects fewer at 0.05."""
    alpha = 0.05
    lo, hi = 0.5, 4.0
    for _ in range(60):  # t with 2 P(Z1 > t, Z2 > t) = alpha
        t = 0.5 * (lo + hi)
        lo, hi = (t, hi) if same_sign_p(t, 2.0 / 3.0, _GL_X, _GL_W) > alpha else (lo, t)
    zs, ps = [], []
    for sc in _scans():
        adj, z, p = _edges(sc)
        e = _horizontal_edges(sc, adj)
        assert len(e) > 1500
        zs.append(z[e[:, 0], e[:, 1]])
        ps.append(p[e[:, 0], e[:, 1]])
    ok, rate, n = _binomial_ok(np.concatenate(zs) > t, alpha)
    assert ok, f"z exceeds its plane quantile on {rate:.4f} of {n} edges"
    assert np.mean(np.concatenate(ps) < alpha) < alpha


def test_continuity_test_does_not_cut_a_crease():
    """Across a convex crease (two walls at 90 degrees, both seen) the range is
    continuous: the step across lies between the slopes on either side, so the test
    rejects the edges that cross the crease no more often than alpha (upper limit of
    the 99.9 % interval; measured well below)."""
    sc = _corner_scan()
    adj, z, p = _edges(sc)
    nb = np.where(adj >= 0, adj, 0)
    cross = (adj >= 0) & (sc.face[nb] != sc.face[:, None])
    assert cross.sum() > 200
    alpha = 0.01
    rate = float(np.mean(p[cross] < alpha))
    n = cross.sum()
    assert rate <= alpha + 3.3 * np.sqrt(alpha * (1 - alpha) / n), rate


def _pillar_scan():
    """A pillar 1.5 m in front of a wall: occlusion borders on both sides of it."""
    reg = FaceRegistry()
    wall = Box(reg, "wall", (14.0, 0.0, 3.0), np.eye(3), (0.2, 8.0, 3.0))
    pillar = Box(reg, "pillar", (12.0, 0.5, 1.5), np.eye(3), (0.3, 0.3, 1.5))
    return scan_spherical(union(wall, pillar), scanner=(0.0, 0.0, 1.5),
                          azimuth=(-0.3, 0.3), elevation=(-0.05, 0.25), step=0.004,
                          range_sigma=(0.002, 5e-5), rng=2)


def _ledge_scan():
    """A wall with a ledge whose 2 cm front face is narrower than a grid step (5 cm at
    13 m)."""
    reg = FaceRegistry()
    wall = Box(reg, "wall", (14.0, 0.0, 3.0), np.eye(3), (0.2, 8.0, 3.0))
    ledge = Box(reg, "ledge", (13.75, 0.0, 2.5), np.eye(3), (0.3, 3.0, 0.01))
    return scan_spherical(union(wall, ledge), scanner=(0.0, 0.0, 1.5), azimuth=(-0.3, 0.3),
                          elevation=(-0.05, 0.25), step=0.004, range_sigma=(0.002, 5e-5),
                          rng=3)


def test_continuity_test_power_at_an_occlusion_and_visible_boundaries():
    """Grid edges between the pillar and the wall behind it (depth jump 1.5-2 m) are
    rejected at 0.001 (measured 98.7 %: the others are not tested, their grid line not
    continuing on both sides, at the pillar's corners), so are most points beside them
    (``jump_p``); the visible test then
    labels the points within 0.25 r_k of the end of either visible surface boundaries."""
    sc = _pillar_scan()
    adj, z, p = _edges(sc)
    nb = np.where(adj >= 0, adj, 0)
    pil = np.char.startswith(np.array(sc.meta["face_names"])[sc.face].astype(str), "pillar")
    jump = (adj >= 0) & (pil[nb] != pil[:, None])
    assert jump.sum() > 100
    assert np.mean(p[jump] < 0.001) > 0.97
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True, boundary="visible")
    assert res.classes.meta["boundary"] == "visible"
    at = jump.any(axis=1)
    assert np.mean(res["jump_p"][at] < 0.001) > 0.97
    nbh = res.features.neighborhoods
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
    near = sc.fields["boundary_distance"] < 0.25 * rk
    assert near.sum() > 300
    assert np.mean(res.point_class[near] == PointClass.BOUNDARY) > 0.95


def test_resolved_jumps_at_an_occlusion_but_not_at_a_face_narrower_than_the_grid():
    """A jump between the pillar and the wall behind it has planes on both sides over
    three grid nodes: 89.7 % of the rejected jump edges are resolved (the others run into
    the pillar's corners). A ledge whose front face (2 cm) is narrower than a grid step
    (5 cm at 13 m) is a "jump" to the continuity test on every one of its 952 crossing
    grid edges, but only 0.2 % of them are resolved: the front face is not a plane over
    three nodes. Resolved jumps are what turns an edge candidate into a boundary."""
    sc = _pillar_scan()
    adj, _, p = _edges(sc)
    res = _resolved(sc, adj)
    nb = np.where(adj >= 0, adj, 0)
    pil = np.char.startswith(np.array(sc.meta["face_names"])[sc.face].astype(str), "pillar")
    jump = (adj >= 0) & (pil[nb] != pil[:, None]) & (p < 0.001)
    assert jump.sum() > 500
    assert np.mean(res[jump]) > 0.85
    sc = _ledge_scan()
    adj, _, p = _edges(sc)
    res = _resolved(sc, adj)
    nb = np.where(adj >= 0, adj, 0)
    cross = (adj >= 0) & (sc.face[nb] != sc.face[:, None])
    assert cross.sum() > 500
    assert np.mean(p[cross] < 0.001) > 0.97
    assert np.mean(res[cross & (p < 0.001)]) < 0.02


def test_visible_test_is_conservative_on_a_scan_grid_and_finds_the_borders():
    """On the scanner's grid the visible disc of an interior point is centrally
    symmetric (T2 = 0 to rounding): at alpha = 0.05 no more than alpha of the interior
    points are boundaries (measured 0); points within 0.25 r_k of a border are found."""
    alpha = 0.05
    for sc in _scans():
        res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True,
                         boundary_alpha=alpha, boundary="visible")
        nbh = res.features.neighborhoods
        rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
        bd = sc.fields["boundary_distance"]
        interior = bd > 1.5 * rk
        rate = float(np.mean(res["boundary_p"][interior] < alpha))
        assert rate <= alpha + 3.3 * np.sqrt(alpha * (1 - alpha) / interior.sum()), rate
        near = bd < 0.25 * rk
        assert np.mean(res.point_class[near] == PointClass.BOUNDARY) > 0.95


@pytest.mark.parametrize("scene, floor, gain, edge_floor", [
    ("tls_building", 0.825, 0.05, 0.895), ("tls_plant", 0.828, 0.02, 0.785)])
def test_boundary_f1_on_the_synthetic_scans(scene, floor, gain, edge_floor):
    """Boundary F1 against the support truth at step 0.004 (k = 50, automatic): the
    visible test (with surface points beside a depth jump and edge candidates at a
    resolved jump) reaches 0.831 on the building (the complete-disc 'scan' test 0.747:
    the false boundaries at the foot of the walls are gone; 0.824 without the resolved
    jumps) and 0.833 on the plant (0.826 without), edge F1 0.902 and 0.791 (0.910 and
    0.773 without: the plant's false edges were boundary corners). The plant's misses
    are borders at 0.25-0.5 r_k that the F level does not reach and pipe silhouettes
    whose last step is steeper than the jump. docs/methods/covariance.md has the
    full-resolution figures; the issue's 0.9 is not reached."""
    from lidarstat.synth import make_tls_building, make_tls_plant

    make = {"tls_building": make_tls_building, "tls_plant": make_tls_plant}[scene]
    sc = make(step=0.004, rng=0)
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True, boundary="visible")
    truth = neighborhood_class_truth(sc, res.features.neighborhoods) == PointClass.BOUNDARY
    new = _f1(res.point_class == PointClass.BOUNDARY, truth)
    old = classify_covariance(res.features, points=sc.xyz, boundary="scan")
    f_old = _f1(old.point_class == PointClass.BOUNDARY, truth)
    assert new >= floor, new
    assert new >= f_old + gain, (new, f_old)
    edge = _f1(res.point_class == PointClass.EDGE, truth_edge := (
        neighborhood_class_truth(sc, res.features.neighborhoods) == PointClass.EDGE))
    assert truth_edge.sum() > 1000
    assert edge >= edge_floor, edge


@pytest.mark.parametrize("boundary", ["visible", "grid"])
def test_grid_tests_need_a_sensor_and_the_points(rng, boundary):
    pts = np.c_[rng.uniform(0, 5, (800, 2)), rng.normal(0, 0.002, 800)]
    with pytest.raises(InvalidParameterError, match="needs features computed with a sensor"):
        classify_covariance(covariance_features(pts, k=10), points=pts, boundary=boundary)
    feats = covariance_features(pts, k=10, sensor=(2.0, 2.0, 3.0))
    with pytest.raises(InvalidParameterError, match="needs the `points`"):
        classify_covariance(feats, boundary=boundary)


def test_visible_option_errors(rng):
    pts = np.c_[rng.uniform(0, 5, (800, 2)), rng.normal(0, 0.002, 800)]
    feats = covariance_features(pts, k=10, sensor=(2.0, 2.0, 3.0))
    assert classify_covariance(feats).meta["boundary"] == "scan"
    with pytest.raises(InvalidParameterError, match="jump_alpha"):
        classify_covariance(feats, points=pts, jump_alpha=0.0)
    res = classify_covariance(feats, points=pts)
    assert res.meta["boundary"] == "grid"
    res = classify_covariance(feats, points=pts, boundary="visible")
    assert res.meta["boundary"] == "visible"
    assert {"jump_z", "jump_p", "jump_resolved_p"} <= set(res.to_fields())


def test_grid_adjacency_with_unequal_steps():
    """A scanner's azimuth and elevation steps need not be equal (the real pump scan:
    1 : 3.4). Keeping every third column of the wall scan: the steps are estimated per
    axis, interior nodes get their 8 grid neighbours, and the visible test still calls
    no interior point and the points within 0.25 r_k of the border boundaries."""
    sc = list(_scans())[1]
    keep = sc.fields["col"] % 3 == 0
    xyz = sc.xyz[keep]
    adj, (s_az, s_el) = grid_adjacency(scan_angles(xyz, np.asarray(sc.scanner)))
    assert abs(s_az / s_el - 3.0) < 0.05
    bd = sc.fields["boundary_distance"][keep]
    inner = bd > 0.3
    assert np.mean((adj[inner] >= 0).sum(axis=1) == 8) > 0.99
    res = covariance(xyz, sensor=sc.scanner, k=50, keep_neighbors=True)
    nbh = res.features.neighborhoods
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
    assert np.mean(res.point_class[bd > 1.5 * rk] == PointClass.BOUNDARY) < 0.01
    near = bd < 0.25 * rk
    assert near.sum() > 100
    assert np.mean(res.point_class[near] == PointClass.BOUNDARY) > 0.9
