#!/usr/bin/env python
"""Long seeded fuzz run of the readers (the suite's ``tests/io/test_fuzz_readers.py``, larger).

Mutants of small valid LAS/LAZ/PLY/CSV/TXT/NPZ seeds (and, with ``--real``, of the six
smallest LAS/LAZ files of the shared data) are read with ``read``,
``iter_chunks`` and ``describe`` in sandboxed workers (address-space limit, per-file alarm);
the outcome counts go to stdout and, with ``--out``, to JSON with every failing file's
detail. The mutants stay in ``--tmp`` for replay.

Usage::

    python benchmarks/fuzz_readers.py --count 2000 --seed 15
    python benchmarks/fuzz_readers.py --count 20000 --seed 7 --real --out /tmp/fuzz.json
    python benchmarks/fuzz_readers.py --count 2000 --src /tmp/old/src   # an earlier version
    python benchmarks/fuzz_readers.py --ceiling-mib 0 --limit-gib 4     # default ceiling
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "io"))
sys.path.insert(0, str(ROOT / "src"))

import fuzz_support as fs


def _real_seeds(folder: Path, limit: int = 6) -> list[Path]:
    """The smallest LAS/LAZ files of the shared data, copied whole into `folder`."""
    data = ROOT.parent / "shared" / "data"
    files = sorted((p for p in data.rglob("*") if p.suffix.lower() in (".las", ".laz")),
                   key=lambda p: p.stat().st_size)[:limit]
    out = []
    for p in files:
        dst = folder / f"real_{p.stem}{p.suffix.lower()}"
        dst.write_bytes(p.read_bytes())
        out.append(dst)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=2000, help="mutants (default 2000)")
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--workers", type=int, default=2, help="parallel worker processes")
    ap.add_argument("--batch", type=int, default=250, help="mutants per worker process")
    ap.add_argument("--real", action="store_true", help="also mutate small real files")
    ap.add_argument("--limit-gib", type=float, default=2.0,
                    help="address-space limit of a worker (default 2 GiB)")
    ap.add_argument("--ceiling-mib", type=float, default=256.0,
                    help="LIDARSTAT_MAX_READ_BYTES of the workers; 0: unset (the default "
                         "ceiling, half of the physical memory)")
    ap.add_argument("--src", default=str(ROOT / "src"), help="folder holding lidarstat")
    ap.add_argument("--tmp", type=Path, default=None, help="where seeds and mutants go")
    ap.add_argument("--out", type=Path, default=None, help="JSON report")
    args = ap.parse_args(argv)

    tmp = args.tmp or Path(tempfile.mkdtemp(prefix="lidarstat-fuzz-"))
    seeds = fs.make_seeds(tmp / "seeds", np.random.default_rng(args.seed))
    if args.real:
        seeds += _real_seeds(tmp / "seeds")
    mutants = fs.make_mutants(seeds, tmp / "mutants", args.count, args.seed)
    batches = [mutants[i:i + args.batch] for i in range(0, len(mutants), args.batch)]
    start = time.perf_counter()
    results: dict[str, dict] = {}
    with ThreadPoolExecutor(args.workers) as pool:
        limit = int(args.limit_gib * 2**30)
        ceiling = int(args.ceiling_mib * 2**20) or None
        for part in pool.map(lambda b: fs.run_batch(b, src=args.src, limit_bytes=limit,
                                                    ceiling=ceiling), batches):
            results.update(part)
    seconds = time.perf_counter() - start
    counts = fs.summarize(results)
    by_format: dict[str, dict] = {}
    for f, r in results.items():
        fmt = Path(f).suffix[1:]
        by_format.setdefault(fmt, {}).setdefault(r["outcome"], 0)
        by_format[fmt][r["outcome"]] += 1
    failures = {f: r for f, r in sorted(results.items()) if r["outcome"] in fs.FAILURES}
    print(f"{len(results)} mutants in {seconds:.1f} s ({tmp}): "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    for fmt, c in sorted(by_format.items()):
        print(f"  {fmt:4s} " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
    for f, r in list(failures.items())[:30]:
        print(f"  {Path(f).name}: {r['outcome']}: {r['detail'][:160]}")
    if args.out:
        args.out.write_text(json.dumps({"count": len(results), "seed": args.seed,
                                        "seconds": round(seconds, 1), "outcomes": counts,
                                        "by_format": by_format, "failures": failures},
                                       indent=2))
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
