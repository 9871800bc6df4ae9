"""Catalogues on the command line: a folder, a glob or several files as IN, one output per
tile, resume after a kill, the area report, and the options refused outside a catalogue."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lidarstat.cli import main
from lidarstat.features import curvature
from lidarstat.io import read, write

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from test_catalogue import _assert_same_fields, _cut, _synthetic


def _tiles(tmp_path, seed=0, n=9000, grid=3):
    cloud = _synthetic(seed, n=n)
    whole = read(write(tmp_path / "whole.laz", cloud))
    return whole, _cut(whole, tmp_path / "tiles", n=grid)


def _gather(folder, names):
    xyz, fields = [], {n: [] for n in names}
    for p in sorted(Path(folder).glob("*.laz")):
        c = read(p)
        xyz.append(c.xyz)
        for n in names:
            fields[n].append(np.asarray(c.attributes[n]))
    return np.concatenate(xyz), {n: np.concatenate(v) for n, v in fields.items()}


@pytest.mark.parametrize("how", ["folder", "glob", "files"])
def test_curvature_on_a_catalogue_equals_the_whole_file(tmp_path, capsys, how):
    whole, tiles = _tiles(tmp_path)
    inputs = {"folder": [str(tmp_path / "tiles")],
              "glob": [str(tmp_path / "tiles" / "*.laz")],
              "files": [str(p) for p in tiles]}[how]
    rc = main(["curvature", *inputs, str(tmp_path / "out"), "--radius", "1.5",
               "--sigma", "0.05"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "9 tiles processed, 0 skipped" in out
    expected = curvature(whole.xyz, radius=1.5, sigma=0.05).to_fields()
    _assert_same_fields(_gather(tmp_path / "out", expected), (whole.xyz, expected))


def test_curvature_estimates_one_sigma_for_the_area(tmp_path, capsys):
    _tiles(tmp_path, seed=1)
    assert main(["curvature", str(tmp_path / "tiles"), str(tmp_path / "out"),
                 "--radius", "1.5"]) == 0
    assert "used for every tile" in capsys.readouterr().out


def test_moments_catalogue_report_terrain_and_rerun(tmp_path, capsys):
    from lidarstat.io import read_geotiff

    _tiles(tmp_path, seed=2, n=4000, grid=2)
    args = ["moments", str(tmp_path / "tiles"), str(tmp_path / "out"), "--window", "30",
            "--dtm", str(tmp_path / "dtm"), "--dtm-resolution", "2"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "4 tiles processed" in out and "report:" in out
    assert "decided on the whole area, used for every tile" in out  # one road cut
    page = (tmp_path / "out" / "report" / "index.html").read_text()
    assert "classes.png" in page and "terrain.png" in page and "tile_1_1.laz" in page
    assert "tiles/tile_1_1/index.html" in page
    assert (tmp_path / "out" / "report" / "tiles" / "tile_1_1" / "index.html").is_file()
    assert len(list((tmp_path / "dtm").glob("*.tif"))) == 4
    mosaic = read_geotiff(tmp_path / "dtm" / "dtm.vrt")
    assert mosaic.resolution == 2.0 and np.isfinite(mosaic.values).mean() > 0.9
    assert main(args) == 0
    assert "0 tiles processed, 4 skipped" in capsys.readouterr().out


def test_moments_one_file_terrain_model(tmp_path, capsys, shared_data):
    from lidarstat.io import read_geotiff

    src = shared_data / "ahn3_amsterdam" / "ahn_2386_9702.laz"
    tif = tmp_path / "dtm.tif"
    assert main(["moments", str(src), str(tmp_path / "o.laz"), "--dtm", str(tif),
                 "--no-report", "-q"]) == 0
    dtm = read_geotiff(tif)
    ground = read(tmp_path / "o.laz")
    g = np.isin(ground["classification"], (2, 11))
    # the model passes through the ground points: at each ground point's cell the height
    # is within the spread of the ground heights in that 1 m cell
    c = np.floor((ground.xyz[g, 0] - dtm.left) / dtm.resolution).astype(int)
    r = np.floor((dtm.top - ground.xyz[g, 1]) / dtm.resolution).astype(int)
    ok = (r >= 0) & (r < dtm.shape[0]) & (c >= 0) & (c < dtm.shape[1])
    diff = np.abs(dtm.values[r[ok], c[ok]] - ground.xyz[g, 2][ok])
    assert np.nanmedian(diff) < 0.05
    rc = main(["moments", str(src), str(tmp_path / "o2.laz"), "--dtm", str(tmp_path / "d.png")])
    assert rc == 2 and "--dtm" in capsys.readouterr().err


def test_resume_after_a_kill(tmp_path):
    _tiles(tmp_path, seed=3, n=30000)
    cmd = [sys.executable, "-m", "lidarstat", "curvature", str(tmp_path / "tiles"),
           str(tmp_path / "out"), "--radius", "1.5", "--sigma", "0.05", "--scheduler",
           "sync", "-q"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")}
    proc = subprocess.Popen(cmd, env=env, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
        if (tmp_path / "out").is_dir() and len(list((tmp_path / "out").glob("*.laz"))) >= 2:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert 2 <= len(done_before) < 9
    for p in (tmp_path / "out").iterdir():  # only complete files, no temporaries
        assert p.suffix == ".laz" and len(read(p).xyz) > 0
    run = subprocess.run([c for c in cmd if c != "-q"], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert f"{9 - len(done_before)} tiles processed, {len(done_before)} skipped" in run.stdout
    assert len(list((tmp_path / "out").glob("*.laz"))) == 9


@pytest.mark.parametrize("extra, words", [
    (["--template", "{stem}_x.laz"], "--template: only with a catalogue"),
    (["--buffer", "3"], "--buffer: only with a catalogue"),
])
def test_catalogue_options_are_refused_for_one_file(tmp_path, capsys, extra, words):
    _, tiles = _tiles(tmp_path, n=900)
    rc = main(["curvature", str(tiles[0]), str(tmp_path / "o.laz"), "--radius", "1",
               *extra])
    assert rc == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "o.laz").exists()


@pytest.mark.parametrize("extra, words", [
    (["--tile", "20"], "--tile: not with a catalogue"),
    (["--address", "tcp://127.0.0.1:1"], "--address: needs --scheduler dask"),
])
def test_options_refused_with_a_catalogue(tmp_path, capsys, extra, words):
    _tiles(tmp_path, n=900)
    rc = main(["curvature", str(tmp_path / "tiles"), str(tmp_path / "out"), "--radius", "1",
               *extra])
    assert rc == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_output_of_a_catalogue_must_be_a_folder(tmp_path, capsys):
    _tiles(tmp_path, n=900)
    (tmp_path / "o.laz").write_bytes(b"")
    rc = main(["curvature", str(tmp_path / "tiles"), str(tmp_path / "o.laz"), "--radius", "1"])
    assert rc == 2 and "the output is a folder" in capsys.readouterr().err


def test_output_folder_inside_the_inputs_is_refused_when_it_would_overwrite(tmp_path, capsys):
    _tiles(tmp_path, n=900)
    rc = main(["curvature", str(tmp_path / "tiles"), str(tmp_path / "tiles"), "--radius", "1"])
    assert rc == 2 and "is an input of the catalogue" in capsys.readouterr().err
    assert len(list((tmp_path / "tiles").iterdir())) == 9
