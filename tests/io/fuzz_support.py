"""Seeded mutation fuzzing of the readers: sandboxed workers and their outcomes.

Used by ``tests/io/test_fuzz_readers.py`` (a few hundred mutants per run) and by
``benchmarks/fuzz_readers.py`` (long runs); seeds and mutants come from ``fuzz_mutants``.
The readers run in worker subprocesses with an address-space limit and a per-file alarm, so
an abort, a hang or an allocation beyond the limit ends the worker, not the caller; the file
being read when a worker died is known from its ``start`` line, and a new worker takes the
remaining files.

Outcomes per mutant: ``ok`` (read, the stream and the description agree), ``refused`` (a
:class:`~lidarstat.errors.PointCloudReadError` or :class:`~lidarstat.errors.InvalidPointsError`
whose one-line message names the file) and the failures ``crash`` (killed by a signal or
non-zero exit: abort, segfault, out of memory), ``hang`` (per-file alarm), ``foreign``
(any other exception type), ``message`` (allowed type, but several lines or no file name)
and ``mismatch`` (``read`` and ``iter_chunks`` disagree: one refuses what the other
reads, or they give different points, as two reads of a nondeterministic file do).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
from fuzz_mutants import make_mutants, make_seeds

__all__ = ["FAILURES", "make_mutants", "make_seeds", "run_batch", "summarize", "worker"]

FAILURES = ("crash", "hang", "foreign", "message", "mismatch")


# --------------------------------------------------------------------------- worker
def _one(path: str) -> dict:
    import lidarstat.io as lio
    from lidarstat.errors import InvalidPointsError, PointCloudReadError

    def attempt(fn):
        try:
            return "ok", fn()
        except (PointCloudReadError, InvalidPointsError) as exc:
            msg = str(exc)
            good = "\n" not in msg and Path(path).name in msg
            return ("refused" if good else "message"), f"{type(exc).__name__}: {msg}"
        except Exception as exc:  # noqa: BLE001 - a foreign exception is the finding
            return "foreign", f"{type(exc).__name__}: {str(exc)[:200]}"

    r_out, whole = attempt(lambda: lio.read(path))
    s_out, chunks = attempt(lambda: list(lio.iter_chunks(path, 128)))
    outcome = r_out if r_out not in ("ok", "refused") else s_out
    detail = whole if r_out != "ok" else chunks if s_out != "ok" else ""
    if r_out in ("ok", "refused") and s_out in ("ok", "refused"):
        if (r_out == "ok") != (s_out == "ok"):
            why = whole if r_out != "ok" else chunks
            outcome, detail = "mismatch", f"read {r_out}, iter_chunks {s_out}: {why}"
        elif r_out == "ok" and not np.array_equal(np.vstack([c.xyz for c in chunks]), whole.xyz):
            outcome, detail = "mismatch", "iter_chunks and read give different points"
        else:
            outcome = r_out
    if outcome in ("ok", "refused") and Path(path).suffix.lower() in (".las", ".laz"):
        d_out, d_detail = attempt(lambda: lio.describe(path))
        if d_out not in ("ok", "refused"):
            outcome, detail = d_out, f"describe: {d_detail}"
    return {"outcome": outcome, "detail": detail if isinstance(detail, str) else ""}


def worker(limit_bytes: int, alarm_s: int) -> None:
    """Read the files named on stdin (one JSON list), report one JSON line per file."""
    import resource
    import signal

    resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    signal.signal(signal.SIGALRM, signal.SIG_DFL)  # a hang in native code still ends
    files = json.loads(sys.stdin.read())
    for i, path in enumerate(files):
        print(json.dumps({"start": i}), flush=True)
        signal.alarm(alarm_s)
        result = _one(path)
        signal.alarm(0)
        print(json.dumps({"done": i, **result}), flush=True)


def run_batch(files: list[Path], *, limit_bytes: int = 2 << 30, alarm_s: int = 20,
              ceiling: int | None = 256 << 20, src: str | None = None) -> dict[str, dict]:
    """Read `files` in sandboxed workers; ``{file: {"outcome", "detail"}}``.

    `src` is the folder holding the ``lidarstat`` package the workers import (default: the
    one this process imported); `ceiling` their ``LIDARSTAT_MAX_READ_BYTES`` (None: unset,
    the library's default, half of the physical memory).
    """
    if src is None:
        import lidarstat

        src = str(Path(lidarstat.__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    env.pop("LIDARSTAT_MAX_READ_BYTES", None)
    if ceiling is not None:
        env["LIDARSTAT_MAX_READ_BYTES"] = str(ceiling)
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    results: dict[str, dict] = {}
    todo = [str(f) for f in files]
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            f"import fuzz_support; fuzz_support.worker({limit_bytes}, {alarm_s})")
    while todo:
        proc = subprocess.run([sys.executable, "-c", code], input=json.dumps(todo), env=env,
                              capture_output=True, text=True, check=False,
                              timeout=alarm_s * (len(todo) + 5))
        current = None
        for line in proc.stdout.splitlines():
            msg = json.loads(line)
            if "start" in msg:
                current = msg["start"]
            else:
                results[todo[msg["done"]]] = {"outcome": msg["outcome"], "detail": msg["detail"]}
                current = None
        if proc.returncode == 0 and current is None:
            break
        if current is None:  # died between files (should not happen): blame nobody, stop
            raise RuntimeError(f"fuzz worker exited {proc.returncode}: {proc.stderr[-500:]}")
        rc = proc.returncode
        kind = "hang" if rc == -14 else "crash"
        tail = proc.stderr.strip().splitlines()[-1:] or [""]
        results[todo[current]] = {"outcome": kind, "detail": f"exit {rc}: {tail[0][:200]}"}
        todo = todo[current + 1:]
    return results


def summarize(results: dict[str, dict]) -> Counter:
    """Count of each outcome."""
    return Counter(r["outcome"] for r in results.values())


if __name__ == "__main__":  # pragma: no cover - a worker is started with -c
    raise SystemExit("use run_batch()")
