"""Shared fixtures: seeded RNG, the real data folder (skipped with its path when absent)."""

from __future__ import annotations

import os
from pathlib import Path

# The test processes (two xdist workers, and the commands they start) share two cores.
# Numba's OpenMP threads otherwise spin after each parallel region, taking the other
# worker's core.
# Set before NumPy and Numba load the OpenMP runtime; a value the caller set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

# Repository root is tests/..; the shared data lives beside the repository.
SHARED_DATA = Path(
    os.environ.get("LIDARSTAT_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data")
)


@pytest.fixture
def rng():
    """A seeded generator; every stochastic test starts from it."""
    return np.random.default_rng(20261122)


@pytest.fixture
def shared_data():
    """Path of ``../shared/data``; the test is skipped (reason names the path) if missing."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder not found: {SHARED_DATA}")
    return SHARED_DATA


def shared_file(relpath: str) -> Path:
    """Path of one file of the shared data, or skip the calling test naming it."""
    path = SHARED_DATA / relpath
    if not path.is_file():
        pytest.skip(f"real data file not found: {path}")
    return path


# ------------------------------------------------------------------ compile time of the run
# Numba's compile time, summed over the run's processes (xdist workers report theirs to
# the controller), is printed in the summary: the share of the suite's time that a warm
# cache saves. Outermost compile events only (a kernel's helpers compile inside it); the
# CPU seconds (the compiling thread's) do not grow when other jobs share the machine.
_COMPILES = {"seconds": 0.0, "cpu": 0.0, "count": 0}
# (kernel and argument types, compile CPU seconds) of every outermost compilation; written
# to the file named by LIDARSTAT_COMPILE_LOG (JSON) when set, to find what compiles twice.
_KERNELS: list = []


def _count_compiles():
    from _compile_listener import count_compiles

    count_compiles(_COMPILES, _KERNELS)


def pytest_configure(config):
    _count_compiles()


# ------------------------------------------------------------------ file order under xdist
#: The files of the longest total run time on a cold cache (``slowest_files_s`` of
#: ``benchmarks/results_first_run.json``, key ``suite``), the longest first: sent to the
#: workers first. xdist's own order (``--loadscope-reorder``: the files with the most
#: tests first) sends those of few long tests (a g++ build of the CGAL driver, the Sphinx
#: build, whole-catalogue runs) last, and the suite then ends with one worker running one
#: of them while the other has nothing left; ``pyproject.toml`` turns it off
#: (``--no-loadscope-reorder``) for this order: these files, then the others by decreasing
#: number of tests.
_LONG_FILES = (
    "tests/features/test_jets.py",
    "tests/test_docs.py",
    "tests/cli/test_catalogue_cli.py",
    "tests/classify/test_covariance_classes.py",
    "tests/cli/test_catalogue_methods.py",
    "tests/segment/test_sar_segmentation.py",
    "tests/io/test_e57_sensor.py",
    "tests/segment/test_covariance_segments.py",
    "tests/independent/test_indep_curvature.py",
    "tests/report/test_command_reports.py",
)


def pytest_collection_modifyitems(session, config, items):
    if not hasattr(config, "workerinput"):  # one process: the collection order
        return
    files = {}
    for item in items:
        files.setdefault(item.nodeid.split("::", 1)[0], []).append(item)
    first = {name: rank for rank, name in enumerate(_LONG_FILES)}
    order = sorted(files, key=lambda f: (first.get(f, len(first)), -len(files[f])))
    items[:] = [item for f in order for item in files[f]]


# ------------------------------------------------------------------ compile once, then test
# On the xdist controller, before the workers start: the warm-up commands in a few
# processes at once, at most one per worker (tests/_compile_report.py), so that each kernel
# the commands use is compiled once into the cache the workers and the CLI subprocesses
# load from, not by every process that needs it first at the same time; their report is
# what tests/cli/test_compilation.py checks. Only for the whole suite (no test paths
# given), where nearly every kernel is needed; LIDARSTAT_TEST_WARMUP=1 asks for it on any
# run under xdist, =0 never.
_WARMUP = {}


def _warm_up_first(config) -> int:
    """Number of warm-up processes for this run (0: none)."""
    if (hasattr(config, "workerinput") or not config.pluginmanager.hasplugin("dsession")
            or config.option.collectonly):
        return 0
    n = len(getattr(config.option, "tx", None) or ())  # the workers xdist starts
    wanted = os.environ.get("LIDARSTAT_TEST_WARMUP")
    if wanted == "0" or n < 2:
        return 0
    if wanted == "1" or config.args_source == pytest.Config.ArgsSource.TESTPATHS:
        return n
    return 0


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    n = _warm_up_first(session.config)
    if not n:
        return
    import json
    import tempfile

    from _compile_report import run

    tr = session.config.pluginmanager.get_plugin("terminalreporter")
    if tr is not None:
        tr.write_line("compiling the warm-up commands' kernels before the workers start "
                      "(LIDARSTAT_TEST_WARMUP=0 skips it)")
    got = run(n)
    for key in ("seconds", "cpu", "count"):
        _COMPILES[key] += got["compiles"][key]
    _KERNELS.extend(got["compiles"]["kernels"])
    path = Path(tempfile.mkdtemp(prefix="lidarstat-tests-")) / "compile_report.json"
    path.write_text(json.dumps(got))
    os.environ["LIDARSTAT_COMPILE_REPORT"] = str(path)  # the workers inherit it
    _WARMUP.update(wall_s=got["wall_s"], processes=got["processes"], errors=len(got["errors"]),
                   path=path, groups=got["groups"])


def pytest_sessionfinish(session):
    if "path" in _WARMUP:
        import shutil

        shutil.rmtree(_WARMUP["path"].parent, ignore_errors=True)
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["numba_compiles"] = dict(_COMPILES)
        workeroutput["numba_kernels"] = list(_KERNELS)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    theirs = getattr(node, "workeroutput", {}).get("numba_compiles", {})
    _COMPILES["seconds"] += theirs.get("seconds", 0.0)
    _COMPILES["cpu"] += theirs.get("cpu", 0.0)
    _COMPILES["count"] += theirs.get("count", 0)
    _KERNELS.extend(getattr(node, "workeroutput", {}).get("numba_kernels", []))


def pytest_terminal_summary(terminalreporter):
    log = os.environ.get("LIDARSTAT_COMPILE_LOG")
    if log:
        import json

        Path(log).write_text(json.dumps(sorted(_KERNELS, key=lambda kv: -kv[1]), indent=0))
    if _WARMUP:
        terminalreporter.write_line(
            f"Warm-up before the workers: {_WARMUP['processes']} processes, "
            f"{_WARMUP['wall_s']:.0f} s ({_WARMUP['errors']} failed; each: "
            + ", ".join(f"{g['wall_s']:.0f} s wall {g['cpu_s']:.0f} s CPU"
                        for g in _WARMUP["groups"]) + ")")
    if _COMPILES["count"]:
        terminalreporter.write_line(
            f"Numba: {_COMPILES['count']} compilations, {_COMPILES['seconds']:.0f} s compiling "
            f"({_COMPILES['cpu']:.0f} s CPU) "
            f"(summed over the test processes and the warm-up; a warm cache loads instead)")
