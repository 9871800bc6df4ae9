"""One output plan per command, checked before any work.

A command lists every path it will write (main output, tables, lines, summaries, report
folders) and every file it will read; :func:`check_outputs` refuses the run, naming the
path as the user typed it and the option it came from, when

- an output suffix is not one that output accepts;
- an output is an input: the same path, a symlink to it or a hard link of it (same
  device and inode), or the sensor sidecar an input may carry;
- two outputs are the same file;
- an output is an existing folder (or a folder output an existing file);
- an output's folder is missing or not writable.

Nothing is computed or written before the whole plan passes, so a bad side output never
leaves a main output behind.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..errors import InvalidParameterError, UnknownFormatError

__all__ = ["LINE_SUFFIXES", "POINT_CLOUD_SUFFIXES", "Output", "check_outputs"]

#: Suffixes a point-cloud output may have (``.e57`` is read only).
POINT_CLOUD_SUFFIXES = (".las", ".laz", ".ply", ".csv", ".txt", ".npz")
#: Suffixes of lines (segment and ridge lines): GeoJSON, a vertex table or points.
LINE_SUFFIXES = (".geojson", ".json", ".csv", ".las", ".laz", ".ply", ".npz", ".txt")

#: kind -> (suffixes accepted, what the error calls it); None: a folder, any name.
_KINDS = {
    "cloud": (POINT_CLOUD_SUFFIXES, "point-cloud format"),
    "json": ((".json",), "format for JSON"),
    "table": ((".csv", ".json"), "table format"),
    "lines": (LINE_SUFFIXES, "format for lines"),
    "png": ((".png",), "image format"),
    "raster": ((".tif", ".tiff"), "raster format (GeoTIFF)"),
    "folder": (None, "folder"),
}


@dataclasses.dataclass(frozen=True)
class Output:
    """One path a command will write.

    Parameters
    ----------
    option : str
        How the user names it: ``"--summary-json"``, or the positional's name (``"output"``).
    path : str or path-like or None
        As typed (or derived); None: not written this run (skipped).
    kind : {'cloud', 'json', 'table', 'lines', 'png', 'folder'}
        Which suffixes it accepts; a folder is created if missing (its parent must exist).
    default : bool
        The path was derived, not typed: messages say so and name the option to set.
    members : tuple of str
        Names of the files a folder output will hold (checked against inputs and the
        other outputs).
    """

    option: str
    path: str | os.PathLike | None
    kind: str = "cloud"
    default: bool = False
    members: tuple[str, ...] = ()

    def label(self) -> str:
        """Option and path for messages, e.g. ``--table scan.segments.csv (the default)``."""
        text = f"{self.option} {os.fspath(self.path)}"
        return text + " (the default, from the output's name)" if self.default else text


def _identity(path: Path):
    """``(st_dev, st_ino)`` of an existing file (following symlinks), else None."""
    try:
        st = path.stat()
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (OSError, RuntimeError):  # symlink loop
        return path.absolute()


def _check_suffix(out: Output) -> None:
    suffixes, what = _KINDS[out.kind]
    if suffixes is None:
        return
    suffix = Path(out.path).suffix.lower()
    if suffix in suffixes:
        return
    shown = Path(out.path).suffix or "(none)"
    if out.kind == "cloud" and suffix == ".e57":
        raise UnknownFormatError(f"{out.label()}: E57 is read only; write "
                                 + ", ".join(suffixes))
    raise UnknownFormatError(f"{out.label()}: unknown {what} '{shown}'; use "
                             + ", ".join(suffixes))


def _check_place(out: Output, path: Path) -> None:
    """The path's kind against what exists there, and its parent folder."""
    if out.kind == "folder":
        if path.exists() and not path.is_dir():
            raise InvalidParameterError(f"{out.label()}: exists and is not a folder; choose "
                                        "another path")
        if path.is_dir():
            if not os.access(path, os.W_OK | os.X_OK):
                raise InvalidParameterError(f"{out.label()}: the folder is not writable")
            return
    elif path.is_dir():
        raise InvalidParameterError(f"{out.label()}: is a folder; give a file name")
    parent = path.parent
    if not parent.is_dir():
        raise InvalidParameterError(f"{out.label()}: folder {os.fspath(parent)} does not "
                                    "exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InvalidParameterError(f"{out.label()}: folder {os.fspath(parent)} is not "
                                    "writable")


def _inputs(inputs: Iterable) -> list[tuple[Path, str]]:
    """Every file read: the inputs and the sensor sidecars they carry, with a description."""
    found = []
    for given in inputs:
        if given is None:
            continue
        path = Path(given)
        found.append((path, "is the input file (refusing to overwrite it)"))
        side = path.with_name(path.name + ".sensor.json")
        if side.exists():
            found.append((side, f"is the sensor sidecar of the input {os.fspath(given)}"))
    return found


def check_outputs(inputs: Iterable, outputs: Sequence[Output]) -> list[Path | None]:
    """Check a command's whole output plan before any work (see the module notes).

    Parameters
    ----------
    inputs : iterable of path-like or None
        The files the command reads (None entries are skipped).
    outputs : sequence of Output
        Every path it writes; entries whose ``path`` is None are skipped.

    Returns
    -------
    list of Path or None
        The output paths, in the order given (None where skipped).

    Raises
    ------
    UnknownFormatError
        An output's suffix is not one it accepts.
    InvalidParameterError
        An output is an input, two outputs are one file, or the place is unusable.
    """
    read = [(path, what, _identity(path), _resolved(path)) for path, what in _inputs(inputs)]
    seen: list[tuple[Output, tuple | None, Path]] = []
    result = []
    for out in outputs:
        if out.path is None:
            result.append(None)
            continue
        path = Path(out.path)
        targets = [(t, _identity(t), _resolved(t), "" if t is path else f" (its file {t.name})")
                   for t in [path] + [path / name for name in out.members]]
        for _, ident, res, where in targets:
            for _, what, in_ident, in_res in read:
                if (ident is not None and ident == in_ident) or res == in_res:
                    raise InvalidParameterError(f"{out.label()}{where}: {what}; choose "
                                                "another path")
        _check_place(out, path)
        _check_suffix(out)
        for _, ident, res, where in targets:
            for other, o_ident, o_res in seen:
                if (ident is not None and ident == o_ident) or res == o_res:
                    raise InvalidParameterError(f"{out.label()}{where}: is also the "
                                                f"{other.option} file; choose another path")
        seen.extend((out, ident, res) for _, ident, res, _ in targets)
        result.append(path)
    return result
