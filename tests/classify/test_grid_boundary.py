"""The 'grid' boundary test: the distance to the end of the visible surface on the scan grid."""

import numpy as np
import pytest

from lidarstat.classify import PointClass, covariance
from lidarstat.classify._visible import (BORDER_JUMP, BORDER_MISSING, BORDER_WINDOW,
                                        border_edges)
from lidarstat.errors import InvalidParameterError
from lidarstat.synth import neighborhood_class_truth, scan_spherical
from lidarstat.synth._csg import Box, FaceRegistry, union

from test_covariance_classes import _f1
from test_scan_boundary import _scans
from test_visible_boundary import _edges, _pillar_scan


def _border_edges(sc, adj, p, jump_alpha=0.001):
    from scipy.special import ndtri

    d = sc.xyz - sc.scanner
    r = np.linalg.norm(d, axis=1)
    out = np.empty(adj.shape, dtype=np.bool_)
    border_edges(np.ascontiguousarray(d / r[:, None]), np.ascontiguousarray(1.0 / r),
                 np.ascontiguousarray(sc.fields["range_sigma"] / r ** 2), adj,
                 np.ascontiguousarray((adj >= 0) & (p < jump_alpha)), float(ndtri(0.975)), out)
    return out


def test_grid_test_is_silent_inside_planes_and_finds_the_window_border():
    """Interior points of a grazing ground slab and of a wall face on (more than 1.5 r_k
    from the end of the visible surface): the rate of boundaries is within a binomial
    bound of the jump level's budget (measured 0); points within 0.4 r_k of the scan
    window are all found, and the estimated border distance there is within one point
    spacing of the truth (the window border is the last row's nodes, as in the truth)."""
    for sc in _scans():
        res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True,
                         boundary="grid")
        assert res.classes.meta["boundary"] == "grid"
        nbh = res.features.neighborhoods
        rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
        bd = sc.fields["boundary_distance"]
        interior = bd > 1.5 * rk
        assert interior.sum() > 15000
        rate = float(np.mean(res.point_class[interior] == PointClass.BOUNDARY))
        assert rate <= 0.01 + 3.3 * np.sqrt(0.01 * 0.99 / interior.sum()), rate
        near = bd < 0.4 * rk
        assert near.sum() > 500
        assert np.mean(res.point_class[near] == PointClass.BOUNDARY) > 0.97
        est = res["border_distance"]
        spacing = rk / np.sqrt(50 / np.pi)
        close = bd < 1.0 * rk
        err = np.abs(est[close] - bd[close]) / spacing[close]
        assert np.median(err) < 0.25 and np.quantile(err, 0.95) < 1.0, np.quantile(err, 0.95)
        kinds = res["border_kind"][near]
        assert np.isin(kinds, (BORDER_WINDOW, BORDER_MISSING)).mean() > 0.95


def test_border_edges_at_an_occlusion_but_not_at_a_face_narrower_than_the_grid():
    """Behind a pillar the wall's depth jump is a border on most of its rejected grid edges
    (smooth surfaces on both sides, no bypass); the 2 cm front face of a ledge, narrower
    than a grid step, is a 'jump' to the continuity test on almost every crossing edge but
    a border on almost none of them."""
    sc = _pillar_scan()
    adj, _, p = _edges(sc)
    be = _border_edges(sc, adj, p)
    nb = np.where(adj >= 0, adj, 0)
    pil = np.char.startswith(np.array(sc.meta["face_names"])[sc.face].astype(str), "pillar")
    jump = (adj >= 0) & (pil[nb] != pil[:, None]) & (p < 0.001)
    assert jump.sum() > 500
    assert np.mean(be[jump]) > 0.8, np.mean(be[jump])
    assert not be[(adj >= 0) & ~jump & (p >= 0.001)].any()
    reg = FaceRegistry()
    wall = Box(reg, "wall", (14.0, 0.0, 3.0), np.eye(3), (0.2, 8.0, 3.0))
    ledge = Box(reg, "ledge", (13.75, 0.0, 2.5), np.eye(3), (0.3, 3.0, 0.01))
    sc = scan_spherical(union(wall, ledge), scanner=(0.0, 0.0, 1.5), azimuth=(-0.3, 0.3),
                        elevation=(-0.05, 0.25), step=0.004, range_sigma=(0.002, 5e-5),
                        rng=3)
    adj, _, p = _edges(sc)
    be = _border_edges(sc, adj, p)
    nb = np.where(adj >= 0, adj, 0)
    cross = (adj >= 0) & (sc.face[nb] != sc.face[:, None])
    assert np.mean(p[cross] < 0.001) > 0.97
    assert np.mean(be[cross]) < 0.02, np.mean(be[cross])


@pytest.mark.parametrize("scene, edge_floor, boundary_floor", [
    ("tls_building", 0.82, 0.81), ("tls_plant", 0.9, 0.9)])
def test_grid_test_on_the_synthetic_scans(scene, edge_floor, boundary_floor):
    """Support-truth F1 at step 0.004 (k = 50, automatic). With 'grid' the plant reaches
    edge 0.915 / boundary 0.908 (the 'visible' default: 0.791 / 0.833): the truth's
    boundary corners are boundaries and the Hotelling reach is gone. The building loses
    edges to false borders at its window recesses (edge 0.839 / boundary 0.829 against
    0.902 / 0.831), which is why 'grid' is not the default (docs/methods/covariance.md)."""
    from lidarstat.synth import make_tls_building, make_tls_plant

    make = {"tls_building": make_tls_building, "tls_plant": make_tls_plant}[scene]
    sc = make(step=0.004, rng=0)
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True, boundary="grid")
    truth = neighborhood_class_truth(sc, res.features.neighborhoods)
    edge = _f1(res.point_class == PointClass.EDGE, truth == PointClass.EDGE)
    bnd = _f1(res.point_class == PointClass.BOUNDARY, truth == PointClass.BOUNDARY)
    assert edge >= edge_floor, edge
    assert bnd >= boundary_floor, bnd


def test_grid_option_errors(rng):
    from lidarstat.classify import classify_covariance
    from lidarstat.features import covariance_features

    pts = np.c_[rng.uniform(0, 5, (800, 2)), rng.normal(0, 0.002, 800)]
    with pytest.raises(InvalidParameterError, match="needs features computed with a sensor"):
        classify_covariance(covariance_features(pts, k=10), points=pts, boundary="grid")
    feats = covariance_features(pts, k=10, sensor=(2.0, 2.0, 3.0))
    with pytest.raises(InvalidParameterError, match="needs the `points`"):
        classify_covariance(feats, boundary="grid")
    with pytest.raises(InvalidParameterError, match="border_band"):
        classify_covariance(feats, points=pts, boundary="grid", border_band=0.0)
    res = classify_covariance(feats, points=pts, boundary="grid")
    f = res.to_fields()
    assert {"border_distance", "border_kind", "border_p"} <= set(f)
    assert f["border_kind"].dtype == np.uint8
    jump = f["border_kind"] == BORDER_JUMP
    assert np.all(f["border_p"][jump] < 0.001) and np.all(f["border_p"][~jump] == 0)
