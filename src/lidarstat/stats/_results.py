"""Result type of every vectorised hypothesis test."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TestResult:
    """Outcome of a hypothesis test, vectorised over points.

    Attributes
    ----------
    statistic : ndarray of float64
        Test statistic per point (NaN where the test could not be computed).
    pvalue : ndarray of float64
        p-value per point (NaN where undefined).
    df : ndarray of float64 or float
        Degrees of freedom of the reference distribution (per point where they vary).
    reject : ndarray of bool
        True where the null hypothesis is rejected at `alpha` (False where undefined).
    alpha : float
        Significance level used.
    """

    __test__ = False  # not a pytest class

    statistic: np.ndarray
    pvalue: np.ndarray
    df: np.ndarray | float
    reject: np.ndarray
    alpha: float

    @property
    def defined(self) -> np.ndarray:
        """True where the test could be computed."""
        return np.isfinite(self.pvalue)
