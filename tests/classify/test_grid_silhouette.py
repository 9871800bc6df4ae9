"""The 'grid' boundary test on curved surfaces: borders placed on the fitted cylinder."""

import numpy as np
import pytest

from lidarstat.classify import PointClass, covariance
from lidarstat.classify._grid_borders import (BORDER_JUMP, BORDER_MISSING, cylinder_border,
                                              shadow_border)
from lidarstat.classify._scan_grid import _grid_rays
from lidarstat.synth import scan_spherical
from lidarstat.synth._csg import Box, Cylinder, FaceRegistry, union

_AXIS = np.array([0.0, 1.0, 0.0])


def _pipes_scan(rng=0):
    """Two horizontal pipes across the view, 8 m from a scanner 1.5 m above the ground:
    ``low`` (radius 0.15 m) in front of a wall 4 m behind it (its silhouettes end at
    depth jumps), ``high`` (radius 0.25 m) against the sky above the wall (its upper
    silhouette ends at missing returns); both 3 m long, inside the scan window."""
    reg = FaceRegistry()
    wall = Box(reg, "wall", (12.0, 0.0, 1.0), np.eye(3), (0.2, 6.0, 1.5))
    low = Cylinder(reg, "low", (8.0, 0.0, 1.6), _AXIS, 0.15, 3.0)
    high = Cylinder(reg, "high", (8.0, 0.0, 3.2), _AXIS, 0.25, 3.0)
    # a post at the side reaching above the scan window (the grid's top row is the scan
    # window there, not the pipe's silhouette)
    post = Box(reg, "post", (10.0, -2.4, 3.0), np.eye(3), (0.15, 0.15, 3.0))
    return scan_spherical(union(union(union(wall, low), high), post), sensor=(0.0, 0.0, 1.5),
                          azimuth=(-0.25, 0.25), elevation=(-0.1, 0.25), step=0.004,
                          range_sigma=(0.002, 5e-5), rng=rng)


def test_cylinder_border_is_the_tangent_point_or_the_mid_ray_on_the_cylinder():
    """Exact geometry: where the surface ends by itself, the returned point is the
    silhouette - on the cylinder, its ray tangent there (perpendicular to the radial
    direction) - whether the tangent ray lies between the node's ray and the next one, up
    to two steps beyond the next one, or behind the node's own ray (a node whose ray
    misses the model); where the surface is cut by a nearer surface (occluded), or no
    silhouette lies within two steps (the end of a pipe), it is the near intersection with
    the cylinder of the mid ray (of the rays that meet it)."""
    sensor = np.zeros(3)
    centre = np.array([[8.0, 0.0, 0.0]])
    axis = _AXIS[None]
    radius = np.array([0.2])
    step = 0.004
    steps = (step, step)
    # the top silhouette of the cylinder is at elevation asin(0.2 / 8); grid position in
    # steps, azimuth cut at 0; the node is its ray's hit `frac` steps below it
    el_sil = np.arcsin(0.2 / 8.0)
    tangent = np.array([8.0 - 0.2 * np.sin(el_sil), 0.0, 0.2 * np.cos(el_sil)])
    for frac, occluded, expect in ((0.3, False, "tangent"), (1.7, False, "tangent"),
                                   (0.3, True, 0.15), (1.7, True, 0.5),
                                   (4.5, False, 0.5), (-0.4, False, "tangent")):
        g = np.array([[0.0, el_sil / step - frac]])
        ray0 = _grid_rays(g, steps, 0.0)[0]
        if frac > 0:
            b = ray0 @ centre[0]
            node = ((b - np.sqrt(b * b - (centre[0] @ centre[0] - 0.04))) * ray0)[None]
        else:  # the node's ray passes above the cylinder: a node 1 mm off the model
            node = (tangent + np.array([0.0, 0.0, 0.001]))[None]
        q, ok = cylinder_border(sensor, node, g, np.array([0.0, 1.0]), steps, 0.0, centre,
                                axis, radius, np.array([occluded]))
        assert ok[0]
        rad = q[0] - centre[0] - ((q[0] - centre[0]) @ _AXIS) * _AXIS
        assert abs(np.linalg.norm(rad) - 0.2) < 1e-9
        el = np.arcsin(q[0, 2] / np.linalg.norm(q[0]))
        if expect == "tangent":
            assert abs(q[0] @ rad) < 1e-9 * np.linalg.norm(q[0])  # tangent ray
            assert np.linalg.norm(q[0] - tangent) < 1e-8
        else:
            assert abs(el - (g[0, 1] + expect) * step) < 1e-6 * step
            assert abs(q[0] @ rad) > 1e-4
    # a node off its cylinder (a wrong model) is not placed on it
    _, ok = cylinder_border(sensor, np.array([[7.0, 0.0, 0.5]]), np.array([[0.0, 1.0]]),
                            np.array([0.0, 1.0]), steps, 0.0, centre, axis, radius,
                            np.array([False]))
    assert not ok[0]


