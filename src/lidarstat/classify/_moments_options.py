"""Options of the moments classification: the method, the analysis options, the units."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameterError
from ._cycle import ElevationRule

__all__ = ["MomentsMethod", "MomentsOptions", "unit_factors"]


class MomentsMethod(str, enum.Enum):
    """How a window's elevation cut is chosen.

    ``moments``: the sequential skewness/kurtosis procedure of Crosilla et al. (2011);
    ``skewness-balancing``: Bartels and Wei (2006), the highest points removed until the
    skewness of what is left is <= 0, in the same windows (the baseline).
    """

    MOMENTS = "moments"
    SKEWNESS_BALANCING = "skewness-balancing"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class MomentsOptions:
    """The options every analysis window uses (lengths in coordinate units).

    Attributes
    ----------
    alpha : float
        Level of the dip tests.
    min_points : int
        Smallest cluster a cut may leave on either side.
    smoothing : float
        Moving-average width of the curves as a fraction of the values analysed.
    cycle : int or None
        Separating cycle forced on the first analysis of every window.
    bandwidth : str or float
        Kernel density bandwidth of the reported densities.
    method : MomentsMethod
    elevation_rule : ElevationRule
    window, min_window : float
        Side of the root analysis windows and the smallest side a split may reach.
    ground_spread : float
        A cut stays at least this many robust standard deviations above the centre of
        the ground cluster it leaves (0: off).
    seed : int
        Seed of the dip tests' subsample and dequantisation.
    max_steps : int
        Most clustering steps per window (the paper's steps 1-4 repeated).
    building_alpha : float
        Level of the building tests (local plane, residual, patch share).
    sigma : float or None
        Noise std of the building tests in metres (None: estimated from the ground).
    evidence : bool
        Whether the recorded analyses carry what only the report reads: the density
        estimate of every analysed population and the dip test of every window's heights.
    """

    alpha: float
    min_points: int
    smoothing: float
    cycle: int | None
    bandwidth: object
    method: MomentsMethod
    elevation_rule: ElevationRule
    window: float
    min_window: float
    ground_spread: float
    seed: int = 0
    max_steps: int = 6
    building_alpha: float = 0.01
    sigma: float | None = None
    evidence: bool = True

    @property
    def min_window_points(self) -> int:
        """Fewest points of a window that a split leaves in each quadrant on average."""
        return 4 * self.min_points

    @property
    def finest_window(self) -> float:
        """Side of the smallest window the progressive split can make."""
        size = self.window
        while size / 2 >= self.min_window:
            size /= 2
        return size


def unit_factors(units, source=None) -> tuple[float, float]:
    """(horizontal, vertical) metres per coordinate unit from a number, pair or LinearUnits."""
    if hasattr(units, "horizontal"):
        pair = (units.horizontal, units.vertical)
    elif np.ndim(units) == 0:
        pair = (units, units)
    else:
        pair = tuple(units)
    if len(pair) != 2 or not all(np.isfinite(float(u)) and float(u) > 0 for u in pair):
        raise InvalidParameterError(f"{source or 'points'}: `units` must be metres per "
                                    f"coordinate unit > 0 (or a pair); got {units!r}")
    return float(pair[0]), float(pair[1])
