"""Killed mid-write: the output is absent or complete, and no temporary file remains.

Real ``python -m lidarstat`` processes, signalled while their unnamed temporary files
(the output being written, the tile scratch) are open: the test watches
``/proc/PID/fd`` for ``O_TMPFILE`` files in the output folder and signals at that moment.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarstat
from lidarstat._shared._atomic import _open_unnamed
from lidarstat.io import PointCloud, write

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(),
                                reason="needs Linux /proc to watch the process")

N_POINTS = 60_000
SRC = str(Path(lidarstat.__file__).resolve().parents[1])


def _unnamed_supported(folder: Path) -> bool:
    fd = _open_unnamed(folder, folder / "x")
    if fd is None:
        return False
    os.close(fd)
    return True


@pytest.fixture(scope="module")
def cloud_file(tmp_path_factory):
    side = int(np.sqrt(N_POINTS))
    g = np.arange(side) * 0.05
    x, y = np.meshgrid(g, g)
    z = 0.3 * np.sin(x) * np.cos(0.8 * y) + np.random.default_rng(1).normal(0, 0.002, x.shape)
    path = tmp_path_factory.mktemp("kill_src") / "in.las"
    write(path, PointCloud(np.c_[x.ravel(), y.ravel(), z.ravel()]))
    return path, side * side


def _unnamed_open(pid: int, folder: Path) -> int:
    """How many descriptors of `pid` are unnamed (O_TMPFILE) files in `folder`."""
    n = 0
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return 0
    for fd in fds:
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith(f"{folder}/#") and target.endswith("(deleted)"):
            n += 1
    return n


def _start(cmd, tmpdir: Path):
    env = {**os.environ, "PYTHONPATH": SRC, "TMPDIR": str(tmpdir)}
    # SIGINT at its default in the child, whatever the test runner ignores
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT,  # noqa: PLW1509
                                                             signal.SIG_DFL))


def _signal_all(runs: dict) -> None:
    """Signal each run once its number of unnamed files is open (all run concurrently)."""
    deadline = time.monotonic() + 150
    waiting = dict(runs)
    while waiting and time.monotonic() < deadline:
        for name, run in list(waiting.items()):
            proc = run["proc"]
            if proc.poll() is not None:
                del waiting[name]
            elif _unnamed_open(proc.pid, run["folder"]) >= run["open_files"]:
                proc.send_signal(run["signal"])
                run["sent"] = True
                del waiting[name]
        time.sleep(0.002)
    for run in runs.values():
        proc = run["proc"]
        try:
            run["stdout"], run["stderr"] = proc.communicate(timeout=90)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()


def _assert_nothing_left(folder: Path, tmpdir: Path, inp: Path, out: Path, n: int):
    names = sorted(p.name for p in folder.iterdir())
    assert set(names) <= {inp.name, out.name}, names
    assert not list(tmpdir.iterdir())
    if out.exists():  # complete, or absent
        assert laspy.read(out).header.point_count == n


# (extra options, unnamed files open when the signal goes, signal, exit status)
CASES = {
    "kill-writing": ([], 1, signal.SIGKILL, -signal.SIGKILL),
    "term-writing": ([], 1, signal.SIGTERM, 143),
    "kill-tile-scratch": (["--tile", "4"], 1, signal.SIGKILL, -signal.SIGKILL),
    "kill-tile-writing": (["--tile", "4"], 3, signal.SIGKILL, -signal.SIGKILL),
    "term-tile-scratch": (["--tile", "4"], 2, signal.SIGTERM, 143),
    "int-tile": (["--tile", "4"], 2, signal.SIGINT, 130),
}
MESSAGES = {143: "lidarstat: terminated (SIGTERM)", 130: "lidarstat: interrupted"}


@pytest.fixture(scope="module")
def runs(cloud_file, tmp_path_factory):
    """Every case of :data:`CASES`, run concurrently, each in a folder of its own."""
    src, _ = cloud_file
    base = tmp_path_factory.mktemp("kill")
    if not _unnamed_supported(base):
        pytest.skip("no O_TMPFILE on this file system: temporaries have names")
    runs = {}
    for case, (extra, open_files, sig, _) in CASES.items():
        folder, tmpdir = base / case / "run", base / case / "tmp"
        folder.mkdir(parents=True)
        tmpdir.mkdir()
        inp, out = folder / "in.las", folder / "out.laz"
        os.link(src, inp)  # a hard link: the test also sees that the input stays intact
        cmd = [sys.executable, "-m", "lidarstat", "curvature", str(inp), str(out),
               "--radius", "0.11", "--sigma", "0.002", "--chunk-points", "20000", "-q",
               *extra]
        runs[case] = {"proc": _start(cmd, tmpdir), "folder": folder, "tmpdir": tmpdir,
                      "inp": inp, "out": out, "open_files": open_files, "signal": sig,
                      "sent": False, "before": src.read_bytes()}
    _signal_all(runs)
    return runs


@pytest.mark.parametrize("case", list(CASES))
def test_signal_leaves_output_absent_or_complete(cloud_file, runs, case):
    _, n = cloud_file
    run = runs[case]
    code, err = run["proc"].returncode, run["stderr"]
    status = CASES[case][3]
    assert run["sent"], f"the run ended before the moment to signal it: {code} {err}"
    assert code == status, err
    if status in MESSAGES:
        assert err.strip().splitlines() == [MESSAGES[status]], err
    assert run["inp"].read_bytes() == run["before"]
    _assert_nothing_left(run["folder"], run["tmpdir"], run["inp"], run["out"], n)
