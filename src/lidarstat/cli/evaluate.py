"""``lidarstat evaluate RESULT --reference REF``: filter errors, confusion matrix, kappa.

RESULT and REF may be two files or two catalogues of tiles (folders, globs): tiles are
paired by name and their counts summed, one pair in memory at a time."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import _options as opt

def _pairs(args):
    """(result, reference) files: the two files, or the tiles of two catalogues paired by
    name (a result tile and its reference tile share their name without suffix)."""
    from ..errors import InvalidParameterError
    from ..pipeline import Catalogue

    def catalogue(text):
        return Path(text).is_dir() or any(c in text for c in "*?[")

    if not (catalogue(args.result) or catalogue(args.reference)):
        return [(Path(args.result), Path(args.reference))]
    res = {_stem(f.path): f.path for f in Catalogue(args.result, one_crs=False)}
    ref = {_stem(f.path): f.path for f in Catalogue(args.reference, one_crs=False)}
    missing = sorted(set(res) - set(ref))
    if missing:
        raise InvalidParameterError(
            f"{res[missing[0]]}: no reference tile of the same name in {args.reference} "
            f"({len(missing)} result tiles unmatched); tiles are paired by name")
    return [(res[k], ref[k]) for k in sorted(res)]


def _stem(path: Path) -> str:
    name = path.name
    for suffix in (".copc.laz", ".laz", ".las"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


def _counts(result_path, reference_path, args):
    """The ground/object confusion and the class pairs' counts of one pair of files."""
    from ..errors import InvalidParameterError
    from ..io import read

    res = read(result_path)
    ref = read(reference_path)
    if len(res) != len(ref):
        raise InvalidParameterError(
            f"{result_path}: {len(res)} points but the reference {reference_path} has "
            f"{len(ref)}; evaluate compares the same points in the same order")
    r = np.asarray(res[args.field]).astype(np.int64)
    t = np.asarray(ref[args.reference_field]).astype(np.int64)
    rg = np.isin(r, args.ground_codes)
    tg = np.isin(t, args.ground_codes if args.reference_ground_codes is None
                 else args.reference_ground_codes)
    cm = np.array([[np.sum(tg & rg), np.sum(tg & ~rg)], [np.sum(~tg & rg), np.sum(~tg & ~rg)]],
                  dtype=np.int64)
    pairs = {}
    if args.classes:
        keys, n = np.unique(np.c_[t, r], axis=0, return_counts=True)
        pairs = {(int(a), int(b)): int(c) for (a, b), c in zip(keys, n)}
    return cm, pairs


def _run(args):
    from ..classify import ClassScores, FilterErrors
    from ._app import Output, check_plan

    files = _pairs(args)
    check_plan([p for pair in files for p in pair], Output("--json", args.json, "json"))
    total = np.zeros((2, 2), dtype=np.int64)
    pairs: dict = {}
    tiles = []
    for result_path, reference_path in files:  # one pair in memory at a time
        cm, counts = _counts(result_path, reference_path, args)
        total += cm
        for key, n in counts.items():
            pairs[key] = pairs.get(key, 0) + n
        if len(files) > 1:
            tiles.append({"result": str(result_path), "reference": str(reference_path),
                          "ground_object": FilterErrors.from_confusion(cm).to_dict()})
    fe = FilterErrors.from_confusion(total)
    out = {"result": str(args.result), "reference": str(args.reference),
           "field": args.field, "reference_field": args.reference_field,
           "ground_codes": list(args.ground_codes), "ground_object": fe.to_dict()}
    if args.classes:
        labels = np.array(sorted({c for key in pairs for c in key}), dtype=np.int64)
        index = {int(c): i for i, c in enumerate(labels)}
        matrix = np.zeros((labels.size, labels.size), dtype=np.int64)
        for (t, r), n in pairs.items():
            matrix[index[t], index[r]] += n
        out["classes"] = ClassScores.from_confusion(labels, matrix).to_dict()
    if tiles:
        out["tiles"] = tiles
    if args.json:
        from .._shared._atomic import atomic_path

        with atomic_path(args.json) as tmp:
            tmp.write_text(json.dumps(out, indent=2))
    if not args.quiet:
        _print(args, out, fe, len(files))
    return 0


def _print(args, out, fe, n_files):
    cm = fe.confusion
    area = f"  ({n_files} tiles)" if n_files > 1 else ""
    print(f"{args.result} vs {args.reference}  ({fe.n} points){area}")
    print(f"  Type I  (ground -> object) {100 * fe.type_i:6.2f} %")
    print(f"  Type II (object -> ground) {100 * fe.type_ii:6.2f} %")
    print(f"  total error                {100 * fe.total:6.2f} %")
    print(f"  kappa                      {fe.kappa:6.3f}")
    print("  confusion (rows reference, columns result):")
    print(f"              ground    object\n  ground  {cm[0, 0]:>9} {cm[0, 1]:>9}\n"
          f"  object  {cm[1, 0]:>9} {cm[1, 1]:>9}")
    if args.classes:
        cs = out["classes"]
        labels = cs["labels"]
        print(f"  classes: accuracy {cs['accuracy']:.4f}, kappa {cs['kappa']:.4f}")
        print("  ref\\res " + "".join(f"{v:>9}" for v in labels))
        for lab, row in zip(labels, cs["confusion"]):
            print(f"  {lab:>7} " + "".join(f"{v:>9}" for v in row))


def register(sub):
    """Add the ``evaluate`` subcommand."""
    s = sub.add_parser("evaluate", help="Type I/II/total error, confusion matrix and kappa",
                       description="Compare the classes of RESULT with those of REF (same "
                       "points, same order; or two catalogues of tiles paired by name, "
                       "scored as one area): ground/object errors as defined by Sithole and "
                       "Vosselman (2004), their confusion matrix and Cohen's kappa; "
                       "--classes adds the full multi-class comparison.")
    s.add_argument("result")
    s.add_argument("--reference", required=True)
    s.add_argument("--field", default="classification", help="class field of RESULT")
    s.add_argument("--reference-field", default="classification",
                   help="class field of REF")
    s.add_argument("--ground-codes", type=opt.codes_list, default="2,8,9,11",
                   help="codes counted as ground (comma-separated)")
    s.add_argument("--reference-ground-codes", type=opt.codes_list, default=None,
                   help="ground codes of REF when they differ")
    s.add_argument("--classes", action="store_true", help="full multi-class comparison")
    s.add_argument("--json", default=None, help="write the scores as JSON here")
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(func=_run)
