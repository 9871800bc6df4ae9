"""CloudCompare's command line reads the PLY files lidarstat writes: normals, colours and
every scalar field, with their values.

Skipped when ``CloudCompare`` is not on PATH (Debian: ``apt-get install cloudcompare``, see
``ci/debian-packages.txt``). CloudCompare 2.11 builds its PLY field dialog even with
``-SILENT``, so it needs a Qt platform: the test runs it with ``QT_QPA_PLATFORM=offscreen``
(no X server), and with a fresh ``HOME`` so that no saved dialog state is restored.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

import lidarstat.io as lio

CLOUDCOMPARE = shutil.which("CloudCompare")
pytestmark = pytest.mark.skipif(
    CLOUDCOMPARE is None,
    reason="CloudCompare is not on PATH (Debian package 'cloudcompare', ci/debian-packages.txt)")

N = 200
# CloudCompare keeps coordinates (after its global shift) and scalar fields as float32 and
# its ASCII export prints 12 decimals: values agree to float32 rounding (2**-23 relative,
# with a factor 2 of margin) plus the printed digits (1e-12). It stores normals quantised
# (measured on 200 000 random normals: at most 0.16 degrees, 2.3e-3 per component off).
F32 = 2.0 ** -23
NORMAL_DEGREES = 0.25


def _cloud(rng, offset):
    normal = rng.normal(size=(N, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    xyz = rng.random((N, 3)) * [30.0, 20.0, 5.0] + offset
    attrs = {"intensity": rng.integers(0, 65535, N).astype(np.uint16),
             "red": rng.integers(0, 256, N).astype(np.uint8),
             "green": rng.integers(0, 256, N).astype(np.uint8),
             "blue": rng.integers(0, 256, N).astype(np.uint8)}
    plane_p = rng.random(N)
    plane_p[::7] = np.nan  # "not tested"
    fields = {"NormalX": normal[:, 0], "NormalY": normal[:, 1], "NormalZ": normal[:, 2],
              "point_class": rng.integers(0, 4, N).astype(np.uint8),
              "plane_p": plane_p, "K": rng.normal(size=N) * 1e-3,
              "Eigenvalue0": rng.random(N) * 1e-6,
              "neighbors": rng.integers(5, 80, N).astype(np.int32),
              "boundary_T2": rng.random(N) * 1e4}
    return lio.PointCloud(xyz, attrs), fields


def _cloudcompare_ascii(tmp_path, ply):
    env = dict(os.environ, HOME=str(tmp_path / "home"), QT_QPA_PLATFORM="offscreen",
               XDG_RUNTIME_DIR=str(tmp_path / "run"))
    (tmp_path / "run").mkdir(mode=0o700)
    # -GLOBAL_SHIFT AUTO: recentre large (projected) coordinates before the float32 cast, as
    # the GUI proposes to; without it -SILENT keeps 450000 m at float32 (1/32 m steps).
    proc = subprocess.run([CLOUDCOMPARE, "-SILENT", "-O", "-GLOBAL_SHIFT", "AUTO", str(ply),
                           "-C_EXPORT_FMT", "ASC", "-ADD_HEADER", "-SAVE_CLOUDS"],
                          check=False, cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    exported = sorted(tmp_path.glob(f"{ply.stem}*.asc"))
    assert proc.returncode == 0 and len(exported) == 1, proc.stdout[-2000:] + proc.stderr[-2000:]
    with open(exported[0]) as fh:
        header = fh.readline()
    assert header.startswith("//"), header
    # CloudCompare drops the scalar_ prefix; its export may spell '_' as ' ' in a name.
    names = [n.replace(" ", "_") for n in header[2:].split()]
    table = np.loadtxt(exported[0], comments="//", ndmin=2)
    assert table.shape == (N, len(names))
    return dict(zip(names, table.T))


@pytest.mark.parametrize("offset", [0.0, 4.5e5], ids=["local", "utm"])
def test_cloudcompare_loads_normals_colours_and_every_scalar_field(tmp_path, rng, offset):
    cloud, fields = _cloud(rng, np.array([offset, offset * 10, 0.0]))
    ply = tmp_path / "out.ply"
    lio.write(ply, cloud, fields=fields)
    cols = _cloudcompare_ascii(tmp_path, ply)
    scalars = [n for n in [*cloud.attributes, *fields]
               if n not in ("red", "green", "blue", "NormalX", "NormalY", "NormalZ")]
    assert sorted(cols) == sorted(["X", "Y", "Z", "R", "G", "B", "Nx", "Ny", "Nz", *scalars])
    # Coordinates: float32 relative to CloudCompare's global shift (the extent, <= 30 m).
    for j, c in enumerate("XYZ"):
        np.testing.assert_allclose(cols[c], cloud.xyz[:, j], rtol=0, atol=30 * F32 + 1e-12)
    for c, name in zip("RGB", ("red", "green", "blue")):
        np.testing.assert_array_equal(cols[c], cloud[name])
    got = np.column_stack([cols[c] for c in ("Nx", "Ny", "Nz")])
    want = np.column_stack([fields[n] for n in ("NormalX", "NormalY", "NormalZ")])
    cos = np.sum(got * want, axis=1) / np.linalg.norm(got, axis=1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < NORMAL_DEGREES
    values = {**cloud.attributes, **fields}
    for name in scalars:
        expected = np.asarray(values[name], dtype=np.float64)
        np.testing.assert_array_equal(np.isnan(cols[name]), np.isnan(expected), err_msg=name)
        np.testing.assert_allclose(cols[name], expected, rtol=F32, atol=1e-12, err_msg=name)
