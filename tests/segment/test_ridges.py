"""Ridges from fourth-order jets: found where they are, nowhere else; the direct segmentation."""

import json

import numpy as np
import pytest

from lidarstat.cli._app import main
from lidarstat.errors import InvalidParameterError
from lidarstat.io import PointCloud, read, write
from lidarstat.segment import ridge_segments, ridges
from lidarstat.synth import make_cylinder, make_sphere_cap

A, S = 0.4, 0.5  # Gaussian crest z = A exp(-x^2 / 2 S^2)
SPACING = 0.02
SIGMA = 0.001


def _crest(sign, rng=0):
    rng = np.random.default_rng(rng)
    g = np.arange(-1.2, 1.2 + 1e-9, SPACING)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    x = x + rng.uniform(-0.3, 0.3, x.size) * SPACING
    y = y + rng.uniform(-0.3, 0.3, y.size) * SPACING
    z = sign * A * np.exp(-x * x / (2 * S * S)) + rng.normal(0, SIGMA, x.size)
    return np.c_[x, y, z]


def _flank_extremum():
    """|x| where the profile curvature kappa = f''/(1 + f'^2)^1.5 is extremal on the flank."""
    x = np.linspace(0.5, 1.2, 200001)
    e = np.exp(-x * x / (2 * S * S))
    f1 = -A * x / S**2 * e
    f2 = A * (x * x / S**4 - 1 / S**2) * e
    return float(x[np.argmax(f2 / (1 + f1 * f1) ** 1.5)])


@pytest.fixture(scope="module")
def crest_result():
    pts = _crest(1.0)
    return pts, ridges(pts, radius=0.25, sigma=SIGMA, alpha=0.05)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_gaussian_crest_and_trench_ridges_where_they_are(sign, crest_result):
    """Crest of a Gaussian ridge on x = 0 and ravines on the flanks where the profile
    curvature is extremal; a trench swaps the two. Away from the patch border (a jet radius),
    the vertices of the main lines lie within half a point spacing of the true line in the
    median (90% within 1.5 spacings, all within 2), the flank lines (weaker: |k''| 4x smaller) within two spacings in the
    median; the main lines span the patch."""
    if sign > 0:
        pts, res = crest_result
    else:
        pts = _crest(-1.0)
        res = ridges(pts, radius=0.25, sigma=SIGMA, alpha=0.05)
    main_type, flank_type = (1, 2) if sign > 0 else (2, 1)
    a = res.lines.attributes
    lines = res.lines.vertices
    xf = _flank_extremum()
    inner = 1.2 - 0.25

    def deviations(t, ref):
        dev = [np.abs(np.abs(v[:, 0]) - ref)[np.abs(v[:, 1]) < inner]
               for v, tt in zip(lines, a["ridge"]) if tt == t]
        return np.concatenate(dev) if dev else np.empty(0)

    main = [v for v, t in zip(lines, a["ridge"]) if t == main_type]
    assert main, "no line of the main type"
    dev = deviations(main_type, 0.0)
    assert np.median(dev) < 0.5 * SPACING and np.quantile(dev, 0.9) < 1.5 * SPACING, dev
    assert dev.max() < 2 * SPACING
    covered = np.concatenate([v[:, 1] for v in main])
    assert covered.min() < -0.8 and covered.max() > 0.8
    assert sum(np.ptp(v[:, 1]) for v in main) > 0.8 * 1.9
    # the flank ravines (|k''| about 4x weaker) are fragmented at this noise: any piece
    # longer than the minimum length lies within two spacings of the truth in the median
    dev = deviations(flank_type, xf)
    if dev.size:
        assert np.median(dev) < 2 * SPACING, np.median(dev)
    # per-point labels: on the lines, and strength/sharpness positive
    lab = res["ridge"]
    on_main = np.isin(res["ridge_line"], a["line_id"][a["ridge"] == main_type])
    assert np.all(np.abs(pts[on_main, 0]) < 3 * SPACING)
    assert np.all(a["strength"] > 0) and np.all(a["sharpness"] > 0)
    assert np.all(a["length"] >= 0.5)  # twice the jet radius
    k_main = a["mean_k"][a["ridge"] == main_type]
    assert np.all(np.sign(k_main) == -sign)


@pytest.mark.parametrize("surface", ["sphere", "cylinder", "plane"])
def test_no_ridges_on_spheres_cylinders_planes(surface):
    rng = np.random.default_rng(3)
    if surface == "sphere":
        cloud = make_sphere_cap(1.0, spacing=SPACING, sigma=SIGMA, rng=rng).xyz
    elif surface == "cylinder":
        cloud = make_cylinder(0.8, spacing=SPACING, sigma=SIGMA, rng=rng).xyz
    else:
        g = np.arange(-1, 1, SPACING)
        x, y = [a.ravel() for a in np.meshgrid(g, g)]
        cloud = np.c_[x, y, 0.1 * x - 0.2 * y + rng.normal(0, SIGMA, x.size)]
    res = ridges(cloud, radius=0.25, sigma=SIGMA, alpha=0.05)
    assert len(res.lines) == 0
    assert (res["ridge"] > 0).mean() == 0
    if surface == "sphere":
        inner = np.hypot(cloud[:, 0], cloud[:, 1]) < 0.5
        assert res["umbilic"][inner].mean() > 0.9


