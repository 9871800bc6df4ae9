"""Each kernel compiles once per command run; a cold cache is announced on a terminal only.

An engineering invariant, not a statistical one: a kernel called with int32 indices in one
place and int64 in another (or a C and a non-contiguous array, or None and an array, or two
constants) is compiled twice on a fresh installation, and the first run waits for both.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path


def _report():
    """Each warm-up command's kernel signatures: the report the xdist controller made
    before the workers started (``tests/conftest.py``), else made here (``-n 0``)."""
    path = os.environ.get("LIDARSTAT_COMPILE_REPORT")
    if path and Path(path).is_file():
        return json.loads(Path(path).read_text())
    from _compile_report import run

    return run(1)


def test_each_command_compiles_each_kernel_once():
    # processes of their own: other tests call the kernels through the API with other types
    got = _report()
    assert not got["errors"], got["errors"]
    report = got["report"]
    assert {"curvature", "covariance", "ridges", "moments"} <= set(report)
    assert all(report[c] for c in report if c != "synth"), "a command ran no kernel"
    # a helper given tuples of two lengths (``_put(out, (a, b, ...))``) is two functions
    # by design: the variants that count differ in anything but a tuple's length
    many = {f"{command}: {kernel}": sigs for command, found in report.items()
            for kernel, sigs in found.items()
            if len({re.sub(r"UniTuple\((\w+), \d+\)", r"UniTuple(\1)", s) for s in sigs}) > 1}
    assert not many, json.dumps(many, indent=1)


def test_no_kernel_compiles_twice_across_the_commands():
    # one neighbour-index dtype (int32), one array type per argument: a kernel two commands
    # share is compiled once on a fresh installation, not once per command's types
    report = _report()["report"]
    union = {}
    for found in report.values():
        for kernel, sigs in found.items():
            union.setdefault(kernel, set()).update(
                re.sub(r"UniTuple\((\w+), \d+\)", r"UniTuple(\1)", s) for s in sigs)
    many = {kernel: sorted(sigs) for kernel, sigs in union.items() if len(sigs) > 1}
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


def test_read_only_inputs_compile_no_second_variant():
    # Numba types a read-only array apart from a writable one; a synthetic cloud's arrays
    # are read-only, a file's are not: the wrappers hand the kernels writable arrays.
    import numpy as np

    from lidarstat.neighbors import CellIndex, find_duplicates, knn_neighbors
    from lidarstat.neighbors import _kernels as nk
    from lidarstat.segment import _refine, _scales
    from lidarstat.segment._covariance_segments import segment_planes
    from lidarstat.segment._refine import segment_plane_models
    from lidarstat.segment._scales import planar_scales

    rng = np.random.default_rng(5)
    pts = np.c_[rng.uniform(0, 4, (300, 2)), rng.normal(0, 0.01, 300)]
    labels = np.where(pts[:, 0] < 2, 1, 2)
    sigma = np.full(300, 0.01)
    for a in (pts, sigma):
        a.flags.writeable = False
    kernels = [nk.grid_keys, nk.column_hash, _refine._seg_moments, _refine._residual_units,
               _scales._prefix_planes]
    before = [set(k.signatures) for k in kernels]  # other tests may have run them
    CellIndex(pts, 0.5)
    find_duplicates(pts)
    segment_plane_models(pts, labels, sigma)
    segment_planes(pts, labels)
    planar_scales(pts, knn_neighbors(pts, 20), sigma, scales=(10, 20))
    readonly = {k.py_func.__name__: [str(s) for s in set(k.signatures) - old
                                     if "', True" in str(s)] for k, old in zip(kernels, before)}
    assert not any(readonly.values()), readonly


def test_warmup_groups_cover_every_step_once():
    from _compile_report import groups

    from lidarstat.cli.warmup import STEPS

    labels = [label for label, _ in STEPS if label != "synth"]
    for n in (1, 2, 3, 8):
        got = groups(n)
        assert 1 <= len(got) <= n and all(g[0] == "synth" for g in got)
        steps = [s for g in got for s in g[1:]]
        assert sorted(steps) == sorted(labels), (n, got)
