"""``--report`` of curvature, covariance, ridges and segment: the page of one file and of a
catalogue (one area page, one page per tile), opened in headless Chromium (no console
message, every picture loaded, a screenshot that is not blank)."""

import re
import sys
from pathlib import Path

import pytest

from lidarstat.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from test_catalogue_cli import _tiles
from test_run_report import CHROMIUM, _chromium, _console

COMMANDS = {
    "curvature": (["--radius", "1.5", "--sigma", "0.05"], ["surface_type", "Fields",
                                                            "H not significant"]),
    "covariance": (["--radius", "1.5", "--sigma", "0.05"], ["point_class", "surface",
                                                             "plane (low curvature)"]),
    "ridges": (["--radius", "3", "--sigma", "0.05"], ["ridge", "jet chi-square", "k1"]),
    "segment": (["--method", "covariance", "--radius", "1.5", "--sigma", "0.05"],
                ["segment_id", "points in a segment", "in no segment"]),
}


def _opens(page, tmp_path):
    dom = _chromium(tmp_path, "--dump-dom", page.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert re.search(r'<body[^>]*data-images="ok"', dom.stdout), dom.stdout[:500]
    assert _console(dom.stderr) == []
    return dom.stdout


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_report_of_one_file(tmp_path, capsys, command):
    options, words = COMMANDS[command]
    _tiles(tmp_path, seed=6, n=2000, grid=1)
    out = "o.ply" if command == "covariance" else "o.laz"  # the report reads any format
    rc = main([command, str(tmp_path / "whole.laz"), str(tmp_path / out), *options,
               "--report", str(tmp_path / "rep")])
    assert rc == 0, capsys.readouterr().err
    assert "report:" in capsys.readouterr().out
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "<h2>Run</h2>" in html and "classes.png" in html
    assert "Where the tests were not significant" in html
    for w in words:
        assert w in html, w
    for png in re.findall(r"src='([^']+\.png)'", html):
        assert (tmp_path / "rep" / png).stat().st_size > 5_000
    if CHROMIUM is not None:
        _opens(tmp_path / "rep" / "index.html", tmp_path)


def test_no_report_unless_asked(tmp_path, capsys):
    _tiles(tmp_path, seed=6, n=900, grid=1)
    assert main(["covariance", str(tmp_path / "whole.laz"), str(tmp_path / "o.laz"),
                 "--radius", "2", "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.laz", "tiles", "whole.laz"]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed "
                    "(ci/debian-packages.txt lists it; ci/install-test-packages.sh installs it)")
def test_area_report_of_a_catalogue_in_a_browser(tmp_path, capsys):
    _tiles(tmp_path, seed=7, n=2500, grid=2)
    options, _ = COMMANDS["segment"]
    rc = main(["segment", str(tmp_path / "tiles"), str(tmp_path / "out"), *options,
               "--report", str(tmp_path / "rep"), "-q"])
    assert rc == 0, capsys.readouterr().err
    page = tmp_path / "rep" / "index.html"
    text = _opens(page, tmp_path)
    assert "Tiles" in text and "tile_1_1.laz" in text
    links = re.findall(r"href=\"(tiles/[^\"]+/index.html)\"", text)
    assert len(links) == 4
    _opens(page.parent / links[0], tmp_path)
    shot = tmp_path / "shot.png"
    run = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1200,2400",
                    page.as_uri())
    assert run.returncode == 0 and shot.stat().st_size > 20_000
    import matplotlib.image as mpimg

    assert mpimg.imread(shot)[..., :3].std() > 0.05  # not a blank page
