"""Warnings of a run: one line each, after a success; a failure prints its error alone."""

import logging
import warnings

import pytest

from lidarstat.cli import _app
from lidarstat.errors import LidarstatError, LidarstatWarning


def _run(monkeypatch, capsys, func, *extra):
    monkeypatch.setattr(_app, "cmd_info", func)
    code = _app.main(["info", "any.las", *extra])
    return code, capsys.readouterr().err.splitlines()


@pytest.fixture
def noisy():
    def run(args):
        logging.getLogger("lidarstat.features").warning("cloud has copies\nsecond line")
        warnings.warn("no usable intensity", LidarstatWarning, stacklevel=2)
        warnings.warn("no usable intensity", LidarstatWarning, stacklevel=2)
        return 0
    return run


@pytest.mark.filterwarnings("default::lidarstat.errors.LidarstatWarning")
def test_success_prints_each_warning_once_on_one_line(monkeypatch, capsys, noisy):
    code, err = _run(monkeypatch, capsys, noisy)
    assert code == 0
    assert err == ["lidarstat: warning: cloud has copies",
                   "lidarstat: warning: no usable intensity"]


@pytest.mark.filterwarnings("default::lidarstat.errors.LidarstatWarning")
def test_failure_prints_the_error_alone(monkeypatch, capsys, noisy):
    def fail(args):
        noisy(args)
        raise LidarstatError("any.las: 100,000 points share 1 location")

    code, err = _run(monkeypatch, capsys, fail)
    assert code == 2
    assert err == ["lidarstat: error: any.las: 100,000 points share 1 location"]


def test_handlers_and_showwarning_are_restored(monkeypatch, capsys, noisy):
    before = (list(logging.getLogger().handlers), warnings.showwarning)
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        _run(monkeypatch, capsys, noisy)
    assert (list(logging.getLogger().handlers), warnings.showwarning) == before
