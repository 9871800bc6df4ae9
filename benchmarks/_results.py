"""The results files of the benchmark scripts: one JSON object per file, a key per run."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["store"]


def store(path, key: str, value) -> None:
    """Set `key` of the JSON object in `path` to `value`, keeping the file's other keys;
    the file is replaced whole (written beside it, then renamed)."""
    path = Path(path)
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc[key] = value
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    tmp.replace(path)
