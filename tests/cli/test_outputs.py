"""The output plan: every path a command writes is checked before any work.

No output may be an input (same path, symlink, hard link, the input's sensor sidecar),
two outputs may not be one file, folders must exist and suffixes fit. A refusal leaves
the input byte-identical and writes nothing.
"""

import os
import signal
import threading

import numpy as np
import pytest

from lidarstat.cli import _app, main
from lidarstat.io import PointCloud, write


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def valid(tmp_path):
    path = tmp_path / "valid.las"
    xyz = np.random.default_rng(0).uniform(0, 10, (400, 3))
    write(path, PointCloud(xyz=xyz, attributes={"classification": np.full(400, 2, np.uint8)}))
    return path


#: command line before the side option (IN and OUT are filled in), per command
COMMANDS = {
    "curvature": ["curvature", "{in}", "{out}", "--radius", "1"],
    "covariance": ["covariance", "{in}", "{out}"],
    "segment": ["segment", "{in}", "{out}", "--method", "sar"],
    "ridges": ["ridges", "{in}", "{out}", "--radius", "1"],
    "moments": ["moments", "{in}", "{out}"],
    "evaluate": ["evaluate", "{in}", "--reference", "{in}"],
}
SIDE_OPTIONS = [("curvature", "--summary-json"), ("covariance", "--summary-json"),
                ("segment", "--table"), ("segment", "--lines"), ("segment", "--summary-json"),
                ("segment", "--diagnostics"), ("ridges", "--lines"),
                ("ridges", "--summary-json"), ("moments", "--report"),
                ("moments", "--summary-json"), ("evaluate", "--json")]


def _argv(command, inp, out):
    return [a.format(**{"in": inp, "out": out}) for a in COMMANDS[command]]


