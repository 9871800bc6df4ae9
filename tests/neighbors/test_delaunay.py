"""Planar Delaunay triangulation: Qhull's triangles for points in general position (seed
sweeps of three layouts), and a valid Delaunay triangulation of the degenerate sets a
terrain model meets (lattices of cell centres, copies, co-circular and collinear points),
checked by its defining properties rather than against one choice of diagonals."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from lidarstat.errors import InvalidPointsError
from lidarstat.neighbors import delaunay_triangles


def _as_set(tri):
    return set(map(tuple, np.sort(tri, axis=1).tolist()))


def _layout(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 4000))
    kind = seed % 3
    if kind == 0:
        return rng.uniform(0, 100, (n, 2))
    if kind == 1:
        return rng.normal(0, 10, (n, 2)) + [155000.0, 463000.0]  # national-grid offsets
    return np.c_[rng.uniform(0, 1000, n), rng.uniform(0, 3, n)]  # a long strip


@pytest.mark.parametrize("seed", range(12))
def test_equals_qhull_in_general_position(seed):
    """Against Qhull on coordinates about their middle: on national-grid coordinates
    (1.5e5 m offsets, 10 m spread) Qhull's own triangles fail the empty-circle test."""
    xy = _layout(seed)
    tri = delaunay_triangles(xy)
    assert _as_set(tri) == _as_set(Delaunay(xy - xy.mean(axis=0)).simplices)
    _check_delaunay(xy, tri)


def _check_delaunay(xy, tri):
    """The properties that define a Delaunay triangulation of the distinct points."""
    unique = np.unique(xy, axis=0)
    a = xy[tri[:, 1]] - xy[tri[:, 0]]
    b = xy[tri[:, 2]] - xy[tri[:, 0]]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    assert (cross > 0).all()  # counter-clockwise, none flat
    hull = ConvexHull(unique)
    assert abs(0.5 * cross.sum() - hull.volume) <= 1e-9 * hull.volume  # a tiling
    # every distinct location once; triangles 2U - h - 2 (h: points on the hull's edges)
    assert np.unique(tri).size == len(unique)
    eq = hull.equations
    off = np.abs(unique @ eq[:, :2].T + eq[:, 2]).min(axis=1)
    on_edge = off <= 1e-12 * np.abs(unique).max()
    assert len(tri) == 2 * len(unique) - on_edge.sum() - 2
    # empty circumcircles: no point strictly inside (relative tolerance 1e-9)
    d = 2.0 * cross
    aa, bb = (a ** 2).sum(1), (b ** 2).sum(1)
    ux = (b[:, 1] * aa - a[:, 1] * bb) / d
    uy = (a[:, 0] * bb - b[:, 0] * aa) / d
    centre = xy[tri[:, 0]] + np.c_[ux, uy]
    inside = cKDTree(unique).query_ball_point(centre, np.hypot(ux, uy) * (1 - 1e-9),
                                             return_length=True)
    assert (inside == 0).all()


_LATTICE = np.stack(np.meshgrid(np.arange(120.0) + 0.5, np.arange(80.0) + 0.5),
                    -1).reshape(-1, 2) * 2.0
_ANGLES = np.linspace(0, 2 * np.pi, 400, endpoint=False)


@pytest.mark.parametrize("name", ["lattice", "lattice with holes", "copies", "circle",
                                  "circle and centre", "two lattices", "thin strip",
                                  "centimetres"])
@pytest.mark.parametrize("seed", range(2))
def test_degenerate_sets_give_a_delaunay_triangulation(name, seed):
    rng = np.random.default_rng(seed)
    circle = np.c_[np.cos(_ANGLES), np.sin(_ANGLES)] * 50.0 + rng.uniform(-5, 5, 2)
    xy = {"lattice": _LATTICE + rng.integers(-1000, 1000, 2) * 2.0,
          "lattice with holes": _LATTICE[rng.random(len(_LATTICE)) < 0.6],
          "copies": np.r_[_LATTICE, _LATTICE[rng.integers(0, len(_LATTICE), 700)]],
          "circle": circle,
          "circle and centre": np.r_[circle, circle.mean(axis=0, keepdims=True)],
          "two lattices": np.r_[_LATTICE, _LATTICE + [0.25, 0.0]],
          "thin strip": np.c_[rng.uniform(0, 1000, 5000), rng.uniform(0, 1e-3, 5000)],
          "centimetres": rng.uniform(0, 60, (20000, 2)).round(2)}[name]
    _check_delaunay(xy, delaunay_triangles(xy))


def test_collinear_and_too_few_points_give_no_triangle():
    x = np.arange(50.0)
    assert delaunay_triangles(np.c_[x, 2 * x + 1]).shape == (0, 3)
    assert delaunay_triangles(np.zeros((2, 2))).shape == (0, 3)
    assert delaunay_triangles(np.ones((10, 2))).shape == (0, 3)  # one location


@pytest.mark.parametrize("bad", [np.zeros((5, 3)), np.array([[0.0, 0.0], [1.0, np.nan],
                                                              [2.0, 1.0]])])
def test_bad_input_is_refused(bad):
    with pytest.raises(InvalidPointsError, match="xy"):
        delaunay_triangles(bad)
