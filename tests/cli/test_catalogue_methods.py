"""Every command on a catalogue: covariance and ridges give the whole-file answer with
their reach as buffer (field by field), segment joins its segments across the tiles
(its difference from the whole-file run measured), and info
summarises a catalogue and writes its tile index."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.io import read

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from test_catalogue import _assert_same_fields, _by_xyz, _cut
from test_catalogue_cli import _gather, _tiles


def _whole_fields(path):
    c = read(path)
    names = [k for k in c.attributes if k not in read(path.parent / "whole.laz").attributes]
    return c.xyz, {k: np.asarray(c.attributes[k]) for k in names}


def _run(args, capsys):
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return out.out


@pytest.mark.parametrize("seed, neighbourhood", [(0, ["--radius", "1.5"]),
                                                 (2, ["--k", "20"]),
                                                 (1, [])])  # the automatic scale
def test_covariance_on_a_catalogue_equals_the_whole_file(tmp_path, capsys, seed,
                                                         neighbourhood):
    _tiles(tmp_path, seed=seed)
    _run(["covariance", tmp_path / "whole.laz", tmp_path / "w.laz", *neighbourhood,
          "--sigma", "0.05", "-q"], capsys)
    xyz, whole = _whole_fields(tmp_path / "w.laz")
    out = _run(["covariance", tmp_path / "tiles", tmp_path / "out", *neighbourhood,
                "--sigma", "0.05"], capsys)
    assert "9 tiles processed" in out
    _assert_same_fields(_gather(tmp_path / "out", whole), (xyz, whole))


def test_covariance_estimates_one_sigma_for_the_area(tmp_path, capsys):
    _tiles(tmp_path, seed=3)
    out = _run(["covariance", tmp_path / "tiles", tmp_path / "out", "--radius", "1.5"],
               capsys)
    assert "used for every tile" in out


def test_ridges_jets_do_not_depend_on_the_tiling(tmp_path, capsys):
    """The jets (every Monge coefficient, test and sd) are the whole file's; the ridge
    points agree where the lines are traced the same (measured, not exact)."""
    _tiles(tmp_path, seed=4)
    _run(["ridges", tmp_path / "whole.laz", tmp_path / "w.laz", "--radius", "3",
          "--sigma", "0.05", "-q"], capsys)
    xyz, whole = _whole_fields(tmp_path / "w.laz")
    _run(["ridges", tmp_path / "tiles", tmp_path / "out", "--radius", "3", "--sigma",
          "0.05", "-q"], capsys)
    ridge_names = {"ridge", "ridge_line", "umbilic", "extremality"}
    (_, a), (_, b) = (_by_xyz(_gather(tmp_path / "out", whole)), _by_xyz((xyz, whole)))
    _assert_same_jets(a, b, set(b) - ridge_names)
    np.testing.assert_array_equal(a["umbilic"], b["umbilic"])
    assert np.mean(a["ridge"] == b["ridge"]) > 0.99
    assert len(list((tmp_path / "out").glob("*.ridges.geojson"))) == 9


def _assert_same_jets(a, b, names):
    """The fields `names` of the tiled run `a` equal the whole cloud's `b`: the same
    neighbour counts, and the floats where the fit is well posed."""
    np.testing.assert_array_equal(a["neighbors"], b["neighbors"])
    # a degree-4 jet has 15 coefficients: fits on fewer than twice that many points are
    # near-singular (condition numbers of 1e4 and more), their floats compared on the
    # decisions only, as the quadrics' fits on 7-9 points are
    posed = b["neighbors"] >= 30
    for name in names:
        if np.issubdtype(b[name].dtype, np.floating):
            scale = np.nanpercentile(np.abs(b[name]), 99) if np.isfinite(b[name]).any() else 1
            np.testing.assert_allclose(a[name][posed], b[name][posed], rtol=1e-6,
                                       atol=1e-6 * scale, equal_nan=True, err_msg=name)
        else:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def _agreement(a, b):
    """Share of points in the best-matching segment of the other labelling: for each
    segment of `a` its largest overlap with a segment of `b` (points in no segment in
    both count as agreeing)."""
    pairs, counts = np.unique(np.c_[a, b], axis=0, return_counts=True)
    best = {}
    for (x, y), c in zip(pairs.tolist(), counts.tolist()):
        if x == 0 or y == 0:
            best.setdefault(("none", x), 0)
            if x == 0 and y == 0:
                best[("none", x)] += c
            continue
        best[x] = max(best.get(x, 0), c)
    return sum(best.values()) / len(a)


def test_segment_ids_are_joined_over_the_area(tmp_path, capsys):
    """Segments crossing tile borders keep one id; every tile's table lists the segments
    of its points under those ids, with their points over the area."""
    _tiles(tmp_path, seed=5)
    _run(["segment", tmp_path / "whole.laz", tmp_path / "w.laz", "--method", "covariance",
          "--radius", "1.5", "--sigma", "0.05", "-q"], capsys)
    out = _run(["segment", tmp_path / "tiles", tmp_path / "out", "--method", "covariance",
                "--radius", "1.5", "--sigma", "0.05"], capsys)
    assert "9 tiles processed" in out
    _, ids = _gather(tmp_path / "out", ["segment_id"])
    ids = ids["segment_id"].astype(np.int64)
    found, counts = np.unique(ids[ids > 0], return_counts=True)
    assert found.tolist() == list(range(1, found.size + 1))  # numbered 1.. over the area
    for p in sorted((tmp_path / "out").glob("*.laz")):  # each tile's table: its segments
        table = (tmp_path / "out" / (p.stem + ".segments.csv")).read_text().splitlines()
        head = table[0].split(",")
        rows = {int(r.split(",")[0]): int(r.split(",")[head.index("n_points")])
                for r in table[1:]}
        assert set(rows) == set(np.unique(read(p)["segment_id"]).tolist()) - {0}
        assert all(rows[k] == counts[k - 1] for k in rows)
    xyz, whole = _whole_fields(tmp_path / "w.laz")
    (_, a), (_, b) = (_by_xyz(_gather(tmp_path / "out", ["segment_id"])),
                      _by_xyz((xyz, {"segment_id": whole["segment_id"]})))
    # the buffer: a tile's segments never mix two whole-file segments; the join: a
    # whole-file segment is one segment of the catalogue
    assert _agreement(a["segment_id"], b["segment_id"]) > 0.98
    assert _agreement(b["segment_id"], a["segment_id"]) > 0.98


def test_segment_table_option_is_refused_with_a_catalogue(tmp_path, capsys):
    _tiles(tmp_path, n=900)
    rc = main(["segment", str(tmp_path / "tiles"), str(tmp_path / "out"), "--method",
               "covariance", "--table", str(tmp_path / "t.csv")])
    assert rc == 2 and "--table: not with a catalogue" in capsys.readouterr().err


def test_info_of_a_catalogue_and_its_tile_index(tmp_path, capsys):
    _tiles(tmp_path, n=900)
    out = _run(["info", tmp_path / "tiles", "--tindex", tmp_path / "t.geojson"], capsys)
    assert "catalogue: 9 tiles, 900 points" in out and "no CRS" in out
    assert "covered by no tile 0.0 %, by several 0.0 %" in out
    doc = json.loads((tmp_path / "t.geojson").read_text())
    assert len(doc["features"]) == 9
    assert sum(f["properties"]["points"] for f in doc["features"]) == 900
    ring = doc["features"][0]["geometry"]["coordinates"][0]
    assert ring[0] == ring[-1] and len(ring) == 5
    d = json.loads(_run(["info", tmp_path / "tiles", "--json"], capsys))
    assert d["tiles"] == 9 and d["crs_consistent"]
    # one file stays the single-file description
    assert "catalogue:" not in _run(["info", tmp_path / "whole.laz"], capsys)


def test_info_reports_a_gap_and_mixed_crs(tmp_path, capsys):
    from lidarstat.io import PointCloud, write

    pts = np.random.default_rng(0).uniform(0, 10, (200, 3))
    write(tmp_path / "a.laz", PointCloud(pts, crs="EPSG:28992"))
    write(tmp_path / "b.laz", PointCloud(pts + [20, 0, 0], crs="EPSG:2154"))
    out = _run(["info", tmp_path / "a.laz", tmp_path / "b.laz"], capsys)
    assert "2 different CRSs" in out
    uncovered = float(out.split("covered by no tile ")[1].split(" %")[0])
    assert 30 < uncovered < 36  # 10 m of 30 m of the box's width


def test_an_option_the_tile_function_does_not_pass_is_refused(tmp_path, capsys, monkeypatch):
    """An option of the one-file command that the catalogue's tile function does not pass
    on is refused, never ignored (here: as if the tile function did not know --eigen-mode)."""
    from lidarstat.cli import _catalogue_methods

    _tiles(tmp_path, n=900)
    every = dict(_catalogue_methods.TILE_OPTIONS)
    every["covariance"] = every["covariance"] - {"eigen_mode"}
    monkeypatch.setattr(_catalogue_methods, "TILE_OPTIONS", every)
    rc = main(["covariance", str(tmp_path / "tiles"), str(tmp_path / "out"), "--radius", "2",
               "--eigen-mode", "sqrt"])
    assert rc == 2
    assert "--eigen-mode: not supported with a catalogue of tiles" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command, options", [
    ("covariance", ["--radius", "2", "--eigen-mode", "sqrt", "--curved", "variation"]),
    ("ridges", ["--radius", "6", "--ratio", "3", "--weight", "none"]),
    ("curvature", ["--radius", "2", "--frame", "pca", "--minimal-detectable"]),
])
def test_every_option_of_the_command_reaches_the_tiles(tmp_path, capsys, command, options):
    _tiles(tmp_path, n=900)
    _run([command, tmp_path / "tiles", tmp_path / "out", *options, "--sigma", "0.05", "-q"],
         capsys)
    assert len(list((tmp_path / "out").glob("*.laz"))) == 9


@pytest.mark.parametrize("command, options, words", [
    ("ridges", ["--radius", "6"], "used for every tile"),  # one sigma for the area
    ("segment", ["--method", "covariance", "--sigma", "0.05"], "buffer"),  # k-NN reach
])
def test_estimated_sigma_and_knn_reach(tmp_path, capsys, command, options, words):
    _tiles(tmp_path, n=900)
    out = _run([command, tmp_path / "tiles", tmp_path / "out", *options], capsys)
    assert words in out and "9 tiles processed" in out


def test_curvature_automatic_scale_is_decided_for_the_area(tmp_path, capsys):
    """No --radius: one ladder for the area (median of the sampled tiles' ladders), so
    every field of every point is the whole cloud's at that ladder."""
    from lidarstat.cli._catalogue_methods import area_ladder, curvature_ladder
    from lidarstat.features import curvature
    from lidarstat.pipeline import Catalogue

    whole, _ = _tiles(tmp_path, seed=6, n=4000)
    out = _run(["curvature", tmp_path / "tiles", tmp_path / "out", "--sigma", "0.05"],
               capsys)
    assert "automatic scale: radii" in out and "9 tiles processed" in out
    ladder = area_ladder(Catalogue(tmp_path / "tiles"), curvature_ladder)
    expected = curvature(whole.xyz, sigma=0.05, scales=ladder).to_fields()
    _assert_same_fields(_gather(tmp_path / "out", expected), (whole.xyz, expected))


def test_ridges_automatic_scale_is_decided_for_the_area(tmp_path, capsys):
    """No --radius or --k: the jets' ladder is decided once for the area and the buffer
    is three times its largest radius; the jets (and the radius each point chose) are
    then the whole cloud's at that ladder."""
    from lidarstat.cli._catalogue_methods import area_ladder, jet_ladder
    from lidarstat.pipeline import Catalogue
    from lidarstat.segment import ridges

    whole, _ = _tiles(tmp_path, seed=7, n=3000)
    out = _run(["ridges", tmp_path / "tiles", tmp_path / "out", "--sigma", "0.05"], capsys)
    assert "automatic scale: radii" in out and "9 tiles processed" in out
    ladder = area_ladder(Catalogue(tmp_path / "tiles"), jet_ladder)
    assert f"buffer {3 * max(ladder):g}" in out
    res = ridges(whole.xyz, sigma=0.05, alpha=0.01, scales=ladder)
    expected = {k: v for k, v in res.to_fields().items()
                if k not in {"ridge", "ridge_line", "umbilic", "extremality"}}
    (_, a), (_, b) = (_by_xyz(_gather(tmp_path / "out", expected)),
                      _by_xyz((whole.xyz, expected)))
    np.testing.assert_array_equal(a["radius"], b["radius"])
    _assert_same_jets(a, b, b)


@pytest.mark.parametrize("method, words", [("sar", "radius"), ("curvature", "radii"),
                                           ("ridges", "radius")])
def test_segment_automatic_scale_is_decided_for_the_area(tmp_path, capsys, method, words):
    """A scale the segmentation chooses from the data is chosen once for the area and
    sets the buffer: no --radius or --buffer needed."""
    from lidarstat.cli._catalogue_methods import area_ladder, curvature_ladder
    from lidarstat.features import curvature
    from lidarstat.pipeline import Catalogue

    whole, _ = _tiles(tmp_path, seed=8, n=3000)
    out = _run(["segment", tmp_path / "tiles", tmp_path / "out", "--method", method,
                "--sigma", "0.05"], capsys)
    assert f"automatic scale: {words}" in out and "9 tiles processed" in out
    if method == "curvature":  # the tested classes are local: the whole cloud's
        ladder = area_ladder(Catalogue(tmp_path / "tiles"), curvature_ladder)
        expected = {"surface_type": curvature(whole.xyz, sigma=0.05, scales=ladder,
                                              frame="pca").fields["surface_type"]}
        (_, a), (_, b) = (_by_xyz(_gather(tmp_path / "out", expected)),
                          _by_xyz((whole.xyz, expected)))
        np.testing.assert_array_equal(a["surface_type"], b["surface_type"])


def test_evaluate_two_catalogues_scores_the_area(tmp_path, capsys):
    """Tiles paired by name, their counts summed: the scores of the whole area (the same
    points in another order give the same confusion), and one line per unmatched tile."""
    from lidarstat.io import PointCloud, write

    rng = np.random.default_rng(7)
    n = 9000
    xy = rng.uniform(0, 60, (n, 2)) + [150000.0, 450000.0]
    ref_cls = rng.choice(np.array([1, 2, 6, 11], np.uint8), n)
    res_cls = np.where(rng.random(n) < 0.9, ref_cls, rng.choice(np.array([2, 6], np.uint8), n))
    xyz = np.c_[xy, rng.normal(0, 1, n)]
    write(tmp_path / "ref.laz", PointCloud(xyz, {"classification": ref_cls}))
    write(tmp_path / "res.laz", PointCloud(xyz, {"classification": res_cls}))
    _cut(read(tmp_path / "ref.laz"), tmp_path / "ref")
    _cut(read(tmp_path / "res.laz"), tmp_path / "res")
    for args, name in (([tmp_path / "res.laz", "--reference", tmp_path / "ref.laz"], "w"),
                       ([tmp_path / "res", "--reference", tmp_path / "ref"], "t")):
        _run(["evaluate", *args, "--classes", "--json", tmp_path / f"{name}.json", "-q"],
             capsys)
    whole, tiled = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "wt")
    assert tiled["ground_object"] == whole["ground_object"]
    assert tiled["classes"] == whole["classes"]
    assert len(tiled["tiles"]) == 9
    assert sum(t["ground_object"]["n"] for t in tiled["tiles"]) == n
    (tmp_path / "ref" / "tile_0_0.laz").unlink()
    rc = main(["evaluate", str(tmp_path / "res"), "--reference", str(tmp_path / "ref")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "tile_0_0.laz: no reference tile" in err[0]


@pytest.mark.parametrize("seed", range(5))
def test_each_line_is_written_by_exactly_one_tile(seed):
    """Tiles whose point bounds leave gaps between them (and may overlap): every line is
    kept by one tile, the one whose bounds hold its middle vertex when one does."""
    from types import SimpleNamespace

    from lidarstat.cli._catalogue_methods import _lines_in_tile
    from lidarstat.segment import Polylines

    g = np.random.default_rng(seed)
    lo = np.array([[x, y] for x in range(3) for y in range(3)], float) * 10.0
    extents = np.c_[lo + g.uniform(-0.5, 1.5, lo.shape), lo + 10 - g.uniform(-0.5, 1.5, lo.shape)]
    lines = Polylines([g.uniform(-2, 32, (int(g.integers(2, 6)), 3)) for _ in range(400)],
                      {"line_id": np.arange(1, 401)})
    mids = np.array([v[len(v) // 2, :2] for v in lines.vertices])
    kept = np.zeros(400, int)
    for i, e in enumerate(extents):
        tile = SimpleNamespace(xmin=e[0], ymin=e[1], xmax=e[2], ymax=e[3])
        ids = _lines_in_tile(lines, tile, extents, i).attributes["line_id"] - 1
        kept[ids] += 1
        inside = np.all((mids >= e[:2]) & (mids <= e[2:]), axis=1)
        alone = inside & (np.all((mids[:, None] >= extents[None, :, :2])
                                 & (mids[:, None] <= extents[None, :, 2:]), axis=2)
                          .sum(axis=1) == 1)
        assert np.isin(np.flatnonzero(alone), ids).all()
    assert (kept == 1).all()
