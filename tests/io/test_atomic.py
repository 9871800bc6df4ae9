"""Atomic output: every writer works through an unnamed temporary and leaves nothing else."""

import contextlib
import errno
import os

import numpy as np
import pytest

from lidarstat._shared import _atomic
from lidarstat._shared._atomic import atomic_path, unnamed_file
from lidarstat.io import PointCloud, read, rewrite, write
from lidarstat.segment import Polylines

FORMATS = ["las", "laz", "ply", "csv", "txt", "npz"]


@pytest.fixture(params=["unnamed", "named", "copied"])
def mode(request, monkeypatch):
    """The O_TMPFILE path, the named fallback, and the copy when linking is refused."""
    if request.param == "named":
        monkeypatch.setattr(_atomic, "_open_unnamed", lambda directory, path: None)
    elif request.param == "copied":
        def refuse(fd, dst):
            raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), str(dst))

        monkeypatch.setattr(_atomic, "_linkat", refuse)
    return request.param


def _cloud(n=500, shift=0.0):
    xyz = np.random.default_rng(0).random((n, 3)) + shift
    return PointCloud(xyz=xyz, attributes={"intensity": np.arange(n, dtype=np.uint16)})


def test_every_format_written_and_overwritten(tmp_path, mode):
    for fmt in FORMATS:
        path = tmp_path / f"o.{fmt}"
        for k in (1, 2):  # a new file, then over an existing one
            write(path, _cloud(), fields={"f": np.arange(500) * k})
            back = read(path)
            assert len(back) == 500 and np.array_equal(back["f"], np.arange(500) * k), fmt
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"o.{f}" for f in FORMATS)
    with open(tmp_path / "o.laz", "rb") as fh:  # the compressed bit of the point format
        fh.seek(104)
        assert fh.read(1)[0] & 0x80
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "o.las").stat().st_mode & 0o777 == 0o666 & ~mask


def test_streamed_las_write(tmp_path, mode):
    src = tmp_path / "in.las"
    write(src, _cloud(3000))
    out = tmp_path / "out.laz"
    rewrite(src, out, lambda s, c: {"rank": np.arange(s, s + len(c))}, points_per_chunk=700)
    assert np.array_equal(read(out)["rank"], np.arange(3000))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las", "out.laz"]


def test_side_writers(tmp_path, mode):
    from lidarstat.report._views import plot_field

    lines = Polylines.from_segments([[0, 0, 0]], [[1, 0, 0]], {"w": [2.0]})
    for name in ("l.geojson", "l.csv", "l.las"):
        lines.write(tmp_path / name)
    xyz = _cloud().xyz
    plot_field(tmp_path / "v.png", xyz, xyz[:, 2], title="z")
    assert (tmp_path / "v.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.csv", "l.geojson", "l.las",
                                                          "v.png"]


def test_failure_keeps_the_old_file_and_leaves_nothing(tmp_path, mode):
    path = tmp_path / "o.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["o.txt"]


def test_errors_name_the_users_path(tmp_path, mode):
    target = tmp_path / "missing" / "o.las"
    with pytest.raises(OSError) as info:
        write(target, _cloud())
    assert str(target) in str(info.value)
    assert "/proc/" not in str(info.value) and ".tmp" not in str(info.value)

    def fail_inside(tmp):
        raise FileNotFoundError(errno.ENOENT, "gone", str(tmp))

    with pytest.raises(FileNotFoundError) as info, atomic_path(tmp_path / "x.json") as tmp:
        fail_inside(tmp)
    assert info.value.filename == str(tmp_path / "x.json")


def test_unnamed_file_leaves_no_name(tmp_path):
    with unnamed_file(tmp_path) as fh:
        fh.write(b"scratch")
        fh.seek(0)
        assert fh.read() == b"scratch"
        assert list(tmp_path.iterdir()) == []
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fails", [False, True])
def test_output_group_all_or_nothing(tmp_path, mode, fails):
    from lidarstat._shared._atomic import output_group

    (tmp_path / "b.txt").write_text("old")
    with pytest.raises(RuntimeError) if fails else contextlib.nullcontext(), output_group():
        write(tmp_path / "a.laz", _cloud())
        with atomic_path(tmp_path / "b.txt") as tmp:
            tmp.write_text("new")
        shown = sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("."))
        assert shown == ["b.txt"]  # (the named fallback's hidden temporaries aside)
        if fails:
            raise RuntimeError("the last step fails")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == (["b.txt"] if fails else ["a.laz", "b.txt"])
    assert (tmp_path / "b.txt").read_text() == ("old" if fails else "new")
    if not fails:
        assert len(read(tmp_path / "a.laz")) == 500