def test_shadow_of_a_pipe_begins_on_its_silhouette_ray():
    """Exact geometry: a wall node behind a pipe, its grid neighbour (toward the pipe) on
    the pipe; the end of the wall's visible surface is where the ray grazing the pipe
    meets the wall - on the wall's plane, tangent to the pipe (1e-9), between the two
    rays - and on a curved background (a larger cylinder behind) on that cylinder."""
    sensor = np.zeros(3)
    step = 0.004
    steps = (step, step)
    centre = np.array([[8.0, 0.0, 0.0]])
    radius = np.array([0.2])
    el_sil = np.arcsin(0.2 / 8.0)
    # the occluder: the pipe's hit 0.4 steps below its top silhouette; the node one step
    # above it, on the wall x = 12 (normal -x) or on a cylinder of radius 1 about x = 13
    gb = np.array([[0.0, el_sil / step - 0.4]])
    ray_b = _grid_rays(gb, steps, 0.0)[0]
    bb = ray_b @ centre[0]
    occ = ((bb - np.sqrt(bb * bb - (centre[0] @ centre[0] - 0.04))) * ray_b)[None]
    ray_a = _grid_rays(gb + (0.0, 1.0), steps, 0.0)[0]
    tangent_ray = np.array([np.cos(el_sil), 0.0, np.sin(el_sil)])
    for wall in ("plane", "cylinder"):
        if wall == "plane":
            node = (12.0 / ray_a[0] * ray_a)[None]
            node_cyl = (np.full((1, 3), np.nan), np.full((1, 3), np.nan), np.full(1, np.nan))
        else:
            cb = np.array([13.0, 0.0, 0.0])
            bq = ray_a @ cb
            node = ((bq - np.sqrt(bq * bq - (cb @ cb - 1.0))) * ray_a)[None]
            node_cyl = (cb[None], _AXIS[None], np.array([1.0]))
        q, ok = shadow_border(sensor, node, np.array([[-1.0, 0.0, 0.0]]), occ, gb,
                              np.array([0.0, -1.0]), steps, 0.0,
                              (centre, _AXIS[None], radius), node_cyl)
        assert ok[0]
        d = q[0] / np.linalg.norm(q[0])
        assert np.linalg.norm(d - tangent_ray) < 1e-9
        if wall == "plane":
            assert abs(q[0, 0] - 12.0) < 1e-9
        else:
            assert abs(np.hypot(q[0, 0] - 13.0, q[0, 2]) - 1.0) < 1e-9
            assert q[0, 0] < 13.0
    # an occluder whose silhouette is not between the two rays (2.5 steps on) leaves the
    # midpoint rule
    gb = gb - (0.0, 2.1)
    ray_b = _grid_rays(gb, steps, 0.0)[0]
    bb = ray_b @ centre[0]
    occ = ((bb - np.sqrt(bb * bb - (centre[0] @ centre[0] - 0.04))) * ray_b)[None]
    ray_a = _grid_rays(gb + (0.0, 1.0), steps, 0.0)[0]
    _, ok = shadow_border(sensor, (12.0 / ray_a[0] * ray_a)[None],
                          np.array([[-1.0, 0.0, 0.0]]), occ, gb, np.array([0.0, -1.0]), steps,
                          0.0, (centre, _AXIS[None], radius),
                          (np.full((1, 3), np.nan), np.full((1, 3), np.nan), np.full(1, np.nan)))
    assert not ok[0]


