"""Warnings of a command run, held until the run ends: one line each, after success only.

A run that fails prints one error line and nothing else (the error says what is wrong);
a run that succeeds prints its warnings, Python warnings and log records of level WARNING
and above alike, as ``lidarstat: warning: <message>``, once each, after its own output.
With ``-v`` log records stream as they come, with their logger's name.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings
from collections.abc import Iterator

__all__ = ["held_warnings"]


class _Collect(logging.Handler):
    def __init__(self, lines: list[str]):
        super().__init__(level=logging.WARNING)
        self.lines = lines

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(_line(record.getMessage()))


def _line(message) -> str:
    text = str(message).strip()
    return f"lidarstat: warning: {text.splitlines()[0] if text else 'warning'}"


@contextlib.contextmanager
def held_warnings(verbose: bool) -> Iterator[None]:
    """Hold the run's warnings; print them (deduplicated) if the block ends without error.

    Parameters
    ----------
    verbose : bool
        Log records of level INFO and above stream to stderr as they come instead.
    """
    if verbose:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    lines: list[str] = []
    root = logging.getLogger()
    handler = None if verbose else _Collect(lines)
    if handler is not None:
        root.addHandler(handler)
        root.setLevel(logging.WARNING)
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        lines.append(_line(message))

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown
        if handler is not None:
            root.removeHandler(handler)
    for text in dict.fromkeys(lines):  # reached only without an exception
        print(text, file=sys.stderr)
