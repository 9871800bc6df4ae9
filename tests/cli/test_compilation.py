"""Each kernel compiles once per command run; a cold cache is announced on a terminal only.

An engineering invariant, not a statistical one: a kernel called with int32 indices in one
place and int64 in another (or a C and a non-contiguous array, or None and an array) is
compiled twice on a fresh installation, and the first run waits for both.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path


_SPECIALISATIONS = r"""
import json, sys
from lidarstat.cli import main
x, out = sys.argv[1], sys.argv[2]
assert main(["synth", "hip_roof", x]) == 0
assert main(["curvature", x, out + "/c.laz", "--radius", "1"]) == 0
assert main(["covariance", x, out + "/v.laz"]) == 0
from numba.core.registry import CPUDispatcher
seen, found = set(), {}
for name, mod in list(sys.modules.items()):
    if name.startswith("lidarstat"):
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher) and id(obj) not in seen:
                seen.add(id(obj))
                found[f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"] = [
                    str(s) for s in obj.signatures]
print(json.dumps(found))
"""


def test_curvature_and_covariance_compile_each_kernel_once(tmp_path):
    # a process of its own: other tests call the kernels through the API with other types
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[2] / "src"), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run(
        [sys.executable, "-c", _SPECIALISATIONS, str(tmp_path / "x.laz"), str(tmp_path)],
        capture_output=True, text=True, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-2000:]
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    assert any(found.values()), "no kernel ran"
    many = {k: v for k, v in found.items() if len({_argument_types(s) for s in v}) > 1}
    assert not many, json.dumps(many, indent=1)


def _argument_types(signature: str) -> str:
    """A signature without what a calling kernel adds on a cold cache, not a Python caller.

    A helper inlined into a kernel is also typed at each call site with the constants it is
    given (``Literal[int](3)``) and with ``uint64`` for a ``prange`` index; those are the
    compiler's, not a dtype or layout chosen at a Python boundary, and vanish on a warm
    cache (the caller's cached code carries its helpers).
    """
    signature = re.sub(r"Literal\[int\]\(-?\d+\)", "int64", signature)
    signature = re.sub(r"Literal\[bool\]\((?:True|False)\)", "bool", signature)
    return signature.replace("uint64", "int64")


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
