"""Label fields of a catalogue joined across its tile files (``process_catalogue(...,
labels=)``), by the nodes, records and rule of ``_stream_labels`` that one file in
square tiles uses.

A point of one tile's buffer is a core point of a neighbouring tile, so the points near
a tile border are labelled by two runs; a point is named over the area by its number
in the catalogue (the points of the files before its file plus its place in its file).

1. Each tile's run writes its output with the labels as its method numbered them
   (from 1 in each tile) into the folder ``OUT/.lidarstat-pending`` and then, beside
   it, a record: for each joined field the
   :data:`LINK` records of the points it shares with other tiles (its buffer points, and
   its core points inside a neighbour's buffer window), for each field its largest
   label and its core points per label, and the run's ``info``.
2. When every tile has a record, the records are read in catalogue order: each tile's
   labels get nodes (:class:`Labels`, so the ids do not depend on the order in which
   the tiles finished: sync, threads and Dask give the same ids), ``collect`` sees each
   tile's ``info`` with its bases, the shared points join the nodes
   (:meth:`Labels.finish`) and ``finish`` gets the final maps.
3. Each pending output is rewritten with its final ids into OUT (streamed, atomically,
   one after the other), then the pending folder is removed.

Nothing appears in OUT before the join: a run stopped in step 1 or 2 leaves no output,
and its records let the rerun go on (tiles with a record are not run again). A run
stopped in step 3 leaves some outputs and every record: the rerun joins the same
records again and writes the outputs still missing. An output without a record (of an
earlier complete run) is not joined with tiles run now: the run is refused until it is
overwritten. A record is resumed only by a run of the same method with the same options
(its ``key``); a record of other options is run again. Memory: the link records of the border points (25 bytes each) and a few
numbers per label, not the points of the area.
"""

from __future__ import annotations

import os
import pickle
import shutil
from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path, output_group
from ..errors import InvalidParameterError, PointCloudWriteError
from ..io import rewrite, write
from ._stream_labels import LINK, Labels

__all__ = ["PENDING"]

#: Folder of OUT holding the tiles' runs until the join is done.
PENDING = ".lidarstat-pending"


def _pending(out: Path, outdir: Path) -> Path:
    """Where the run of the tile with output `out` waits for the join."""
    name = os.fspath(out.relative_to(outdir)).replace(os.sep, "%")
    return Path(outdir) / PENDING / name


def _record(out: Path, outdir: Path) -> Path:
    p = _pending(out, outdir)
    return p.with_name(p.name + ".join")


def _in_neighbours_windows(cat, i: int, xyz: np.ndarray, buffer: float) -> np.ndarray:
    """Points of tile `i` that a neighbour reads into its buffer (its closed window)."""
    near = np.zeros(len(xyz), bool)
    for j in cat.neighbours(i, buffer) if buffer > 0 else ():
        x0, y0, x1, y1 = cat.window(j, buffer)
        near |= ((xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0)
                 & (xyz[:, 1] <= y1))
    return near


def put_pending(cat, i: int, out: Path, outdir: Path, tile, fields: dict, info: dict,
                labels: dict, buffer: float, key: str | None = None) -> None:
    """Step 1 for tile `i`: its output (labels as numbered by the method) and its record, in PENDING."""
    n = tile.n_core
    shared = np.flatnonzero(_in_neighbours_windows(cat, i, tile.core.xyz, buffer))
    rows = np.r_[shared, n + np.arange(len(tile.buffer.xyz))]
    numbers = np.r_[cat.point_offsets()[i] + shared, tile.buffer_ids].astype(np.int64)
    core_fields = {name: values[:n] for name, values in fields.items()}
    record = {"input": str(cat.files[i].path), "n_points": n, "buffer": float(buffer),
              "key": key, "info": info, "tops": {}, "counts": {}, "links": {}}
    for name, join in labels.items():
        if name not in fields:
            raise InvalidParameterError(f"{cat.files[i].path}: the method returned no "
                                        f"label field {name!r}")
        local = np.maximum(np.asarray(fields[name]).astype(np.int64), 0)
        top = int(local.max(initial=0))
        record["tops"][name] = top
        record["counts"][name] = np.bincount(local[:n], minlength=top + 1)
        if join:
            rec = np.empty(rows.size, LINK)
            rec["i"], rec["node"], rec["tile"] = numbers, local[rows], i
            rec["core"] = rows < n
            record["links"][name] = rec
    target = _pending(out, outdir)
    target.parent.mkdir(exist_ok=True)
    with output_group(defer=False):  # the output first: a record means a complete run
        write(target, tile.core, fields=core_fields)
    with (output_group(defer=False), atomic_path(_record(out, outdir)) as tmp,
          open(tmp, "wb") as fh):
        pickle.dump(record, fh, protocol=pickle.HIGHEST_PROTOCOL)