@pytest.fixture(scope="module")
def pipes():
    sc = _pipes_scan()
    res = covariance(sc.xyz, sensor=sc.scanner, k=50, keep_neighbors=True, boundary="grid")
    return sc, res


def test_silhouette_distance_against_the_analytic_truth(pipes):
    """On the pipes, within one r_k of the end of their visible surface (silhouettes
    against the wall and against the sky), the estimated border distance is unbiased to
    0.2 point spacings in the median for both kinds of border (measured -0.005 at the
    jumps, +0.14 at the missing returns: +0.10 along the pipe, +0.22 within 0.3 m of its
    ends, where a diagonal grid line finds the silhouette a little beyond the end) and
    within one spacing for 90 % of the points (measured 0.14 and 0.35); the tangent-plane
    estimate (no cylinder) is biased short by about a spacing there (-1.36 and -1.05).
    On the wall behind the low pipe the shadow's border is on the pipe's silhouette ray."""
    from lidarstat.classify._grid_boundary import grid_boundary
    from lidarstat.classify._scan_grid import grid_edges

    sc, res = pipes
    nbh = res.features.neighborhoods
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
    spacing = rk / np.sqrt(50 / np.pi)
    names = np.array(sc.meta["face_names"]).astype(str)[sc.face]
    pipe = np.char.endswith(names, "_side")
    bd = sc.fields["boundary_distance"]
    est = res["border_distance"]
    kind = res["border_kind"]
    err = (est - bd) / spacing
    for k in (BORDER_JUMP, BORDER_MISSING):
        m = pipe & (bd < rk) & (kind == k)
        assert m.sum() > 150, (k, m.sum())
        assert abs(np.median(err[m])) < 0.2, (k, np.median(err[m]))
        assert np.quantile(np.abs(err[m]), 0.9) < 1.0, (k, np.quantile(np.abs(err[m]), 0.9))
    # the tangent plane of the same nodes
    cl = res.classes
    f = res.features
    a, b = cl.meta["range_noise"]
    along = a + b * f.ray_range
    plane = grid_boundary(sc.xyz, f.sensor, f.normals, along,
                          grid=grid_edges(sc.xyz, f.sensor, along),
                          jump_alpha=cl.meta["jump_alpha"], smooth_alpha=cl.alpha)
    m = pipe & (bd < rk) & (plane["border_kind"] == BORDER_MISSING)
    assert np.median((plane["border_distance"][m] - bd[m]) / spacing[m]) < -0.5
    # the wall behind the low pipe (and beside the post): the shadow of the pipe begins on
    # its silhouette ray (measured -0.001 spacings; the midpoint rule: +0.16)
    wall = names == "wall_-x"
    m = wall & (bd < rk) & (kind == BORDER_JUMP)
    assert m.sum() > 500
    assert abs(np.median(err[m])) < 0.05, np.median(err[m])
    m = wall & (bd < rk) & (plane["border_kind"] == BORDER_JUMP)
    assert np.median((plane["border_distance"][m] - bd[m]) / spacing[m]) > 0.1


def test_pipe_boundaries_against_the_support_truth(pipes):
    """Boundary F1 of the pipes' points against the support truth (k = 50): with the
    borders on the cylinders 0.92 (with their tangent planes: 0.66), every false or
    missed boundary within 0.15 r_k of the 0.5 r_k band (measured 0.074)."""
    from lidarstat.synth import neighborhood_class_truth

    sc, res = pipes
    nbh = res.features.neighborhoods
    rk = nbh.distances.reshape(len(nbh), -1)[:, -1]
    truth = neighborhood_class_truth(sc, nbh) == PointClass.BOUNDARY
    names = np.array(sc.meta["face_names"]).astype(str)[sc.face]
    pipe = np.char.endswith(names, "_side")
    pred = res.point_class == PointClass.BOUNDARY
    tp = np.sum(pred & truth & pipe)
    f1 = 2 * tp / (np.sum(pred & pipe) + np.sum(truth & pipe))
    assert f1 > 0.9, f1
    wrong = pipe & (pred != truth)
    bd = sc.fields["boundary_distance"]
    assert np.all(np.abs(bd[wrong] / rk[wrong] - 0.5) < 0.15)
