"""Terrestrial scans: the truth of scan_spherical and the TLS scenes checked against
independent computations (face equations, point-in-solid tests along the rays, brute
force distances to densely sampled crease lines, the 1/r^2 density law, noise moments)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.synth import (
    SCENES,
    Box,
    Cylinder,
    FaceRegistry,
    crease_lines,
    make_tls_building,
    make_tls_plant,
    scan_spherical,
    union,
)


@pytest.fixture(scope="module")
def building():
    return make_tls_building(step=0.006, rng=1)


@pytest.fixture(scope="module")
def plant():
    return make_tls_plant(step=0.008, rng=2)


def _face_residual(cloud):
    """|signed distance| of every true hit to the analytic surface of its face."""
    p = cloud.meta["xyz_true"]
    res = np.empty(len(cloud))
    for fid in np.unique(cloud.face):
        m = cloud.face == fid
        f = cloud.meta["faces"][fid]
        if f["kind"] == "plane":
            res[m] = (p[m] - f["point"]) @ np.asarray(f["normal"])
        else:
            w = p[m] - f["center"]
            a = np.asarray(f["axis"])
            rad = np.linalg.norm(w - (w @ a)[:, None] * a, axis=1)
            res[m] = rad - f["radius"]
            assert np.all(np.abs(w @ a) <= f["length"] / 2 + 1e-9)
    return np.abs(res)


@pytest.mark.parametrize("scene", ["building", "plant"])
def test_hits_lie_on_their_faces_with_true_normals(scene, request):
    c = request.getfixturevalue(scene)
    assert len(c) > 5000
    assert _face_residual(c).max() < 1e-9
    p = c.meta["xyz_true"]
    # normals: unit, face the scanner, equal to the plane normal (sign from the CSG)
    assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0)
    to_scanner = c.scanner - p
    assert np.all(np.einsum("ij,ij->i", c.normal, to_scanner) > 0)
    for fid in np.unique(c.face):
        f = c.meta["faces"][fid]
        if f["kind"] == "plane":
            m = c.face == fid
            assert np.allclose(np.abs(c.normal[m] @ np.asarray(f["normal"])), 1.0)
    # range and incidence are those of the geometry
    assert np.allclose(np.linalg.norm(to_scanner, axis=1), c.fields["range"])
    cosi = np.einsum("ij,ij->i", c.normal, to_scanner) / c.fields["range"]
    assert np.allclose(np.cos(c.fields["incidence"]), cosi)


def test_hits_are_first_hits_by_point_in_solid(plant):
    """Nothing of the solid lies between the scanner and the hit (independent contains)."""
    c = plant
    rng = np.random.default_rng(0)
    idx = rng.choice(len(c), 3000, replace=False)
    p = c.meta["xyz_true"][idx]
    s = c.scanner
    solid = c.meta["solid"]
    for frac in np.linspace(0.02, 0.9995, 40):
        assert not solid.contains(s + frac * (p - s)).any()
    # just beyond the hit we are inside the solid
    assert solid.contains(s + 1.0005 * (p - s)).mean() > 0.99


def test_edge_distance_matches_brute_force(building, plant):
    from scipy.spatial import cKDTree

    for c in (building, plant):
        near = c.edge_distance < 0.5
        assert near.sum() > 1000
        p = c.meta["xyz_true"][near]
        lo, hi = p.min(0) - 0.5, p.max(0) + 0.5
        v = np.concatenate([np.stack([e["vertices"][:-1], e["vertices"][1:]], axis=1)
                            for e in c.meta["edges"]])  # (S, 2, 3) pieces
        a, ab = v[:, 0], v[:, 1] - v[:, 0]
        # the part of every piece inside the box
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo - a) / ab, (hi - a) / ab
        t0 = np.fmax(0.0, np.nanmax(np.where(ab == 0, np.nan, np.minimum(ta, tb)), axis=1))
        t1 = np.fmin(1.0, np.nanmin(np.where(ab == 0, np.nan, np.maximum(ta, tb)), axis=1))
        ok = t1 > t0
        a, ab, t0, t1 = a[ok], ab[ok], t0[ok], t1[ok]
        n = np.maximum(((t1 - t0) * np.linalg.norm(ab, axis=1) / 0.004).astype(int), 1) + 1
        k = np.repeat(np.arange(n.size), n)
        u = np.arange(k.size) - np.repeat(np.cumsum(n) - n, n)
        t = t0[k] + (t1 - t0)[k] * u / (n[k] - 1)
        dense = a[k] + t[:, None] * ab[k]
        brute = cKDTree(dense).query(p)[0]
        # points within 0.5 m of an edge (their nearest edge point is inside the box);
        # dense sampling every 4 mm: brute force is above and within 2 mm + arc chords
        assert np.all(brute >= c.edge_distance[near] - 1e-9)
        assert np.all(brute - c.edge_distance[near] < 2.1e-3)


def test_known_creases_of_the_house(building):
    names = building.meta["face_names"]
    segs = building.meta["edge_segments"]
    pairs = [tuple(sorted(names[i] for i in f)) for f in building.meta["edge_segment_faces"]]

    def find(a, b):
        return [s for s, p in zip(segs, pairs) if p == tuple(sorted((a, b)))]

    # south facade on the ground: one concave line x = -6 .. 6 at y = 10, z = 0
    s = find("ground_+z", "house_wall_-y")
    assert len(s) == 1
    assert np.allclose(sorted(s[0][:, 0]), [-6, 6]) and np.allclose(s[0][:, 1:], [10, 0])
    # the recessed window 1: four rim creases (wall / recess side) and four inner ones
    rim = find("house_wall_-y", "house_win1_+x") + find("house_wall_-y", "house_win1_-z")
    assert len(rim) == 2
    inner = find("house_win1_+y", "house_win1_+x")
    assert len(inner) == 1 and np.isclose(np.ptp(inner[0][:, 2]), 1.4)
    conv = {tuple(sorted(names[i] for i in e["faces"])): e["convex"]
            for e in building.meta["edges"]}
    assert conv[("house_wall_-y", "house_win1_+x")] is True  # salient rim
    assert conv[("house_win1_+x", "house_win1_+y")] is False  # re-entrant corner
    assert conv[("ground_+z", "house_wall_-y")] is False


def test_plant_circles(plant):
    names = plant.meta["face_names"]
    arcs = {tuple(sorted(names[i] for i in e["faces"])): e
            for e in plant.meta["edges"] if e["kind"] == "arc"}
    e = arcs[("ground_+z", "tank1_side")]
    assert np.isclose(e["radius"], 3.0) and np.isclose(e["phi1"] - e["phi0"], 2 * np.pi)
    assert ("pipe_a_side", "pump_-x") in arcs  # pipe entering the pump housing
    assert ("pipe_a_cap_bottom", "pipe_a_side") in arcs  # open end


def test_boundaries_around_openings(building):
    c = building
    names = np.array(c.meta["face_names"])
    fn = names[c.face]
    bd = c.fields["boundary_distance"]
    room = np.char.startswith(fn.astype(str), "house_room")
    assert room.sum() > 20
    # the room seen through a 1.2 x 1.4 m hole (its image on the back wall is about 1.3
    # times larger): every point is within 0.9 m of the hole's rim
    assert np.all(bd[room] < 0.9)
    # the facade is bordered around the through-windows (win3 rim at x = -4.5 .. -3.3)
    p = c.meta["xyz_true"]
    wall = (fn == "house_wall_-y") & (c.fields["boundary"] == 1)
    near_win3 = wall & (p[:, 0] > -4.7) & (p[:, 0] < -3.1) & (p[:, 2] > 3.2) & (p[:, 2] < 5.0)
    assert near_win3.sum() > 10
    # recessed (not through) windows are creases, not borders
    win1_back = fn == "house_win1_+y"
    assert np.median(bd[win1_back]) > 0.2
    # boundary points are within about one point spacing (range * step / cos incidence)
    b = c.fields["boundary"] == 1
    spacing = c.meta["step"] * c.fields["range"] / np.cos(c.fields["incidence"])
    assert np.all(bd[b] <= 1.5 * spacing[b] + 1e-9)


def test_density_falls_as_inverse_square_of_range():
    reg = FaceRegistry()
    ground = Box(reg, "g", (0, 0, -0.5), np.eye(3), (100, 100, 0.5))
    h, step, daz = 5.0, 0.0008, 0.15
    c = scan_spherical(ground, sensor=(0, 0, h), azimuth=(0.0, daz),
                       elevation=(-1.0, -0.07), step=step, range_sigma=(0, 0))
    rho = np.hypot(c.xyz[:, 0], c.xyz[:, 1])
    dens = []
    n_cols = c.meta["grids"][0]["shape"][1]
    for r1 in (5.0, 10.0, 20.0, 40.0):
        r2 = r1 * 1.5
        n = np.count_nonzero((rho >= r1) & (rho < r2))
        dens.append(n / (0.5 * n_cols * step * (r2**2 - r1**2)))
        # integral over the annulus of the density cos(i) / (r^2 step^2 cos e) of a
        # uniform angular grid: n_cols * (e(r1) - e(r2)) / step rays
        expected = n_cols * (np.arctan(h / r1) - np.arctan(h / r2)) / step
        assert abs(n / expected - 1) < 0.03, (r1, n, expected)
    # far from the scanner the density on the ground falls as 1 / rho^3 (1 / r^2 times
    # cos incidence): doubling the distance divides it by about 8
    assert 7.0 < dens[2] / dens[3] < 8.5
    # on a wall facing the scanner (cos i = 1 at the foot of the perpendicular) the
    # density is 1 / (r^2 step^2): check at 10 and 30 m
    for dist in (10.0, 30.0):
        reg = FaceRegistry()
        wall = Box(reg, "w", (dist + 0.5, 0, 0), np.eye(3), (0.5, 5, 5))
        w = scan_spherical(wall, sensor=(0, 0, 0), azimuth=(-0.1, 0.1),
                           elevation=(-0.1, 0.1), step=0.002, range_sigma=(0, 0))
        m = (np.abs(w.xyz[:, 1]) < 0.5) & (np.abs(w.xyz[:, 2]) < 0.5)
        assert abs(m.sum() / (1 / (dist**2 * 0.002**2)) - 1) < 0.1


def test_range_noise_statistics(rng):
    reg = FaceRegistry()
    wall = Box(reg, "w", (20, 0, 5), np.eye(3), (0.5, 30, 5))
    a, b = 0.003, 2e-4
    c = scan_spherical(wall, sensor=(0, 0, 1.5), azimuth=(-0.8, 0.8), elevation=(-0.05, 0.2),
                       step=0.004, range_sigma=(a, b), rng=rng)
    d = c.xyz - c.scanner
    r_obs = np.linalg.norm(d, axis=1)
    z = (r_obs - c.fields["range"]) / c.fields["range_sigma"]
    assert np.allclose(c.fields["range_sigma"], a + b * c.fields["range"])
    n = z.size
    assert abs(z.mean()) < 4 / np.sqrt(n)
    assert abs(z.std() - 1) < 4 / np.sqrt(2 * n)
    # noise only along the ray
    u = (c.meta["xyz_true"] - c.scanner) / c.fields["range"][:, None]
    assert np.allclose(np.cross(d, u), 0.0, atol=1e-9)


def test_two_stations_and_determinism():
    c1 = make_tls_building(step=0.03, stations=2, rng=5)
    c2 = make_tls_building(step=0.03, stations=2, rng=5)
    assert np.array_equal(c1.xyz, c2.xyz)
    assert c1.scanner is None and c1.meta["scanners"].shape == (2, 3)
    st = c1.fields["station"]
    assert set(np.unique(st)) == {0, 1}
    for s in (0, 1):
        m = st == s
        to_sc = c1.meta["scanners"][s] - c1.meta["xyz_true"][m]
        assert np.allclose(np.linalg.norm(to_sc, axis=1), c1.fields["range"][m])
    c3 = make_tls_building(step=0.03, stations=2, rng=6)
    assert c3.xyz.shape == c1.xyz.shape and not np.array_equal(c3.xyz, c1.xyz)
    assert np.array_equal(c3.meta["xyz_true"], c1.meta["xyz_true"])


def test_crease_lines_of_a_box_on_a_cylinder():
    reg = FaceRegistry()
    box = Box(reg, "b", (0, 0, 0), np.eye(3), (1, 2, 3))
    cr = crease_lines(box)
    assert len(cr) == 12 and all(e["convex"] for e in cr)
    assert np.isclose(sum(np.linalg.norm(np.diff(e["vertices"], axis=0)) for e in cr),
                      8 * (1 + 2 + 3))
    cyl = Cylinder(reg, "c", (0, 0, 3.5), (0, 0, 1), 0.5, 1.0)  # stands on the box top
    cr = crease_lines(union(box, cyl))
    arcs = [e for e in cr if e["kind"] == "arc"]
    assert len(arcs) == 2  # top rim (convex) and foot on the box (concave)
    assert sorted(e["convex"] for e in arcs) == [False, True]


def test_invalid_parameters():
    reg = FaceRegistry()
    box = Box(reg, "b", (5, 0, 0), np.eye(3), (1, 1, 1))
    with pytest.raises(InvalidParameterError, match="sensor"):
        scan_spherical(box, sensor=(0, np.nan, 0))
    with pytest.raises(InvalidParameterError, match="range_sigma"):
        scan_spherical(box, sensor=(0, 0, 0), range_sigma=(-1, 0))
    with pytest.raises(InvalidParameterError, match="elevation"):
        scan_spherical(box, sensor=(0, 0, 0), elevation=(0.5, 0.1))
    with pytest.raises(InvalidParameterError, match="step"):
        scan_spherical(box, sensor=(0, 0, 0), step=0)


def test_registered_scenes():
    assert SCENES["tls_building"] is make_tls_building
    assert SCENES["tls_plant"] is make_tls_plant


def test_intensity_and_point_classes(building):
    from lidarstat.synth import point_class_truth

    c = building
    inten = c.attributes["intensity"].astype(float)
    assert np.all(c.attributes["return_number"] == 1)
    refl = np.array([f["reflectance"] for f in c.meta["faces"]])[c.face]
    # intensity / (reflectance cos i) follows 1 / (1 + (r / 30)^2) up to the 10 % speckle
    ratio = inten / (50000 * refl * np.cos(c.fields["incidence"])
                     / (1 + (c.fields["range"] / 30) ** 2))
    ok = inten > 100  # away from the uint16 rounding
    assert abs(np.log(ratio[ok]).std() - 0.1) < 0.01
    assert abs(np.median(ratio[ok]) - 1) < 0.01
    names = np.array(c.meta["face_names"])[c.face]
    assert np.median(inten[names == "house_win1_+y"]) < 0.4 * np.median(
        inten[names == "house_wall_-y"])
    cls = point_class_truth(c, 0.1)
    assert set(np.unique(cls)) == {1, 2, 3}
    assert np.array_equal(cls == 3, c.fields["boundary_distance"] < 0.1)
    assert np.all(cls[(c.edge_distance < 0.1) & (c.fields["boundary_distance"] >= 0.1)] == 2)


def test_plant_platform_station_sees_tank_tops():
    c = make_tls_plant(step=0.012, stations=2, rng=0)
    names = np.array(c.meta["face_names"])[c.face]
    st = c.fields["station"]
    for tank, top in (("tank1", 6.0), ("tank2", 4.0)):
        m = names == f"{tank}_cap_top"
        assert m.sum() > 20 and np.all(st[m] == 1)
        assert np.allclose(c.meta["xyz_true"][m, 2], top, atol=1e-9)
        assert np.allclose(c.normal[m], [0, 0, 1])
    assert _face_residual(c).max() < 1e-9


def test_crease_where_three_planes_share_the_line():
    # The eave line y = 9.6, z = 6 carries three planes: the south roof, its fascia and
    # the top plane of the wall behind the fascia.  The crease is roof | fascia; keeping
    # one pair of planes per geometric line used to lose it (and bias edge_distance
    # there by up to 0.2 m).
    c = make_tls_building(step=0.05, rng=0)
    names = c.meta["face_names"]
    pairs = {tuple(sorted((names[a], names[b]))): e for e in crease_lines(c.meta["solid"])
             for a, b in [e["faces"]]}
    for side, y in (("south", 9.6), ("north", 18.4)):
        e = pairs[tuple(sorted((f"house_roof_{side}", f"house_roof_fascia_{side}")))]
        assert np.allclose(e["vertices"][:, 1:], [[y, 6.0], [y, 6.0]])
        assert np.isclose(abs(e["vertices"][1, 0] - e["vertices"][0, 0]), 12.8)
