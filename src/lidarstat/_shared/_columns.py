"""Per-column minimum and maximum of a tall array.

``a.min(axis=0)`` on an (N, 2) or (N, 3) array reduces row by row without vectorisation
(about 50 ms per million rows); reducing each column on its own is 10-30 times faster and
gives the same values.
"""

from __future__ import annotations

import numpy as np


def column_min(a) -> np.ndarray:
    """``a.min(axis=0)`` of a 2-D array, one column at a time.

    >>> column_min(np.array([[3.0, 1.0], [2.0, 5.0]])).tolist()
    [2.0, 1.0]
    """
    a = np.asarray(a)
    return np.array([a[:, j].min() for j in range(a.shape[1])], dtype=a.dtype)


def column_max(a) -> np.ndarray:
    """``a.max(axis=0)`` of a 2-D array, one column at a time.

    >>> column_max(np.array([[3.0, 1.0], [2.0, 5.0]])).tolist()
    [3.0, 5.0]
    """
    a = np.asarray(a)
    return np.array([a[:, j].max() for j in range(a.shape[1])], dtype=a.dtype)
