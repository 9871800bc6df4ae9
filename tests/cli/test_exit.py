"""The end of a ``lidarstat`` process (:func:`lidarstat.cli.run`): outputs complete, exit
handlers run, streams flushed, the status kept; live threads joined as usual.

Real processes (``python -m lidarstat`` and small scripts calling
:func:`lidarstat.cli._app.end`), since the point is what happens after the interpreter's
last line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarstat
from lidarstat.io import PointCloud, write

SRC = str(Path(lidarstat.__file__).resolve().parents[1])
ENV = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _python(code_or_args, tmp_path):
    args = ["-c", code_or_args] if isinstance(code_or_args, str) else code_or_args
    return subprocess.run([sys.executable, *args], env=ENV, cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def town(tmp_path_factory):
    rng = np.random.default_rng(3)
    n = 20_000
    xy = rng.uniform(0, 60, (n, 2))
    z = 0.02 * xy[:, 0] + rng.normal(0, 0.03, n)
    roof = (np.abs(xy[:, 0] - 30) < 8) & (np.abs(xy[:, 1] - 30) < 8)
    z[roof] += 6.0
    path = tmp_path_factory.mktemp("exit_src") / "town.las"
    write(path, PointCloud(np.c_[xy, z], {"intensity": rng.integers(100, 4000, n).astype(
        np.uint16)}))
    return path, n


def test_command_output_complete_and_summary_printed(town, tmp_path):
    src, n = town
    out = tmp_path / "out.las"
    proc = _python(["-m", "lidarstat", "moments", str(src), str(out), "--no-report"],
                   tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert f"{n} points" in proc.stdout  # the summary reached the pipe
    las = laspy.read(out)
    assert len(las.points) == n
    assert set(np.unique(las.classification)) <= {1, 2, 3, 4, 5, 6, 11}
    assert not [p for p in tmp_path.iterdir() if p.name != "out.las"]


def test_command_error_status_and_one_line(town, tmp_path):
    proc = _python(["-m", "lidarstat", "moments", str(tmp_path / "absent.las"),
                    str(tmp_path / "o.las")], tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "absent.las" in lines[0]


@pytest.mark.parametrize("rc", [0, 3])
def test_exit_handlers_run_streams_flushed_status_kept(tmp_path, rc):
    code = ("import atexit, sys\n"
            "from lidarstat.cli._app import end\n"
            "atexit.register(lambda: open('handler', 'w').write('ran'))\n"
            "sys.stdout.write('no newline, still buffered')\n"
            "sys.stderr.write('err text')\n"
            f"end({rc})\n"
            "open('after', 'w').write('end returned')\n")
    proc = _python(code, tmp_path)
    assert proc.returncode == rc
    assert proc.stdout == "no newline, still buffered"
    assert proc.stderr == "err text"
    assert (tmp_path / "handler").read_text() == "ran"
    assert not (tmp_path / "after").exists()


def test_live_thread_is_joined(tmp_path):
    code = ("import threading, time\n"
            "from lidarstat.cli._app import end\n"
            "def late():\n"
            "    time.sleep(0.5)\n"
            "    open('thread', 'w').write('finished')\n"
            "threading.Thread(target=late).start()\n"
            "end(0)\n")
    proc = _python(code, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "thread").read_text() == "finished"


@pytest.mark.parametrize("rc, status, err", [(None, 0, ""), ("a message", 1, "a message")])
def test_status_that_is_not_a_number(tmp_path, rc, status, err):
    proc = _python(f"from lidarstat.cli._app import end\nend({rc!r})\n", tmp_path)
    assert proc.returncode == status
    assert proc.stderr.strip() == err