def test_direct_segmentation_cuts_along_the_crest(crest_result):
    pts, res = crest_result
    seg = ridge_segments(pts, res, min_points=100)
    lab = seg.labels
    big = np.bincount(lab)[1:].argsort()[::-1][:2] + 1
    # the two largest regions lie on either side of the crest
    sides = [np.sign(np.median(pts[lab == b, 0])) for b in big]
    assert sorted(sides) == [-1.0, 1.0]
    for b in big:
        x = pts[lab == b, 0]
        assert np.mean(np.sign(x) == np.sign(np.median(x))) > 0.99
    assert seg.method == "ridges" and "ridge" in seg.fields


def test_ridges_errors():
    pts = _crest(1.0)[:500]
    with pytest.raises(InvalidParameterError, match="ratio"):
        ridges(pts, radius=0.25, ratio=0.5)
    with pytest.raises(InvalidParameterError, match="at most one"):
        ridges(pts, radius=0.25, k=30)


def test_cli_ridges_and_segment(tmp_path, crest_result):
    pts, _ = crest_result
    src = tmp_path / "crest.npz"
    write(src, PointCloud(xyz=pts, attributes={"intensity": np.arange(len(pts)) % 7}))
    out = tmp_path / "out.npz"
    summary = tmp_path / "s.json"
    assert main(["ridges", str(src), str(out), "--radius", "0.25", "--sigma", str(SIGMA),
                 "--alpha", "0.05", "--summary-json", str(summary), "-q"]) == 0
    cloud = read(out)
    for name in ("ridge", "k1", "k2", "b0", "c4", "c4_sd", "d1x", "umbilic", "chi2_pass",
                 "intensity"):
        assert name in cloud.attributes, name
    lines = json.loads((tmp_path / "out.ridges.geojson").read_text())
    assert lines["type"] == "FeatureCollection" and len(lines["features"]) >= 1
    assert json.loads(summary.read_text())["n_lines"] == len(lines["features"])
    seg_out = tmp_path / "seg.npz"
    assert main(["segment", str(src), str(seg_out), "--method", "ridges", "--radius", "0.25",
                 "--sigma", str(SIGMA), "--alpha", "0.05", "--min-points", "100", "-q"]) == 0
    seg = read(seg_out)
    assert seg.attributes["segment_id"].max() >= 2
    for name in ("ridge", "crease", "barrier"):
        assert name in seg.attributes, name
    assert (tmp_path / "seg.segments.csv").exists()


@pytest.mark.parametrize("scene", ["agpart", "column"])
def test_scan_scenes_cut_along_their_true_edges(scene):
    """agpart-like and column-like range scans (noise 0.0015 dm, jet radius 0.2 dm): the
    ridge points lie on the true creases (95% within 2.5 point spacings of an edge); the
    direct segmentation (ridge band + chi-square rejections as barriers, barrier points
    assigned by the units' jets) recovers every connected face (Hoover T = 0.8), and the
    boundaries between its units cover at least 85% of the visible crease length within a
    point spacing (0.02 dm), 99% of them within 2.5 spacings of a true edge. Measured:
    agpart 6/6, column 5/5; docs/methods/jets.md."""
    from lidarstat.neighbors import knn_neighbors
    from lidarstat.segment import components, crease_coverage, hoover
    from lidarstat.synth import make_agpart, make_column

    sigma = 0.0015
    sc = (make_agpart if scene == "agpart" else make_column)(sigma=sigma, rng=0)
    res = ridges(sc.xyz, radius=0.2, sigma=sigma, alpha=0.01)
    rp = res["ridge"] > 0
    assert rp.sum() > 300
    assert np.mean(sc.edge_distance[rp] < 0.05) > 0.95
    assert np.all(sc.edge_distance[rp] < 0.2)
    seg = ridge_segments(sc.xyz, res)
    # truth units: the connected parts of each face (agpart's shaft side is seen as two
    # patches, above and below the disk, which no method can join)
    nb = knn_neighbors(sc.xyz, 8)
    src = np.repeat(np.arange(len(sc.xyz)), np.diff(nb.indptr))
    parts = components(nb, edge_ok=sc.face[src] == sc.face[nb.indices])
    h = hoover(seg.labels, parts, min_points=50)
    assert h.correct == h.n_truth == (6 if scene == "agpart" else 5)
    crease = seg.fields["crease"] > 0
    cov = crease_coverage(sc.meta["creases"], sc.xyz[crease], 0.02,
                          points=sc.meta["xyz_true"], faces=sc.face)
    assert cov.ratio > 0.85, cov.ratio
    assert np.mean(sc.edge_distance[crease] < 0.05) > 0.99
    assert np.mean(sc.edge_distance[crease] < 0.02) > 0.75


