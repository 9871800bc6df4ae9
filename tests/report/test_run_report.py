"""The run report: maps and hillshades against analytic cases, and the page as a person
opens it, in headless Chromium (a screenshot, no console message, every picture loaded)."""

import re
import shutil
import subprocess

import numpy as np
import pytest

from lidarstat.pipeline import terrain_model
from lidarstat.report import class_grid, hillshade, write_run_report
from lidarstat.synth import make_als_town

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.parametrize("slope_deg", [0.0, 20.0, 45.0, 70.0])
@pytest.mark.parametrize("facing", ["north-west", "south-east"])
def test_hillshade_of_planes(slope_deg, facing):
    """A plane of slope s facing the light (azimuth 315, altitude 45) has shade
    cos(s - 45 deg); facing away, max(0, cos(s + 45 deg))."""
    res = 0.5
    g = np.tan(np.deg2rad(slope_deg)) / np.sqrt(2)  # equal parts along x and y
    x = res * np.arange(40)
    y = -res * np.arange(30)  # rows run south
    sign = 1.0 if facing == "south-east" else -1.0  # the surface falls toward `facing`
    z = sign * (-g * x[None, :] + g * y[:, None])
    shade = hillshade(z, res)
    expected = np.cos(np.deg2rad(slope_deg - 45.0)) if facing == "north-west" else max(
        0.0, np.cos(np.deg2rad(slope_deg + 45.0)))
    np.testing.assert_allclose(shade[1:-1, 1:-1], expected, atol=1e-9)


def test_class_grid_shows_the_topmost_point():
    xyz = np.array([[0.2, 0.2, 5.0], [0.3, 0.3, 1.0], [1.5, 0.5, 0.0], [0.5, 1.5, 2.0]])
    grid, extent = class_grid(xyz, np.array([5, 2, 2, 6]), 1.0, bounds=(0, 0, 2, 2))
    assert grid.tolist() == [[6, -1], [5, 2]]  # first row north
    assert extent == (0, 2, 0, 2)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    town = make_als_town(extent=(80.0, 60.0), density=6.0, rng=3)
    cls = town.fields["true_class"]
    dtm = terrain_model(town.xyz, cls, resolution=1.0)
    folder = tmp_path_factory.mktemp("report")
    tiles = [{"tile": f"t{i}", "points": 1000 + i, "ground": f"{40 + i} %"} for i in range(3)]
    page = write_run_report(
        folder, title="lidarstat moments", facts={"input": "town.laz", "output": "out.laz",
                                                  "points": len(cls)},
        params={"alpha": 0.05, "window": 64.0}, xyz=town.xyz, classes=cls, dtm=dtm,
        tiles=tiles, flags={"dip test not significant": town.xyz[:, 0] > 40},
        links={"per-tile moment plots": "tiles.html"})
    return page


def _chromium(tmp_path, *args):
    profile = tmp_path / "profile"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={profile}", "--enable-logging=stderr",
           "--v=0", "--virtual-time-budget=5000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


def _console(stderr):
    return [line for line in stderr.splitlines() if ":CONSOLE" in line]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed "
                    "(ci/debian-packages.txt lists it; ci/install-test-packages.sh installs it)")
def test_report_opens_in_a_browser(report, tmp_path):
    html = report.read_text()
    for png in ("classes.png", "terrain.png", "flags_0.png"):
        assert f"src='{png}'" in html and (report.parent / png).stat().st_size > 10_000
    dom = _chromium(tmp_path, "--dump-dom", report.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert re.search(r'<body[^>]*data-images="ok"', dom.stdout), dom.stdout[:500]
    assert "ground" in dom.stdout and "Terrain model" in dom.stdout
    assert _console(dom.stderr) == []
    shot = tmp_path / "shot.png"
    run = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1200,2400",
                    report.as_uri())
    assert run.returncode == 0 and shot.stat().st_size > 20_000
    import matplotlib.image as mpimg

    pixels = mpimg.imread(shot)[..., :3]
    assert pixels.std() > 0.05  # not a blank page


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")
def test_a_missing_picture_is_named_on_the_page(report, tmp_path):
    """The load check can fail: a picture removed from the report is reported."""
    broken = tmp_path / "broken"
    shutil.copytree(report.parent, broken)
    (broken / "terrain.png").unlink()
    dom = _chromium(tmp_path, "--dump-dom", (broken / "index.html").as_uri())
    assert re.search(r'<body[^>]*data-images="broken"', dom.stdout)
    assert "Pictures that could not be shown: terrain.png" in dom.stdout
