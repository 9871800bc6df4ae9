"""``lidarstat curvature`` parses with its own subcommand and imports only what it uses."""

import subprocess
import sys

from lidarstat.cli._app import CORE_COMMANDS, build_parser, command_of


def _run_without(statements, prefixes=(), modules=()):
    """Run `statements` in a fresh interpreter; fail if it imported a module starting with
    one of `prefixes` or one of `modules`."""
    code = ("import sys\n" + statements
            + f"bad = [m for m in sys.modules if m.startswith({tuple(prefixes)!r})]\n"
            + f"bad += [m for m in {tuple(modules)!r} if m in sys.modules]\n"
            + "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_command_of_skips_the_global_options():
    assert command_of(["-v", "curvature", "a.las", "b.las"]) == "curvature"
    assert command_of(["--version"]) is None
    assert command_of(["--", "curvature"]) is None


def test_a_core_command_parses_alone_and_the_same():
    full, alone = build_parser(), build_parser("curvature")
    argv = ["curvature", "in.las", "out.las", "--radius", "0.5", "--sigma", "0.01", "-q"]
    assert vars(full.parse_args(argv)).keys() == vars(alone.parse_args(argv)).keys()
    assert {k: v for k, v in vars(full.parse_args(argv)).items() if k != "func"} == \
        {k: v for k, v in vars(alone.parse_args(argv)).items() if k != "func"}
    sub = next(a for a in alone._actions if a.dest == "command")
    assert set(sub.choices) == {"curvature"}
    assert {"curvature", "segment"} <= set(next(
        a for a in full._actions if a.dest == "command").choices)
    assert set(CORE_COMMANDS) <= set(next(a for a in full._actions if a.dest == "command").choices)


def test_curvature_run_does_not_import_scipy_stats_or_other_methods(tmp_path):
    # nor scipy.special at a fixed radius: the tests' tails and the sigma estimate's
    # chi-square medians run in kernels; nor scipy.linalg, which Numba's start would
    # import to learn whether a BLAS is there (lidarstat._shared._jit)
    import numpy as np

    from lidarstat.io import PointCloud, write

    g = np.linspace(0, 3, 30)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    rng = np.random.default_rng(0)
    write(tmp_path / "in.las", PointCloud(xyz=np.c_[x, y, 0.1 * x * x + rng.normal(0, 0.01, x.size)]))
    _run_without(
        "from lidarstat.cli._app import main\n"
        f"assert main(['curvature', {str(tmp_path / 'in.las')!r}, {str(tmp_path / 'out.las')!r},"
        " '--radius', '0.6', '-q']) == 0\n",
        prefixes=("scipy.stats", "scipy.spatial", "scipy.linalg", "scipy.special", "lidarstat.segment",
                  "lidarstat.classify", "lidarstat.pipeline", "lidarstat.report", "matplotlib",
                  "dask", "pandas", "rasterio"),
        # the other local models of lidarstat.features and the rasters of lidarstat.io
        modules=("lidarstat.features._jets", "lidarstat.features._covariance",
                 "lidarstat.features._cylinder", "lidarstat.features._plane_regression",
                 "lidarstat.io._raster", "lidarstat.io._extent"))
    assert (tmp_path / "out.las").exists()


def test_a_kernel_using_blas_still_finds_it():
    # the start answers Numba's BLAS question without importing scipy.linalg; a kernel
    # calling np.dot must still import it when compiled, and the answer must be yes
    code = ("import sys\n"
            "import numpy as np\n"
            "import lidarstat._shared._jit as jit\n"
            "from numba import njit\n"
            "import numba.np.arraymath as am\n"
            "assert 'scipy.linalg' not in sys.modules and am._HAVE_BLAS\n"
            "f = njit(lambda a, b: np.dot(a, b))\n"
            "assert f(np.arange(3.0), np.arange(3.0)) == 5.0\n"
            "assert 'scipy.linalg' in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_parsing_imports_no_numerics():
    """``lidarstat curvature --help`` and a refused option parse without the numerical
    packages, NumPy included (the catalogue options' modules import it where used)."""
    _run_without("from lidarstat.cli._app import build_parser\nbuild_parser('curvature')\n",
                 modules=("numpy", "numba", "scipy", "laspy", "pyproj", "matplotlib", "dask",
                          "pandas"))


def test_a_module_command_parses_alone_and_the_same():
    from lidarstat.cli._app import COMMAND_MODULES

    full = build_parser()
    argv = ["moments", "in.las", "out.las", "--no-report", "--window", "32", "-q"]
    alone = build_parser(command_of(argv))
    assert {k: v for k, v in vars(full.parse_args(argv)).items() if k != "func"} == \
        {k: v for k, v in vars(alone.parse_args(argv)).items() if k != "func"}
    for name in COMMAND_MODULES:
        sub = next(a for a in build_parser(name)._actions if a.dest == "command")
        assert set(sub.choices) == {name}


def test_moments_run_does_not_import_the_other_methods(tmp_path):
    import numpy as np

    from lidarstat.io import PointCloud, write

    g = np.random.default_rng(0)
    xy = g.uniform(0, 40, (3000, 2))
    write(tmp_path / "in.las", PointCloud(xyz=np.c_[xy, 0.05 * xy[:, 0] + g.normal(0, 0.02, 3000)],
                                          attributes={"intensity": g.integers(50, 200, 3000)
                                                      .astype(np.uint16)}))
    _run_without(
        "from lidarstat.cli._app import main\n"
        f"assert main(['moments', {str(tmp_path / 'in.las')!r}, {str(tmp_path / 'out.las')!r},"
        " '--no-report', '-q']) == 0\n",
        prefixes=("lidarstat.segment", "lidarstat.synth", "lidarstat.report", "matplotlib"))
    assert (tmp_path / "out.las").exists()


def test_console_script_ends_at_once_after_a_success_with_its_output_delivered(tmp_path):
    # as the console script, a successful `curvature` ends the process without the
    # interpreter's teardown (an exit hook does not run) once its summary is flushed into
    # the pipe and its file written; a failure exits normally with its status
    import numpy as np

    from lidarstat.io import PointCloud, read, write

    g = np.linspace(0, 3, 30)
    x, y = [a.ravel() for a in np.meshgrid(g, g)]
    rng = np.random.default_rng(1)
    write(tmp_path / "in.las", PointCloud(xyz=np.c_[x, y, 0.1 * x * y + rng.normal(0, 0.01, x.size)]))

    def console(*argv):
        code = ("import atexit, sys\n"
                "atexit.register(lambda: print('teardown', flush=True))\n"
                f"sys.argv = ['lidarstat', *{list(argv)!r}]\n"
                "from lidarstat.cli import main\n"
                "raise SystemExit(main())\n")
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)

    done = console("curvature", str(tmp_path / "in.las"), str(tmp_path / "out.las"),
                   "--radius", "0.6", "--sigma", "0.01")
    assert done.returncode == 0, done.stderr
    assert "teardown" not in done.stdout
    assert "surface types:" in done.stdout and done.stdout.rstrip().endswith("%")
    from lidarstat.cli._app import main

    assert main(["curvature", str(tmp_path / "in.las"), str(tmp_path / "same.las"),
                 "--radius", "0.6", "--sigma", "0.01", "-q"]) == 0
    a, b = read(tmp_path / "out.las"), read(tmp_path / "same.las")
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert a.attributes.keys() == b.attributes.keys()
    for name in a.attributes:
        np.testing.assert_array_equal(a.attributes[name], b.attributes[name])
    failed = console("curvature", str(tmp_path / "missing.las"), str(tmp_path / "o.las"),
                     "--radius", "0.6")
    assert failed.returncode == 2 and "teardown" in failed.stdout
