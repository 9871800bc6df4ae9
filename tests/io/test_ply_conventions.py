"""PLY property names in CloudCompare's conventions, and both spellings read back."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest

import lidarstat.io as lio
from lidarstat.errors import InvalidParameterError
from lidarstat.io import _ply

N = 50


def _props(path) -> dict[str, str]:
    return {p.name: p.val_dtype for p in plyfile.PlyData.read(str(path))["vertex"].properties}


def _cloud(rng, xyz=None):
    normal = rng.normal(size=(N, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    attrs = {"NormalX": normal[:, 0], "NormalY": normal[:, 1], "NormalZ": normal[:, 2],
             "red": rng.integers(0, 256, N).astype(np.uint8),
             "green": rng.integers(0, 256, N).astype(np.uint8),
             "blue": rng.integers(0, 256, N).astype(np.uint8),
             "intensity": rng.integers(0, 65535, N).astype(np.uint16)}
    return lio.PointCloud(rng.random((N, 3)) if xyz is None else xyz, attrs)


def test_normals_colours_and_scalars_use_cloudcompare_names(tmp_path, rng):
    cloud = _cloud(rng)
    fields = {"K": rng.normal(size=N), "point_class": rng.integers(0, 4, N).astype(np.uint8),
              "plane_p": rng.random(N)}
    out = tmp_path / "c.ply"
    lio.write(out, cloud, fields=fields)
    props = _props(out)
    assert list(props)[:9] == ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]
    assert [props[c] for c in ("red", "green", "blue")] == ["u1"] * 3
    assert {"scalar_intensity", "scalar_K", "scalar_point_class", "scalar_plane_p"} <= set(props)
    assert not {"NormalX", "K", "point_class", "intensity"} & set(props)
    back = lio.read(out)
    assert list(back.attributes) == [*cloud.attributes, *fields]
    for name, values in {**cloud.attributes, **fields}.items():
        np.testing.assert_array_equal(back[name], values)
        assert back[name].dtype == values.dtype


def test_lidarstat_spellings_are_still_read(tmp_path, rng):
    arr = np.zeros(N, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("NormalX", "<f8"),
                             ("point_class", "u1"), ("scalar_K", "<f8"), ("nz", "<f4")])
    arr["point_class"] = 2
    arr["scalar_K"] = rng.normal(size=N)
    path = tmp_path / "old.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(arr, "vertex")]).write(str(path))
    back = lio.read(path)
    assert list(back.attributes) == ["NormalX", "point_class", "K", "NormalZ"]
    np.testing.assert_array_equal(back["K"], arr["scalar_K"])


def test_names_that_would_collide_are_kept():
    assert _ply.field_names(["K", "scalar_K", "nx", "NormalX", "scalar_x", "scalar_"]) == {
        "K": "K", "scalar_K": "scalar_K", "nx": "nx", "NormalX": "NormalX",
        "scalar_x": "scalar_x", "scalar_": "scalar_"}


def test_field_names_round_trip_exactly(tmp_path, rng):
    odd = {"nx": np.ones(N), "scalar_q": np.zeros(N), "NormalY": rng.random(N),
           "v": rng.random((N, 3))}
    path = tmp_path / "odd.ply"
    lio.write(path, lio.PointCloud(rng.random((N, 3)), odd))
    assert "nx" not in _props(path) and "scalar_nx" in _props(path)  # no normal trio
    assert list(lio.read(path).attributes) == ["nx", "scalar_q", "NormalY", "v_0", "v_1", "v_2"]


def test_sixteen_bit_colours_scale_to_uchar(tmp_path, rng):
    cloud = _cloud(rng)
    rgb16 = {c: (cloud[c].astype(np.uint16) * 257) for c in ("red", "green", "blue")}
    rgb16["red"][0] = 65535
    path = tmp_path / "rgb16.ply"
    lio.write(path, cloud.with_fields(**rgb16))
    back = lio.read(path)
    for c in ("red", "green", "blue"):
        assert back[c].dtype == np.uint8
        np.testing.assert_array_equal(back[c], np.round(rgb16[c] / 257.0))
    with pytest.raises(InvalidParameterError, match="colour 'red'"):
        lio.write(tmp_path / "bad.ply", cloud.with_fields(red=np.full(N, -1.0)))


def test_coordinates_are_float_only_when_exact(tmp_path, rng):
    exact = np.round(rng.random((N, 3)) * 1024) / 64  # float32 holds these exactly
    lio.write(tmp_path / "f.ply", _cloud(rng, exact))
    assert [_props(tmp_path / "f.ply")[c] for c in "xyz"] == ["f4"] * 3
    np.testing.assert_array_equal(lio.read(tmp_path / "f.ply").xyz, exact)
    utm = exact + [5e5, 4e6, 0.0]
    lio.write(tmp_path / "d.ply", _cloud(rng, utm + 1e-3))
    assert [_props(tmp_path / "d.ply")[c] for c in "xyz"] == ["f8"] * 3
    np.testing.assert_array_equal(lio.read(tmp_path / "d.ply").xyz, utm + 1e-3)