def _load(path: Path) -> dict | None:
    try:
        with open(path, "rb") as fh:
            return pickle.load(fh)
    except (OSError, EOFError, pickle.UnpicklingError):
        return None


def plan(cat, paths: list[Path], outdir: Path, buffer: float, resume: bool,
         key: str | None = None) -> tuple[list[int], list[int], bool]:
    """Which tiles run, which are resumed from their record, and whether the join and
    the outputs are to be made at all (False: every output exists, none pending).

    A record is kept only for the same input, buffer and `key` (the method and its
    options): a record of a run with other options is run again, never joined."""
    outdir = Path(outdir)
    if not resume:
        shutil.rmtree(outdir / PENDING, ignore_errors=True)
        return list(range(len(cat))), [], True
    kept = []
    for i, out in enumerate(paths):
        rec = _load(_record(out, outdir)) if _record(out, outdir).exists() else None
        if rec is not None and (rec["input"] != str(cat.files[i].path)
                                or rec["n_points"] != cat.files[i].n_points
                                or rec["buffer"] != float(buffer)
                                or rec.get("key") != key
                                or not _pending(out, outdir).exists()):
            rec = None  # another run's: run the tile again
        kept.append(rec is not None)
    exists = [p.exists() for p in paths]
    if all(exists) and not any(kept):
        shutil.rmtree(outdir / PENDING, ignore_errors=True)
        return [], [], False
    for i, out in enumerate(paths):
        if exists[i] and not kept[i]:
            raise PointCloudWriteError(
                f"{out}: an output of an earlier run; the labels are joined across the "
                "tiles, so every tile must be run again to join it with the others: "
                "overwrite it (--overwrite) or remove it")
    todo = [i for i in range(len(cat)) if not kept[i]]
    return todo, [i for i in range(len(cat)) if kept[i]], True


def join_outputs(cat, paths: list[Path], outdir: Path, labels: dict, *, resume: bool,
                 collect=None, finish=None, points_per_chunk: int = 1_000_000) -> dict:
    """Steps 2 and 3: join every tile's record, write the outputs, remove PENDING.

    Returns the maps (field -> :class:`LabelMap`).
    """
    outdir = Path(outdir)
    state = {name: Labels(name, bool(join)) for name, join in labels.items()}
    parts: dict[str, list] = {name: [] for name, lab in state.items() if lab.join}
    bases = []
    for i, out in enumerate(paths):
        rec = _load(_record(out, outdir))
        if rec is None:
            raise PointCloudWriteError(f"{_record(out, outdir)}: the record of a tile's "
                                       "run is unreadable; rerun with --overwrite")
        tile_bases = {}
        for name, lab in state.items():
            base = lab.add_tile(rec["tops"][name], rec["counts"][name])
            tile_bases[name] = base
            if lab.join:
                links = rec["links"][name]
                links["node"] = np.where(links["node"] > 0, links["node"] + base, 0)
                parts[name].append(links)
        bases.append(tile_bases)
        if collect is not None:
            collect(i, rec["info"], tile_bases)
        del rec
    maps = {}
    for name, lab in state.items():
        links = np.concatenate(parts.pop(name)) if lab.join and len(cat) else None
        maps[name] = lab.finish(links)
        del links
    with output_group(defer=False):  # outputs appear one by one, before PENDING goes
        if finish is not None:
            finish(maps)
        for i, out in enumerate(paths):
            if resume and out.exists():  # written from these records by a stopped run
                continue

            def fields_of(start, chunk, b=bases[i]):
                out_fields = {}
                for name in state:
                    local = np.asarray(chunk.attributes[name])
                    nodes = np.where(local > 0, local.astype(np.int64) + b[name], 0)
                    out_fields[name] = maps[name](nodes).astype(local.dtype)
                return out_fields

            rewrite(_pending(out, outdir), out, fields_of, points_per_chunk=points_per_chunk)
    shutil.rmtree(outdir / PENDING, ignore_errors=True)
    return maps
