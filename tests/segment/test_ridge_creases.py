"""The crease test of ``ridges`` (``segment/_ridge_creases.py``) against a brute force:
every point of the cloud examined over its whole neighbourhood at once, where the test
searches each point it needs once, in blocks; and the crease lines climbing the ladder
against fits of every point at every rung. Seed sweeps on folds with random bands of
rejected jets."""

import numpy as np
import pytest

from lidarstat.features import FitStatus
from lidarstat.neighbors import KnnIndex, knn_neighbors
from lidarstat.segment import _ridge_creases as rc


def _brute_crease_points(points, fields, *, alpha, n_eff, radius=0.0, spacing=None):
    """The crease test of :func:`rc.crease_points` evaluated at every point over its whole
    neighbourhood (no subsets, no blocks): the obviously complete version."""
    n = points.shape[0]
    strong = (fields["status"] == FitStatus.MODEL_REJECTED) & (
        fields["chi2_p"] < alpha / max(1.0, n_eff))
    if n < 8 or not strong.any():
        return np.zeros(n, bool)
    spacing = rc.point_spacing(points) if spacing is None else spacing
    across_reach = max(rc.ACROSS * spacing, rc.REACH * radius)
    along_reach = max(rc.ALONG * spacing, rc.REACH * radius)
    band_reach = max(across_reach, float(radius))
    reach = max(band_reach, along_reach) / spacing
    k = min(max(rc.CREASE_K, int(np.ceil(1.5 * np.pi * reach * reach))), n)
    nb = knn_neighbors(points, k)
    idx, d = nb.indices.reshape(n, k), nb.distances.reshape(n, k)
    k10 = min(rc.NORMAL_K, n)
    x = points[knn_neighbors(points, k10).indices.reshape(n, k10)]
    x = x - x.mean(axis=1, keepdims=True)
    normals = np.linalg.eigh(np.einsum("nki,nkj->nij", x, x))[1][:, :, 0]
    ok = d <= band_reach
    nn = normals[idx] * ok[..., None]
    axis = np.linalg.eigh(np.einsum("nki,nkj->nij", nn, nn))[1][:, :, 0]
    c = np.cross(axis, normals)
    across_dir = c / np.maximum(np.linalg.norm(c, axis=1), 1e-12)[:, None]
    off = points[idx] - points[:, None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        cs = np.einsum("nkj,nj->nk", off, axis) / d
        side = np.where(np.einsum("nkj,nj->nk", off, across_dir) >= 0, 1.0, -1.0)
    cos = np.where(d > 0, side * np.sqrt(np.clip(1.0 - cs * cs, 0.0, 1.0)), 0.0)
    cone = (np.abs(cos) >= rc.COS_ACROSS) & (d > 0) & (d <= band_reach) & strong[idx]
    depth = np.minimum((cone & (cos > 0)).sum(axis=1), (cone & (cos < 0)).sum(axis=1))
    along = ((np.abs(cos) <= rc.COS_ALONG) & (d <= along_reach)) | (d == 0)
    smooth = (depth[idx] * along).sum(axis=1) / np.maximum(along.sum(axis=1), 1)
    across = (np.abs(cos) >= rc.COS_ACROSS) & (d > 0) & (d <= across_reach)
    higher = (((1.0 - rc.TOLERANCE) * smooth[idx] > smooth[:, None]) & across).any(axis=1)
    both = (across & (cos > 0)).any(axis=1) & (across & (cos < 0)).any(axis=1)
    return strong & ~higher & both & (smooth > 0)


def _banded_fold(seed):
    """A fold of two planes (random slopes, azimuth and spacing) with jets 'rejected' in
    a band about it of random width, ragged edges and scattered false rejections."""
    rng = np.random.default_rng(seed)
    spacing = float(rng.uniform(0.015, 0.03))
    g = np.arange(-0.5, 0.5 + spacing / 2, spacing)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    x = x + rng.uniform(-0.3, 0.3, x.size) * spacing
    y = y + rng.uniform(-0.3, 0.3, y.size) * spacing
    left, right = np.tan(np.radians(rng.uniform(10, 40, 2)))
    z = rng.choice([-1.0, 1.0]) * np.where(x < 0, left * x, -right * x)
    z = z + rng.normal(0, 0.002, x.size) + 0.05 * np.sin(3 * y) * rng.uniform(0, 1)
    th = float(rng.uniform(0, 2 * np.pi))
    c, s = np.cos(th), np.sin(th)
    pts = np.c_[c * x - s * y, s * x + c * y, z]
    pts -= pts.mean(axis=0)
    width = rng.uniform(2, 6) * spacing
    rejected = (np.abs(x) < width * rng.uniform(0.7, 1.3, x.size)) | (rng.random(x.size) < 0.03)
    status = np.where(rejected, int(FitStatus.MODEL_REJECTED), int(FitStatus.OK))
    fields = {"status": status.astype(np.uint8),
              "chi2_p": np.where(rejected, rng.uniform(0, 1e-6, x.size), rng.random(x.size))}
    radius = float(rng.uniform(3, 9) * spacing)
    return pts, fields, radius, spacing


@pytest.mark.parametrize("seed", range(12))
def test_crease_points_equal_the_brute_force(seed, monkeypatch):
    """Same crease points as the brute force, with the default blocks and with blocks of
    a few rows (each point is searched in the block of the pass that first needs it)."""
    pts, fields, radius, spacing = _banded_fold(seed)
    kw = dict(alpha=0.01, n_eff=pts.shape[0] / 50.0, radius=radius, spacing=spacing)
    want = _brute_crease_points(pts, fields, **kw)
    assert want.sum() >= 10  # the band has a centre line
    assert np.array_equal(rc.crease_points(pts, fields, **kw), want)
    monkeypatch.setattr(rc, "CREASE_BLOCK", 3 * rc.CREASE_K)
    assert np.array_equal(rc.crease_points(pts, fields, **kw), want)


@pytest.mark.parametrize("seed", range(4))
def test_knn_index_blocks_equal_one_query(seed):
    """Blocks of queries on one KnnIndex give the rows of knn_neighbors' single query."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(3000, 3)) * [50, 50, 5] + [6e5, 5e6, 100]
    whole = knn_neighbors(pts, 40)
    index = KnnIndex(pts)
    rows = rng.permutation(3000)
    for b in np.array_split(rows, 7):
        part = index.query(40, query=b)
        assert np.array_equal(part.indices.reshape(-1, 40), whole.indices.reshape(-1, 40)[b])
        assert np.array_equal(part.distances.reshape(-1, 40),
                              whole.distances.reshape(-1, 40)[b])


@pytest.mark.parametrize("seed", range(3))
def test_last_rung_fits_only_what_it_is_read_for(seed, monkeypatch):
    """Fitting every point at every rung leaves the crease points and lines unchanged:
    each jet depends on its own neighbourhood only, and of the last rung only the
    candidates' misfit is read."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
    from test_indep_creases import _fold

    from lidarstat.features import radius_ladder

    xyz = _fold(seed)[0]
    local = xyz - xyz.mean(axis=0)
    nb = knn_neighbors(local, 16)
    step = float(np.median(nb.distances[nb.indptr[1:] - 1]))
    radii = radius_ladder(local)
    radii = radii[rc.crease_rung(radii, 0.001):][:2]
    kw = dict(sigma=0.001, noise="z", sensor=None, weight="tricube", alpha=0.01,
              min_vertices=3, smooth=5)
    got = rc.find_creases(local, nb, step, radii, **kw)
    fitted = []
    variance_factor = rc.variance_factor

    def every_point(points, query, radius, **k):
        fitted.append(np.asarray(query).size)
        fields, factor = variance_factor(points, np.arange(points.shape[0]), radius, **k)
        return {key: np.asarray(v)[query] for key, v in fields.items()}, factor[query]

    monkeypatch.setattr(rc, "variance_factor", every_point)
    want = rc.find_creases(local, nb, step, radii, **kw)
    assert got.mask.any() and len(fitted) == 2 and fitted[1] < fitted[0] == local.shape[0]
    for name in ("mask", "line", "rung", "radii"):
        assert np.array_equal(getattr(got, name), getattr(want, name))
    for name, value in want.attributes.items():
        np.testing.assert_array_equal(got.attributes[name], value)
    assert len(got.vertices) == len(want.vertices)
    for a, b in zip(got.vertices, want.vertices):
        assert np.array_equal(a, b)
