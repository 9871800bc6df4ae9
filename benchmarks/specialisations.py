"""Which kernels a run compiled more than once, and why: read from Numba's cache index.

A cached kernel's index file (``__pycache__/<module>.<kernel>-<line>.py3XX.nbi``) lists
every specialisation that runs in that tree compiled and saved: after a test suite on a
cold cache (a fresh clone), a kernel with two entries was compiled twice. Each extra
entry is classified by how its signature differs from the first one:

``readonly``   an array argument typed read-only in one and writable in the other (a
               caller passed a read-only view, e.g. of a synthetic cloud's truth arrays or
               ``np.broadcast_to``), ``int32/int64`` (neighbour indices of two dtypes),
               ``layout`` (C against non-contiguous), ``scalar`` (an int where a float is
               expected), ``arity`` (tuples of different lengths: intended) and ``other``.

    python benchmarks/specialisations.py SRC_DIR [--label NAME] [--out FILE]

SRC_DIR is the ``src`` folder whose ``__pycache__`` folders hold the cache (or a folder
given to ``NUMBA_CACHE_DIR``). Stored under ``specialisations/<label>`` of
``benchmarks/results_first_run.json``.
"""

from __future__ import annotations

import argparse
import json
import pickle
import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
_ARRAY = re.compile(r"Array\((\w+), (\d+), '(\w)', (True|False)")


def index_entries(root: Path) -> dict[str, list[str]]:
    """Kernel (folder:file stem) -> signatures stored in its cache index."""
    found: dict[str, list[str]] = {}
    for path in sorted(Path(root).rglob("*.nbi")):
        with open(path, "rb") as fh:
            pickle.load(fh)  # Numba's version
            _stamp, overloads = pickle.loads(fh.read())
        name = path.name.rsplit(".py3", 1)[0]
        folder = path.parent.parent if path.parent.name == "__pycache__" else path.parent
        where = folder.name
        found[f"{where}:{name}"] = [str(key[0]) for key in overloads]
    return found


def why(first: str, other: str) -> str:
    """The kind of difference between two signatures of one kernel."""
    a, b = _ARRAY.findall(first), _ARRAY.findall(other)
    if len(a) == len(b) and a != b:
        kinds = set()
        for x, y in zip(a, b):
            if x[3] != y[3] and x[:3] == y[:3]:
                kinds.add("readonly")
            elif {x[0], y[0]} == {"int32", "int64"}:
                kinds.add("int32/int64")
            elif x[2] != y[2]:
                kinds.add("layout")
            elif x != y:
                kinds.add("other")
        return "+".join(sorted(kinds))
    tuples = re.compile(r"UniTuple\(\w+, (\d+)\)")
    if first.count(",") != other.count(",") or tuples.findall(first) != tuples.findall(other):
        return "arity"
    if re.sub(r"int64|float64", "N", first) == re.sub(r"int64|float64", "N", other):
        return "scalar"
    if {"int32", "int64"} & set(re.findall(r"int\d+", first + other)):
        return "int32/int64"
    return "other"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="src folder (its __pycache__ folders) or a NUMBA_CACHE_DIR")
    ap.add_argument("--label", default="current")
    ap.add_argument("--note", default="")
    ap.add_argument("--out", default=str(HERE / "results_first_run.json"))
    args = ap.parse_args()
    found = index_entries(Path(args.root))
    multi = {k: {"signatures": len(v), "why": sorted({why(v[0], s) for s in v[1:]})}
             for k, v in sorted(found.items()) if len(v) > 1}
    extra: dict[str, int] = {}
    for k, v in multi.items():
        for reason in v["why"]:
            extra[reason] = extra.get(reason, 0) + 1
    result = {"kernels": len(found), "specialisations": sum(map(len, found.values())),
              "extra": sum(v["signatures"] - 1 for v in multi.values()),
              "kernels_by_reason": extra, "multi": multi, "note": args.note}
    for k, v in multi.items():
        print(f"{k:70s} {v['signatures']}  {', '.join(v['why'])}")
    print(f"{result['kernels']} kernels, {result['specialisations']} specialisations, "
          f"{result['extra']} beyond one per kernel; kernels by reason {extra}")
    out = Path(args.out)
    store = json.loads(out.read_text()) if out.exists() else {}
    store.setdefault("specialisations", {})[args.label] = result
    out.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