def test_min_size_is_a_deprecated_spelling_of_min_points(crest_result):
    from lidarstat.errors import LidarstatDeprecationWarning

    pts, res = crest_result
    new = ridge_segments(pts, res, min_points=100)
    with pytest.warns(LidarstatDeprecationWarning, match="min_size is deprecated"):
        old = ridge_segments(pts, res, min_size=100)
    np.testing.assert_array_equal(new.labels, old.labels)
    assert new.params["min_points"] == 100 and "min_size" not in new.params


def test_k_of_the_growing_graph_is_grow_k(crest_result):
    from lidarstat.errors import LidarstatDeprecationWarning

    pts, res = crest_result
    new = ridge_segments(pts, res, grow_k=10, min_points=100)
    with pytest.warns(LidarstatDeprecationWarning, match="k is deprecated; use grow_k"):
        old = ridge_segments(pts, res, k=10, min_points=100)
    np.testing.assert_array_equal(new.labels, old.labels)
    assert new.params["grow_k"] == 10


def test_segmentation_routes_k_to_the_jets_only(crest_result):
    """One vocabulary: ``k`` is the jets' neighbourhood, the growing graph is ``grow_k``."""
    from lidarstat.pipeline import segmentation

    pts, _ = crest_result
    seg = segmentation(pts, method="ridges", k=200, sigma=SIGMA, alpha=0.05, min_points=100)
    assert seg.params["k"] == 200 and seg.params["grow_k"] == 8


def test_ridge_result_params(crest_result):
    _, res = crest_result
    p = res.params
    assert p["sigma"] == res.jets.sigma and p["alpha"] == 0.05 and p["weight"] == "tricube"
    assert res.jets.params["noise"] == "z" and res.jets.params["radius"] == 0.25
    assert "jets of degree 4" in res.jets.summary()


def test_segment_curvature_speaks_the_shared_vocabulary():
    """segment_curvature: min_points and search (min_size, threshold deprecated)."""
    from lidarstat.errors import LidarstatDeprecationWarning
    from lidarstat.segment import segment_curvature

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (3000, 2))
    z = np.where(xy[:, 0] < 5, 0.0, 0.2 * (xy[:, 0] - 5) ** 2) + rng.normal(0, 0.005, 3000)
    pts = np.c_[xy, z]
    new = segment_curvature(pts, radius=1.0, sigma=0.005, min_points=40)
    with pytest.warns(LidarstatDeprecationWarning, match="min_size is deprecated"):
        old = segment_curvature(pts, radius=1.0, sigma=0.005, min_size=40)
    np.testing.assert_array_equal(new.labels, old.labels)
    assert new.params["min_points"] == 40 and new.params["sigma"] == 0.005
    assert new.params["noise"] == "z"


def test_cli_ridges_at_the_automatic_scale(tmp_path, capsys):
    """`lidarstat ridges IN OUT` runs with no scale argument, prints the scale it chose,
    writes it per point (`radius`) and in the summary, and finds the crest;
    `segment --method ridges` runs without a scale too (one radius from the data: the
    smallest of the ladder, what its crease barriers need)."""
    rng = np.random.default_rng(11)
    g = np.arange(-0.6, 0.6 + 1e-9, SPACING)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    z = 0.3 * np.exp(-x * x / (2 * 0.15**2)) + rng.normal(0, SIGMA, x.size)
    src = tmp_path / "narrow.npz"
    write(src, PointCloud(xyz=np.c_[x, y, z]))
    out = tmp_path / "out.npz"
    summary = tmp_path / "s.json"
    assert main(["ridges", str(src), str(out), "--summary-json", str(summary)]) == 0
    text = capsys.readouterr().out
    assert "scale: automatic, radius median" in text
    meta = json.loads(summary.read_text())
    assert meta["scale"] == "auto" and meta["params"]["radii"]
    cloud = read(out)
    r = cloud.attributes["radius"]
    assert np.all(np.isin(r, meta["params"]["radii"]))
    crest = cloud.attributes["ridge"] == 1
    inner = np.abs(y) < 0.4
    assert np.mean(np.abs(x[crest & inner]) <= SPACING + 1e-9) > 0.9  # within a spacing
    assert np.ptp(y[crest & (np.abs(x) < SPACING)]) > 0.8
    seg_out = tmp_path / "seg.npz"
    seg_json = tmp_path / "seg.json"
    assert main(["segment", str(src), str(seg_out), "--method", "ridges", "-q",
                 "--summary-json", str(seg_json)]) == 0
    assert read(seg_out).attributes["segment_id"].max() >= 1
    used = json.loads(seg_json.read_text())
    assert np.isclose(used["params"]["radius"], min(meta["params"]["radii"]))
