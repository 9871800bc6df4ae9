"""E57 input (poses applied) and the scanner position a file carries (E57 pose, sidecar)."""

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.errors import LidarstatWarning, PointCloudReadError, UnknownFormatError
from lidarstat.io import PointCloud, read, read_sensor, sensor_sidecar, write, write_sensor

from conftest import shared_file


def _quaternion_z(angle):
    """(w, x, y, z) of a rotation by `angle` about z, and its matrix."""
    c, s = np.cos(angle), np.sin(angle)
    return (np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)]),
            np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


def _write_e57(path, scans):
    """scans: list of (local xyz, intensity, quaternion, translation)."""
    pye57 = pytest.importorskip("pye57", reason="pye57 not installed (E57 input)")
    e57 = pye57.E57(str(path), mode="w")
    for xyz, inten, q, t in scans:
        e57.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                            "cartesianZ": xyz[:, 2], "intensity": inten},
                           rotation=q, translation=t)
    e57.close()


def _room(rng, n=6000):
    """Floor and two walls around a scanner at the local origin (scanner frame)."""
    floor = np.c_[rng.uniform(-3, 3, (n, 2)), np.full(n, -1.6)]
    wall = np.c_[rng.uniform(-3, 3, n), np.full(n, 3.0), rng.uniform(-1.6, 1.0, n)]
    side = np.c_[np.full(n, -3.0), rng.uniform(-3, 3, n), rng.uniform(-1.6, 1.0, n)]
    pts = np.vstack([floor, wall, side])
    return pts + rng.normal(0, 0.002, pts.shape)


def test_e57_points_in_the_global_frame_and_sensor_from_the_pose(rng, tmp_path):
    local = _room(rng)
    q, rot = _quaternion_z(np.radians(30.0))
    t = np.array([512_000.0, 5_430_000.0, 101.6])
    path = tmp_path / "scan.e57"
    _write_e57(path, [(local, np.linspace(0, 1, len(local)), q, t)])
    cloud = read(path)
    np.testing.assert_allclose(cloud.xyz, local @ rot.T + t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(cloud.attributes["intensity"], np.linspace(0, 1, len(local)),
                               atol=1e-6)
    assert cloud.source_format == "e57" and "scan_index" not in cloud.attributes
    sensor, source = read_sensor(path)
    np.testing.assert_array_equal(sensor, t)
    assert source == "E57 pose"
    # the CLI orients every normal toward the pose's position without --sensor
    out = tmp_path / "out.npz"
    assert main(["covariance", str(path), str(out), "--k", "20", "-q"]) == 0
    res = read(out)
    n = np.c_[res.attributes["NormalX"], res.attributes["NormalY"], res.attributes["NormalZ"]]
    toward = np.einsum("ij,ij->i", n, t - res.xyz)
    assert np.all(toward > 0)


def test_e57_several_stations(rng, tmp_path):
    a, b = _room(rng, 500), _room(rng, 400)
    q, _ = _quaternion_z(0.0)
    path = tmp_path / "two.e57"
    _write_e57(path, [(a, np.zeros(len(a)), q, np.zeros(3)),
                      (b, np.zeros(len(b)), q, np.array([10.0, 0.0, 0.0]))])
    cloud = read(path)
    assert len(cloud) == len(a) + len(b)
    assert cloud.attributes["scan_index"].tolist() == [0] * len(a) + [1] * len(b)
    np.testing.assert_allclose(cloud.xyz[len(a):], b + [10.0, 0, 0], atol=1e-9)
    with pytest.warns(LidarstatWarning, match="2 scans from different positions"):
        assert read_sensor(path) == (None, None)


def test_sidecar_roundtrip_errors_and_override(rng, tmp_path, capsys):
    path = tmp_path / "scan.laz"
    local = _room(rng, 1500)
    write(path, PointCloud(local + [10.0, 20.0, 0.0]))
    assert read_sensor(path) == (None, None)
    side = write_sensor(path, [10.0, 20.0, 0.0])
    assert side == sensor_sidecar(path) == tmp_path / "scan.laz.sensor.json"
    sensor, source = read_sensor(path)
    assert sensor.tolist() == [10.0, 20.0, 0.0] and source == str(side)
    out = tmp_path / "out.npz"
    assert main(["covariance", str(path), str(out), "--k", "15"]) == 0
    assert "sensor 10.0000 20.0000 0.0000 from" in capsys.readouterr().err
    res = read(out)
    n = np.c_[res.attributes["NormalX"], res.attributes["NormalY"], res.attributes["NormalZ"]]
    assert np.all(np.einsum("ij,ij->i", n, [10.0, 20.0, 0.0] - res.xyz) > 0)
    # --sensor overrides the sidecar: a position far below flips the floor normals down
    assert main(["covariance", str(path), str(out), "--k", "15", "-q",
                 "--sensor", "10", "20", "-100", "--sigma", "0.002"]) == 0
    res = read(out)
    floor = (res.xyz[:, 2] < -1.5) & (np.abs(res.xyz[:, :2] - [10.0, 20.0]).max(axis=1) < 2.5)
    assert np.all(res.attributes["NormalZ"][floor] < 0)
    side.write_text('{"sensor": [1, 2]}')
    with pytest.raises(PointCloudReadError, match="3 finite numbers"):
        read_sensor(path)
    side.write_text("not json")
    with pytest.raises(PointCloudReadError, match="unreadable sensor sidecar"):
        read_sensor(path)


def test_e57_is_read_only(tmp_path, capsys):
    with pytest.raises(UnknownFormatError, match="read only"):
        from lidarstat.cli._app import check_output

        check_output(str(tmp_path / "x.e57"))
    from lidarstat.errors import PointCloudWriteError

    with pytest.raises(PointCloudWriteError, match="not supported"):
        write(tmp_path / "x.e57", PointCloud(np.zeros((3, 3))))


def test_real_pump_scan_e57_pose():
    """The libE57 pump scan (identity pose): the scanner is at the origin of the file."""
    path = shared_file("e57_pump_tls/pumpARowColumnIndexNoInvalidPoints.e57")
    pytest.importorskip("pye57", reason="pye57 not installed (E57 input)")
    sensor, source = read_sensor(path)
    assert sensor.tolist() == [0.0, 0.0, 0.0] and source == "E57 pose"
    assert len(read(path)) == 155_201


def test_real_pump_scan_laz_with_sidecar(tmp_path):
    """The LAZ converted from it has no pose: a sidecar gives the identity pose's origin."""
    import shutil

    src = shared_file("e57_pump_tls/pump_scan.laz")
    path = tmp_path / src.name
    shutil.copy(src, path)
    write_sensor(path, [0.0, 0.0, 0.0])
    out = tmp_path / "pump.npz"
    assert main(["covariance", str(path), str(out), "-q"]) == 0
    res = read(out)
    n = np.c_[res.attributes["NormalX"], res.attributes["NormalY"], res.attributes["NormalZ"]]
    ok = np.isfinite(n).all(axis=1)
    assert ok.mean() > 0.99
    assert np.all(np.einsum("ij,ij->i", n[ok], -res.xyz[ok]) > 0)
