"""Each kernel compiles once per command run; a cold cache is announced on a terminal only.

An engineering invariant, not a statistical one: a kernel called with int32 indices in one
place and int64 in another (or a C and a non-contiguous array, or None and an array, or two
constants) is compiled twice on a fresh installation, and the first run waits for both.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


# Every command the warm-up runs, one after the other in one process started for the test
# (other tests call the kernels through the API with other types). Before each command,
# every lidarstat dispatcher forgets the specialisations it holds in memory, so the
# command asks for its own again, loading them from the disk cache, as in a process of
# its own (a kernel used by two commands with two dtypes is not a repeat). On a warm
# cache the kernels called from Python are loaded with the signatures the command asks
# for, so a second one shows on a warm cache too; on a cold one, the helpers that kernels
# call show as well.
_SPECIALISATIONS = r"""
import gc, json, os, sys
from pathlib import Path
from lidarstat.cli import main
from lidarstat.cli.warmup import STEPS
from numba.core.registry import CPUDispatcher

def dispatchers():
    return [obj for obj in gc.get_objects() if isinstance(obj, CPUDispatcher)
            and getattr(obj.py_func, "__module__", "").startswith("lidarstat")]

def signatures():
    found = {}
    for obj in dispatchers():
        if obj.signatures:
            py = obj.py_func
            # a driver made per kernel (a closure) is named by what it closes over
            inner = [getattr(c.cell_contents, "py_func", None) for c in py.__closure__ or ()]
            inner = ",".join(sorted(f.__name__ for f in inner if f is not None))
            key = f"{py.__module__}.{py.__qualname__}" + (f"[{inner}]" if inner else "")
            found.setdefault(key, set()).update(str(s) for s in obj.signatures)
    return {key: sorted(sigs) for key, sigs in found.items()}

tmp = Path(sys.argv[1])
report = {}
stdout, stderr = sys.stdout, sys.stderr
for i, (label, argv) in enumerate(STEPS):
    argv = [a.format(x=tmp / "x.laz", o=tmp / f"o{i}") for a in argv]
    for obj in dispatchers():
        obj._reset_overloads()
    sys.stdout = sys.stderr = open(os.devnull, "w")
    code = main(argv)
    sys.stdout, sys.stderr = stdout, stderr
    assert code == 0, f"{label} failed"
    report[label] = signatures()
print(json.dumps(report))
"""


def test_each_command_compiles_each_kernel_once(tmp_path):
    # processes of their own: other tests call the kernels through the API with other types
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[2] / "src"), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", _SPECIALISATIONS, str(tmp_path)],
                          capture_output=True, text=True, env=env, timeout=3600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert {"curvature", "covariance", "ridges", "moments"} <= set(report)
    assert all(report[c] for c in report if c != "synth"), "a command ran no kernel"
    many = {f"{command}: {kernel}": sigs for command, found in report.items()
            for kernel, sigs in found.items() if len(sigs) > 1}
    assert not many, json.dumps(many, indent=1)


def test_first_compile_callback_fires_on_a_cache_miss_only(tmp_path):
    code = r"""
import numpy as np
from lidarstat._shared._jit import on_first_compile
from lidarstat.neighbors._kernels import radix_order
calls = []
with on_first_compile(lambda: calls.append(1)):
    radix_order(np.arange(5, dtype=np.int64)[::-1].copy(), 3)
    radix_order(np.arange(7, dtype=np.int64), 3)
print(len(calls))
"""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[2] / "src"), os.environ.get("PYTHONPATH", "")]))
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=env, timeout=600) for _ in range(2)]
    assert [r.stdout.strip() for r in runs] == ["1", "0"], [r.stderr[-800:] for r in runs]


def test_the_notice_stays_off_stderr_that_is_not_a_terminal(tmp_path, capsys):
    from lidarstat.cli import main

    assert main(["synth", "plane", str(tmp_path / "p.laz")]) == 0
    assert "compiling" not in capsys.readouterr().err


def test_every_warmup_step_is_a_valid_command_line(tmp_path):
    from lidarstat.cli._app import build_parser
    from lidarstat.cli.warmup import STEPS

    parser = build_parser()
    for label, argv in STEPS:
        args = parser.parse_args([a.format(x=tmp_path / "x.laz", o=tmp_path / "o")
                                  for a in argv])
        assert callable(args.func), label
    commands = {argv[0] for _, argv in STEPS}
    assert {"curvature", "covariance", "ridges", "moments", "segment"} <= commands


def test_a_failing_warmup_step_is_one_error_line(monkeypatch, capsys):
    from lidarstat.cli import main
    from lidarstat.cli import warmup

    monkeypatch.setattr(warmup, "STEPS", (("bad", ("info", "no-such-file.las")),))
    assert main(["warmup"]) == 2
    err = capsys.readouterr().err
    assert "warmup step 'bad' failed" in err and err.count("error") == 1
