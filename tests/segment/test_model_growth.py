"""Growth of units by their fitted models (:mod:`lidarstat.segment._model_growth`): the
bands left without a tested class along the creases of a plane and a half-cylinder go to
the face they lie on, and no point crosses a crease."""

import numpy as np
import pytest

from lidarstat.neighbors import knn_neighbors, radius_neighbors
from lidarstat.segment._model_growth import UnitModels, free_pairs, grow_by_models

SIGMA = 0.005


def _bump(seed, spacing=0.05, radius=1.0, half=2.5, length=3.0):
    """A half-cylinder (axis y, radius 1) lying on the plane z = 0: two 90-degree
    creases at x = +-1; noise along the normal. Returns points, true face (1 cylinder,
    2 plane), the distance along the surface to the nearest crease and the normals."""
    rng = np.random.default_rng(seed)
    y = np.arange(0, length, spacing)
    xs = np.arange(-half, half, spacing)
    xs = xs[np.abs(xs) > radius]
    px, py = (a.ravel() for a in np.meshgrid(xs, y, indexing="ij"))
    plane = np.c_[px, py, rng.normal(0, SIGMA, px.size)]
    th = np.arange(spacing / radius / 2, np.pi, spacing / radius)
    ct, cy = (a.ravel() for a in np.meshgrid(th, y, indexing="ij"))
    r = radius + rng.normal(0, SIGMA, ct.size)
    cyl = np.c_[r * np.cos(ct), cy, r * np.sin(ct)]
    pts = np.r_[cyl, plane]
    face = np.r_[np.ones(ct.size, int), np.full(px.size, 2)]
    dist = np.r_[radius * np.minimum(ct, np.pi - ct), np.abs(px) - radius]
    normal = np.r_[np.c_[np.cos(ct), np.zeros(ct.size), np.sin(ct)],
                   np.tile([0.0, 0.0, 1.0], (px.size, 1))]
    return pts, face, dist, normal


@pytest.mark.parametrize("seed", range(3))
def test_bands_along_creases_join_their_face(seed):
    pts, face, dist, normal = _bump(seed)
    band = dist < 0.4  # eight spacings on each side of each crease
    # units: the cylinder's top, and the plane's two sides (one unit each)
    labels = np.where(band, 0, np.where(face == 1, 1, np.where(pts[:, 0] < 0, 2, 3)))
    knn = knn_neighbors(pts, 9)
    src, dst = knn.edges()
    src, dst = np.r_[src, dst], np.r_[dst, src]
    models = UnitModels(pts, labels, np.array([True, False, False]), normal, SIGMA)
    assert models.kind.tolist() == [2, 1, 1]
    assert abs(models.radius[0] - 1.0) < 0.01
    out, joined = grow_by_models(pts, labels, src, dst, models)
    assert joined[band].mean() > 0.97
    right = np.where(face == 1, out == 1, np.isin(out, (2, 3)))
    # beyond 3 noise units of a crease, a point fits one face only
    clear = band & (dist > 3 * SIGMA * 3)
    assert right[clear & joined].mean() > 0.995
    assert not (out[~band] != labels[~band]).any()


def test_no_model_no_growth():
    """A unit whose points the noise model rejects as a plane and that is not curved gets
    no model, and nothing joins it."""
    rng = np.random.default_rng(7)
    pts = np.c_[rng.uniform(0, 1, (400, 2)), rng.normal(0, 10 * SIGMA, 400)]
    labels = np.r_[np.ones(300, int), np.zeros(100, int)]
    models = UnitModels(pts, labels, np.array([False]), np.zeros_like(pts), SIGMA)
    assert models.kind.tolist() == [0]
    knn = knn_neighbors(pts, 9)
    src, dst = knn.edges()
    out, joined = grow_by_models(pts, labels, np.r_[src, dst], np.r_[dst, src], models)
    assert not joined.any() and np.array_equal(out, labels)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("kind", ["knn", "radius", "query"])
def test_free_pairs_are_the_growth_pairs_of_the_whole_graph(seed, kind):
    """:func:`free_pairs` gives exactly what :func:`grow_by_models` keeps of the pairs of
    both directions of the whole graph (same pairs, same order, int64), on kNN rows,
    radius rows of varying length and rows of a subset of query points."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, (600, 3))
    if kind == "knn":
        nbh = knn_neighbors(pts, 9)
    elif kind == "radius":
        nbh = radius_neighbors(pts, 0.15)
    else:
        nbh = radius_neighbors(pts, 0.15, query=rng.choice(600, 250, replace=False))
    free = rng.uniform(size=600) < [0.02, 0.3, 0.9, 0.5][seed]
    s, d = nbh.edges()
    src, dst = np.r_[s, d], np.r_[d, s]
    keep = free[src]
    got_src, got_dst = free_pairs(nbh, free)
    assert got_src.dtype == got_dst.dtype == np.int64
    np.testing.assert_array_equal(got_src, src[keep])
    np.testing.assert_array_equal(got_dst, dst[keep])
    none_src, _ = free_pairs(nbh, np.zeros(600, dtype=bool))
    assert none_src.size == 0
