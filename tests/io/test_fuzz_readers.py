"""Seeded fuzz run of the readers: every mutant is read or refused cleanly.

A few hundred mutants of small valid seed files (LAS 1.2/1.4 with VLRs, EVLRs and extra
bytes, LAZ with fixed and variable chunks, binary and ASCII PLY, CSV, TXT, NPZ, E57): byte
flips, truncations, header fields overwritten at their known offsets (counts, offsets, VLR
counts and lengths, the LAZ chunk table pointer and count, LasZip items, scales), PLY header
edits, bad text cells, NPZ arrays of the wrong kind, E57 XML values with valid checksums. Each mutant goes through ``read``, ``iter_chunks`` and,
for LAS/LAZ, ``describe`` in a worker process limited to 2 GiB of address space and 20 s a
file, so an abort or a hang is a counted failure instead of the end of pytest. Longer runs:
``benchmarks/fuzz_readers.py``.
"""

from __future__ import annotations

import numpy as np
from fuzz_support import FAILURES, make_mutants, make_seeds, run_batch, summarize

N_MUTANTS = 330
SEED = 15


def test_seed_files_are_read(tmp_path):
    seeds = make_seeds(tmp_path / "seeds", np.random.default_rng(SEED))
    results = run_batch(seeds)
    assert {r["outcome"] for r in results.values()} == {"ok"}, results


def test_fuzzed_readers_never_crash_hang_or_leak_foreign_exceptions(tmp_path):
    seeds = make_seeds(tmp_path / "seeds", np.random.default_rng(SEED))
    mutants = make_mutants(seeds, tmp_path / "mutants", N_MUTANTS, SEED)
    results = run_batch(mutants)
    counts = summarize(results)
    failures = {f: r for f, r in results.items() if r["outcome"] in FAILURES}
    shown = "\n".join(f"{f}: {r['outcome']}: {r['detail']}" for f, r in
                      sorted(failures.items())[:20])
    assert not failures, f"{dict(counts)}\n{shown}"
    assert sum(counts.values()) == N_MUTANTS
    # The mutants exercise both paths: some still read, most are refused.
    assert counts["ok"] >= N_MUTANTS // 20 and counts["refused"] >= N_MUTANTS // 2