def _alias(valid, how):
    if how == "same":
        return valid
    alias = valid.with_name(f"{how}.las")
    (os.symlink if how == "symlink" else os.link)(valid, alias)
    return alias


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("command,option", SIDE_OPTIONS)
def test_side_output_on_the_input_is_refused(valid, tmp_path, capsys, command, option, how):
    before = valid.read_bytes()
    target = _alias(valid, how)
    out = tmp_path / "out.las"
    code, _, err = _run(_argv(command, valid, out) + [option, target], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"{option} {target}" in lines[0], err
    assert "is the input file" in lines[0]
    assert valid.read_bytes() == before
    assert not out.exists()


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("command", ["curvature", "covariance", "segment", "ridges", "moments"])
def test_main_output_on_the_input_is_refused(valid, capsys, command, how):
    before = valid.read_bytes()
    target = _alias(valid, how)
    code, _, err = _run(_argv(command, valid, target), capsys)
    assert code == 2 and f"output {target}: is the input file" in err, err
    assert valid.read_bytes() == before


def test_evaluate_json_on_the_reference_is_refused(valid, tmp_path, capsys):
    ref = tmp_path / "ref.las"
    ref.write_bytes(valid.read_bytes())
    code, _, err = _run(["evaluate", valid, "--reference", ref, "--json", ref], capsys)
    assert code == 2 and f"--json {ref}: is the input file" in err
    assert ref.read_bytes() == valid.read_bytes()


def test_default_segment_table_colliding_with_the_input(tmp_path, capsys):
    inp = tmp_path / "scan.segments.csv"  # a CSV cloud: OUT scan.las puts the table here
    inp.write_text("x,y,z\n" + "".join(f"{i},{i % 7},{i % 3}\n" for i in range(50)))
    before = inp.read_bytes()
    out = tmp_path / "scan.las"
    code, _, err = _run(["segment", inp, out, "--method", "sar"], capsys)
    assert code == 2 and f"--table {inp} (the default" in err and "is the input file" in err
    assert inp.read_bytes() == before and not out.exists()


def test_sensor_sidecar_is_an_input(valid, tmp_path, capsys):
    side = valid.with_name(valid.name + ".sensor.json")
    side.write_text('{"sensor": [0, 0, 0]}')
    before = side.read_bytes()
    code, _, err = _run(["covariance", valid, tmp_path / "o.las", "--summary-json", side],
                        capsys)
    assert code == 2 and "sensor sidecar" in err and side.read_bytes() == before


@pytest.mark.parametrize("argv,words", [
    (["covariance", "{in}", "{out}", "--summary-json", "no/such/dir/s.json"],
     "--summary-json no/such/dir/s.json: folder no/such/dir does not exist"),
    (["segment", "{in}", "{out}", "--method", "sar", "--table", "t.xyz"],
     "--table t.xyz: unknown table format '.xyz'"),
    (["segment", "{in}", "{out}", "--method", "sar", "--table", "missing/t.csv"],
     "--table missing/t.csv: folder missing does not exist"),
    (["segment", "{in}", "{out}", "--method", "sar", "--lines", "l.xyz"],
     "--lines l.xyz: unknown format for lines"),
    (["ridges", "{in}", "{out}", "--radius", "1", "--lines", "nowhere/l.geojson"],
     "--lines nowhere/l.geojson: folder nowhere does not exist"),
    (["moments", "{in}", "{out}", "--report", "{in}x"], "exists and is not a folder"),
    (["curvature", "{in}", "{out}", "--radius", "1", "--summary-json", "s.txt"],
     "--summary-json s.txt: unknown format for JSON '.txt'"),
    (["segment", "{in}", "{out}", "--method", "sar", "--table", "same.csv", "--lines",
      "same.csv"], "--lines same.csv: is also the --table file"),
    (["ridges", "{in}", "{out}", "--radius", "1", "--lines", "{out}"],
     "is also the output file"),
    (["segment", "{in}", "{out}", "--method", "sar", "--summary-json", "{out}_report"],
     "unknown format for JSON"),
    (["curvature", "{in}", ".", "--radius", "1"], "output .: is a folder"),
])
def test_bad_side_output_fails_before_any_output(valid, tmp_path, capsys, monkeypatch, argv,
                                                 words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "valid.lasx").write_text("a file")
    out = tmp_path / "out.las"
    code, _, err = _run([a.format(**{"in": valid, "out": out}) for a in argv], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert words.format(**{"in": valid}) in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["valid.las", "valid.lasx"]


def test_two_outputs_on_one_file_through_a_link(valid, tmp_path, capsys):
    table = tmp_path / "t.csv"
    table.write_text("old")
    os.symlink(table, tmp_path / "l.csv")
    code, _, err = _run(["segment", valid, tmp_path / "o.las", "--method", "sar", "--table",
                         table, "--lines", tmp_path / "l.csv"], capsys)
    assert code == 2 and "is also the --table file" in err
    assert table.read_text() == "old"


def test_read_only_folder_is_refused(valid, tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, _, err = _run(["covariance", valid, tmp_path / "o.las", "--summary-json",
                             ro / "s.json"], capsys)
    finally:
        ro.chmod(0o755)
    assert code == 2 and "is not writable" in err and not (tmp_path / "o.las").exists()


def test_demo_folder_checked(tmp_path, capsys):
    code, _, err = _run(["demo", tmp_path / "no" / "demo"], capsys)
    assert code == 2 and "folder" in err and "does not exist" in err
    (tmp_path / "file").write_text("")
    code, _, err = _run(["demo", tmp_path / "file"], capsys)
    assert code == 2 and "outdir" in err and "not a folder" in err


# --------------------------------------------------------------------------- main()
def _with_command(monkeypatch, func):
    monkeypatch.setattr(_app, "cmd_info", func)
    return ["info", "whatever.las"]


def test_ctrl_c_one_line_exit_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    code, _, err = _run(_with_command(monkeypatch, interrupted), capsys)
    assert code == 130 and err.strip() == "lidarstat: interrupted"


def test_unexpected_exception_one_line_exit_1(monkeypatch, capsys):
    def buggy(args):
        return {}["missing"]

    argv = _with_command(monkeypatch, buggy)
    code, _, err = _run(argv, capsys)
    assert code == 1
    assert err.strip() == ("lidarstat: internal error: KeyError: 'missing' (run with -v for "
                           "the traceback)")
    code, _, err = _run(["-v", *argv], capsys)
    assert code == 1 and "Traceback" in err and err.strip().endswith("the traceback)")


def test_memory_error_one_line(monkeypatch, capsys):
    def hungry(args):
        raise MemoryError("Unable to allocate 14.9 GiB")

    code, _, err = _run(_with_command(monkeypatch, hungry), capsys)
    assert code == 2 and err.strip() == ("lidarstat: error: out of memory (Unable to allocate "
                                         "14.9 GiB)")


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(),
                    reason="signal handlers need the main thread")
def test_sigterm_unwinds_exit_143(monkeypatch, capsys, tmp_path):
    from lidarstat._shared._atomic import atomic_path

    target = tmp_path / "o.txt"

    def terminated(args):
        with atomic_path(target) as tmp:
            tmp.write_text("partial")
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs at the next bytecode
                pass
        return 0

    before = signal.getsignal(signal.SIGTERM)
    code, _, err = _run(_with_command(monkeypatch, terminated), capsys)
    assert code == 143 and err.strip() == "lidarstat: terminated (SIGTERM)"
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) == before


def test_failure_after_the_main_output_leaves_none(valid, tmp_path, capsys, monkeypatch):
    from lidarstat.cli import covariance as covariance_cli

    def disk_full(path, meta):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(covariance_cli, "write_summary_json", disk_full)
    out = tmp_path / "o.las"
    code, _, err = _run(["covariance", valid, out, "--k", "10", "-q", "--summary-json",
                         tmp_path / "s.json"], capsys)
    assert code == 2 and "s.json" in err and "No space left" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["valid.las"]
