"""Truth consistency of lidarstat.synth: the exact curvatures, normals, faces and edge
distances are checked against independent computations (finite differences of the analytic
height functions, point-in-solid tests, local quadric fits of the sampled geometry)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.synth import (
    SCENES,
    SURFACE_KINDS,
    SyntheticCloud,
    make_agpart,
    make_column,
    make_cylinder,
    make_paraboloid,
    make_plane,
    make_scherk,
    make_sphere_cap,
    make_surface,
    surface_type_from_curvature,
)


@pytest.fixture(scope="module")
def agpart():
    return make_agpart()


@pytest.fixture(scope="module")
def column():
    return make_column()


# ----------------------------------------------------------------- analytic height fields
def height_function(cloud):
    """Independent z = f(x, y) of a height-field cloud, from its parameters."""
    m = cloud.meta
    kind = m["kind"]
    if kind == "plane":
        n = np.asarray(m["plane_normal"])
        return lambda x, y: -(n[0] * x + n[1] * y) / n[2]
    if kind in ("cylinder", "trough"):
        a, R = np.asarray(m["axis"]), m["radius"]
        sg = 1.0 if m["convex"] else -1.0
        return lambda x, y: sg * np.sqrt(R**2 - (-x * a[1] + y * a[0]) ** 2)
    if kind in ("sphere", "bowl"):
        R, sg = m["radius"], (1.0 if m["convex"] else -1.0)
        return lambda x, y: sg * np.sqrt(R**2 - x**2 - y**2)
    if kind == "paraboloid":
        a, b, t = m["a"], m["b"], np.radians(m["angle"])

        def f(x, y):
            u = np.cos(t) * x + np.sin(t) * y
            v = -np.sin(t) * x + np.cos(t) * y
            return 0.5 * (a * u * u + b * v * v)

        return f
    if kind == "scherk":
        c = m["scale"]
        return lambda x, y: (np.log(np.cos(c * y)) - np.log(np.cos(c * x))) / c
    raise AssertionError(kind)


def fd_curvature(f, x, y, h=1e-5):
    """Normal and curvatures from finite differences via the shape operator I^-1 II."""
    fx = (f(x + h, y) - f(x - h, y)) / (2 * h)
    fy = (f(x, y + h) - f(x, y - h)) / (2 * h)
    g = 5e-5
    f0 = f(x, y)
    fxx = (f(x + g, y) - 2 * f0 + f(x - g, y)) / g**2
    fyy = (f(x, y + g) - 2 * f0 + f(x, y - g)) / g**2
    fxy = (f(x + g, y + g) - f(x + g, y - g) - f(x - g, y + g) + f(x - g, y - g)) / (4 * g**2)
    W = np.sqrt(1 + fx**2 + fy**2)
    normal = np.stack([-fx, -fy, np.ones_like(fx)], 1) / W[:, None]
    first = np.array([[1 + fx**2, fx * fy], [fx * fy, 1 + fy**2]]).transpose(2, 0, 1)
    second = np.array([[fxx, fxy], [fxy, fyy]]).transpose(2, 0, 1) / W[:, None, None]
    S = np.linalg.solve(first, second)
    K = np.linalg.det(S)
    H = 0.5 * np.trace(S, axis1=1, axis2=2)
    ev = np.sort(np.linalg.eigvals(S).real, axis=1)
    return normal, K, H, ev[:, 0], ev[:, 1]


HEIGHT_FIELDS = [
    *[(k, lambda k=k: make_surface(k, spacing=0.05)) for k in SURFACE_KINDS],
    ("paraboloid rotated", lambda: make_paraboloid(0.7, -1.3, angle=30, spacing=0.05)),
    ("hyperbolic paraboloid", lambda: make_paraboloid(1.0, -1.0, spacing=0.05)),
    ("cylinder oblique", lambda: make_cylinder(0.8, axis=(1, 2), convex=False, spacing=0.03,
                                               jitter=0.3, rng=1)),
    ("scherk scaled", lambda: make_scherk(2.0, spacing=0.02)),
]


@pytest.mark.parametrize("label,factory", HEIGHT_FIELDS, ids=[h[0] for h in HEIGHT_FIELDS])
def test_height_field_truth_matches_finite_differences(label, factory):
    c = factory()
    assert len(c) > 100
    p = c.meta["xyz_true"]
    f = height_function(c)
    np.testing.assert_allclose(p[:, 2], f(p[:, 0], p[:, 1]), atol=1e-12)
    normal, K, H, kmin, kmax = fd_curvature(f, p[:, 0], p[:, 1])
    np.testing.assert_allclose(c.normal, normal, atol=1e-6)
    np.testing.assert_allclose(c.K, K, atol=2e-5)
    np.testing.assert_allclose(c.H, H, atol=2e-5)
    np.testing.assert_allclose(c.kmin, kmin, atol=2e-5)
    np.testing.assert_allclose(c.kmax, kmax, atol=2e-5)
    np.testing.assert_allclose(c.K, c.kmin * c.kmax, atol=1e-12)
    np.testing.assert_allclose(c.H, 0.5 * (c.kmin + c.kmax), atol=1e-12)
    assert np.all(c.kmin <= c.kmax)
    # the type follows the exact K, H (checked where FD values are far from zero)
    clear = (np.abs(K) > 1e-4) & (np.abs(H) > 1e-4)
    np.testing.assert_array_equal(c.surface_type[clear],
                                  surface_type_from_curvature(K, H)[clear])
    # XY distance to the domain border: positive inside, ~0 at the border
    assert np.all(c.edge_distance >= 0) and c.edge_distance.min() < 0.05


@pytest.mark.parametrize("kind", sorted(SURFACE_KINDS))
def test_make_surface_type_constant_over_patch(kind):
    c = make_surface(kind, spacing=0.04)
    assert c.name == kind
    assert set(np.unique(c.surface_type).tolist()) == {SURFACE_KINDS[kind]}


def test_sign_convention_examples():
    ridge = make_paraboloid(-1.0, 0.0, spacing=0.1)
    o = np.flatnonzero((ridge.xyz[:, 0] == 0) & (ridge.xyz[:, 1] == 0))[0]
    assert ridge.H[o] == -0.5 and ridge.K[o] == 0.0 and ridge.surface_type[o] == 2
    cyl = make_cylinder(2.0, spacing=0.1)
    assert np.all(cyl.H == -0.25) and np.all(cyl.K == 0) and np.all(cyl.kmin == -0.5)
    trough = make_cylinder(2.0, convex=False, spacing=0.1)
    assert np.all(trough.H == 0.25) and np.all(trough.kmax == 0.5)
    dome = make_sphere_cap(2.0, spacing=0.1)
    assert np.all(dome.K == 0.25) and np.all(dome.H == -0.5)
    bowl = make_sphere_cap(2.0, convex=False, spacing=0.1)
    assert np.all(bowl.H == 0.5) and np.all(bowl.surface_type == 5)
    for c in (ridge, cyl, trough, dome, bowl):
        assert np.all(c.normal[:, 2] > 0)
        np.testing.assert_allclose(np.linalg.norm(c.normal, axis=1), 1.0, atol=1e-12)


def test_plane_noise_std_and_only_along_z(rng):
    sigma = 0.05
    c = make_plane(extent=2.0, spacing=0.01, normal=(0.2, 0.1, 1.0), sigma=sigma, rng=rng)
    d = c.xyz - c.meta["xyz_true"]
    assert np.all(d[:, :2] == 0)
    assert len(c) > 30000
    assert abs(d[:, 2].std() / sigma - 1) < 0.05
    assert c.sigma == sigma
    assert np.all(c.surface_type == 1) and np.all(c.K == 0) and np.all(c.H == 0)


def test_n_sets_the_number_of_points():
    c = make_plane(5000, extent=(2.0, 1.0))
    assert 4500 < len(c) < 5500
    s = make_sphere_cap(1.0, n=3000)
    assert 2700 < len(s) < 3300


def test_determinism_and_seeds():
    a = make_surface("peak", spacing=0.05, sigma=0.01, jitter=0.3, rng=7)
    b = make_surface("peak", spacing=0.05, sigma=0.01, jitter=0.3, rng=7)
    c = make_surface("peak", spacing=0.05, sigma=0.01, jitter=0.3, rng=8)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a.H, b.H)
    assert not np.array_equal(a.xyz, c.xyz)
    g1 = make_agpart(spacing=0.05, sigma=0.01, rng=np.random.default_rng(3))
    g2 = make_agpart(spacing=0.05, sigma=0.01, rng=3)
    np.testing.assert_array_equal(g1.xyz, g2.xyz)
    np.testing.assert_array_equal(g1.edge_distance, g2.edge_distance)


def test_result_is_frozen_and_readonly():
    c = make_surface("pit", spacing=0.1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.sigma = 1.0
    with pytest.raises(ValueError):
        c.H[0] = 1.0
    fields = c.to_fields()
    assert set(fields) == {"true_K", "true_H", "true_surface_type", "face"}
    assert fields["true_surface_type"].dtype == np.uint8 and fields["face"].dtype == np.int32
    assert fields["true_K"].shape == (len(c),)
    fields["true_H"][0] = 5.0  # a copy
    assert c.H[0] != 5.0
    assert isinstance(c, SyntheticCloud) and c.scanner is None


def test_invalid_parameters():
    with pytest.raises(InvalidParameterError, match="'kind'"):
        make_surface("donut")
    with pytest.raises(InvalidParameterError, match="'radius'"):
        make_cylinder(-1.0)
    with pytest.raises(InvalidParameterError, match="'normal'"):
        make_plane(normal=(1.0, 0.0, 0.0))
    with pytest.raises(InvalidParameterError, match="'sigma'"):
        make_agpart(sigma=-0.1)
    with pytest.raises(InvalidParameterError, match="'extent'"):
        make_scherk(1.0, extent=3.0)
    with pytest.raises(ValueError):
        make_agpart(spacing=(0.02, -1))


# ----------------------------------------------------------------------- CSG range scans
def _face_name(cloud, i):
    return cloud.meta["faces"][i]["name"]


def check_points_on_faces(cloud):
    p = cloud.meta["xyz_true"]
    for f in cloud.meta["faces"]:
        m = cloud.face == f["id"]
        if not m.any():
            continue
        q, n = p[m], cloud.normal[m]
        if f["kind"] == "plane":
            nrm = np.asarray(f["normal"])
            np.testing.assert_allclose((q - f["point"]) @ nrm, 0.0, atol=1e-9, err_msg=f["name"])
            np.testing.assert_allclose(n, np.tile(nrm, (len(q), 1)), atol=1e-12)
        else:
            c, a, R = np.asarray(f["center"]), np.asarray(f["axis"]), f["radius"]
            w = q - c
            s = w @ a
            radial = w - s[:, None] * a
            r = np.linalg.norm(radial, axis=1)
            np.testing.assert_allclose(r, R, atol=1e-9, err_msg=f["name"])
            assert np.all(np.abs(s) <= f["length"] / 2 + 1e-9)
            sign = -1.0 if f["flipped"] else 1.0
            np.testing.assert_allclose(n, sign * radial / r[:, None], atol=1e-9)
            np.testing.assert_array_equal(cloud.H[m], -sign / (2 * R))
            np.testing.assert_array_equal(cloud.K[m], 0.0)
            np.testing.assert_array_equal(cloud.surface_type[m], 2 if sign > 0 else 3)
    np.testing.assert_allclose(np.linalg.norm(cloud.normal, axis=1), 1.0, atol=1e-12)
    assert np.all(cloud.normal[:, 2] > 0)
    assert np.all(cloud.face >= 0)


def test_agpart_points_on_primitives(agpart):
    check_points_on_faces(agpart)


def test_column_points_on_primitives(column):
    check_points_on_faces(column)


def _inside_agpart(cloud, p):
    """Independent point-in-solid test of (shaft U disk) - bore."""
    a = np.asarray(cloud.meta["axis"])

    def in_cyl(c, R, L):
        w = p - np.asarray(c)
        s = w @ a
        r = np.linalg.norm(w - s[:, None] * a, axis=1)
        return (r < R) & (np.abs(s) < L / 2)

    m = cloud.meta
    shaft = in_cyl(m["shaft"]["center"], m["shaft"]["radius"], m["shaft"]["length"])
    disk = in_cyl(m["disk"]["center"], m["disk"]["radius"], m["disk"]["thickness"])
    bore = in_cyl(m["shaft"]["center"], m["bore"]["radius"], m["bore"]["length"])
    return (shaft | disk) & ~bore


def test_agpart_samples_are_first_hits(agpart):
    p = agpart.meta["xyz_true"]
    idx = np.random.default_rng(0).choice(len(p), 3000, replace=False)
    q = p[idx]
    below = q - [0, 0, 1e-7]
    # slightly below the sample we are inside the solid (unless the ray grazes a rim)
    assert _inside_agpart(agpart, below).mean() > 0.995
    # nowhere above the sample along the ray
    for dz in np.linspace(1e-6, 4.0, 400):
        assert not _inside_agpart(agpart, q + [0, 0, dz]).any()


def test_agpart_faces_counts_and_extent(agpart):
    counts = {f["name"]: f["n_points"] for f in agpart.meta["faces"]}
    for name in ("shaft_side", "shaft_cap_top", "disk_side", "disk_cap_top"):
        assert counts[name] > 2000, name
    assert counts["bore_side"] >= 300
    assert counts["shaft_cap_bottom"] == counts["disk_cap_bottom"] == 0
    assert 28_000 <= len(agpart) <= 40_000
    ext = np.ptp(agpart.xyz[:, :2], axis=0)
    assert 3.8 <= ext[0] <= 4.2 and 3.0 <= ext[1] <= 4.2
    types = np.bincount(agpart.surface_type, minlength=9)
    assert types[1] > 0 and types[2] > 0 and types[3] >= 300
    assert set(np.unique(agpart.surface_type).tolist()) == {1, 2, 3}
    bore = agpart.face == agpart.meta["face_names"].index("bore_side")
    np.testing.assert_array_equal(agpart.H[bore], 1 / 0.56)
    # grid spacing of the paper
    ij = agpart.meta["ij"]
    x0, y0 = agpart.meta["grid_origin"]
    np.testing.assert_allclose(agpart.xyz[:, 0], x0 + 0.02 * ij[:, 1], atol=1e-12)
    np.testing.assert_allclose(agpart.xyz[:, 1], y0 + 0.0168 * ij[:, 0], atol=1e-12)


def test_column_vertex_of_three_box_faces_visible(column):
    counts = {f["name"]: f["n_points"] for f in column.meta["faces"]}
    visible = {k for k, v in counts.items() if v > 0}
    assert visible == {"base_+x", "base_-y", "base_+z", "column_side", "column_cap_top"}
    assert 24_000 <= len(column) <= 32_000
    b = column.meta["base"]
    R, he = np.asarray(b["rotation"]), np.asarray(b["half_extents"])
    corner = np.asarray(b["center"]) + R @ (he * [1, -1, 1])
    p = column.meta["xyz_true"]
    near = np.linalg.norm(p - corner, axis=1) < 0.08
    names = {_face_name(column, i) for i in np.unique(column.face[near])}
    assert names == {"base_+x", "base_-y", "base_+z"}


def _local_quadric_H(p, normal, centre, radius):
    e1 = np.cross(normal, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    d = p - centre
    nb = np.linalg.norm(d, axis=1) < radius
    u, v, w = d[nb] @ e1, d[nb] @ e2, d[nb] @ normal
    X = np.c_[np.ones_like(u), u, v, u * u / 2, u * v, v * v / 2]
    c = np.linalg.lstsq(X, w, rcond=None)[0]
    return 0.5 * (c[3] + c[5]), c[3] * c[5] - c[4] ** 2


@pytest.mark.parametrize("scene", ["agpart", "column"])
def test_truth_curvature_matches_sampled_geometry(scene, agpart, column):
    """A local quadric fitted to the noise-free samples reproduces the true H (and sign)."""
    cloud = agpart if scene == "agpart" else column
    p = cloud.meta["xyz_true"]
    r = 0.08
    gen = np.random.default_rng(1)
    for f in cloud.meta["faces"]:
        # grazing samples (n_z small) are too sparse across the slope for a stable fit
        cand = np.flatnonzero((cloud.face == f["id"]) & (cloud.edge_distance > r + 0.01)
                              & (cloud.normal[:, 2] > 0.3))
        if f["n_points"] == 0:
            continue
        assert cand.size >= 20, f["name"]
        for i in gen.choice(cand, 10, replace=False):
            H, K = _local_quadric_H(p, cloud.normal[i], p[i], r)
            assert abs(H - cloud.H[i]) < 0.1 * abs(cloud.H[i]) + 0.02, (f["name"], H, cloud.H[i])
            assert abs(K) < 0.05 + 0.1 * cloud.H[i] ** 2


@pytest.mark.parametrize("scene", ["agpart", "column"])
def test_edge_distance_selects_interior_points(scene, agpart, column):
    cloud = agpart if scene == "agpart" else column
    ny, nx = cloud.meta["grid_shape"]
    img = np.full((ny, nx), -1)
    ij = cloud.meta["ij"]
    img[ij[:, 0], ij[:, 1]] = cloud.face
    step = np.hypot(*cloud.meta["spacing"])
    # every point farther than two grid diagonals from an edge has 8 neighbours, same face
    far = cloud.edge_distance > 2 * step
    assert far.mean() > 0.5
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            nb = img[ij[far, 0] + di, ij[far, 1] + dj]
            np.testing.assert_array_equal(nb, cloud.face[far])
    # points next to another face / the background are close to an edge: a crease pair
    # (depth difference <= 3 x separation) has its midpoint within sqrt(10)/2 separations
    near = np.zeros(len(cloud), bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            near |= img[ij[:, 0] + di, ij[:, 1] + dj] != cloud.face
    assert np.all(cloud.edge_distance[near] <= 1.6 * step)
    assert np.all(np.isfinite(cloud.edge_distance)) and np.all(cloud.edge_distance >= 0)


def test_noise_on_scene(rng):
    c = make_agpart(spacing=0.04, sigma=0.01, rng=rng)
    d = c.xyz - c.meta["xyz_true"]
    assert abs(d[:, 2].std() / 0.01 - 1) < 0.05 and np.all(d[:, :2] == 0)


def test_scenes_registry():
    assert {"agpart", "column", *SURFACE_KINDS} <= set(SCENES)
    for name in ("agpart", "column", *SURFACE_KINDS):
        c = SCENES[name](spacing=0.2, sigma=0.0, rng=0)
        assert isinstance(c, SyntheticCloud) and len(c) > 10 and c.name == name


def test_synth_imports_numpy_only():
    code = ("import sys, lidarstat.synth as s; s.make_agpart(spacing=0.1); "
            "bad = [m for m in ('scipy', 'numba') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)
