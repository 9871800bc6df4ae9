"""Airborne scenes: classes, roof planes, returns, intensities and footprints checked
against the scene's geometry (plane equations, height above the analytic terrain,
point-in-polygon tests) and the scan model (pulse density, return bookkeeping)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.synth import SCENES, make_als_town, make_hip_roof_scene


@pytest.fixture(scope="module")
def town():
    return make_als_town(extent=(110.0, 90.0), density=6.0, rng=3)


@pytest.fixture(scope="module")
def hip():
    return make_hip_roof_scene(rng=4)


def _in_polygon(px, py, poly):
    """Even-odd rule, vectorised over points."""
    inside = np.zeros(px.shape, dtype=bool)
    x, y = poly[:, 0], poly[:, 1]
    for i in range(len(poly)):
        x0, y0, x1, y1 = x[i - 1], y[i - 1], x[i], y[i]
        cross = (y0 > py) != (y1 > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (px < xi)
    return inside


@pytest.mark.parametrize("scene", ["town", "hip"])
def test_roof_plane_points_satisfy_their_plane(scene, request):
    c = request.getfixturevalue(scene)
    rp = c.meta["roof_planes"]
    pid = c.fields["roof_plane"]
    on = pid > 0
    assert on.sum() > 1000
    n, d = rp["normal"][pid[on] - 1], rp["offset"][pid[on] - 1]
    assert np.allclose(np.linalg.norm(rp["normal"], axis=1), 1.0)
    assert np.all(rp["normal"][:, 2] > 0)
    res_true = np.einsum("ij,ij->i", c.meta["xyz_true"][on], n) - d
    assert np.abs(res_true).max() < 1e-8
    res = np.einsum("ij,ij->i", c.xyz[on], n) - d
    # noise along near-vertical rays: residual std = sigma * |n . ray| <= sigma
    assert res.std() < 1.05 * c.sigma and res.std() > 0.7 * c.sigma
    assert np.allclose(c.normal[on], n)
    # ids are consistent with the table and the buildings
    assert np.array_equal(rp["building_id"][pid[on] - 1], c.fields["building_id"][on])
    assert np.array_equal(np.bincount(pid, minlength=len(rp["id"]) + 1)[1:], rp["n_points"])
    assert np.all(c.attributes["classification"][on] == 6)


def test_class_proportions_and_rules(town):
    cls = town.attributes["classification"]
    assert np.array_equal(cls, town.fields["true_class"])
    frac = {k: np.mean(cls == k) for k in (1, 2, 3, 4, 5, 6, 7, 11)}
    assert 0.5 < frac[2] + frac[11] < 0.9
    assert 0.04 < frac[11] < 0.25
    assert 0.05 < frac[6] < 0.35
    assert 0.01 < frac[3] + frac[4] + frac[5] < 0.2
    assert frac[3] > 0 and frac[4] > 0
    assert 0.001 < frac[1] < 0.03
    assert 0.001 < frac[7] < 0.004
    hag = town.fields["height_above_ground"]
    veg = np.isin(cls, (3, 4, 5))
    assert np.array_equal(cls[veg], np.where(hag[veg] < 0.5, 3, np.where(hag[veg] < 2, 4, 5)))
    ground = np.isin(cls, (2, 11))
    assert np.abs(hag[ground]).max() < 1e-6  # true points on the terrain
    noise = cls == 7
    assert np.all(np.abs(hag[noise]) > 1.0)
    # no roof plane / building outside class 6; cars are class 1 at car height
    assert np.all(town.fields["roof_plane"][cls != 6] == 0)
    assert np.all(town.fields["building_id"][cls != 6] == 0)
    assert np.all((hag[cls == 1] > -0.5) & (hag[cls == 1] < 2.0))


def test_returns_are_consistent(town):
    rn = town.attributes["return_number"]
    nr = town.attributes["number_of_returns"]
    assert np.all((rn >= 1) & (rn <= nr)) and nr.max() >= 3
    pulse = town.fields["pulse_id"]
    order = np.lexsort((rn, pulse))
    p, r, n = pulse[order], rn[order], nr[order]
    rng_ = town.fields["range"][order]
    first = np.r_[True, p[1:] != p[:-1]]
    starts = np.flatnonzero(first)
    counts = np.diff(np.r_[starts, p.size])
    # every pulse has returns 1..n exactly once, n equal on all its echoes
    assert np.array_equal(counts, n[starts])
    assert np.array_equal(r, np.arange(p.size) - np.repeat(starts, counts) + 1)
    same = ~first
    assert np.all(n[same] == n[np.flatnonzero(same) - 1])
    # later returns are farther along the pulse, at least 1.5 m apart
    assert np.all(rng_[same] - rng_[np.flatnonzero(same) - 1] >= 1.5 - 1e-9)
    # single returns dominate; multiple returns come from vegetation
    multi = nr > 1
    cls = town.attributes["classification"]
    assert np.mean(multi) < 0.2
    firsts = multi & (rn == 1)
    assert np.all(np.isin(cls[firsts], (3, 4, 5, 7)))


def test_trees_overhang_roofs(town, hip):
    for c in (town, hip):
        assert any(t["overhangs"] for t in c.meta["trees"])
        pulse = c.fields["pulse_id"]
        cls = c.attributes["classification"]
        veg_first = pulse[(c.attributes["return_number"] == 1) & (cls == 5)]
        roof_last = pulse[(c.attributes["return_number"] == c.attributes["number_of_returns"])
                          & (c.fields["roof_plane"] > 0)]
        assert np.intersect1d(veg_first, roof_last).size > 5


def test_intensity_separates_roads(town):
    inten = town.attributes["intensity"].astype(float)
    mat = town.fields["material"]
    road, grass = inten[mat == 3], inten[mat == 1]
    assert np.percentile(road, 95) < np.percentile(grass, 5)
    assert np.median(road) < 0.3 * np.median(grass)
    # the range / incidence effect: intensity / reflectance varies with the scan
    assert road.std() / road.mean() > 0.1


def test_footprints_and_roof_parts(town):
    cls = town.attributes["classification"]
    xyz = town.meta["xyz_true"]
    bid = town.fields["building_id"]
    rp = town.fields["roof_plane"]
    for b in town.meta["buildings"]:
        m = (bid == b["id"]) & (rp > 0)
        if not m.any():
            continue
        inside = _in_polygon(xyz[m, 0], xyz[m, 1], b["footprint"])
        assert inside.mean() > 0.999
    names = np.array(town.meta["face_names"])
    face = town.face
    named = face >= 0
    fn = np.full(face.size, "", dtype=object)
    fn[named] = names[face[named]]
    chim = np.array(["chimney" in s for s in fn])
    cheek = np.array(["cheek" in s or "_front" in s for s in fn])
    dormer_roof = np.array(["dormer" in s and "_roof" in s for s in fn])
    assert chim.sum() > 0 and dormer_roof.sum() > 0
    assert np.all(rp[chim] == 0) and np.all(cls[chim] == 6)
    assert np.all(rp[cheek] == 0)
    assert np.all(rp[dormer_roof] > 0)
    # each roof type is present
    assert {"flat", "gable", "hip", "L"} <= {b["roof"] for b in town.meta["buildings"]}
    # the L-shaped roofs have four planes
    for b in town.meta["buildings"]:
        if b["roof"] == "L":
            ids = np.flatnonzero(town.meta["roof_planes"]["building_id"] == b["id"])
            assert len(ids) == 4


def test_scan_density_and_angles(town):
    W, H = town.meta["extent"]
    n_pulses = town.meta["n_pulses"]
    assert abs(n_pulses / (W * H) / 6.0 - 1) < 0.05
    ang = town.attributes["scan_angle"] * 0.006
    assert np.abs(ang).max() <= 20.0
    # ground density of last returns on open ground close to the nominal density
    cls = town.attributes["classification"]
    g = np.isin(cls, (2, 11)) & (town.attributes["number_of_returns"] == 1)
    assert g.sum() / (W * H) < 6.0


def test_hip_roof_scene_like_the_paper(hip):
    assert 27000 < len(hip) < 34000
    hp = hip.meta["hip_planes"]
    counts = hip.meta["roof_planes"]["n_points"]
    for name, (ns, nsa, m) in hip.meta["paper_table6"].items():
        assert 0.7 * m < counts[hp[name] - 1] < 1.4 * m
    normals = hip.meta["roof_planes"]["normal"]
    # compass orientation of the planes
    assert normals[hp["North"] - 1][1] > 0.4 and normals[hp["South"] - 1][1] < -0.4
    assert normals[hp["East"] - 1][0] > 0.4 and normals[hp["West"] - 1][0] < -0.4
    gable_planes = np.flatnonzero(hip.meta["roof_planes"]["building_id"] == 2)
    assert gable_planes.size == 2


def test_determinism_and_layout_seed():
    a = make_als_town(extent=(60, 60), density=2, rng=1)
    b = make_als_town(extent=(60, 60), density=2, rng=1)
    assert np.array_equal(a.xyz, b.xyz)
    assert np.array_equal(a.attributes["intensity"], b.attributes["intensity"])
    c = make_als_town(extent=(60, 60), density=2, rng=2)
    assert not np.array_equal(a.xyz[:100], c.xyz[:100])
    assert [x["footprint"].tolist() for x in a.meta["buildings"]] == \
        [x["footprint"].tolist() for x in c.meta["buildings"]]


def test_invalid_parameters():
    with pytest.raises(InvalidParameterError, match="density"):
        make_als_town(density=0)
    with pytest.raises(InvalidParameterError, match="extent"):
        make_als_town(extent=(10, 10))
    with pytest.raises(InvalidParameterError, match="swath"):
        make_als_town(extent=(200, 1000), altitude=100)


def test_cli_writes_standard_las_fields(tmp_path):
    laspy = pytest.importorskip("laspy", reason="LAS output needs laspy")
    from lidarstat.cli._app import main

    assert SCENES["hip_roof"] is make_hip_roof_scene and SCENES["als_town"] is make_als_town
    out = tmp_path / "hip.las"
    assert main(["synth", "hip_roof", str(out), "--seed", "4"]) == 0
    las = laspy.read(out)
    c = make_hip_roof_scene(rng=4)
    assert np.array_equal(np.asarray(las.classification), c.attributes["classification"])
    assert np.array_equal(np.asarray(las.intensity), c.attributes["intensity"])
    assert np.array_equal(np.asarray(las.return_number), c.attributes["return_number"])
    assert np.array_equal(np.asarray(las.roof_plane), c.fields["roof_plane"])
    assert np.allclose(las.x, c.xyz[:, 0], atol=1e-4)


def test_surface_echoes_are_first_hits(hip):
    """Between the aircraft and a last echo there is neither a solid nor the terrain
    (independent point-in-solid tests along the pulse)."""
    c = hip
    last = (c.attributes["return_number"] == c.attributes["number_of_returns"]) & \
        (c.attributes["classification"] != 7) & (c.fields["tree_id"] == 0)
    idx = np.random.default_rng(0).choice(np.flatnonzero(last), 3000, replace=False)
    p = c.meta["xyz_true"][idx]
    o = c.meta["pulse_origin"][c.fields["pulse_id"][idx]]
    ter = c.meta["terrain"]
    for frac in np.linspace(0.9, 0.99999, 30):  # the last 10 % of the way down
        q = o + frac * (p - o)
        assert np.all(q[:, 2] > ter.z(q[:, 0], q[:, 1]))
        for solid in c.meta["solids"]:
            assert not solid.contains(q).any()
    # and the echo lies on the terrain or on a face of a solid
    on_face = c.face[idx] >= 0
    assert np.allclose(p[~on_face, 2], ter.z(p[~on_face, 0], p[~on_face, 1]), atol=1e-9)
    faces = c.meta["faces"]
    res = [abs(np.dot(faces[f]["normal"], q - faces[f]["point"]))
           for f, q in zip(c.face[idx][on_face], p[on_face])]
    assert max(res) < 1e-8


def test_overlapping_strips():
    c = make_als_town(extent=(80, 120), density=3, rng=0, strips=2)
    psid = c.attributes["point_source_id"]
    assert set(np.unique(psid)) == {1, 2}
    (a0, a1, af), (b0, b1, bf) = c.meta["strips"]
    assert a1 > b0  # the bands overlap
    y = c.xyz[:, 1]
    last = c.attributes["return_number"] == c.attributes["number_of_returns"]
    both = last & (y > b0 + 2) & (y < a1 - 2)
    one = last & (y < b0 - 2)
    dens_both = both.sum() / (80 * (a1 - b0 - 4))
    dens_one = one.sum() / (80 * (b0 - 2))
    assert 1.7 < dens_both / dens_one < 2.3
    # scan angles are measured from each strip's own flight line
    ang = np.abs(c.attributes["scan_angle"] * 0.006)
    assert ang.max() < 5.0
    with pytest.raises(InvalidParameterError, match="strips"):
        make_als_town(strips=0)


def test_large_town_layouts_build():
    # Larger extents draw low gable roofs; those get no dormer instead of an error.
    from lidarstat.synth import make_als_town

    town = make_als_town(extent=(400.0, 300.0), density=0.5, rng=1)
    assert len(town.meta["buildings"]) > 60
