"""Shared fixtures: seeded RNG, the real data folder (skipped with its path when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

# Repository root is tests/..; the shared data lives beside the repository.
SHARED_DATA = Path(
    os.environ.get("LIDARSTAT_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data")
)


@pytest.fixture
def rng():
    """A seeded generator; every stochastic test starts from it."""
    return np.random.default_rng(20261122)


@pytest.fixture
def shared_data():
    """Path of ``../shared/data``; the test is skipped (reason names the path) if missing."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder not found: {SHARED_DATA}")
    return SHARED_DATA


def shared_file(relpath: str) -> Path:
    """Path of one file of the shared data, or skip the calling test naming it."""
    path = SHARED_DATA / relpath
    if not path.is_file():
        pytest.skip(f"real data file not found: {path}")
    return path
