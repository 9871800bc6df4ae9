"""The independent machined parts as benchmark scenes (``tests/independent/indep_parts.py``).

Shared by ``covariance_parts.py`` and ``curvature_parts.py`` so that both score the same
scenes: per seed, the range image (z noise) and the terrestrial scan (range noise) of the
flanged and the bored part, drawn in that order from ``default_rng(1000 + seed)``.
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "independent"))

import indep_parts as ip  # noqa: E402

__all__ = ["MIN_SURFACE", "ip", "scenes"]

#: Faces scored by Hoover's measure (as in the tests): at least this many points.
MIN_SURFACE = 300


def scenes(seeds):
    """Yield ``(seed, scene, part, scan, truth)`` for seeds ``0..seeds-1``: `scene` the
    generator's name, `truth` the face ids of the faces of at least :data:`MIN_SURFACE`
    points (0 elsewhere)."""
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        for gen in (ip.range_image, ip.tls_scan):
            for kind in ("flange", "block"):
                scan = gen(rng, kind)
                cnt = np.bincount(scan.face)
                yield seed, gen.__name__, kind, scan, np.where(cnt[scan.face] >= MIN_SURFACE,
                                                                scan.face, 0)
